"""Dual-antenna GNSS model: lever arms, baseline heading under tilt, noise, outages."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.stats import chi2

from sensor_sim.geodesy import geodetic_to_enu_m
from sensor_sim.scenario import load_scenario
from sensor_sim.sensor_errors import GnssErrorConfig
from sensor_sim.sensor_models import GnssSimulator
from sensor_sim.truth import TruthModel

PRIMARY = np.array([0.3, -0.9, 1.2])
SECONDARY = np.array([-0.5, 0.7, 0.9])
NOISE_FREE = GnssErrorConfig(
    position_noise_horizontal_m=0.0,
    position_noise_vertical_m=0.0,
    velocity_noise_horizontal_mps=0.0,
    velocity_noise_vertical_mps=0.0,
    baseline_noise_horizontal_m=0.0,
    baseline_noise_vertical_m=0.0,
)


def rotation_zyx(roll, pitch, yaw):
    cr, sr, cp, sp, cy, sy = (
        np.cos(roll),
        np.sin(roll),
        np.cos(pitch),
        np.sin(pitch),
        np.cos(yaw),
        np.sin(yaw),
    )
    rz = np.array([[cy, -sy, 0], [sy, cy, 0], [0, 0, 1]])
    ry = np.array([[cp, 0, sp], [0, 1, 0], [-sp, 0, cp]])
    rx = np.array([[1, 0, 0], [0, cr, -sr], [0, sr, cr]])
    return rz @ ry @ rx


def tilted_truth(roll=30.0, pitch=20.0, yaw=-115.0):
    scenario = load_scenario(
        "static",
        overrides=[f"motion.roll_deg={roll}", f"motion.pitch_deg={pitch}", f"motion.yaw_deg={yaw}"],
    )
    return TruthModel(scenario)


def test_heading_is_the_azimuth_of_the_rotated_baseline_under_large_tilt():
    for yaw in (-115.0, 0.0, 37.0, 170.0):
        gnss = GnssSimulator(tilted_truth(yaw=yaw), NOISE_FREE, PRIMARY, SECONDARY, seed=1)
        sample = gnss.measure([0.0, 1.0])
        rotation = rotation_zyx(*np.deg2rad([30.0, 20.0, yaw]))
        baseline = rotation @ (SECONDARY - PRIMARY)
        np.testing.assert_allclose(sample.baseline_enu_m, [baseline] * 2, atol=1e-12)
        np.testing.assert_allclose(
            sample.heading_yaw_rad, np.arctan2(baseline[1], baseline[0]), atol=1e-12
        )
        # Under this tilt the baseline azimuth is far from the body yaw: a naive heading = yaw
        # model would be wrong by degrees.
        body_yaw_gap = np.angle(np.exp(1j * (sample.heading_yaw_rad[0] - np.deg2rad(yaw))))
        naive_gap = np.arctan2(*(SECONDARY - PRIMARY)[[1, 0]])
        assert abs(body_yaw_gap - naive_gap) > np.deg2rad(3.0)


def test_primary_antenna_position_is_the_rotated_lever_arm():
    truth = tilted_truth()
    gnss = GnssSimulator(truth, NOISE_FREE, PRIMARY, SECONDARY, seed=1)
    sample = gnss.measure([3.0])
    origin = np.deg2rad(38.9), np.deg2rad(117.7), 0.0
    antenna_enu = geodetic_to_enu_m(
        np.deg2rad(sample.latitude_deg),
        np.deg2rad(sample.longitude_deg),
        sample.altitude_m,
        *origin,
    )
    rotation = rotation_zyx(*np.deg2rad([30.0, 20.0, -115.0]))
    np.testing.assert_allclose(antenna_enu[0], rotation @ PRIMARY, atol=1e-8)


def test_antenna_velocity_is_the_rate_of_its_position_on_a_turning_platform():
    truth = TruthModel(load_scenario("wind_tunnel"))
    gnss = GnssSimulator(truth, NOISE_FREE, PRIMARY, SECONDARY, seed=1)
    # Geodetic coordinates resolve about 1e-9 m, so the step cannot be much shorter.
    dt = 2e-3
    centre = np.array([40.0, 77.7, 133.3])
    t = np.concatenate([centre - dt, centre + dt, centre])
    sample = gnss.measure(t)
    origin = np.deg2rad(38.9), np.deg2rad(117.7), 0.0
    enu = geodetic_to_enu_m(
        np.deg2rad(sample.latitude_deg),
        np.deg2rad(sample.longitude_deg),
        sample.altitude_m,
        *origin,
    )
    numerical = (enu[3:6] - enu[0:3]) / (2 * dt)
    np.testing.assert_allclose(sample.velocity_enu_mps[6:], numerical, atol=1e-5)
    assert np.min(np.linalg.norm(numerical, axis=1)) > 0.05


def test_noise_levels_and_heading_variance_are_consistent():
    config = GnssErrorConfig()
    truth = tilted_truth()
    gnss = GnssSimulator(truth, config, PRIMARY, SECONDARY, seed=3)
    ideal = GnssSimulator(truth, NOISE_FREE, PRIMARY, SECONDARY, seed=3)
    t = np.arange(0.0, 400.0, 0.1)
    noisy, clean = gnss.measure(t), ideal.measure(t)
    n = t.size
    low3, high3 = chi2.ppf(1e-4, 3 * n), chi2.ppf(1 - 1e-4, 3 * n)

    origin = (
        np.deg2rad(clean.latitude_deg[0]),
        np.deg2rad(clean.longitude_deg[0]),
        clean.altitude_m[0],
    )
    position_error = geodetic_to_enu_m(
        np.deg2rad(noisy.latitude_deg), np.deg2rad(noisy.longitude_deg), noisy.altitude_m, *origin
    )
    checks = (
        (position_error, noisy.position_covariance_enu_m2),
        (noisy.velocity_enu_mps - clean.velocity_enu_mps, noisy.velocity_covariance_enu_m2s2),
        (noisy.baseline_enu_m - clean.baseline_enu_m, None),
    )
    for error, covariance in checks:
        if covariance is not None:
            np.testing.assert_allclose(
                covariance[:, [0, 1, 2], [0, 1, 2]][0], error.var(axis=0), rtol=0.1
            )
            normalised = np.sum(error**2 / np.diagonal(covariance, axis1=1, axis2=2))
            assert low3 < normalised < high3
    baseline_sigma = np.array([0.003, 0.003, 0.006])
    normalised = np.sum(((noisy.baseline_enu_m - clean.baseline_enu_m) / baseline_sigma) ** 2)
    assert low3 < normalised < high3

    heading_error = np.angle(np.exp(1j * (noisy.heading_yaw_rad - clean.heading_yaw_rad)))
    normalised = np.sum(heading_error**2 / noisy.heading_variance_rad2)
    assert chi2.ppf(1e-4, n) < normalised < chi2.ppf(1 - 1e-4, n)
    horizontal_length = np.hypot(*clean.baseline_enu_m[0, :2])
    assert np.sqrt(noisy.heading_variance_rad2.mean()) == pytest.approx(
        0.003 / horizontal_length, rel=0.01
    )


def test_outages_invalidate_fix_and_heading():
    config = GnssErrorConfig(fix_outages_s=((2.0, 3.0),), heading_outages_s=((5.0, 6.5),))
    gnss = GnssSimulator(tilted_truth(), config, PRIMARY, SECONDARY, seed=1)
    t = np.arange(0.0, 8.0, 0.5)
    sample = gnss.measure(t)
    no_fix = (t >= 2.0) & (t < 3.0)
    no_heading = no_fix | ((t >= 5.0) & (t < 6.5))
    np.testing.assert_array_equal(sample.fix_valid, ~no_fix)
    np.testing.assert_array_equal(sample.heading_valid, ~no_heading)
    assert np.all(np.isnan(sample.latitude_deg[no_fix]))
    assert np.all(np.isnan(sample.velocity_enu_mps[no_fix]))
    assert np.all(np.isfinite(sample.latitude_deg[~no_fix]))
    assert np.all(np.isnan(sample.heading_yaw_rad[no_heading]))
    assert np.all(np.isnan(sample.baseline_enu_m[no_heading]))
    assert np.all(np.isfinite(sample.heading_variance_rad2[~no_heading]))


def test_same_seed_same_output_other_seed_other_output():
    truth = tilted_truth()
    t = np.arange(0.0, 2.0, 0.1)
    first = GnssSimulator(truth, GnssErrorConfig(), PRIMARY, SECONDARY, seed=4).measure(t)
    second = GnssSimulator(truth, GnssErrorConfig(), PRIMARY, SECONDARY, seed=4).measure(t)
    other = GnssSimulator(truth, GnssErrorConfig(), PRIMARY, SECONDARY, seed=5).measure(t)
    np.testing.assert_array_equal(first.baseline_enu_m, second.baseline_enu_m)
    np.testing.assert_array_equal(first.latitude_deg, second.latitude_deg)
    assert not np.allclose(first.baseline_enu_m, other.baseline_enu_m)


def test_coincident_antennas_are_refused():
    with pytest.raises(ValueError, match="must not coincide"):
        GnssSimulator(tilted_truth(), GnssErrorConfig(), PRIMARY, PRIMARY, seed=1)
