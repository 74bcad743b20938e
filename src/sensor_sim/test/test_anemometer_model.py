"""Sonic anemometer model: what a moving, rotated, offset sensor must read."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.stats import chi2

from sensor_sim.scenario import load_scenario
from sensor_sim.sensor_errors import AnemometerErrorConfig
from sensor_sim.sensor_models import AnemometerSimulator
from sensor_sim.truth import TruthModel

NOISE_FREE = AnemometerErrorConfig(noise_mps=0.0)
MAST = np.array([0.2, -0.1, 3.0])


def elementary_rotation(axis, angle):
    c, s = np.cos(angle), np.sin(angle)
    if axis == "x":
        return np.array([[1, 0, 0], [0, c, -s], [0, s, c]])
    if axis == "y":
        return np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]])
    return np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])


def test_still_buoy_in_still_air_reads_only_noise():
    truth = TruthModel(load_scenario("static", overrides=["wind.speed_mps=0"]))
    sensor = AnemometerSimulator(truth, AnemometerErrorConfig(), MAST, [0, 0, 0], seed=1)
    reading = sensor.measure(np.arange(0.0, 100.0, 0.05))
    n = reading.size
    assert chi2.ppf(1e-4, n) < np.sum((reading / 0.02) ** 2) < chi2.ppf(1 - 1e-4, n)
    assert np.all(np.abs(reading.mean(axis=0)) < 4 * 0.02 / np.sqrt(reading.shape[0]))


def test_pure_translation_reads_minus_the_velocity():
    scenario = load_scenario(
        "static",
        overrides=[
            "wind.speed_mps=0",
            "motion.roll_deg=0",
            "motion.pitch_deg=0",
            "motion.surge_velocity_amplitude_mps=0.8",
            "motion.lateral_velocity_amplitude_mps=0.5",
            "motion.heave_velocity_amplitude_mps=0.3",
        ],
    )
    truth = TruthModel(scenario)
    sensor = AnemometerSimulator(truth, NOISE_FREE, MAST, [0, 0, 0], seed=1)
    t = np.linspace(0.0, 30.0, 301)
    state = truth.evaluate(t)
    assert np.all(state.angular_rate_body_rad_s == 0.0)
    body_to_enu = elementary_rotation("z", np.deg2rad(30.0))
    np.testing.assert_allclose(sensor.measure(t), -state.velocity_enu_mps @ body_to_enu, atol=1e-12)
    assert np.max(np.abs(state.velocity_enu_mps)) > 0.5


def test_pure_rotation_reads_minus_the_mast_velocity():
    truth = TruthModel(load_scenario("wind_tunnel", overrides=["wind.speed_mps=0"]))
    sensor = AnemometerSimulator(truth, NOISE_FREE, MAST, [0, 0, 0], seed=1)
    dt = 1e-4
    centre = np.array([35.0, 61.3, 97.0, 140.2])
    attitude_before = truth.evaluate(centre - dt).attitude
    attitude_after = truth.evaluate(centre + dt).attitude
    # Velocity of the sensor over ground: rate of change of R_nb B (the origin does not move).
    mast_velocity_enu = (attitude_after.apply(MAST) - attitude_before.apply(MAST)) / (2 * dt)
    state = truth.evaluate(centre)
    expected_body = -state.attitude.inv().apply(mast_velocity_enu)
    np.testing.assert_allclose(sensor.measure(centre), expected_body, atol=1e-6)
    np.testing.assert_allclose(
        expected_body, -np.cross(state.angular_rate_body_rad_s, MAST), atol=1e-6
    )
    assert np.min(np.linalg.norm(expected_body, axis=1)) > 0.1


def test_mounting_rotation_rotates_the_reading():
    truth = TruthModel(load_scenario("sea_state"))
    t = np.linspace(10.0, 20.0, 51)
    level = AnemometerSimulator(truth, NOISE_FREE, MAST, [0, 0, 0], seed=1).measure(t)
    roll, pitch, yaw = 2.0, -3.0, 135.0
    mounted = AnemometerSimulator(truth, NOISE_FREE, MAST, [roll, pitch, yaw], seed=1).measure(t)
    anemometer_to_body = (
        elementary_rotation("z", np.deg2rad(yaw))
        @ elementary_rotation("y", np.deg2rad(pitch))
        @ elementary_rotation("x", np.deg2rad(roll))
    )
    np.testing.assert_allclose(mounted, level @ anemometer_to_body, atol=1e-12)
    np.testing.assert_allclose(np.linalg.norm(mounted, axis=1), np.linalg.norm(level, axis=1))


def test_anemometer_noise_is_seeded():
    truth = TruthModel(load_scenario("static"))
    t = np.arange(0.0, 1.0, 0.1)
    first = AnemometerSimulator(truth, AnemometerErrorConfig(), MAST, [0, 0, 0], seed=2)
    second = AnemometerSimulator(truth, AnemometerErrorConfig(), MAST, [0, 0, 0], seed=2)
    other = AnemometerSimulator(truth, AnemometerErrorConfig(), MAST, [0, 0, 0], seed=3)
    np.testing.assert_array_equal(first.measure(t), second.measure(t))
    assert not np.allclose(first.measure(t), other.measure(t))


def test_bad_geometry_is_refused():
    truth = TruthModel(load_scenario("static"))
    with pytest.raises(ValueError, match="anemometer position"):
        AnemometerSimulator(truth, AnemometerErrorConfig(), [0.0, 1.0], [0, 0, 0], seed=1)
