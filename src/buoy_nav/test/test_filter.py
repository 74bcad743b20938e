"""Error-state filter: error model against the mechanization, Kalman algebra, gating."""

import math

import numpy as np
import pytest
from scipy.spatial.transform import Rotation
from scipy.stats import chi2

from buoy_nav import earth
from buoy_nav.config import FusionConfig
from buoy_nav.error_dynamics import discrete_error_model
from buoy_nav.error_state_filter import (
    ERROR_STATES,
    ErrorStateFilter,
    ImuErrorModel,
    NavState,
    inject_error_state,
)
from buoy_nav.mechanization import StrapdownIntegrator
from buoy_nav.rotations import (
    rotation_matrix_from_rotation_vector,
    rotation_vector_from_rotation_matrix,
)

RNG = np.random.default_rng(5)
STATES = ERROR_STATES
STATE_DIM = STATES.dim
IMU_MODEL = ImuErrorModel.from_config(FusionConfig())


def imu_sample(t):
    """A buoy-like motion: rates of tenths of rad/s and wave accelerations on gravity (body)."""
    gyro = np.array(
        (0.3 * math.sin(1.1 * t), -0.2 * math.cos(0.7 * t + 0.3), 0.1 + 0.05 * math.sin(0.4 * t))
    )
    force = np.array(
        (0.8 * math.sin(0.9 * t), 1.1 * math.cos(0.6 * t), 9.8 + 1.5 * math.sin(1.3 * t + 1.0))
    )
    return gyro, force


def integrator_from(state: NavState) -> StrapdownIntegrator:
    return StrapdownIntegrator(
        state.attitude_xyzw,
        state.velocity_enu_mps,
        state.latitude_rad,
        state.longitude_rad,
        state.altitude_m,
        state.gyro_bias_rad_s,
        state.accel_bias_mps2,
    )


def error_between(true: StrapdownIntegrator, nominal: StrapdownIntegrator) -> np.ndarray:
    """The 15-state error true − nominal, in the filter's parameterisation."""
    phi = rotation_vector_from_rotation_matrix(true.rotation_nb @ nominal.rotation_nb.T)
    position = earth.enu_offset_scalar(
        nominal.latitude_rad,
        nominal.longitude_rad,
        nominal.altitude_m,
        true.latitude_rad,
        true.longitude_rad,
        true.altitude_m,
    )
    return np.concatenate(
        (
            phi,
            np.subtract(true.velocity_enu_mps, nominal.velocity_enu_mps),
            position,
            np.subtract(true.gyro_bias_rad_s, nominal.gyro_bias_rad_s),
            np.subtract(true.accel_bias_mps2, nominal.accel_bias_mps2),
        )
    )


def test_error_model_predicts_the_mechanization_difference():
    """Φ from the batched propagation sums maps an initial error to the error that two strapdown
    runs (nominal, and nominal with the error injected) actually develop on the same IMU data."""
    nominal_state = NavState(
        attitude_xyzw=tuple(Rotation.from_euler("ZYX", [0.8, 0.15, -0.2]).as_quat()),
        velocity_enu_mps=np.array((1.0, -0.5, 0.2)),
        latitude_rad=math.radians(35.0),
        longitude_rad=math.radians(120.0),
        altitude_m=2.0,
        gyro_bias_rad_s=np.array((1e-3, -2e-3, 5e-4)),
        accel_bias_mps2=np.array((0.02, -0.01, 0.03)),
    )
    initial_error = np.concatenate(
        (
            (2e-3, -1.5e-3, 3e-3),
            (0.02, -0.01, 0.015),
            (0.3, -0.2, 0.1),
            (2e-4, -1e-4, 3e-4),
            (0.02, 0.03, -0.02),
        )
    )
    nominal = integrator_from(nominal_state)
    true = integrator_from(inject_error_state(nominal_state, initial_error))
    np.testing.assert_allclose(error_between(true, nominal), initial_error, rtol=1e-6, atol=1e-9)

    dt, steps_per_interval, intervals = 0.01, 10, 20
    transition = np.eye(STATE_DIM)
    gyro0, force0 = imu_sample(0.0)
    for interval in range(intervals):
        for step in range(steps_per_interval):
            t1 = (interval * steps_per_interval + step + 1) * dt
            gyro1, force1 = imu_sample(t1)
            nominal.step(dt, gyro0, gyro1, force0, force1)
            true.step(dt, gyro0, gyro1, force0, force1)
            gyro0, force0 = gyro1, force1
        sums = nominal.take_propagation_sums()
        true.take_propagation_sums()
        phi_k, _ = discrete_error_model(
            sums, nominal.latitude_rad, nominal.altitude_m, nominal.velocity_enu_mps, IMU_MODEL
        )
        transition = phi_k @ transition

    actual = error_between(true, nominal)
    predicted = transition @ initial_error
    change = actual - initial_error
    # Over 2 s the errors change by mrad, cm/s and cm; the linear model predicts the change to
    # within a few percent (the remainder is second order in the error).
    for block in (STATES.attitude, STATES.velocity, STATES.position):
        assert np.linalg.norm(actual[block] - predicted[block]) < 0.03 * np.linalg.norm(
            change[block]
        ), block
    # The bias errors persist (random walk without decay), as in the two strapdown runs.
    for block in (STATES.gyro_bias, STATES.accel_bias):
        np.testing.assert_array_equal(predicted[block], initial_error[block])
        np.testing.assert_allclose(actual[block], initial_error[block], rtol=1e-12)


