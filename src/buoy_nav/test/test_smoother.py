"""The fixed-interval smoother of the closed-loop filter against the textbook RTS smoother.

For a linear system the closed-loop filter (the estimate injected into the nominal state after
each update, the error mean reset to zero) and the open-loop filter estimate the same state, so
the closed-loop smoother of :mod:`buoy_nav.smoother` must reproduce the Rauch–Tung–Striebel
smoother of the open-loop filter, written here from its textbook form, to rounding.
"""

import numpy as np
import pytest

from buoy_nav.smoother import SmootherRecorder, SymmetricPacking
from buoy_nav.spill import BLOCK_RECORDS, SpillDirectory
from buoy_nav.state_layout import StateLayout

STATES = StateLayout(("position", 2), ("velocity", 2), ("bias", 1))
STEP_S = 0.1


def linear_system():
    """A 2-D constant-velocity model with a random-walk bias on the x position measurement."""
    transition = np.eye(5)
    transition[0, 2] = transition[1, 3] = STEP_S
    noise = np.diag((1e-4, 1e-4, 1e-2, 1e-2, 1e-5))
    measurement = np.zeros((2, 5))
    measurement[0, 0] = measurement[1, 1] = 1.0
    measurement[0, 4] = 1.0
    return transition, noise, measurement, np.diag((0.25, 0.25))


def simulate(steps, seed, measured_every=1):
    rng = np.random.default_rng(seed)
    transition, noise, measurement, measurement_noise = linear_system()
    state = rng.normal(size=5)
    truth, measurements = [], []
    for k in range(steps):
        if k:
            state = transition @ state + rng.multivariate_normal(np.zeros(5), noise)
        truth.append(state)
        z = measurement @ state + rng.multivariate_normal(np.zeros(2), measurement_noise)
        measurements.append(z if k % measured_every == 0 else None)
    return np.array(truth), measurements


def update(covariance, innovation, measurement, measurement_noise):
    s = measurement @ covariance @ measurement.T + measurement_noise
    gain = covariance @ measurement.T @ np.linalg.inv(s)
    i_kh = np.eye(covariance.shape[0]) - gain @ measurement
    return gain @ innovation, i_kh @ covariance @ i_kh.T + gain @ measurement_noise @ gain.T


def textbook_rts(measurements, initial_mean, initial_covariance):
    """Open-loop Kalman filter and RTS smoother (Rauch, Tung, Striebel 1965)."""
    transition, noise, measurement, measurement_noise = linear_system()
    means, covariances, priors, prior_covariances = [], [], [], []
    mean, covariance = initial_mean, initial_covariance
    for k, z in enumerate(measurements):
        if k:
            mean = transition @ mean
            covariance = transition @ covariance @ transition.T + noise
        priors.append(mean)
        prior_covariances.append(covariance)
        if z is not None:
            correction, covariance = update(
                covariance, z - measurement @ mean, measurement, measurement_noise
            )
            mean = mean + correction
        means.append(mean)
        covariances.append(covariance)
    smoothed, smoothed_covariances = [means[-1]], [covariances[-1]]
    for k in range(len(measurements) - 2, -1, -1):
        gain = covariances[k] @ transition.T @ np.linalg.inv(prior_covariances[k + 1])
        smoothed.insert(0, means[k] + gain @ (smoothed[0] - priors[k + 1]))
        smoothed_covariances.insert(
            0,
            covariances[k] + gain @ (smoothed_covariances[0] - prior_covariances[k + 1]) @ gain.T,
        )
    return np.array(smoothed), np.array(smoothed_covariances)


def closed_loop_smoother(measurements, initial_mean, initial_covariance, spill):
    """The closed-loop filter with the recorder hooked in as the engine hooks it; returns the
    nominal states and the smoothed errors and covariances at the epochs."""
    transition, noise, measurement, measurement_noise = linear_system()
    recorder = SmootherRecorder(STATES, spill)
    nominal, covariance = initial_mean.copy(), initial_covariance
    recorder.begin_segment(0.0, covariance)
    nominals = []
    for k, z in enumerate(measurements):
        if k:
            nominal = transition @ nominal
            posterior = covariance
            covariance = transition @ covariance @ transition.T + noise
            recorder.propagated(k * STEP_S, transition, covariance, posterior)
        if z is not None:
            correction, covariance = update(
                covariance, z - measurement @ nominal, measurement, measurement_noise
            )
            nominal = nominal + correction
            recorder.corrected(correction)
        nominals.append(nominal)
    recorder.end_segment(covariance)
    epochs = recorder.smooth()
    error, smoothed_covariance = epochs.at(np.arange(len(measurements)) * STEP_S)
    return np.array(nominals), error, smoothed_covariance


