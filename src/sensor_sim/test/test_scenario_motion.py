"""Each shipped scenario reproduces the amplitudes, rates and periods its paper describes."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.signal import welch

from sensor_sim.scenario import load_scenario
from sensor_sim.truth import TruthModel

DT = 0.02


def dominant_period_s(signal, dt, shortest_s=0.0, longest_s=np.inf):
    """Period of the largest spectral peak within [shortest_s, longest_s] (zero-padded FFT)."""
    centred = signal - signal.mean()
    padded = 16 * centred.size
    spectrum = np.abs(np.fft.rfft(centred * np.hanning(centred.size), padded))
    frequency = np.fft.rfftfreq(padded, dt)
    with np.errstate(divide="ignore"):
        period = 1.0 / frequency
    band = (period >= shortest_s) & (period <= longest_s)
    return period[band][np.argmax(spectrum[band])]


def run(name, *overrides, duration=None):
    scenario = load_scenario(name, overrides=list(overrides))
    end = scenario.duration_s if duration is None else duration
    t = np.arange(0.0, end, DT)
    return t, TruthModel(scenario).evaluate(t)


def test_static_is_a_constant_tilt_in_a_steady_wind():
    t, s = run("static", duration=50.0)
    np.testing.assert_allclose(np.rad2deg(s.euler_rad), [[1.0, -0.5, 30.0]] * t.size, atol=1e-12)
    assert np.all(s.angular_rate_body_rad_s == 0.0)
    assert np.all(s.velocity_enu_mps == 0.0)
    # 6 m/s from the West (270 deg): the air moves toward the East.
    np.testing.assert_allclose(s.wind_enu_mps, [[6.0, 0.0, 0.0]] * t.size, atol=1e-12)
    assert s.current_enu_mps is None
    np.testing.assert_allclose(s.latitude_deg, 38.9)
    np.testing.assert_allclose(s.longitude_deg, 117.7)


def test_tilt_table_ten_swings_of_15_deg_at_5_deg_s():
    t, s = run("tilt_table")
    roll = np.rad2deg(s.euler_rad[:, 0])
    roll_rate = np.rad2deg(s.angular_rate_body_rad_s[:, 0])
    still = (t < 60.0) | (t > 190.5)
    assert np.all(roll[still] == 0.0)
    assert np.all(roll_rate[still] == 0.0)
    assert np.max(np.abs(roll)) == pytest.approx(15.0, abs=1e-9)
    assert np.max(np.abs(roll_rate)) == pytest.approx(5.0, abs=1e-9)
    upward_crossings = np.count_nonzero((roll[:-1] < 7.5) & (roll[1:] >= 7.5))
    downward_crossings = np.count_nonzero((roll[:-1] > -7.5) & (roll[1:] <= -7.5))
    assert upward_crossings == downward_crossings == 10
    # Back-to-back 30 deg ramps at 5 deg/s with 0.5 s corners: 13 s per full swing.
    swinging = (t > 70.0) & (t < 180.0)
    assert dominant_period_s(roll[swinging], DT, 5.0, 40.0) == pytest.approx(13.0, rel=0.02)
    np.testing.assert_allclose(np.rad2deg(s.euler_rad[:, 2]), 30.0)


def test_wind_tunnel_rotation_and_sway():
    t, s = run("wind_tunnel")
    roll, pitch, yaw = np.rad2deg(s.euler_rad).T
    moving = t > 30.0
    assert np.max(np.abs(roll)) == pytest.approx(15.0, abs=1e-9)
    assert np.all(pitch == 0.0)
    assert yaw.min() == pytest.approx(0.0, abs=1e-9)
    assert yaw.max() == pytest.approx(180.0, abs=1e-9)
    euler_rates = np.rad2deg(np.gradient(s.euler_rad, DT, axis=0))
    assert np.max(np.abs(euler_rates[:, 0])) == pytest.approx(6.0, rel=1e-3)
    assert np.max(np.abs(euler_rates[:, 2])) == pytest.approx(10.0, rel=1e-3)
    assert dominant_period_s(roll[moving], DT, 5.0, 30.0) == pytest.approx(13.0, rel=0.01)
    # The turntable turns in place.
    assert np.all(s.velocity_enu_mps == 0.0)
    np.testing.assert_allclose(s.wind_enu_mps, [[-5.0, 0.0, 0.0]] * t.size, atol=1e-12)


def test_wind_tunnel_speed_override_and_level_reference():
    _, fast = run("wind_tunnel", "wind.speed_mps=15", duration=5.0)
    np.testing.assert_allclose(np.linalg.norm(fast.wind_enu_mps, axis=1), 15.0)
    _, level = run(
        "wind_tunnel", "motion.rotation_range_deg=0", "motion.sway_amplitude_deg=0", duration=100.0
    )
    assert np.all(level.euler_rad == 0.0)
    assert np.all(level.angular_rate_body_rad_s == 0.0)


def test_vertical_wind_pitches_into_the_wind():
    t, s = run("vertical_wind")
    roll, pitch, _ = np.rad2deg(s.euler_rad).T
    assert np.all(roll == 0.0)
    assert np.max(np.abs(pitch)) == pytest.approx(15.0, abs=1e-9)
    assert dominant_period_s(pitch[t > 30.0], DT, 5.0, 30.0) == pytest.approx(13.0, rel=0.01)
    forward = s.attitude.apply([1.0, 0.0, 0.0])
    wind_unit = s.wind_enu_mps / np.linalg.norm(s.wind_enu_mps, axis=1, keepdims=True)
    # Forward axis faces upwind; the sway axis (body y) is horizontal and across the wind.
    horizontal_forward = forward[:, :2] / np.linalg.norm(forward[:, :2], axis=1, keepdims=True)
    np.testing.assert_allclose(np.sum(horizontal_forward * wind_unit[:, :2], axis=1), -1.0)
    left = s.attitude.apply([0.0, 1.0, 0.0])
    np.testing.assert_allclose(left[:, 2], 0.0, atol=1e-12)
    np.testing.assert_allclose(np.sum(left * wind_unit, axis=1), 0.0, atol=1e-12)


def test_sea_state_paper_002_amplitudes_and_periods():
    _, s = run("sea_state")
    roll, pitch, yaw = np.rad2deg(s.euler_rad).T
    assert np.max(np.abs(roll)) == pytest.approx(10.0, rel=1e-3)
    assert np.max(np.abs(pitch)) == pytest.approx(5.0, rel=1e-3)
    assert dominant_period_s(roll, DT, 2.0, 60.0) == pytest.approx(9.0, rel=0.01)
    assert dominant_period_s(pitch, DT, 2.0, 60.0) == pytest.approx(6.0, rel=0.01)
    assert dominant_period_s(yaw, DT, 2.0, 60.0) == pytest.approx(6.0, rel=0.01)
    # Mooring rotation: 45 deg mean heading, +-40 deg slow swing plus the 5 deg yaw sinusoid.
    assert yaw.max() - 45.0 <= 45.0 + 1e-9
    assert yaw.max() - yaw.min() > 2 * 40.0
    assert np.mean(yaw) == pytest.approx(45.0, abs=8.0)

    heading = np.deg2rad(45.0)
    relative = s.velocity_enu_mps - s.current_enu_mps
    surge = relative[:, 0] * np.cos(heading) + relative[:, 1] * np.sin(heading)
    lateral = -relative[:, 0] * np.sin(heading) + relative[:, 1] * np.cos(heading)
    assert np.max(np.abs(surge)) == pytest.approx(0.03, rel=1e-3)
    assert np.max(np.abs(lateral)) == pytest.approx(0.1, rel=1e-3)
    assert np.max(np.abs(relative[:, 2])) == pytest.approx(0.02, rel=1e-3)
    assert dominant_period_s(relative[:, 2], DT, 2.0, 60.0) == pytest.approx(7.0, rel=0.01)
    assert dominant_period_s(surge, DT, 2.0, 60.0) == pytest.approx(6.0, rel=0.01)
    assert dominant_period_s(lateral, DT, 2.0, 60.0) == pytest.approx(8.0, rel=0.01)
    assert s.latitude_deg[0] == pytest.approx(35.0)
    assert s.longitude_deg[0] == pytest.approx(120.0)
    # 0.15 m/s toward 60 deg and the tide, 30 deg of phase before full flood toward 150 deg.
    flood = np.array([np.sin(np.deg2rad(150.0)), np.cos(np.deg2rad(150.0)), 0.0])
    np.testing.assert_allclose(
        s.current_enu_mps[0],
        0.15 * np.array([np.sin(np.pi / 3), np.cos(np.pi / 3), 0.0])
        + 0.25 * np.cos(np.deg2rad(-30.0)) * flood,
        atol=1e-15,
    )


def test_sea_state_phases_come_from_the_seed():
    _, first = run("sea_state", duration=10.0)
    _, same = run("sea_state", duration=10.0)
    _, other = run("sea_state", "seed=77", duration=10.0)
    np.testing.assert_array_equal(first.euler_rad, same.euler_rad)
    assert not np.allclose(first.euler_rad[:, 0], other.euler_rad[:, 0])


def test_open_ocean_waves_match_the_jonswap_sea():
    _, s = run("open_ocean")
    heave = s.position_enu_m[:, 2]
    # Hs = 4 sqrt(m0); a 20-minute record of a Gaussian sea estimates it within a few percent.
    assert 4.0 * heave.std() == pytest.approx(3.0, rel=0.1)
    frequency, density = welch(heave, fs=1.0 / DT, nperseg=int(300 / DT))
    assert 1.0 / frequency[np.argmax(density)] == pytest.approx(9.0, rel=0.15)
    tilt = np.rad2deg(s.euler_rad[:, :2])
    assert 14.0 < np.max(np.abs(tilt)) < 30.0
    assert np.sqrt(np.sum(tilt.var(axis=0))) == pytest.approx(20.0 / 3.0, rel=0.1)
    # Vertical velocity of a wave follower is the elevation rate: sigma = omega * sigma_eta.
    vertical_speed_ratio = s.velocity_enu_mps[:, 2].std() / heave.std()
    assert 2 * np.pi / 9.0 * 0.8 < vertical_speed_ratio < 2 * np.pi / 9.0 * 1.6