def test_bias_errors_are_random_walks_with_the_gauss_markov_driving_noise():
    """No decay (the switch-on bias does not go away); variance grows by 2σ²T/τ."""
    transition, noise = discrete_error_model(_still_sums(0.1), 0.6, 0.0, np.zeros(3), IMU_MODEL)
    biases = slice(STATES.gyro_bias.start, STATES.accel_bias.stop)
    np.testing.assert_array_equal(transition[biases, biases], np.eye(6))
    for block, sigma, tau in (
        (STATES.gyro_bias, IMU_MODEL.gyro_markov_sigma_rad_s, IMU_MODEL.gyro_correlation_time_s),
        (STATES.accel_bias, IMU_MODEL.accel_markov_sigma_mps2, IMU_MODEL.accel_correlation_time_s),
    ):
        np.testing.assert_allclose(noise[block, block], 2 * sigma**2 * 0.1 / tau * np.eye(3))


def test_white_noise_grows_linearly_with_time():
    one = discrete_error_model(_still_sums(0.1), 0.6, 0.0, np.zeros(3), IMU_MODEL)[1]
    two = discrete_error_model(_still_sums(0.2), 0.6, 0.0, np.zeros(3), IMU_MODEL)[1]
    white = slice(STATES.attitude.start, STATES.velocity.stop)
    np.testing.assert_allclose(two[white, white], 2 * one[white, white], rtol=1e-12)
    east = STATES.index("attitude", 0)
    assert one[east, east] == pytest.approx(IMU_MODEL.gyro_noise_psd_rad2_s * 0.1)
    # 0.2 °/√h: after one hour, 1σ = 0.2°.
    assert math.sqrt(IMU_MODEL.gyro_noise_psd_rad2_s * 3600) == pytest.approx(math.radians(0.2))


def _still_sums(duration):
    from buoy_nav.mechanization import PropagationSums

    return PropagationSums(
        duration_s=duration,
        rotation_integral_s=np.eye(3) * duration,
        specific_force_increment_enu_mps=np.array((0.0, 0.0, 9.8 * duration)),
        gyro_rate_sq_integral_rad2_s=np.zeros(3),
        force_deviation_sq_integral_m2_s3=np.zeros(3),
    )


def random_covariance(size, scale=1.0):
    matrix = RNG.normal(size=(size, size)) * scale
    return matrix @ matrix.T + np.eye(size) * 1e-3 * scale**2


