"""Flux products as a stream: synthetic turbulence of known covariance through the averager,
windows that wait for the sonic temperature, the pairing of temperatures with wind samples,
and the quality flag of a non-stationary window."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from buoy_common.contract import QualityFlag
from wind_comp.flux_products import TEMPERATURE_WAIT_S, FluxAverager
from wind_comp.fluxes import window_fluxes

RATE_HZ = 10.0
WINDOW_S = 1800.0
START_S = 1_767_225_600.0  # a multiple of 30 min
# streamwise u, v, w (m/s) and Ts (K) of a marine surface layer
COVARIANCE = np.array(
    [
        [1.00, 0.05, -0.30, 0.02],
        [0.05, 0.70, 0.10, 0.00],
        [-0.30, 0.10, 0.40, -0.012],
        [0.02, 0.00, -0.012, 0.04],
    ]
)
MEAN_SPEED_MPS = 16.0
"""The wind whose drag the stress of COVARIANCE is (u*² = 0.32 m²/s², C_D = 1.2e-3)."""


def turbulence(seed: int, windows: int = 2):
    """Stamps, ENU wind (the mean wind from an arbitrary direction) and sonic temperature of
    ``windows`` 30-min windows of jointly normal fluctuations of :data:`COVARIANCE`."""
    rng = np.random.default_rng(seed)
    samples = int(windows * WINDOW_S * RATE_HZ)
    fluctuations = rng.multivariate_normal(np.zeros(4), COVARIANCE, size=samples)
    streamwise = fluctuations[:, :3] + [MEAN_SPEED_MPS, 0.0, 0.0]
    wind_enu = Rotation.from_euler("Z", 118.0, degrees=True).apply(streamwise)
    return START_S + np.arange(samples) / RATE_HZ, wind_enu, 20.0 + fluctuations[:, 3]


def sampling_sigma(i: int, j: int, samples: int) -> float:
    """Standard error of a sample covariance of jointly normal series (Isserlis)."""
    c = COVARIANCE
    return math.sqrt((c[i, i] * c[j, j] + c[i, j] ** 2) / samples)


def test_known_covariances_come_out_of_each_window_as_the_library_computes_them():
    t, wind, temperature = turbulence(seed=3)
    averager = FluxAverager(WINDOW_S)
    products = []
    # as the live node takes them: each wind sample, then its temperature
    for part in np.array_split(np.arange(t.size), 400):
        products += averager.add_batch(t[part], wind[part])
        for index in part:
            products += averager.add_temperature(t[index], temperature[index])
    products += averager.flush()
    assert [p.window_start_s for p in products] == [START_S, START_S + WINDOW_S]
    samples = int(WINDOW_S * RATE_HZ)
    for index, product in enumerate(products):
        members = slice(index * samples, (index + 1) * samples)
        reference = window_fluxes(
            t[members],
            wind[members],
            temperature[members],
            window_start_s=product.window_start_s,
            window_end_s=product.window_end_s,
        )
        assert product.u_w_m2_s2 == reference.u_w_m2_s2
        assert product.w_ts_k_mps == reference.w_ts_k_mps
        assert product.n_temperature == samples
        assert product.u_w_m2_s2 == pytest.approx(-0.30, abs=4 * sampling_sigma(0, 2, samples))
        assert product.v_w_m2_s2 == pytest.approx(0.10, abs=4 * sampling_sigma(1, 2, samples))
        assert product.w_ts_k_mps == pytest.approx(-0.012, abs=4 * sampling_sigma(2, 3, samples))
        assert product.coverage == 1.0
        assert product.quality_flag == QualityFlag.GOOD


def test_a_window_waits_for_its_temperatures_unless_they_stopped():
    t, wind, temperature = turbulence(seed=4)
    end = START_S + WINDOW_S
    inside = t < end
    averager = FluxAverager(WINDOW_S)
    for stamp, value in zip(t[inside], temperature[inside], strict=True):
        assert averager.add_temperature(stamp, value) == []
    # the wind passes the end: the temperature of the window's last samples may still come
    just_after = (t >= end) & (t < end + 1.0)
    assert averager.add_batch(t[inside | just_after], wind[inside | just_after]) == []
    (product,) = averager.add_temperature(end + 0.05, 20.0)
    assert product.window_end_s == end and product.n_temperature == inside.sum()
    # a temperature that stops: the next window closes once the wind is well past its end
    second = FluxAverager(WINDOW_S)
    second.add_temperature(t[0], temperature[0])
    waiting = t < end + TEMPERATURE_WAIT_S
    assert second.add_batch(t[waiting], wind[waiting]) == []
    (closed,) = second.add_batch([end + TEMPERATURE_WAIT_S], [wind[0]])
    assert closed.n_temperature == 1


def test_temperatures_pair_with_the_wind_samples_nearest_in_stamp():
    t, wind, temperature = turbulence(seed=5, windows=1)
    first_half = t < START_S + WINDOW_S / 2
    averager = FluxAverager(WINDOW_S)
    # stamped 3 ms after their wind sample, and only for the first half of the window
    for stamp, value in zip(t[first_half], temperature[first_half], strict=True):
        averager.add_temperature(stamp + 0.003, value)
    averager.add_batch(t, wind)
    (product,) = averager.flush()
    half = int(first_half.sum())
    assert product.n_temperature == half
    assert product.w_ts_k_mps == pytest.approx(-0.012, abs=4 * sampling_sigma(2, 3, half))
    without = FluxAverager(WINDOW_S)
    without.add_batch(t, wind)
    (no_temperature,) = without.flush()
    assert no_temperature.n_temperature == 0 and math.isnan(no_temperature.w_ts_k_mps)
    assert no_temperature.u_w_m2_s2 == product.u_w_m2_s2


def test_a_non_stationary_window_is_flagged():
    t, wind, _ = turbulence(seed=6, windows=1)
    # a slow swing of u and w in phase over the window: a covariance the whole window holds and
    # no 5-min sub-window does (Foken and Wichura's sign of non-stationarity)
    swing = np.sin(2 * np.pi * (t - START_S) / WINDOW_S)
    to_enu = Rotation.from_euler("Z", 118.0, degrees=True)
    streamwise = to_enu.inv().apply(wind) + np.column_stack((swing, 0 * swing, 0.5 * swing))
    averager = FluxAverager(WINDOW_S)
    averager.add_batch(t, to_enu.apply(streamwise))
    (product,) = averager.flush()
    assert product.coverage == 1.0
    assert product.stationarity_u_w_percent > 100.0
    assert product.quality_flag == QualityFlag.BAD
