"""The sea's water velocity: the tidal current integrates to the drift, the waves' orbital
velocity is the wave follower's own at the surface and decays as linear wave theory says."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.integrate import cumulative_trapezoid

from sensor_sim.current_field import SurfaceCurrent
from sensor_sim.scenario import CurrentConfig, load_scenario
from sensor_sim.truth import TruthModel
from sensor_sim.waves import STANDARD_GRAVITY_MPS2, WaveField

TIDE = CurrentConfig(
    speed_mps=0.2,
    direction_deg=45.0,
    tidal_amplitude_mps=0.3,
    tidal_minor_amplitude_mps=0.1,
    tidal_direction_deg=100.0,
    tidal_period_s=1000.0,
    tidal_phase_deg=20.0,
)


def test_directions_are_where_the_water_flows_toward():
    east = SurfaceCurrent(CurrentConfig(speed_mps=0.5, direction_deg=90.0))
    np.testing.assert_allclose(east.velocity_enu_mps([0.0, 7.0]), [[0.5, 0.0, 0.0]] * 2, atol=1e-15)
    south_west = SurfaceCurrent(CurrentConfig(speed_mps=2.0, direction_deg=225.0))
    np.testing.assert_allclose(
        south_west.velocity_enu_mps(0.0), [[-np.sqrt(2.0), -np.sqrt(2.0), 0.0]], atol=1e-15
    )


def test_drift_is_the_integral_of_the_current_and_the_acceleration_its_rate():
    current = SurfaceCurrent(TIDE)
    t = np.linspace(0.0, 1500.0, 150001)
    displacement, velocity, acceleration = current.drift_en_m(t)
    np.testing.assert_array_equal(displacement[0], [0.0, 0.0])
    np.testing.assert_allclose(
        cumulative_trapezoid(velocity, t, axis=0), displacement[1:], atol=1e-6
    )
    np.testing.assert_allclose(
        cumulative_trapezoid(acceleration, t, axis=0), velocity[1:] - velocity[0], atol=1e-9
    )
    np.testing.assert_allclose(current.velocity_enu_mps(t)[:, :2], velocity)


def test_tide_averages_out_over_its_period_and_turns_as_its_minor_axis_says():
    current = SurfaceCurrent(TIDE)
    t = np.arange(0.0, 1000.0, 0.5)
    velocity = current.velocity_enu_mps(t)
    np.testing.assert_allclose(velocity.mean(axis=0)[:2], current.mean_en_mps, atol=1e-12)
    tidal = velocity[:, :2] - current.mean_en_mps
    # Full flood at phase 0: 0.3 m/s toward 100 deg; the ellipse's extremes are its axes.
    speeds = np.hypot(*tidal.T)
    assert speeds.max() == pytest.approx(0.3, abs=1e-6)
    assert speeds.min() == pytest.approx(0.1, abs=1e-6)
    flood = tidal[np.argmax(speeds)]
    assert np.degrees(np.arctan2(flood[0], flood[1])) % 180.0 == pytest.approx(100.0, abs=0.1)
    # A positive minor axis: the vector turns counter-clockwise seen from above (z of a x b > 0).
    turn = tidal[:-1, 0] * tidal[1:, 1] - tidal[:-1, 1] * tidal[1:, 0]
    assert np.all(turn > 0.0)
    clockwise = SurfaceCurrent(
        CurrentConfig(tidal_amplitude_mps=0.3, tidal_minor_amplitude_mps=-0.1)
    ).velocity_enu_mps(t)[:, :2]
    assert np.all(clockwise[:-1, 0] * clockwise[1:, 1] - clockwise[:-1, 1] * clockwise[1:, 0] < 0)


def test_a_platform_that_drifts_moves_with_the_current_and_one_that_does_not_stays():
    t = np.linspace(0.0, 600.0, 61)
    overrides = ["current.tidal_amplitude_mps=0.3", "current.tidal_direction_deg=10"]
    drifting = TruthModel(load_scenario("static", overrides=overrides)).evaluate(t)
    np.testing.assert_allclose(drifting.velocity_enu_mps, drifting.current_enu_mps, atol=1e-4)
    held = TruthModel(
        load_scenario("static", overrides=[*overrides, "current.platform_drifts=false"])
    ).evaluate(t)
    assert np.all(held.velocity_enu_mps == 0.0)
    np.testing.assert_array_equal(held.current_enu_mps, drifting.current_enu_mps)


def test_cruise_is_a_constant_velocity_over_ground_on_its_course():
    truth = TruthModel(load_scenario("ship_current"))
    state = truth.evaluate(np.linspace(0.0, 3600.0, 37))
    # 5 m/s due North over ground, to the change of the meridian radius over 18 km (3e-5; the
    # displacement is curvilinear at the origin's radii, see sensor_sim.truth).
    np.testing.assert_allclose(state.velocity_enu_mps, [[0.0, 5.0, 0.0]] * 37, rtol=3e-5, atol=0)
    assert state.position_enu_m[-1, 1] == pytest.approx(18000.0, rel=1e-4)
    # The ship is not carried: its current is 2 m/s toward 60 deg, its track is still North.
    np.testing.assert_allclose(state.current_enu_mps[0], [np.sqrt(3.0), 1.0, 0.0], atol=1e-15)


@pytest.mark.parametrize("name", ["open_ocean", "sea_state"])
def test_at_the_surface_the_water_moves_as_the_wave_follower_does(name):
    """At depth 0 the orbital velocity is the buoy's own wave motion: its velocity minus the
    drift with the current (horizontal) and its heave (vertical)."""
    truth = TruthModel(load_scenario(name))
    t = np.linspace(30.0, 90.0, 601)
    state = truth.evaluate(t)
    surface = truth.motion.orbital_velocity_enu_mps(t, np.zeros(t.size))
    # The truth velocity is the local-ENU rate of the curvilinear displacement: equal to it
    # within the change of the Earth's radii over a few metres of drift.
    np.testing.assert_allclose(surface, state.velocity_enu_mps - state.current_enu_mps, atol=1e-6)
    assert np.max(np.abs(surface)) > 0.05


def test_orbital_velocity_decays_with_depth_as_linear_wave_theory_says():
    rng = np.random.default_rng(4)
    waves = WaveField(2.0, 8.0, 3.3, 10.0, 0.0, 1, rng)
    t = np.linspace(0.0, 16.0, 161)
    surface = waves.orbital_velocity_enu_mps(t, 0.0)
    omega = waves.angular_frequencies_rad_s[0]
    for depth in (1.0, 5.0, 20.0):
        deep = waves.orbital_velocity_enu_mps(t, depth)
        # Deep water: k = omega²/g, the velocity falls as exp(-k d) at every phase.
        np.testing.assert_allclose(
            deep, surface * np.exp(-(omega**2) / STANDARD_GRAVITY_MPS2 * depth), atol=1e-12
        )
    # Circular orbits: the speed is a omega, constant, at the surface.
    np.testing.assert_allclose(
        np.linalg.norm(surface, axis=1), waves.amplitudes_m[0] * omega, rtol=1e-12
    )
    # Above the surface (a sensor out of the water) counts as the surface.
    np.testing.assert_allclose(waves.orbital_velocity_enu_mps(t, -1.0), surface)


def test_water_at_the_dvl_averages_to_the_current():
    truth = TruthModel(load_scenario("open_ocean"))
    t = np.arange(0.0, 1200.0, 0.5)
    state = truth.evaluate(t)
    water = truth.water_at(state, (0.0, 0.0, -2.0))
    # Depth below the surface: 2 m when level, less when tilted (up to 20 deg).
    assert water.depth_m.min() > 1.8 and water.depth_m.max() <= 2.0
    np.testing.assert_array_equal(water.current_enu_mps, state.current_enu_mps)
    orbital = water.velocity_enu_mps - water.current_enu_mps
    assert np.all(orbital.std(axis=0) > 0.2)
    # A zero-mean oscillation of wave periods: its 20-min mean is a few mm/s.
    assert np.all(np.abs(orbital.mean(axis=0)) < 0.01)
