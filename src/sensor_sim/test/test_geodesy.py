"""WGS-84 earth model of the simulator against defining constants and closed forms."""

from __future__ import annotations

import numpy as np
import pytest

from sensor_sim.geodesy import (
    ecef_to_geodetic,
    geodetic_to_ecef_m,
    geodetic_to_enu_m,
    meridian_radius_derivative_m,
    meridian_radius_m,
    offset_geodetic,
    prime_vertical_radius_derivative_m,
    prime_vertical_radius_m,
    wgs84_normal_gravity_mps2,
)

A = 6378137.0
INVERSE_FLATTENING = 298.257223563
B = A * (1.0 - 1.0 / INVERSE_FLATTENING)
GAMMA_EQUATOR = 9.7803253359
GAMMA_POLE = 9.8321849378


def somigliana_original_form(latitude_rad):
    """Somigliana (1929) in its original form, (a ge cos² + b gp sin²) / sqrt(a² cos² + b² sin²)."""
    c2, s2 = np.cos(latitude_rad) ** 2, np.sin(latitude_rad) ** 2
    return (A * GAMMA_EQUATOR * c2 + B * GAMMA_POLE * s2) / np.sqrt(A**2 * c2 + B**2 * s2)


def test_normal_gravity_on_the_ellipsoid():
    latitudes = np.deg2rad([0.0, 20.0, 35.0, 38.9, 45.0, 60.0, 90.0])
    np.testing.assert_allclose(
        wgs84_normal_gravity_mps2(latitudes, 0.0), somigliana_original_form(latitudes), atol=1e-10
    )
    assert wgs84_normal_gravity_mps2(0.0, 0.0) == pytest.approx(GAMMA_EQUATOR, abs=1e-12)
    assert wgs84_normal_gravity_mps2(np.pi / 2, 0.0) == pytest.approx(GAMMA_POLE, abs=1e-10)


def test_free_air_gradient():
    # The normal free-air gradient is about 0.3086 mGal/m = 3.086e-6 s^-2, slightly larger at the
    # equator than at the poles.
    for latitude_deg in (0.0, 45.0, 80.0):
        latitude = np.deg2rad(latitude_deg)
        gradient = (
            wgs84_normal_gravity_mps2(latitude, 0.0) - wgs84_normal_gravity_mps2(latitude, 100.0)
        ) / 100.0
        assert 3.07e-6 < gradient < 3.10e-6


def test_radii_of_curvature():
    assert meridian_radius_m(0.0) == pytest.approx(B**2 / A, rel=1e-14)
    assert prime_vertical_radius_m(0.0) == pytest.approx(A, rel=1e-14)
    assert meridian_radius_m(np.pi / 2) == pytest.approx(A**2 / B, rel=1e-14)
    assert prime_vertical_radius_m(np.pi / 2) == pytest.approx(A**2 / B, rel=1e-14)
    latitude = np.deg2rad(np.array([10.0, 35.0, 70.0]))
    step = 1e-6
    np.testing.assert_allclose(
        meridian_radius_derivative_m(latitude),
        (meridian_radius_m(latitude + step) - meridian_radius_m(latitude - step)) / (2 * step),
        rtol=1e-6,
    )
    np.testing.assert_allclose(
        prime_vertical_radius_derivative_m(latitude),
        (prime_vertical_radius_m(latitude + step) - prime_vertical_radius_m(latitude - step))
        / (2 * step),
        rtol=1e-6,
    )


def test_ecef_known_points_and_round_trip():
    np.testing.assert_allclose(geodetic_to_ecef_m(0.0, 0.0, 0.0), [A, 0.0, 0.0], atol=1e-9)
    np.testing.assert_allclose(geodetic_to_ecef_m(np.pi / 2, 0.0, 0.0), [0, 0, B], atol=1e-9)
    np.testing.assert_allclose(
        geodetic_to_ecef_m(0.0, np.pi / 2, 100.0), [0.0, A + 100.0, 0.0], atol=1e-9
    )
    rng = np.random.default_rng(0)
    latitude = rng.uniform(-np.pi / 2 + 1e-3, np.pi / 2 - 1e-3, 1000)
    longitude = rng.uniform(-np.pi, np.pi, 1000)
    height = rng.uniform(-500.0, 20000.0, 1000)
    back = ecef_to_geodetic(geodetic_to_ecef_m(latitude, longitude, height))
    np.testing.assert_allclose(back[0], latitude, atol=1e-12)
    np.testing.assert_allclose(back[1], longitude, atol=1e-12)
    np.testing.assert_allclose(back[2], height, atol=1e-6)


def test_enu_offsets_are_exact():
    origin = np.deg2rad(38.9), np.deg2rad(117.7), 5.0
    offsets = np.array([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0], [300.0, -120.0, 7.0]])
    latitude, longitude, height = offset_geodetic(*origin, offsets)
    np.testing.assert_allclose(
        geodetic_to_enu_m(latitude, longitude, height, *origin), offsets, atol=1e-8
    )
    # One metre north moves the latitude by 1/(R_M + h) radians; one metre up raises h by 1 m.
    assert latitude[1] - origin[0] == pytest.approx(1.0 / (meridian_radius_m(origin[0]) + 5.0))
    assert height[2] - origin[2] == pytest.approx(1.0, abs=1e-9)
    east_rate = 1.0 / ((prime_vertical_radius_m(origin[0]) + 5.0) * np.cos(origin[0]))
    assert longitude[0] - origin[1] == pytest.approx(east_rate, rel=1e-6)
