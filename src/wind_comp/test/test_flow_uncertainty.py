"""The corrected flow's covariance against Monte Carlo runs of the full (nonlinear) Miller
correction: perturbed navigation and sensor samples go through ``miller_correction``, and the
scatter of the results is held against the stated covariance."""

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from wind_comp.flow_uncertainty import (
    FlowCovariance,
    bound_of_correlated_sum,
    corrected_flow_covariance_enu,
    horizontal_and_vertical_sigma,
    window_mean_covariance_enu,
)
from wind_comp.miller import miller_correction, mounting_rotation_from_rpy_deg

DRAWS = 40_000
ATTITUDE = Rotation.from_euler("ZYX", [35.0, 8.0, -12.0], degrees=True)
MOUNTING = mounting_rotation_from_rpy_deg((2.0, -3.0, 150.0))
LEVER_ARM_M = np.array([0.2, -0.15, 2.7])
FLOW_SENSOR_MPS = np.array([-7.0, 3.0, 0.4])
RATE_RAD_S = np.array([0.15, -0.25, 0.05])
VELOCITY_MPS = np.array([0.6, -0.3, 0.8])


def _random_covariance(rng, size, scales):
    """A full (correlated) covariance of the given per-component standard deviations."""
    factor = rng.normal(size=(size, size))
    correlation = factor @ factor.T + 0.05 * np.eye(size)
    d = np.sqrt(np.diag(correlation))
    correlation /= np.outer(d, d)
    return correlation * np.outer(scales, scales)


def _monte_carlo_errors(joint_covariance, seed=0):
    """(DRAWS, 3) corrected-flow errors (perturbed minus nominal) for errors in (attitude rad,
    velocity m/s, rate rad/s, sensor m/s) drawn from the 12×12 ``joint_covariance``."""
    rng = np.random.default_rng(seed)
    errors = rng.multivariate_normal(np.zeros(12), joint_covariance, size=DRAWS)
    nominal = miller_correction(
        FLOW_SENSOR_MPS, ATTITUDE, RATE_RAD_S, VELOCITY_MPS, MOUNTING, LEVER_ARM_M
    ).true_wind_enu_mps
    # The true attitude is the estimate turned by the small ENU rotation δθ.
    perturbed = miller_correction(
        FLOW_SENSOR_MPS + errors[:, 9:12],
        Rotation.from_rotvec(errors[:, 0:3]) * ATTITUDE,
        RATE_RAD_S + errors[:, 6:9],
        VELOCITY_MPS + errors[:, 3:6],
        MOUNTING,
        LEVER_ARM_M,
    ).true_wind_enu_mps
    return perturbed - nominal


def _stated(joint_covariance):
    blocks = [joint_covariance[i : i + 3, i : i + 3][None] for i in (0, 3, 6, 9)]
    return corrected_flow_covariance_enu(
        ATTITUDE.as_matrix()[None],
        MOUNTING.as_matrix(),
        LEVER_ARM_M,
        FLOW_SENSOR_MPS[None],
        RATE_RAD_S[None],
        blocks[0],
        blocks[1],
        blocks[2],
        blocks[3][0],
    ).total[0]


def _block_diagonal(*blocks):
    joint = np.zeros((12, 12))
    for i, block in enumerate(blocks):
        joint[3 * i : 3 * i + 3, 3 * i : 3 * i + 3] = block
    return joint


@pytest.mark.parametrize(
    "which", ["attitude", "velocity", "rate", "sensor"], ids=lambda name: f"{name}_alone"
)
def test_each_error_alone_matches_the_scatter_of_the_full_correction(which):
    rng = np.random.default_rng(3)
    scales = {"attitude": 0.02, "velocity": 0.3, "rate": 0.05, "sensor": 0.1}
    blocks = [np.zeros((3, 3)) for _ in range(4)]
    index = list(scales).index(which)
    blocks[index] = _random_covariance(rng, 3, np.full(3, scales[which]))
    joint = _block_diagonal(*blocks)
    errors = _monte_carlo_errors(joint)
    stated = _stated(joint)
    # One term alone: the bound is that term exactly, so the scatter must match it.
    np.testing.assert_allclose(np.cov(errors.T), stated, rtol=0.05, atol=1e-4 * np.trace(stated))
    # A lever arm or a relative wind maps a 3-D error onto a plane: the normalised error's mean
    # is the rank of the stated covariance.
    rank = np.linalg.matrix_rank(stated, tol=1e-9 * np.abs(stated).max())
    nees = np.einsum(
        "ni,ij,nj->n", errors, np.linalg.pinv(stated, rcond=1e-9, hermitian=True), errors
    )
    assert abs(nees.mean() - rank) < 0.1


def test_correlated_navigation_errors_never_exceed_the_stated_covariance():
    """The messages carry no cross-covariances: with strongly correlated attitude, velocity and
    rate errors, every direction's scattered variance stays within the stated one."""
    rng = np.random.default_rng(11)
    navigation = _random_covariance(
        rng, 9, np.r_[np.full(3, 0.01), np.full(3, 0.05), 0.02, 0.02, 0.02]
    )
    joint = np.zeros((12, 12))
    joint[:9, :9] = navigation
    joint[9:, 9:] = np.diag([0.05, 0.05, 0.03]) ** 2
    scatter = np.cov(_monte_carlo_errors(joint, seed=5).T)
    stated = _stated(joint)
    # stated − scatter is positive semi-definite (up to the Monte Carlo error of 40,000 draws).
    assert np.linalg.eigvalsh(stated - scatter).min() > -0.02 * np.trace(stated)


