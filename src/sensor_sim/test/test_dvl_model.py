"""DVL model: what a moving, rotated, offset water-track DVL reads, its errors, its lost pings."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.stats import binom, chi2

from sensor_sim.scenario import load_scenario
from sensor_sim.sensor_errors import DvlErrorConfig
from sensor_sim.sensor_models import DvlSimulator
from sensor_sim.truth import TruthModel

EXACT = DvlErrorConfig(scale_factor_error_percent=0.0, bias_mps=(0.0, 0.0, 0.0), noise_mps=0.0)
BELOW = np.array([0.4, -0.3, -2.5])
STILL_WATER = ["current=null"]


def elementary_rotation(axis, angle_deg):
    c, s = np.cos(np.deg2rad(angle_deg)), np.sin(np.deg2rad(angle_deg))
    if axis == "x":
        return np.array([[1, 0, 0], [0, c, -s], [0, s, c]])
    if axis == "y":
        return np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]])
    return np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])


def zyx(roll_deg, pitch_deg, yaw_deg):
    """Rz(yaw) Ry(pitch) Rx(roll), written out."""
    return (
        elementary_rotation("z", yaw_deg)
        @ elementary_rotation("y", pitch_deg)
        @ elementary_rotation("x", roll_deg)
    )


def test_still_platform_in_a_uniform_current_reads_minus_the_current():
    scenario = load_scenario(
        "static",
        overrides=[
            "current.speed_mps=0.8",
            "current.direction_deg=30",
            "current.platform_drifts=false",
        ],
    )
    dvl = DvlSimulator(TruthModel(scenario), EXACT, BELOW, [0, 0, 0], seed=1)
    # static: roll 1, pitch -0.5, ENU yaw 30 deg; 0.8 m/s toward 30 deg from North.
    current_enu = 0.8 * np.array([np.sin(np.deg2rad(30.0)), np.cos(np.deg2rad(30.0)), 0.0])
    expected = -(zyx(1.0, -0.5, 30.0).T @ current_enu)
    np.testing.assert_allclose(dvl.measure(np.arange(0.0, 20.0)), [expected] * 20, atol=1e-12)


def test_ship_through_the_papers_current_reads_its_velocity_through_the_water():
    """Paper 003: 5 m/s North over ground, current 2 m/s toward 60 deg: through the water the
    ship moves 4 m/s North and sqrt(3) m/s West; heading North, that is forward and left.
    (The speed over ground grows by 1.2e-4 m/s over the 18 km: the truth's displacement is
    curvilinear at the origin's radii.)"""
    dvl = DvlSimulator(
        TruthModel(load_scenario("ship_current")), EXACT, [0.0, 0.0, -3.0], [0, 0, 0], seed=1
    )
    np.testing.assert_allclose(
        dvl.measure([0.0, 1800.0, 3600.0]), [[4.0, np.sqrt(3.0), 0.0]] * 3, atol=1.3e-4
    )


def test_pure_rotation_in_still_water_reads_minus_the_lever_arm_velocity():
    """The turntable turns and sways about base_link; the DVL moves with d/dt (R_nb p), which
    is taken here by finite differences of the attitude, not from the body rate."""
    truth = TruthModel(load_scenario("wind_tunnel", overrides=STILL_WATER))
    dvl = DvlSimulator(truth, EXACT, BELOW, [0, 0, 0], seed=1)
    dt = 1e-4
    centre = np.array([35.0, 61.3, 97.0, 140.2])
    before, after = truth.evaluate(centre - dt).attitude, truth.evaluate(centre + dt).attitude
    dvl_velocity_enu = (after.apply(BELOW) - before.apply(BELOW)) / (2 * dt)
    state = truth.evaluate(centre)
    expected = state.attitude.inv().apply(dvl_velocity_enu)
    np.testing.assert_allclose(dvl.measure(centre), expected, atol=1e-6)
    # The sign: omega x p, the DVL moving through still water.
    np.testing.assert_allclose(expected, np.cross(state.angular_rate_body_rad_s, BELOW), atol=1e-6)
    assert np.min(np.linalg.norm(expected, axis=1)) > 0.1


def test_mounting_rotation_turns_the_reading_into_the_dvl_axes():
    """A DVL turned 90 deg in yaw has its x axis along body y (left): a platform heading East
    and going East through still water at 0.7 m/s reads (0, -0.7, 0)."""
    scenario = load_scenario(
        "static",
        overrides=[
            *STILL_WATER,
            "motion.roll_deg=0",
            "motion.pitch_deg=0",
            "motion.yaw_deg=0",
            "motion.cruise_speed_mps=0.7",
            "motion.cruise_course_deg=90",
        ],
    )
    t = np.linspace(0.3, 5.0, 11)
    turned = DvlSimulator(TruthModel(scenario), EXACT, BELOW, [0, 0, 90], seed=1).measure(t)
    np.testing.assert_allclose(turned, [[0.0, -0.7, 0.0]] * t.size, atol=1e-12)
    # Any mounting: the reading is R_bd^T times the level one.
    sea = TruthModel(load_scenario("sea_state"))
    roll, pitch, yaw = 180.0, 2.0, 45.0
    level = DvlSimulator(sea, EXACT, BELOW, [0, 0, 0], seed=1).measure(t)
    mounted = DvlSimulator(sea, EXACT, BELOW, [roll, pitch, yaw], seed=1).measure(t)
    np.testing.assert_allclose(mounted, level @ zyx(roll, pitch, yaw), atol=1e-12)


def test_the_current_follows_from_the_reading_by_the_papers_formula():
    """current = v_b + R_nb (omega x p) - R_nb R_bd v_dvl, on the noise-free reading in a sea
    with waves, tide and a turned, offset DVL: the water at the DVL comes back exactly."""
    truth = TruthModel(load_scenario("open_ocean"))
    rpy = [178.0, -3.0, 30.0]
    dvl = DvlSimulator(truth, EXACT, BELOW, rpy, seed=1)
    t = np.linspace(0.0, 120.0, 121)
    reading = dvl.measure(t)
    state = truth.evaluate(t)
    water = truth.water_at(state, BELOW)
    recovered = (
        state.velocity_enu_mps
        + state.attitude.apply(np.cross(state.angular_rate_body_rad_s, BELOW))
        - state.attitude.apply(reading @ zyx(*rpy).T)
    )
    np.testing.assert_allclose(recovered, water.velocity_enu_mps, atol=1e-12)
    # The single pings carry the waves' orbital velocity: far from the current.
    assert np.max(np.linalg.norm(recovered - water.current_enu_mps, axis=1)) > 0.5


def test_systematic_errors_are_the_papers_and_the_noise_is_white():
    truth = TruthModel(load_scenario("ship_current"))
    t = np.arange(0.0, 2000.0)
    ideal, _ = DvlSimulator(truth, EXACT, BELOW, [0, 0, 0], seed=1).ideal(t)
    no_noise = DvlErrorConfig(noise_mps=0.0)
    measured = DvlSimulator(truth, no_noise, BELOW, [0, 0, 0], seed=1).measure(t)
    # The default DVL: 0.2 % of the velocity plus 0.2 cm/s on every axis, for the whole run.
    np.testing.assert_allclose(measured, 1.002 * ideal + 0.002, atol=1e-12)
    noisy = DvlSimulator(truth, DvlErrorConfig(), BELOW, [0, 0, 0], seed=1).measure(t)
    residual = (noisy - measured) / 0.005
    n = residual.size
    assert chi2.ppf(1e-4, n) < np.sum(residual**2) < chi2.ppf(1 - 1e-4, n)
    assert np.all(np.abs(residual.mean(axis=0)) < 4.0 / np.sqrt(t.size))
    lag_one = np.mean(residual[1:] * residual[:-1], axis=0)
    assert np.all(np.abs(lag_one) < 4.0 / np.sqrt(t.size))


def test_lost_pings_are_nan_outages_bubbles_and_chance():
    truth = TruthModel(load_scenario("sea_state"))
    t = np.arange(0.0, 600.0)
    outage = DvlErrorConfig(outages_s=((100.0, 110.5),))
    reading = DvlSimulator(truth, outage, BELOW, [0, 0, 0], seed=1).measure(t)
    lost = np.isnan(reading).any(axis=1)
    np.testing.assert_array_equal(lost, (t >= 100.0) & (t < 110.5))
    assert np.all(np.isnan(reading[lost]))
    # Bubble sweep: a DVL less than min_depth_m below the surface loses its pings. In sea_state
    # the buoy rolls 10 deg: a DVL 0.5 m down and 0.5 m to the side comes up above 0.45 m.
    shallow = DvlSimulator(truth, DvlErrorConfig(min_depth_m=0.45), [0, 0.5, -0.5], [0, 0, 0], 1)
    state = truth.evaluate(t)
    depth = -state.attitude.apply([0.0, 0.5, -0.5])[:, 2]
    lost = np.isnan(shallow.measure(t)).any(axis=1)
    np.testing.assert_array_equal(lost, depth < 0.45)
    assert 0 < np.count_nonzero(lost) < t.size
    chance = DvlErrorConfig(ping_loss_probability=0.2)
    lost = np.isnan(DvlSimulator(truth, chance, BELOW, [0, 0, 0], seed=1).measure(t)).any(axis=1)
    assert binom.ppf(1e-4, t.size, 0.2) < np.count_nonzero(lost) < binom.ppf(1 - 1e-4, t.size, 0.2)


def test_pings_depend_on_their_times_alone_and_on_the_seed():
    truth = TruthModel(load_scenario("sea_state"))
    config = DvlErrorConfig(ping_loss_probability=0.3)
    t = np.arange(0.0, 40.0)
    whole = DvlSimulator(truth, config, BELOW, [0, 0, 0], seed=2).measure(t)
    split = DvlSimulator(truth, config, BELOW, [0, 0, 0], seed=2)
    parts = np.concatenate([split.measure(t[:13]), split.measure(t[13:])])
    np.testing.assert_array_equal(whole, parts)
    other = DvlSimulator(truth, config, BELOW, [0, 0, 0], seed=3).measure(t)
    assert not np.allclose(whole, other, equal_nan=True)


@pytest.mark.parametrize(
    ("position", "rpy", "pattern"),
    [([0.0, 1.0], [0, 0, 0], "DVL position"), (BELOW, [0, np.nan, 0], "DVL mounting")],
)
def test_bad_geometry_is_refused(position, rpy, pattern):
    truth = TruthModel(load_scenario("static"))
    with pytest.raises(ValueError, match=pattern):
        DvlSimulator(truth, DvlErrorConfig(), position, rpy, seed=1)
