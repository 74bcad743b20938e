"""IMU model: exact physics of the ideal output and statistics of the errors."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.stats import chi2

from sensor_sim.geodesy import wgs84_normal_gravity_mps2
from sensor_sim.scenario import load_scenario
from sensor_sim.sensor_errors import ImuErrorConfig
from sensor_sim.sensor_models import ImuSimulator
from sensor_sim.truth import TruthModel

EARTH_RATE = 7.292115e-5
A = 6378137.0
E2 = 0.00669437999014
GAMMA_EQUATOR = 9.7803253359
SOMIGLIANA_K = 0.00193185265241
NO_ERRORS = ImuErrorConfig(
    gyro_noise_deg_sqrt_h=0.0,
    gyro_turn_on_bias_deg_s=0.0,
    gyro_bias_instability_deg_h=0.0,
    accel_noise_mps_sqrt_h=0.0,
    accel_turn_on_bias_mg=0.0,
    accel_bias_instability_mg=0.0,
    scale_factor_error_percent=0.0,
)


def still(roll_deg, pitch_deg, yaw_deg, latitude_deg=38.9):
    scenario = load_scenario(
        "static",
        overrides=[
            f"motion.roll_deg={roll_deg}",
            f"motion.pitch_deg={pitch_deg}",
            f"motion.yaw_deg={yaw_deg}",
            f"origin_latitude_deg={latitude_deg}",
        ],
    )
    return TruthModel(scenario)


def test_still_level_imu_reads_gravity_and_earth_rate():
    latitude = np.deg2rad(38.9)
    yaw = np.deg2rad(30.0)
    imu = ImuSimulator(still(0, 0, 30), NO_ERRORS, seed=1)
    gyro, force = imu.ideal(np.array([0.0, 10.0]))
    # Somigliana in closed form (WGS-84 constants) at the origin, on the ellipsoid.
    s2 = np.sin(latitude) ** 2
    gamma = GAMMA_EQUATOR * (1 + SOMIGLIANA_K * s2) / np.sqrt(1 - E2 * s2)
    np.testing.assert_allclose(force, [[0.0, 0.0, gamma]] * 2, atol=1e-12)
    # Earth rate (0, W cos lat, W sin lat) in ENU seen from a level body heading yaw (from East).
    north, up = EARTH_RATE * np.cos(latitude), EARTH_RATE * np.sin(latitude)
    expected = [north * np.sin(yaw), north * np.cos(yaw), up]
    np.testing.assert_allclose(gyro, [expected] * 2, atol=1e-18)


def test_still_tilted_imu_projects_gravity():
    roll, pitch = np.deg2rad(12.0), np.deg2rad(-7.0)
    imu = ImuSimulator(still(12, -7, 200, latitude_deg=-33.0), NO_ERRORS, seed=1)
    _, force = imu.ideal([5.0])
    gamma = wgs84_normal_gravity_mps2(np.deg2rad(-33.0), 0.0)
    expected = gamma * np.array(
        [-np.sin(pitch), np.sin(roll) * np.cos(pitch), np.cos(roll) * np.cos(pitch)]
    )
    np.testing.assert_allclose(force[0], expected, atol=1e-12)


def _radii(latitude):
    w2 = 1 - E2 * np.sin(latitude) ** 2
    return A * (1 - E2) / w2**1.5, A / np.sqrt(w2)


def _navigation_rates(state_lat, state_h, velocity):
    rm, rn = _radii(state_lat)
    earth = EARTH_RATE * np.array([0.0, np.cos(state_lat), np.sin(state_lat)])
    transport = np.array(
        [
            -velocity[1] / (rm + state_h),
            velocity[0] / (rn + state_h),
            velocity[0] * np.tan(state_lat) / (rn + state_h),
        ]
    )
    return earth, transport, rm, rn


def _skew(v):
    return np.array([[0, -v[2], v[1]], [v[2], 0, -v[0]], [-v[1], v[0], 0]])


@pytest.mark.parametrize("name", ["open_ocean", "sea_state"])
def test_strapdown_integration_of_ideal_imu_reproduces_truth(name):
    """A local-level strapdown mechanization (written here, RK4) fed with the ideal IMU output
    must track the truth: this checks gravity, Coriolis, transport rate and Earth rate terms."""
    truth = TruthModel(load_scenario(name))
    imu = ImuSimulator(truth, NO_ERRORS, seed=0)
    dt, steps, start = 0.01, 1000, 50.0
    times = start + 0.5 * dt * np.arange(2 * steps + 1)
    gyro, force = imu.ideal(times)
    reference = truth.evaluate(times[::2])

    def derivative(state, k):
        attitude = state[:9].reshape(3, 3)
        velocity, lat, h = state[9:12], state[12], state[14]
        earth, transport, rm, rn = _navigation_rates(lat, h, velocity)
        attitude_rate = attitude @ _skew(gyro[k]) - _skew(earth + transport) @ attitude
        gravity = np.array([0.0, 0.0, -wgs84_normal_gravity_mps2(lat, h)])
        velocity_rate = attitude @ force[k] - np.cross(2 * earth + transport, velocity) + gravity
        position_rate = [
            velocity[1] / (rm + h),
            velocity[0] / ((rn + h) * np.cos(lat)),
            velocity[2],
        ]
        return np.concatenate([attitude_rate.ravel(), velocity_rate, position_rate])

    state = np.concatenate(
        [
            reference.attitude[0].as_matrix().ravel(),
            reference.velocity_enu_mps[0],
            np.deg2rad([reference.latitude_deg[0], reference.longitude_deg[0]]),
            [reference.altitude_m[0]],
        ]
    )
    for step in range(steps):
        k = 2 * step
        k1 = derivative(state, k)
        k2 = derivative(state + 0.5 * dt * k1, k + 1)
        k3 = derivative(state + 0.5 * dt * k2, k + 1)
        k4 = derivative(state + dt * k3, k + 2)
        state = state + dt / 6 * (k1 + 2 * k2 + 2 * k3 + k4)

    attitude_error = state[:9].reshape(3, 3) @ reference.attitude[-1].as_matrix().T - np.eye(3)
    assert np.max(np.abs(attitude_error)) < 1e-8
    np.testing.assert_allclose(state[9:12], reference.velocity_enu_mps[-1], atol=1e-7)
    rm, rn = _radii(state[12])
    north_error = (state[12] - np.deg2rad(reference.latitude_deg[-1])) * rm
    east_error = (state[13] - np.deg2rad(reference.longitude_deg[-1])) * rn * np.cos(state[12])
    assert abs(north_error) < 1e-6
    assert abs(east_error) < 1e-6
    assert state[14] == pytest.approx(reference.altitude_m[-1], abs=1e-6)


def _irregular_times(n, nominal_dt, rng):
    return np.cumsum(nominal_dt * rng.uniform(0.5, 1.5, n))


def _chi_square_bounds(dof):
    return chi2.ppf(1e-4, dof), chi2.ppf(1 - 1e-4, dof)


def test_white_noise_matches_the_density_at_the_actual_spacing():
    config = ImuErrorConfig(
        gyro_noise_deg_sqrt_h=0.2,
        gyro_turn_on_bias_deg_s=0.0,
        gyro_bias_instability_deg_h=0.0,
        accel_noise_mps_sqrt_h=0.05,
        accel_turn_on_bias_mg=0.0,
        accel_bias_instability_mg=0.0,
        scale_factor_error_percent=0.0,
    )
    truth = still(0, 0, 0)
    imu = ImuSimulator(truth, config, seed=3, first_interval_s=0.01)
    t = _irregular_times(20000, 0.01, np.random.default_rng(5))
    gyro, force = imu.measure(t)
    ideal_gyro, ideal_force = imu.ideal(t)
    spacing = np.diff(t, prepend=t[0] - 0.01)[:, None]
    # 0.2 deg/sqrt(h) and 0.05 m/s/sqrt(h) converted by hand; per sample: density / sqrt(dt).
    gyro_sigma = np.deg2rad(0.2) / 60.0 / np.sqrt(spacing)
    force_sigma = 0.05 / 60.0 / np.sqrt(spacing)
    low, high = _chi_square_bounds(t.size)
    for normalised in (
        (gyro - ideal_gyro) / gyro_sigma,
        (force - ideal_force) / force_sigma,
    ):
        sums = np.sum(normalised**2, axis=0)
        assert np.all((sums > low) & (sums < high)), sums
        assert np.all(np.abs(normalised.mean(axis=0)) < 4.0 / np.sqrt(t.size))
        lag_one = np.sum(normalised[1:] * normalised[:-1], axis=0) / t.size
        assert np.all(np.abs(lag_one) < 4.0 / np.sqrt(t.size))


def test_gauss_markov_bias_is_exactly_discretised():
    config = ImuErrorConfig(
        gyro_noise_deg_sqrt_h=0.0,
        gyro_turn_on_bias_deg_s=0.0,
        gyro_bias_instability_deg_h=36.0,
        gyro_bias_correlation_time_s=2.0,
        accel_noise_mps_sqrt_h=0.0,
        accel_turn_on_bias_mg=0.0,
        accel_bias_instability_mg=2.0,
        accel_bias_correlation_time_s=3.0,
        scale_factor_error_percent=0.0,
    )
    truth = still(0, 0, 0)
    imu = ImuSimulator(truth, config, seed=11)
    t = _irregular_times(30000, 0.05, np.random.default_rng(6))
    # Two calls: the process must continue across them.
    first_gyro, first_force = imu.measure(t[:12345])
    second_gyro, second_force = imu.measure(t[12345:])
    ideal_gyro, ideal_force = imu.ideal(t)
    cases = (
        (np.vstack([first_gyro, second_gyro]) - ideal_gyro, np.deg2rad(36.0) / 3600.0, 2.0),
        (np.vstack([first_force, second_force]) - ideal_force, 2.0e-3 * 9.80665, 3.0),
    )
    for bias, sigma, tau in cases:
        decay = np.exp(-np.diff(t) / tau)[:, None]
        innovations = (bias[1:] - decay * bias[:-1]) / (sigma * np.sqrt(1 - decay**2))
        low, high = _chi_square_bounds(innovations.shape[0])
        sums = np.sum(innovations**2, axis=0)
        assert np.all((sums > low) & (sums < high)), sums
        lag_one = np.sum(innovations[1:] * innovations[:-1], axis=0) / innovations.shape[0]
        assert np.all(np.abs(lag_one) < 4.0 / np.sqrt(innovations.shape[0]))
        # Stationary spread: about T / (2 tau) = 375 independent stretches per axis.
        assert np.all(np.abs(bias.std(axis=0) / sigma - 1.0) < 0.2)


def test_turn_on_bias_and_scale_factor_spread_over_seeds():
    config = ImuErrorConfig(
        gyro_noise_deg_sqrt_h=0.0,
        gyro_turn_on_bias_deg_s=0.02,
        gyro_bias_instability_deg_h=0.0,
        accel_noise_mps_sqrt_h=0.0,
        accel_turn_on_bias_mg=0.0,
        accel_bias_instability_mg=0.0,
        scale_factor_error_percent=0.5,
    )
    truth = still(0, 0, 0)
    gamma = wgs84_normal_gravity_mps2(np.deg2rad(38.9), 0.0)
    gyro_biases, scale_errors = [], []
    for seed in range(300):
        imu = ImuSimulator(truth, config, seed=seed)
        gyro, force = imu.measure([0.0])
        ideal_gyro, _ = imu.ideal([0.0])
        gyro_biases.append(gyro[0] - (1 + imu.gyro_scale_factor_error) * ideal_gyro[0])
        scale_errors.append(force[0, 2] / gamma - 1.0)
    low, high = _chi_square_bounds(900)
    gyro_sum = np.sum((np.array(gyro_biases) / np.deg2rad(0.02)) ** 2)
    assert low < gyro_sum < high
    low, high = _chi_square_bounds(300)
    assert low < np.sum((np.array(scale_errors) / 0.005) ** 2) < high


def test_determinism_and_batch_independence():
    truth = TruthModel(load_scenario("sea_state"))
    t = np.arange(0.0, 5.0, 0.01)
    config = ImuErrorConfig()
    whole = ImuSimulator(truth, config, seed=5).measure(t)
    again = ImuSimulator(truth, config, seed=5).measure(t)
    split_imu = ImuSimulator(truth, config, seed=5)
    pieces = [split_imu.measure(t[i : i + 1]) for i in range(20)] + [split_imu.measure(t[20:])]
    other = ImuSimulator(truth, config, seed=6).measure(t)
    for axis in range(2):
        np.testing.assert_array_equal(whole[axis], again[axis])
        np.testing.assert_allclose(
            np.vstack([piece[axis] for piece in pieces]), whole[axis], rtol=0, atol=1e-12
        )
        assert not np.allclose(whole[axis], other[axis])


def test_seed_may_be_the_scenario_seed_or_a_sequence_starting_with_it():
    truth = still(0, 0, 0)
    t = np.arange(0.0, 1.0, 0.1)
    from_int = ImuSimulator(truth, ImuErrorConfig(), seed=5).measure(t)[0]
    from_list = ImuSimulator(truth, ImuErrorConfig(), seed=[5]).measure(t)[0]
    np.testing.assert_array_equal(from_int, from_list)
    keyed = ImuSimulator(truth, ImuErrorConfig(), seed=[5, 1]).measure(t)[0]
    assert not np.allclose(keyed, from_int)
    with pytest.raises(ValueError, match="non-negative"):
        ImuSimulator(truth, ImuErrorConfig(), seed=-1)


def test_times_must_increase():
    imu = ImuSimulator(still(0, 0, 0), ImuErrorConfig(), seed=1)
    imu.measure([1.0, 2.0])
    with pytest.raises(ValueError, match="strictly increasing"):
        imu.measure([2.0])
    with pytest.raises(ValueError, match="strictly increasing"):
        ImuSimulator(still(0, 0, 0), ImuErrorConfig(), seed=1).measure([1.0, 1.0])