def test_the_worst_correlation_reaches_the_bound_along_its_direction():
    """Two errors perfectly correlated along one axis: the bound's trace is the tightest that
    holds for every correlation, (√tr A + √tr B)², reached when they add in step."""
    a = np.diag([4.0, 0.0, 0.0])[None]
    b = np.diag([1.0, 0.0, 0.0])[None]
    bound = bound_of_correlated_sum([a, b])
    assert bound[0, 0, 0] == pytest.approx((2.0 + 1.0) ** 2)
    assert bound[0, 1, 1] == bound[0, 2, 2] == 0.0
    only = bound_of_correlated_sum([a, np.zeros_like(a)])
    np.testing.assert_array_equal(only, a)


def test_a_batch_gives_each_sample_what_it_gives_alone():
    rng = np.random.default_rng(2)
    n = 5
    rotations = Rotation.random(n, random_state=4).as_matrix()
    covariances = [
        np.stack([_random_covariance(rng, 3, np.full(3, s)) for _ in range(n)])
        for s in (0.01, 0.2, 0.03)
    ]
    flows, rates = rng.normal(size=(n, 3)) * 5, rng.normal(size=(n, 3)) * 0.2
    noise = np.diag([0.05, 0.05, 0.03]) ** 2
    batch = corrected_flow_covariance_enu(
        rotations, MOUNTING.as_matrix(), LEVER_ARM_M, flows, rates, *covariances, noise
    ).total
    for i in range(n):
        alone = corrected_flow_covariance_enu(
            rotations[i : i + 1],
            MOUNTING.as_matrix(),
            LEVER_ARM_M,
            flows[i : i + 1],
            rates[i : i + 1],
            *(c[i : i + 1] for c in covariances),
            noise,
        ).total
        np.testing.assert_array_equal(batch[i], alone[0])


def _skew(v):
    return np.array([[0.0, -v[2], v[1]], [v[2], 0.0, -v[0]], [-v[1], v[0], 0.0]])


def test_the_compiled_covariance_is_the_first_order_formula():
    """The module docstring's formula with numpy's matrices, sample by sample, against the
    compiled loop over a batch: equal to rounding (1e-14 of each matrix's largest element)."""
    rng = np.random.default_rng(3)
    n = 50
    rotations = Rotation.random(n, random_state=5).as_matrix()
    covariances = [
        np.stack([_random_covariance(rng, 3, np.full(3, s)) for _ in range(n)])
        for s in (0.01, 0.2, 0.03)
    ]
    noises = np.stack([_random_covariance(rng, 3, np.full(3, 0.05)) for _ in range(n)])
    flows, rates = rng.normal(size=(n, 3)) * 5, rng.normal(size=(n, 3)) * 0.2
    mounting = MOUNTING.as_matrix()
    compiled = corrected_flow_covariance_enu(
        rotations, mounting, LEVER_ARM_M, flows, rates, *covariances, noises
    )
    for i in range(n):
        rotation = rotations[i]
        a = rotation @ (mounting @ flows[i] + np.cross(rates[i], LEVER_ARM_M))
        rate_jacobian = rotation @ _skew(LEVER_ARM_M)
        terms = [
            _skew(a) @ covariances[0][i] @ _skew(a).T,
            covariances[1][i],
            rate_jacobian @ covariances[2][i] @ rate_jacobian.T,
        ]
        roots = [np.sqrt(np.trace(term)) for term in terms]
        navigation = sum(term * sum(roots) / root for term, root in zip(terms, roots, strict=True))
        sensor = rotation @ mounting @ noises[i] @ (rotation @ mounting).T
        for ours, formula in ((compiled.navigation[i], navigation), (compiled.sensor[i], sensor)):
            np.testing.assert_allclose(ours, formula, rtol=0, atol=1e-14 * np.abs(formula).max())


def test_horizontal_and_vertical_sigma():
    covariance = np.diag([9.0, 16.0, 4.0])[None]
    horizontal, vertical = horizontal_and_vertical_sigma(covariance)
    assert horizontal[0] == pytest.approx(5.0)
    assert vertical[0] == pytest.approx(2.0)


def test_a_window_mean_keeps_a_common_navigation_error_and_averages_the_noise():
    """N samples sharing one velocity error (as through a GNSS outage) and each with its own
    sensor noise: the mean's scatter is the shared error's plus the noise over N."""
    rng = np.random.default_rng(8)
    n, draws = 50, 20_000
    shared = np.diag([0.2, 0.1, 0.02]) ** 2
    noise = np.diag([0.3, 0.3, 0.2]) ** 2
    common = rng.multivariate_normal(np.zeros(3), shared, size=draws)
    own = rng.multivariate_normal(np.zeros(3), noise, size=(draws, n))
    means = common + own.mean(axis=1)
    stated = window_mean_covariance_enu(
        FlowCovariance(np.broadcast_to(shared, (n, 3, 3)), np.broadcast_to(noise, (n, 3, 3)))
    )
    np.testing.assert_allclose(np.diag(np.cov(means.T)), np.diag(stated), rtol=0.05)
    # Independent navigation errors would average down: the bound then overstates, never less.
    independent = rng.multivariate_normal(np.zeros(3), shared, size=(draws, n)).mean(axis=1)
    assert np.all(np.diag(np.cov(independent.T)) <= np.diag(stated))


def test_an_empty_window_has_no_mean():
    empty = FlowCovariance(np.empty((0, 3, 3)), np.empty((0, 3, 3)))
    assert np.all(np.isnan(window_mean_covariance_enu(empty)))