@pytest.mark.parametrize("measured_every", [1, 3])
def test_closed_loop_smoother_is_the_textbook_rts_smoother(measured_every):
    """Over more epochs than one block of records, with measurements at every epoch and at
    every third one (epochs without a correction)."""
    steps = BLOCK_RECORDS + 500
    _, measurements = simulate(steps, seed=1, measured_every=measured_every)
    initial_mean, initial_covariance = np.zeros(5), np.eye(5)
    expected, expected_covariance = textbook_rts(measurements, initial_mean, initial_covariance)
    with SpillDirectory() as spill:
        nominal, error, covariance = closed_loop_smoother(
            measurements, initial_mean, initial_covariance, spill
        )
    np.testing.assert_allclose(nominal + error, expected, atol=1e-9)
    np.testing.assert_allclose(covariance, expected_covariance, atol=1e-9)


def test_smoothed_errors_are_consistent_and_smaller_than_the_filtered_ones():
    """Against the simulated truth: the smoothed error normalised by the smoothed covariance
    has mean 5 (the state dimension), and the smoothed position and velocity errors are smaller
    than the filtered ones (the bias, which the x measurement cannot tell from the x position,
    is left out)."""
    steps = 3000
    truth, measurements = simulate(steps, seed=2)
    with SpillDirectory() as spill:
        nominal, error, covariance = closed_loop_smoother(
            measurements, truth[0], 1e-6 * np.eye(5), spill
        )
    smoothed_error = truth - (nominal + error)
    nees = np.einsum(
        "ni,ni->n", smoothed_error, np.linalg.solve(covariance, smoothed_error[..., None])[..., 0]
    )
    # Consecutive epochs are correlated: a mean over 3000 of them is far from 3000 independent
    # samples, hence the generous bounds; a covariance off by a factor of 2 still fails.
    assert 5 * 0.75 < nees.mean() < 5 * 1.33
    filtered_rms = np.sqrt(np.mean((truth - nominal) ** 2, axis=0))
    smoothed_rms = np.sqrt(np.mean(smoothed_error**2, axis=0))
    assert np.all(smoothed_rms[:4] < 0.8 * filtered_rms[:4])


def test_segments_are_smoothed_apart():
    """A reset ends a segment: the last epoch before it keeps its filtered estimate (zero
    smoothed error) and the first after it does not look back."""
    transition = np.eye(5)
    with SpillDirectory() as spill:
        recorder = SmootherRecorder(STATES, spill)
        recorder.begin_segment(0.0, np.eye(5))
        recorder.propagated(0.1, transition, 2 * np.eye(5), np.eye(5))
        recorder.corrected(np.ones(5))
        recorder.end_segment(np.eye(5))
        recorder.begin_segment(0.2, np.eye(5))
        recorder.propagated(0.3, transition, 2 * np.eye(5), np.eye(5))
        recorder.corrected(np.full(5, 2.0))
        recorder.end_segment(np.eye(5))
        error, _ = recorder.smooth().at(np.array((0.0, 0.1, 0.2, 0.3)))
    # Within a segment the first epoch is pulled half way (P⁺ = I, P⁻ = 2I) to the correction.
    np.testing.assert_allclose(error, [np.full(5, 0.5), np.zeros(5), np.ones(5), np.zeros(5)])


def test_an_inflation_of_the_covariance_is_process_noise_at_its_stamp():
    """The integrity monitor's inflation (P⁺ = I widened to 3I at 0.1 s) is an epoch of zero
    duration with Φ = I: the RTS gain across it is P⁺ (P⁺ + Q)⁻¹ = 1/3, so a third of what
    follows reaches back across it."""
    identity = np.eye(5)
    with SpillDirectory() as spill:
        recorder = SmootherRecorder(STATES, spill)
        recorder.begin_segment(0.0, identity)
        recorder.propagated(0.1, identity, 2 * identity, identity)
        recorder.corrected(np.ones(5))
        recorder.noise_added(0.1, identity, 3 * identity)
        recorder.propagated(0.2, identity, 4 * identity, 3 * identity)
        recorder.corrected(np.full(5, 2.0))
        recorder.end_segment(identity)
        error, covariance = recorder.smooth().at(np.array((0.0, 0.1, 0.2)))
    # Backwards: at 0.1 s after the inflation C = 3/4, δx = 3/4 · 2 = 1.5 and
    # P^s = 3 + (3/4)² (1 − 4) = 1.3125; before it C = 1/3, δx = (1.5 + 0) / 3 = 0.5, relative to
    # the state before its correction of 1 that is 1.5; at 0 s C = 1/2: 0.75.
    np.testing.assert_allclose(error, [np.full(5, 0.75), np.full(5, 1.5), np.zeros(5)])
    np.testing.assert_allclose(covariance[1], 1.3125 * identity)


def test_symmetric_packing_round_trip():
    rng = np.random.default_rng(0)
    matrix = rng.normal(size=(7, 7))
    matrix = matrix + matrix.T
    packing = SymmetricPacking(7)
    np.testing.assert_array_equal(packing.unpack(packing.pack(matrix)), matrix)
