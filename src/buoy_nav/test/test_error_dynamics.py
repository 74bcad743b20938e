"""The covariance's compiled propagation from the integrator's state vector against the error
model of the interval's sums, and the process noise against its closed form."""

import math

import numpy as np
import pytest

from buoy_nav import kalman_kernel
from buoy_nav.config import FusionConfig
from buoy_nav.error_dynamics import (
    discrete_error_model,
    propagated_covariance,
    stepped_covariance,
)
from buoy_nav.error_state_filter import ERROR_STATES, ImuErrorModel
from buoy_nav.mechanization import StrapdownIntegrator
from buoy_nav.strapdown_kernel import DURATION

IMU_MODEL = ImuErrorModel.from_config(FusionConfig())
RNG = np.random.default_rng(11)


def integrated(steps: int) -> StrapdownIntegrator:
    """An integrator carried over ``steps`` random 10-ms steps of a moving buoy at 35° N."""
    integrator = StrapdownIntegrator(
        (0.05, -0.02, 0.3, math.sqrt(1.0 - 0.05**2 - 0.02**2 - 0.3**2)),
        (1.2, -0.4, 0.05),
        math.radians(35.0),
        math.radians(120.0),
        3.0,
        (1e-4, -2e-4, 5e-5),
        (0.01, -0.02, 0.005),
    )
    gyro, force = RNG.normal(0.0, 0.2, 3), RNG.normal((0.0, 0.0, 9.8), 0.8)
    for _ in range(steps):
        gyro_next, force_next = RNG.normal(0.0, 0.2, 3), RNG.normal((0.0, 0.0, 9.8), 0.8)
        integrator.step(0.01, gyro, gyro_next, force, force_next)
        gyro, force = gyro_next, force_next
    return integrator


def random_covariance() -> np.ndarray:
    factor = RNG.normal(size=(ERROR_STATES.dim, ERROR_STATES.dim)) * 1e-2
    return factor @ factor.T + np.eye(ERROR_STATES.dim) * 1e-6


@pytest.mark.parametrize("scales", [(1.0, 1.0), (3.7, 2.2)])
@pytest.mark.parametrize("steps", [1, 10, 37])
def test_the_state_vectors_propagation_is_the_sums_error_model_to_the_bit(steps, scales):
    integrator = integrated(steps)
    covariance = random_covariance()
    state = integrator.state_vector.copy()
    transition, propagated = propagated_covariance(state, covariance, IMU_MODEL, *scales)
    nominal = integrator.state_vector[:DURATION].copy()
    expected_transition, noise = discrete_error_model(
        integrator.take_propagation_sums(),
        integrator.latitude_rad,
        integrator.altitude_m,
        integrator.velocity_enu_mps,
        IMU_MODEL,
        *scales,
    )
    assert np.array_equal(transition, expected_transition)
    assert np.array_equal(
        propagated, kalman_kernel.propagated(covariance, expected_transition, noise)
    )
    assert np.array_equal(state[:DURATION], nominal)
    assert not state[DURATION:].any(), "the sums restart"


@pytest.mark.parametrize("scales", [(1.0, 1.0), (3.7, 2.2)])
def test_the_bias_and_white_noise_terms_are_their_closed_forms(scales):
    gyro_drift_scale, accel_noise_scale = scales
    integrator = integrated(10)
    duration = integrator.accumulated_duration_s
    _, propagated = propagated_covariance(
        integrator.state_vector, np.zeros((ERROR_STATES.dim, ERROR_STATES.dim)), IMU_MODEL, *scales
    )
    # From a zero covariance the propagated one is the process noise itself.
    noise = np.diag(propagated)
    gyro_bias = noise[ERROR_STATES.gyro_bias]
    accel_bias = noise[ERROR_STATES.accel_bias]
    expected_gyro_drift = (
        2.0
        * (gyro_drift_scale * IMU_MODEL.gyro_markov_sigma_rad_s) ** 2
        * duration
        / IMU_MODEL.gyro_correlation_time_s
    )
    expected_accel_drift = (
        2.0 * IMU_MODEL.accel_markov_sigma_mps2**2 * duration / IMU_MODEL.accel_correlation_time_s
    )
    np.testing.assert_allclose(gyro_bias, expected_gyro_drift, rtol=1e-14)
    np.testing.assert_allclose(accel_bias, expected_accel_drift, rtol=1e-14)
    # The velocity's white noise: the accelerometer's density, scaled, over the interval, at
    # least (the scale-factor noise adds to it).
    velocity = noise[ERROR_STATES.velocity]
    assert np.all(
        velocity >= accel_noise_scale**2 * IMU_MODEL.accel_noise_psd_m2_s3 * duration * (1 - 1e-12)
    )


@pytest.mark.parametrize("corrections", [(True, True), (False, True), (True, False)])
@pytest.mark.parametrize("steps", [0, 1, 9])
def test_the_step_and_the_propagation_in_one_call_are_the_two_calls_to_the_bit(steps, corrections):
    """A step to a measurement's stamp, after ``steps`` steps of the batch: the state, Φ and
    the covariance of one call are those of the integrator's step followed by the
    propagation."""
    integrator = integrated(steps)
    integrator.coning_correction, integrator.sculling_correction = corrections
    covariance = random_covariance()
    samples = (
        RNG.normal(0.0, 0.2, 3).tolist(),
        RNG.normal(0.0, 0.2, 3).tolist(),
        RNG.normal((0.0, 0.0, 9.8), 0.8).tolist(),
        RNG.normal((0.0, 0.0, 9.8), 0.8).tolist(),
    )
    gyro_start, gyro_end, force_start, force_end = samples
    one_call_state = integrator.state_vector.copy()
    transition, propagated = stepped_covariance(
        one_call_state,
        covariance,
        0.0071,
        gyro_start,
        gyro_end,
        force_start,
        force_end,
        corrections,
        IMU_MODEL,
        1.3,
        2.1,
    )
    integrator.step(0.0071, gyro_start, gyro_end, force_start, force_end)
    expected_transition, expected = propagated_covariance(
        integrator.state_vector, covariance, IMU_MODEL, 1.3, 2.1
    )
    assert np.array_equal(one_call_state, integrator.state_vector)
    assert np.array_equal(transition, expected_transition)
    assert np.array_equal(propagated, expected)
    assert one_call_state[DURATION] == 0.0
