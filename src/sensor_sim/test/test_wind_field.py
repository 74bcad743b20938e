"""True wind: meteorological conventions and Kaimal turbulence statistics."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.integrate import quad
from scipy.signal import welch

from sensor_sim.scenario import load_scenario
from sensor_sim.truth import TruthModel
from sensor_sim.wind_field import (
    kaimal_length_scales_m,
    kaimal_spectrum,
    meteorological_to_enu_unit,
)


@pytest.mark.parametrize(
    ("from_deg", "toward_enu"),
    [
        (0.0, [0.0, -1.0]),
        (90.0, [-1.0, 0.0]),
        (180.0, [0.0, 1.0]),
        (270.0, [1.0, 0.0]),
        (225.0, [np.sqrt(0.5), np.sqrt(0.5)]),
    ],
)
def test_meteorological_direction_is_where_the_wind_comes_from(from_deg, toward_enu):
    np.testing.assert_allclose(meteorological_to_enu_unit(from_deg), [*toward_enu, 0.0], atol=1e-15)


def test_kaimal_spectrum_carries_the_variance():
    for length_scale in kaimal_length_scales_m(4.0):
        total, _ = quad(lambda f, L=length_scale: kaimal_spectrum(f, 2.5, L, 8.0), 0, np.inf)
        assert total == pytest.approx(2.5, rel=1e-6)
    np.testing.assert_allclose(kaimal_length_scales_m(4.0), [22.68, 7.56, 1.848])
    np.testing.assert_allclose(kaimal_length_scales_m(100.0), [340.2, 113.4, 27.72])


@pytest.fixture(scope="module")
def turbulent_hour():
    scenario = load_scenario("sea_state", overrides=["duration_s=3600"])
    t = np.arange(0.0, 3600.0, 0.05)
    return scenario, t, TruthModel(scenario).wind.turbulence_uvw_mps(t)


def test_turbulence_intensities_match_the_scenario(turbulent_hour):
    scenario, _, uvw = turbulent_hour
    sigma_u = scenario.wind.turbulence_intensity * scenario.wind.speed_mps
    expected = sigma_u * np.array([1.0, 0.8, 0.5])
    np.testing.assert_allclose(uvw.std(axis=0), expected, rtol=0.15)
    # Zero-mean fluctuations; the hour's mean wind stays within a few percent of sigma.
    assert np.all(np.abs(uvw.mean(axis=0)) < 0.25 * expected)
    correlation = np.corrcoef(uvw.T)
    assert np.all(np.abs(correlation[np.triu_indices(3, 1)]) < 0.1)


def test_turbulence_spectra_follow_kaimal(turbulent_hour):
    scenario, _, uvw = turbulent_hour
    speed = scenario.wind.speed_mps
    sigmas = scenario.wind.turbulence_intensity * speed * np.array([1.0, 0.8, 0.5])
    frequency, density = welch(uvw, fs=20.0, nperseg=2400, axis=0)
    for axis, length_scale in enumerate(kaimal_length_scales_m(scenario.wind.height_m)):
        model = kaimal_spectrum(frequency, sigmas[axis] ** 2, length_scale, speed)
        for low, high in ((0.03, 0.1), (0.1, 0.3), (0.3, 1.0), (1.0, 3.0)):
            band = (frequency >= low) & (frequency < high)
            ratio = density[band, axis].mean() / model[band].mean()
            assert 0.7 < ratio < 1.4, (axis, low, ratio)


def test_wind_vector_is_mean_plus_rotated_turbulence(turbulent_hour):
    scenario = turbulent_hour[0]
    truth = TruthModel(scenario)
    t = np.linspace(0.0, 100.0, 11)
    wind = truth.evaluate(t).wind_enu_mps
    uvw = truth.wind.turbulence_uvw_mps(t)
    along = meteorological_to_enu_unit(225.0)
    left = np.array([-along[1], along[0], 0.0])
    expected = 8.0 * along + uvw[:, :1] * along + uvw[:, 1:2] * left + uvw[:, 2:] * [0, 0, 1]
    np.testing.assert_allclose(wind, expected, atol=1e-12)
    assert np.std(wind[:, 2]) > 0.1


def test_steady_wind_has_no_fluctuation():
    truth = TruthModel(load_scenario("wind_tunnel"))
    wind = truth.evaluate(np.linspace(0.0, 600.0, 101)).wind_enu_mps
    np.testing.assert_allclose(wind, [[-5.0, 0.0, 0.0]] * 101, atol=1e-12)


def test_a_surface_layer_carries_the_momentum_and_heat_fluxes_asked_for():
    scenario = load_scenario(
        "open_ocean",
        [
            "duration_s=3600",
            "wind.momentum_flux_correlation=-0.3",
            "wind.sonic_temperature_degc=25.0",
            "wind.temperature_sigma_k=0.1",
            "wind.heat_flux_correlation=0.4",
        ],
    )
    truth = TruthModel(scenario)
    t = np.arange(0.0, 3600.0, 0.1)
    uvw = truth.wind.turbulence_uvw_mps(t)
    temperature = truth.wind.sonic_temperature_degc(t)
    sigma_u, _, sigma_w = truth.wind.sigmas_mps
    # the mixing keeps each component's variance and gives the covariances asked for
    assert np.std(uvw[:, 0]) == pytest.approx(sigma_u, rel=0.05)
    assert np.cov(uvw[:, 0], uvw[:, 2])[0, 1] == pytest.approx(-0.3 * sigma_u * sigma_w, rel=0.1)
    assert np.std(temperature) == pytest.approx(0.1, rel=0.05)
    assert np.mean(temperature) == pytest.approx(25.0, abs=0.01)
    assert np.cov(uvw[:, 2], temperature)[0, 1] == pytest.approx(0.4 * sigma_w * 0.1, rel=0.1)
    # without fluxes asked for, the wind is the one it was: no correlation, no temperature
    plain = TruthModel(load_scenario("open_ocean", ["duration_s=3600"]))
    plain_uvw = plain.wind.turbulence_uvw_mps(t)
    np.testing.assert_array_equal(plain_uvw[:, 1:], uvw[:, 1:])
    assert abs(np.corrcoef(plain_uvw[:, 0], plain_uvw[:, 2])[0, 1]) < 0.05
    assert plain.wind.sonic_temperature_degc(t) is None
