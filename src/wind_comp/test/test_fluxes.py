"""Eddy-covariance fluxes: synthetic turbulence of known covariance, rotation identities,
planar fit, QC."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from wind_comp.flux_products import FluxAverager
from wind_comp.fluxes import (
    SpikeTest,
    air_density_kg_m3,
    fit_plane,
    rotation_into_mean_wind,
    stationarity_percent,
    vickers_mahrt_spikes,
    window_fluxes,
)

RATE_HZ = 10.0
WINDOW_S = 1800.0
# streamwise u, v, w (m/s) and Ts (K): a neutral-to-unstable marine surface layer
COVARIANCE = np.array(
    [
        [1.00, 0.05, -0.30, 0.02],
        [0.05, 0.70, 0.10, 0.00],
        [-0.30, 0.10, 0.40, -0.012],
        [0.02, 0.00, -0.012, 0.04],
    ]
)
MEAN_SPEED_MPS = 8.0


def turbulence(seed: int, samples: int = int(WINDOW_S * RATE_HZ)):
    """Streamwise fluctuations of the known covariance plus the mean wind and linear trends."""
    rng = np.random.default_rng(seed)
    fluctuations = rng.multivariate_normal(np.zeros(4), COVARIANCE, size=samples)
    t = np.arange(samples) / RATE_HZ
    streamwise = fluctuations[:, :3] + [MEAN_SPEED_MPS, 0.0, 0.0]
    streamwise[:, 0] += 1.5 * t / WINDOW_S  # the wind freshens by 1.5 m/s over the window
    temperature = 20.0 + fluctuations[:, 3] - 0.5 * t / WINDOW_S
    return t, streamwise, temperature


def sampling_sigma(i: int, j: int, samples: int) -> float:
    """Standard error of a sample covariance of jointly normal series (Isserlis)."""
    c = COVARIANCE
    return math.sqrt((c[i, i] * c[j, j] + c[i, j] ** 2) / samples)


@pytest.mark.parametrize("seed", [1, 2])
def test_double_rotation_recovers_the_covariances_of_a_tilted_yawed_sonic(seed):
    t, streamwise, temperature = turbulence(seed)
    # the mean wind blows from an arbitrary direction and 4° up the sonic's axes
    to_instrument = Rotation.from_euler("ZY", [37.0, -4.0], degrees=True)
    measured = to_instrument.apply(streamwise)
    window = window_fluxes(t + 1.7e9, measured, temperature)
    n = t.size
    assert abs(window.u_w_m2_s2 - COVARIANCE[0, 2]) < 4 * sampling_sigma(0, 2, n) + 0.003
    assert abs(window.v_w_m2_s2 - COVARIANCE[1, 2]) < 4 * sampling_sigma(1, 2, n) + 0.003
    assert abs(window.w_ts_k_mps - COVARIANCE[2, 3]) < 4 * sampling_sigma(2, 3, n)
    assert math.isclose(window.tilt_deg, 4.0, abs_tol=0.1)
    expected_u_star = (COVARIANCE[0, 2] ** 2 + COVARIANCE[1, 2] ** 2) ** 0.25
    assert math.isclose(window.friction_velocity_mps, expected_u_star, rel_tol=0.03)
    assert math.isclose(
        window.stress_n_m2, window.air_density_kg_m3 * window.friction_velocity_mps**2
    )
    # Gaussian data have 3.5-σ outliers too: Vickers–Mahrt flag a window above 1 %
    assert window.invalid_share == 0.0 and max(window.spikes) < 0.01 * n


def test_friction_velocity_carries_the_cross_wind_stress():
    # A stress turned 45° off the mean wind (swell from the side): |v'w'| = |u'w'|, so the
    # along-wind stress alone would give u* too small by 2^(1/4) - 1 = 19 %.
    covariance = np.array([[1.0, 0.0, -0.2], [0.0, 0.8, 0.2], [-0.2, 0.2, 0.36]])
    rng = np.random.default_rng(21)
    samples = int(WINDOW_S * RATE_HZ)
    streamwise = rng.multivariate_normal(np.zeros(3), covariance, size=samples)
    streamwise[:, 0] += 7.0
    wind = Rotation.from_euler("Z", 250.0, degrees=True).apply(streamwise)
    window = window_fluxes(np.arange(samples) / RATE_HZ, wind)
    sigma = math.sqrt((covariance[0, 0] * covariance[2, 2] + covariance[0, 2] ** 2) / samples)
    assert abs(window.u_w_m2_s2 - covariance[0, 2]) < 4 * sigma
    assert abs(window.v_w_m2_s2 - covariance[1, 2]) < 4 * sigma
    expected = (covariance[0, 2] ** 2 + covariance[1, 2] ** 2) ** 0.25
    along_wind_only = math.sqrt(abs(covariance[0, 2]))
    assert math.isclose(window.friction_velocity_mps, expected, rel_tol=0.04)
    assert not math.isclose(window.friction_velocity_mps, along_wind_only, rel_tol=0.1)
    assert math.isclose(
        window.stress_n_m2,
        window.air_density_kg_m3 * math.hypot(window.u_w_m2_s2, window.v_w_m2_s2),
    )


def test_without_the_rotation_the_tilt_would_bias_the_momentum_flux():
    # The test above is not passing by luck: the same data unrotated give another u'w'.
    t, streamwise, temperature = turbulence(3)
    measured = Rotation.from_euler("Y", -4.0, degrees=True).apply(streamwise)
    raw_u_w = np.cov(measured[:, 0], measured[:, 2])[0, 1]
    assert abs(raw_u_w - COVARIANCE[0, 2]) > 8 * sampling_sigma(0, 2, t.size)
    assert abs(window_fluxes(t, measured, temperature).u_w_m2_s2 - COVARIANCE[0, 2]) < 0.03


def test_the_rotation_is_a_rotation_into_the_mean_wind():
    rng = np.random.default_rng(4)
    wind = rng.normal([3.0, -5.0, 0.4], [1.0, 1.0, 0.3], size=(5000, 3))
    rotation, tilt = rotation_into_mean_wind(wind.mean(axis=0))
    rotated = wind @ rotation.T
    np.testing.assert_allclose(rotation @ rotation.T, np.eye(3), atol=1e-14)
    assert math.isclose(np.linalg.det(rotation), 1.0)
    np.testing.assert_allclose(rotated.mean(axis=0)[1:], 0.0, atol=1e-12)
    assert math.isclose(rotated.mean(axis=0)[0], np.linalg.norm(wind.mean(axis=0)))
    np.testing.assert_allclose(np.linalg.norm(rotated, axis=1), np.linalg.norm(wind, axis=1))
    assert math.isclose(np.trace(np.cov(rotated.T)), np.trace(np.cov(wind.T)))
    assert math.isclose(math.tan(tilt), 0.4 / math.hypot(3.0, 5.0), rel_tol=0.05)


def test_planar_fit_recovers_the_plane_of_the_mean_streamlines():
    # Mean winds of many windows and directions, all in one plane tilted 3° about a
    # north-east axis, offset by 2 cm/s (a sonic's zero offset).
    normal = Rotation.from_rotvec(np.radians(3.0) * np.array([1, 1, 0]) / math.sqrt(2))
    directions = np.radians(np.arange(0.0, 360.0, 20.0))
    horizontal = np.column_stack([np.cos(directions), np.sin(directions), 0 * directions])
    offset = np.array([0.0, 0.0, 0.02])
    means = normal.apply(horizontal * 6.0) + offset
    plane = fit_plane(means)
    np.testing.assert_allclose(plane.normal, normal.apply([0.0, 0.0, 1.0]), atol=1e-12)
    assert math.isclose(plane.tilt_deg, 3.0, rel_tol=1e-9)
    assert math.isclose(plane.offset_mps, 0.02, abs_tol=1e-12)
    # a window of the tilted plane then keeps its known fluxes, with only a yaw per window
    t, streamwise, temperature = turbulence(5)
    measured = normal.apply(Rotation.from_euler("Z", 70.0, degrees=True).apply(streamwise))
    window = window_fluxes(t, measured + offset, temperature, plane=plane)
    assert abs(window.u_w_m2_s2 - COVARIANCE[0, 2]) < 4 * sampling_sigma(0, 2, t.size) + 0.003
    assert math.isclose(window.tilt_deg, 3.0, rel_tol=1e-9)


def test_planar_fit_refuses_windows_of_one_direction():
    with pytest.raises(ValueError, match="different wind directions"):
        fit_plane([[5.0, 0.0, 0.1], [6.0, 0.0, 0.12], [7.0, 0.0, 0.14]])


def test_windows_are_aligned_to_their_length_and_count_invalid_samples():
    t, streamwise, temperature = turbulence(6, samples=int(2.5 * WINDOW_S * RATE_HZ))
    streamwise[100:400] = np.nan
    averager = FluxAverager(WINDOW_S)
    for stamp, value in zip(t + 3 * WINDOW_S, temperature, strict=True):
        averager.add_temperature(stamp, value)
    windows = averager.add_batch(t + 3 * WINDOW_S, streamwise) + averager.flush()
    assert [w.window_start_s for w in windows] == [5400.0, 7200.0, 9000.0]
    assert math.isclose(windows[0].invalid_share, 300 / (WINDOW_S * RATE_HZ))
    assert windows[0].n_invalid == 300
    assert windows[1].invalid_share == 0.0
    assert windows[2].n_valid == int(0.5 * WINDOW_S * RATE_HZ)


def test_vickers_mahrt_counts_short_spikes_and_keeps_long_excursions():
    rng = np.random.default_rng(7)
    series = rng.normal(0.0, 1.0, size=int(WINDOW_S * RATE_HZ))
    spikes_at = [1000, 5000, 9000, 12000, 15001]
    series[spikes_at] += 10.0
    series[7000:7003] -= 10.0  # a run of three: a spike
    series[3000:3020] += 10.0  # twenty samples: an event, not a spike
    found = vickers_mahrt_spikes(series, RATE_HZ, SpikeTest())
    injected = {*spikes_at, 7000, 7001, 7002}
    assert injected <= set(np.flatnonzero(found))
    assert not found[3000:3020].any()
    # beyond them, only the white noise's own rare 3.5-σ outliers
    extra = found.copy()
    extra[list(injected)] = False
    assert extra.sum() < 0.002 * series.size
    assert np.all(np.abs(series[extra]) > 3.2)  # 3.5 σ of the local, moving mean and σ


def test_stationarity_tells_a_steady_flux_from_one_carried_by_a_trend():
    # Foken–Wichura compares the 5-min sub-window covariances with the window's: a slow change
    # of both series (weather passing) adds to the latter only.
    rng = np.random.default_rng(8)
    u, w = rng.multivariate_normal([0, 0], [[1.0, -0.3], [-0.3, 0.4]], size=18000).T
    t = np.arange(u.size) / RATE_HZ
    assert stationarity_percent(t, u, w, 0.0, WINDOW_S) < 30.0
    drift = np.linspace(-1.0, 1.0, u.size)
    assert stationarity_percent(t, u + drift, w + 0.5 * drift, 0.0, WINDOW_S) > 30.0


def test_stationarity_takes_five_minute_sub_windows_of_any_window():
    # A 20-min window (a FDCHP record) is four 5-min sub-windows, not six of 3 min 20 s.
    rng = np.random.default_rng(9)
    samples = int(1200 * RATE_HZ)
    t = np.arange(samples) / RATE_HZ
    u, w = rng.multivariate_normal([0, 0], [[1.0, -0.3], [-0.3, 0.4]], size=samples).T
    # a swing of u and w in phase, of 10-min period: each sub-window holds half of a swing
    swing = np.sin(2 * np.pi * t / 600.0)
    u, w = u + swing, w + 0.5 * swing
    whole = np.cov(u, w, bias=True)[0, 1]
    percent = stationarity_percent(t, u, w, 0.0, 1200.0)
    parts = [np.cov(u[k], w[k], bias=True)[0, 1] for k in np.array_split(np.arange(samples), 4)]
    assert math.isclose(percent, 100 * abs(np.mean(parts) - whole) / abs(whole), rel_tol=1e-9)
    # shorter than two sub-windows: no steady-state test
    assert math.isnan(stationarity_percent(t[:3000], u[:3000], w[:3000], 0.0, 300.0))


def test_air_density_of_the_standard_atmosphere():
    assert math.isclose(air_density_kg_m3(15.0), 1.225, rel_tol=1e-3)
    assert air_density_kg_m3(math.nan) == air_density_kg_m3(15.0)


def bounded_turbulence(seed: int):
    """:func:`turbulence` with every fluctuation within 3 σ of its component, so that a window
    of it holds no Vickers–Mahrt spike of its own (Gaussian data have 3.5-σ outliers)."""
    t, streamwise, temperature = turbulence(seed)
    sigma = np.sqrt(np.diag(COVARIANCE))
    trend = np.column_stack([MEAN_SPEED_MPS + 1.5 * t / WINDOW_S, 0 * t, 0 * t])
    streamwise = trend + np.clip(streamwise - trend, -3 * sigma[:3], 3 * sigma[:3])
    mean_temperature = 20.0 - 0.5 * t / WINDOW_S
    temperature = mean_temperature + np.clip(
        temperature - mean_temperature, -3 * sigma[3], 3 * sigma[3]
    )
    return t, streamwise, temperature


def with_spikes(streamwise, temperature, seed: int):
    """The series with spikes a faulty sonic gives: 30 single samples and 5 pairs in which u
    jumps up by 8 σu while w drops by 8 σw (a spike of the downward momentum flux), and Ts
    jumps up by 10 σT at 20 of them; returns the spiked series and the samples spiked."""
    rng = np.random.default_rng(seed)
    starts = np.sort(rng.choice(np.arange(10, streamwise.shape[0] - 10, 20), 35, replace=False))
    wind_spikes = np.concatenate([starts, starts[:5] + 1])
    temperature_spikes = starts[5:25]
    sigma = np.sqrt(np.diag(COVARIANCE))
    spiked, spiked_temperature = streamwise.copy(), temperature.copy()
    spiked[wind_spikes, 0] += 8 * sigma[0]
    spiked[wind_spikes, 2] -= 8 * sigma[2]
    spiked_temperature[temperature_spikes] += 10 * sigma[3]
    return spiked, spiked_temperature, wind_spikes, temperature_spikes


@pytest.mark.parametrize("seed", [11, 12])
def test_despiking_takes_out_the_spikes_and_gives_back_the_clean_fluxes(seed):
    t, clean, clean_temperature = bounded_turbulence(seed)
    spiked, spiked_temperature, wind_spikes, temperature_spikes = with_spikes(
        clean, clean_temperature, seed
    )
    reference = window_fluxes(t, clean, clean_temperature)
    assert reference.spikes == (0, 0, 0, 0)
    counted = window_fluxes(t, spiked, spiked_temperature)
    despiked = window_fluxes(t, spiked, spiked_temperature, despike=True)
    # every injected spike is found, in its own component, and nothing else
    expected = (wind_spikes.size, 0, wind_spikes.size, temperature_spikes.size)
    assert counted.spikes == despiked.spikes == expected
    # 40 of 18 000 samples out: the clean window's fluxes within a few thousandths ...
    assert abs(despiked.u_w_m2_s2 - reference.u_w_m2_s2) < 0.01 * abs(reference.u_w_m2_s2)
    assert abs(despiked.v_w_m2_s2 - reference.v_w_m2_s2) < 0.005
    assert abs(despiked.w_ts_k_mps - reference.w_ts_k_mps) < 0.02 * abs(reference.w_ts_k_mps)
    assert math.isclose(despiked.tilt_deg, reference.tilt_deg, abs_tol=0.01)
    # ... where the spikes left in bias u'w' and w'Ts' far beyond that
    assert abs(counted.u_w_m2_s2 - reference.u_w_m2_s2) > 0.2 * abs(reference.u_w_m2_s2)
    assert abs(counted.w_ts_k_mps - reference.w_ts_k_mps) > 0.5 * abs(reference.w_ts_k_mps)


def test_despiking_a_window_without_spikes_changes_nothing():
    t, clean, temperature = bounded_turbulence(13)
    assert window_fluxes(t, clean, temperature, despike=True) == window_fluxes(
        t, clean, temperature
    )


def test_the_averager_despikes_its_windows_when_asked():
    t, clean, temperature = bounded_turbulence(14)
    spiked, spiked_temperature, wind_spikes, _ = with_spikes(clean, temperature, 14)
    stamps = t + 2 * WINDOW_S
    windows = {}
    for despike in (False, True):
        averager = FluxAverager(WINDOW_S, despike=despike)
        for stamp, value in zip(stamps, spiked_temperature, strict=True):
            averager.add_temperature(stamp, value)
        (windows[despike],) = averager.add_batch(stamps, spiked) + averager.flush()
    direct = window_fluxes(
        stamps, spiked, spiked_temperature, window_start_s=2 * WINDOW_S, despike=True
    )
    assert windows[True].u_w_m2_s2 == direct.u_w_m2_s2
    assert windows[True].spikes_u == windows[False].spikes_u == wind_spikes.size
    assert windows[True].u_w_m2_s2 != windows[False].u_w_m2_s2