def test_joseph_update_equals_the_textbook_kalman_update():
    prior = random_covariance(STATE_DIM)
    h = RNG.normal(size=(3, STATE_DIM))
    r = random_covariance(3, 0.5)
    nu = RNG.normal(size=3)
    kalman = ErrorStateFilter(prior, 0.9999)
    correction = kalman.update(nu, h, r)
    gain = prior @ h.T @ np.linalg.inv(h @ prior @ h.T + r)
    np.testing.assert_allclose(correction, gain @ nu, rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(
        kalman.covariance, (np.eye(STATE_DIM) - gain @ h) @ prior, rtol=1e-8, atol=1e-10
    )


def test_stacked_update_equals_sequential_updates():
    """Independent measurements applied together or one after the other: same posterior."""
    prior = random_covariance(STATE_DIM)
    h1, h2 = RNG.normal(size=(3, STATE_DIM)), RNG.normal(size=(1, STATE_DIM))
    r1, r2 = random_covariance(3, 0.3), np.array([[0.2]])
    nu1, nu2 = RNG.normal(size=3), RNG.normal(size=1)
    stacked = ErrorStateFilter(prior, 0.9999)
    r = np.zeros((4, 4))
    r[:3, :3], r[3:, 3:] = r1, r2
    joint = stacked.update(np.concatenate((nu1, nu2)), np.vstack((h1, h2)), r)
    sequential = ErrorStateFilter(prior, 0.9999)
    first = sequential.update(nu1, h1, r1)
    # Second update on the residual innovation after the first correction (error-state mean).
    second = sequential.update(nu2 - h2 @ first, h2, r2)
    np.testing.assert_allclose(joint, first + second, rtol=1e-8, atol=1e-10)
    np.testing.assert_allclose(stacked.covariance, sequential.covariance, rtol=1e-8, atol=1e-10)


@pytest.mark.parametrize("probability", [0.95, 0.99, 0.9999])
def test_gate_threshold_is_the_chi_square_quantile_for_each_dimension(probability):
    kalman = ErrorStateFilter(np.eye(STATE_DIM), probability)
    for dimension in range(1, 7):
        assert kalman.gate_threshold(dimension) == pytest.approx(
            chi2.ppf(probability, dimension), rel=1e-12
        )


def test_gate_uses_the_chi_square_quantile_and_rejects_an_outlier():
    prior = np.eye(STATE_DIM) * 1e-2
    h = np.zeros((3, STATE_DIM))
    h[:, STATES.velocity] = np.eye(3)
    r = np.eye(3) * 4e-4
    kalman = ErrorStateFilter(prior, 0.9999)
    s = 1e-2 + 4e-4
    assert kalman.gate_threshold(3) == pytest.approx(chi2.ppf(0.9999, 3))
    inlier = kalman.gate(np.array((0.1, -0.05, 0.08)), h, r)
    assert inlier.accepted
    assert inlier.nis == pytest.approx((0.1**2 + 0.05**2 + 0.08**2) / s)
    outlier = kalman.gate(np.array((0.0, 0.0, 1.0)), h, r)
    assert not outlier.accepted
    assert outlier.nis == pytest.approx(1.0 / s)
    # A source with a narrower gate of its own rejects the inlier.
    narrow = kalman.gate(np.array((0.1, -0.05, 0.08)), h, r, probability=0.1)
    assert not narrow.accepted and narrow.threshold == pytest.approx(chi2.ppf(0.1, 3))
    assert narrow.nis == inlier.nis
    assert kalman.gate_threshold(3) == pytest.approx(chi2.ppf(0.9999, 3))


def test_nis_is_chi_square_distributed_when_the_model_is_right():
    prior = random_covariance(STATE_DIM, 0.1)
    h = RNG.normal(size=(3, STATE_DIM))
    r = random_covariance(3, 0.05)
    kalman = ErrorStateFilter(prior, 0.9999)
    s = h @ prior @ h.T + r
    samples = RNG.multivariate_normal(np.zeros(3), s, size=4000)
    nis = np.array([kalman.gate(nu, h, r).nis for nu in samples])
    # Mean 3 (dof) with standard error sqrt(6 / 4000).
    assert abs(nis.mean() - 3.0) < 4 * math.sqrt(6 / 4000)
    assert np.mean(nis > chi2.ppf(0.99, 3)) == pytest.approx(0.01, abs=0.006)


def test_covariance_repair_restores_positive_definiteness_and_is_counted():
    prior = np.eye(STATE_DIM)
    kalman = ErrorStateFilter(prior, 0.9999)
    assert not kalman.ensure_positive_definite()
    broken = np.eye(STATE_DIM)
    broken[0, 1] = broken[1, 0] = 1.5  # indefinite
    kalman.covariance = broken
    assert kalman.ensure_positive_definite()
    assert kalman.covariance_repairs == 1
    assert np.all(np.linalg.eigvalsh(kalman.covariance) > 0)
    np.testing.assert_allclose(kalman.covariance, kalman.covariance.T)


def test_reset_jacobian_matches_the_composition_of_rotations():
    """After injecting δφ̂, the remaining error φ' = Log(Exp(φ) Exp(−δφ̂)) has ∂φ'/∂φ = I + ½[δφ̂×]."""
    correction = np.array((0.02, -0.03, 0.05))
    base = np.array((0.001, 0.002, -0.001))

    def remaining(phi):
        return rotation_vector_from_rotation_matrix(
            rotation_matrix_from_rotation_vector(phi)
            @ rotation_matrix_from_rotation_vector(-correction)
        )

    numeric = np.column_stack(
        [(remaining(base + e * 1e-6) - remaining(base - e * 1e-6)) / 2e-6 for e in np.eye(3)]
    )
    # With P_φφ = I and P_φv = 0.5 I the reset turns the cross block into 0.5 G.
    attitude, velocity = STATES.attitude, STATES.velocity
    prior = np.eye(STATE_DIM)
    prior[attitude, velocity] = prior[velocity, attitude] = 0.5 * np.eye(3)
    kalman = ErrorStateFilter(prior, 0.9999)
    update = np.zeros(STATE_DIM)
    update[attitude] = correction
    kalman.reset_after_injection(update)
    g = kalman.covariance[attitude, velocity] / 0.5
    # Equal up to the second-order term |δφ̂|²/12 ≈ 3e-4 of the exact Jacobian.
    np.testing.assert_allclose(g, numeric, atol=1e-3)
    assert np.abs(g - g.T).max() > 0.02  # the skew part, whose sign matters, is present
