"""Truth self-consistency: every rate integrates to the quantity it is the rate of."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.integrate import cumulative_trapezoid
from scipy.spatial.transform import Rotation

from sensor_sim.scenario import load_scenario
from sensor_sim.truth import TruthModel

A = 6378137.0
E2 = 0.00669437999014

# (scenario, window start s, window length s): windows where the motion is active.
WINDOWS = [
    ("static", 0.0, 4.0),
    ("tilt_table", 59.0, 8.0),
    ("wind_tunnel", 29.0, 8.0),
    ("wind_tunnel", 200.0, 8.0),
    ("vertical_wind", 29.0, 8.0),
    ("sea_state", 100.0, 8.0),
    ("open_ocean", 100.0, 8.0),
]


def radii_m(latitude_rad):
    w2 = 1.0 - E2 * np.sin(latitude_rad) ** 2
    return A * (1.0 - E2) / w2**1.5, A / np.sqrt(w2)


@pytest.fixture(scope="module")
def truths():
    return {name: TruthModel(load_scenario(name)) for name in {w[0] for w in WINDOWS}}


@pytest.mark.parametrize(("name", "start", "length"), WINDOWS)
def test_body_rate_integrates_to_attitude(truths, name, start, length):
    dt = 1e-3
    steps = round(length / dt)
    t = start + dt * np.arange(steps + 1)
    midpoints = t[:-1] + dt / 2
    truth = truths[name]
    attitude = truth.evaluate(t).attitude
    rate = truth.evaluate(midpoints).angular_rate_body_rad_s
    # R' = R [omega x]: each step right-multiplies by the body rotation over the step.
    increments = Rotation.from_rotvec(rate * dt).as_matrix()
    integrated = attitude[0].as_matrix()
    for increment in increments:
        integrated = integrated @ increment
    error = Rotation.from_matrix(integrated) * attitude[-1].inv()
    assert error.magnitude() < 5e-7


@pytest.mark.parametrize(("name", "start", "length"), WINDOWS)
def test_velocity_acceleration_and_geodetic_rates_integrate(truths, name, start, length):
    t = np.linspace(start, start + length, 8001)
    s = truths[name].evaluate(t)
    lat = np.deg2rad(s.latitude_deg)
    lon = np.deg2rad(s.longitude_deg)
    rm, rn = radii_m(lat)
    v = s.velocity_enu_mps
    lat_rate = v[:, 1] / (rm + s.altitude_m)
    lon_rate = v[:, 0] / ((rn + s.altitude_m) * np.cos(lat))
    np.testing.assert_allclose(
        cumulative_trapezoid(lat_rate, t), lat[1:] - lat[0], atol=1e-13, rtol=0
    )
    np.testing.assert_allclose(
        cumulative_trapezoid(lon_rate, t), lon[1:] - lon[0], atol=1e-13, rtol=0
    )
    np.testing.assert_allclose(
        cumulative_trapezoid(v[:, 2], t), s.altitude_m[1:] - s.altitude_m[0], atol=1e-6
    )
    np.testing.assert_allclose(
        cumulative_trapezoid(s.acceleration_enu_mps2, t, axis=0), v[1:] - v[0], atol=1e-6
    )
    np.testing.assert_allclose(
        cumulative_trapezoid(s.angular_accel_body_rad_s2, t, axis=0),
        s.angular_rate_body_rad_s[1:] - s.angular_rate_body_rad_s[0],
        atol=1e-6,
    )


def test_tangent_plane_position_follows_the_drift():
    truth = TruthModel(load_scenario("open_ocean"))
    t = np.linspace(0.0, 1200.0, 24001)
    s = truth.evaluate(t)
    np.testing.assert_allclose(s.position_enu_m[0], 0.0, atol=1e-9)
    np.testing.assert_allclose(s.latitude_deg[0], 20.0, atol=1e-12)
    # Waves are zero-mean and bounded: over 20 minutes the mean ENU velocity is the current's.
    drift_velocity = (s.position_enu_m[-1] - s.position_enu_m[0]) / 1200.0
    np.testing.assert_allclose(drift_velocity, s.current_enu_mps.mean(axis=0), atol=0.01)

    # 0.2 m/s toward 45 deg, plus the tide 30 deg past full flood: 0.15 cos 30 toward 100 deg
    # and 0.05 sin 30 along the minor axis, 90 deg counter-clockwise of it (toward 10 deg).
    def toward(direction_deg):
        return np.array([np.sin(np.deg2rad(direction_deg)), np.cos(np.deg2rad(direction_deg)), 0])

    expected = (
        0.2 * toward(45.0)
        + 0.15 * np.cos(np.deg2rad(30.0)) * toward(100.0)
        + 0.05 * np.sin(np.deg2rad(30.0)) * toward(10.0)
    )
    np.testing.assert_allclose(s.current_enu_mps[0], expected, atol=1e-15)


def test_same_truth_at_any_sampling():
    truth = TruthModel(load_scenario("open_ocean"))
    dense = truth.evaluate(np.arange(0.0, 100.0, 0.01))
    sparse = truth.evaluate(np.array([12.34, 50.0]))
    index = [1234, 5000]
    np.testing.assert_allclose(sparse.euler_rad, dense.euler_rad[index], rtol=0, atol=1e-12)
    np.testing.assert_allclose(sparse.wind_enu_mps, dense.wind_enu_mps[index], rtol=0, atol=1e-12)
    np.testing.assert_allclose(
        sparse.velocity_enu_mps, dense.velocity_enu_mps[index], rtol=0, atol=1e-12
    )
    again = TruthModel(load_scenario("open_ocean")).evaluate(np.array([12.34, 50.0]))
    np.testing.assert_array_equal(again.euler_rad, sparse.euler_rad)
    other_seed = TruthModel(load_scenario("open_ocean", seed=99)).evaluate(np.array([50.0]))
    assert not np.allclose(other_seed.euler_rad, sparse.euler_rad[1:])


def test_euler_angles_match_attitude():
    truth = TruthModel(load_scenario("sea_state"))
    s = truth.evaluate(np.linspace(0.0, 60.0, 601))
    roll, pitch, yaw = s.euler_rad.T
    matrices = s.attitude.as_matrix()
    c, si = np.cos, np.sin
    # Third row of Rz(yaw) Ry(pitch) Rx(roll), independent of yaw.
    np.testing.assert_allclose(matrices[:, 2, 0], -si(pitch), atol=1e-12)
    np.testing.assert_allclose(matrices[:, 2, 1], c(pitch) * si(roll), atol=1e-12)
    np.testing.assert_allclose(matrices[:, 0, 0], c(yaw) * c(pitch), atol=1e-12)
    np.testing.assert_allclose(matrices[:, 1, 0], si(yaw) * c(pitch), atol=1e-12)


def test_evaluation_is_fast_enough_for_live_nodes():
    import time

    truth = TruthModel(load_scenario("open_ocean"))
    t = np.arange(0.0, 600.0, 0.01)
    # CPU time, not wall time: other processes on a shared machine must not fail this test.
    begin = time.process_time()
    truth.evaluate(t)
    assert time.process_time() - begin < 5.0
