"""WGS-84 earth model for the simulator: radii, normal gravity, geodetic/ECEF/ENU conversions.

The simulator is an independent witness of the navigation code, so this module is written
from the WGS-84 definition (NIMA TR8350.2) and shares nothing with the estimator packages.
Angles are radians unless a name ends in ``_deg``; heights are ellipsoidal, metres.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike

SEMI_MAJOR_AXIS_M = 6378137.0
FLATTENING = 1.0 / 298.257223563
SEMI_MINOR_AXIS_M = SEMI_MAJOR_AXIS_M * (1.0 - FLATTENING)
ECCENTRICITY_SQUARED = FLATTENING * (2.0 - FLATTENING)
EARTH_RATE_RAD_S = 7.292115e-5
GRAVITATIONAL_CONSTANT_M3_S2 = 3.986004418e14
EQUATORIAL_GRAVITY_MPS2 = 9.7803253359
POLAR_GRAVITY_MPS2 = 9.8321849378

# Somigliana's constant k = b*gamma_p / (a*gamma_e) - 1 and the geodetic parameter
# m = omega^2 a^2 b / GM, both derived from the defining constants above.
_SOMIGLIANA_K = (
    SEMI_MINOR_AXIS_M * POLAR_GRAVITY_MPS2 / (SEMI_MAJOR_AXIS_M * EQUATORIAL_GRAVITY_MPS2) - 1.0
)
_GEODETIC_M = (
    EARTH_RATE_RAD_S**2 * SEMI_MAJOR_AXIS_M**2 * SEMI_MINOR_AXIS_M / GRAVITATIONAL_CONSTANT_M3_S2
)


def meridian_radius_m(latitude_rad: ArrayLike) -> np.ndarray:
    """Meridian radius of curvature R_M (north-south), metres, at geodetic latitude (rad)."""
    sin_lat = np.sin(np.asarray(latitude_rad, dtype=float))
    w2 = 1.0 - ECCENTRICITY_SQUARED * sin_lat**2
    return SEMI_MAJOR_AXIS_M * (1.0 - ECCENTRICITY_SQUARED) / w2**1.5


def prime_vertical_radius_m(latitude_rad: ArrayLike) -> np.ndarray:
    """Prime-vertical radius of curvature R_N (east-west), metres, at geodetic latitude (rad)."""
    sin_lat = np.sin(np.asarray(latitude_rad, dtype=float))
    return SEMI_MAJOR_AXIS_M / np.sqrt(1.0 - ECCENTRICITY_SQUARED * sin_lat**2)


def meridian_radius_derivative_m(latitude_rad: ArrayLike) -> np.ndarray:
    """dR_M/d(latitude), metres per radian."""
    lat = np.asarray(latitude_rad, dtype=float)
    sin_lat, cos_lat = np.sin(lat), np.cos(lat)
    w2 = 1.0 - ECCENTRICITY_SQUARED * sin_lat**2
    return (
        3.0
        * SEMI_MAJOR_AXIS_M
        * (1.0 - ECCENTRICITY_SQUARED)
        * ECCENTRICITY_SQUARED
        * sin_lat
        * cos_lat
        / w2**2.5
    )


def prime_vertical_radius_derivative_m(latitude_rad: ArrayLike) -> np.ndarray:
    """dR_N/d(latitude), metres per radian."""
    lat = np.asarray(latitude_rad, dtype=float)
    sin_lat, cos_lat = np.sin(lat), np.cos(lat)
    w2 = 1.0 - ECCENTRICITY_SQUARED * sin_lat**2
    return SEMI_MAJOR_AXIS_M * ECCENTRICITY_SQUARED * sin_lat * cos_lat / w2**1.5


def wgs84_normal_gravity_mps2(latitude_rad: ArrayLike, height_m: ArrayLike) -> np.ndarray:
    """WGS-84 normal gravity magnitude, m/s², at geodetic latitude (rad) and ellipsoidal height (m).

    Somigliana's closed formula on the ellipsoid, continued upward with the second-order
    free-air expansion of TR8350.2 (eq. 4-3), which is accurate to a few 1e-7 m/s² for the
    heights of a buoy or an aircraft.
    """
    lat = np.asarray(latitude_rad, dtype=float)
    h = np.asarray(height_m, dtype=float)
    sin2 = np.sin(lat) ** 2
    on_ellipsoid = (
        EQUATORIAL_GRAVITY_MPS2
        * (1.0 + _SOMIGLIANA_K * sin2)
        / np.sqrt(1.0 - ECCENTRICITY_SQUARED * sin2)
    )
    a = SEMI_MAJOR_AXIS_M
    height_factor = (
        1.0 - 2.0 / a * (1.0 + FLATTENING + _GEODETIC_M - 2.0 * FLATTENING * sin2) * h
    ) + 3.0 * h**2 / a**2
    return on_ellipsoid * height_factor


def earth_rate_enu_rad_s(latitude_rad: ArrayLike) -> np.ndarray:
    """Earth rotation rate omega_ie^n resolved in local ENU axes, rad/s, shape (..., 3)."""
    lat = np.asarray(latitude_rad, dtype=float)
    return np.stack(
        [
            np.zeros_like(lat),
            EARTH_RATE_RAD_S * np.cos(lat),
            EARTH_RATE_RAD_S * np.sin(lat),
        ],
        axis=-1,
    )


def transport_rate_enu_rad_s(
    latitude_rad: ArrayLike, height_m: ArrayLike, velocity_enu_mps: ArrayLike
) -> np.ndarray:
    """Rotation rate omega_en^n of the local ENU frame over the Earth, rad/s, shape (..., 3).

    It follows from the geodetic rates lat' = vN/(R_M+h), lon' = vE/((R_N+h) cos lat).
    """
    lat = np.asarray(latitude_rad, dtype=float)
    h = np.asarray(height_m, dtype=float)
    v = np.asarray(velocity_enu_mps, dtype=float)
    rm_h = meridian_radius_m(lat) + h
    rn_h = prime_vertical_radius_m(lat) + h
    return np.stack(
        [-v[..., 1] / rm_h, v[..., 0] / rn_h, v[..., 0] * np.tan(lat) / rn_h],
        axis=-1,
    )


def geodetic_to_ecef_m(
    latitude_rad: ArrayLike, longitude_rad: ArrayLike, height_m: ArrayLike
) -> np.ndarray:
    """Earth-centred Earth-fixed position, metres, shape (..., 3), of a geodetic point."""
    lat = np.asarray(latitude_rad, dtype=float)
    lon = np.asarray(longitude_rad, dtype=float)
    h = np.asarray(height_m, dtype=float)
    rn = prime_vertical_radius_m(lat)
    cos_lat = np.cos(lat)
    return np.stack(
        [
            (rn + h) * cos_lat * np.cos(lon),
            (rn + h) * cos_lat * np.sin(lon),
            (rn * (1.0 - ECCENTRICITY_SQUARED) + h) * np.sin(lat),
        ],
        axis=-1,
    )


def ecef_to_geodetic(ecef_m: ArrayLike) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Geodetic latitude (rad), longitude (rad), ellipsoidal height (m) of ECEF points (..., 3).

    Bowring's parametric-latitude iteration; three passes converge far below 1e-12 rad for any
    point within a few hundred kilometres of the ellipsoid surface.
    """
    p = np.asarray(ecef_m, dtype=float)
    x, y, z = p[..., 0], p[..., 1], p[..., 2]
    a, b, e2 = SEMI_MAJOR_AXIS_M, SEMI_MINOR_AXIS_M, ECCENTRICITY_SQUARED
    second_e2 = (a**2 - b**2) / b**2
    rho = np.hypot(x, y)
    lon = np.arctan2(y, x)
    beta = np.arctan2(z * a, rho * b)
    for _ in range(3):
        lat = np.arctan2(z + second_e2 * b * np.sin(beta) ** 3, rho - e2 * a * np.cos(beta) ** 3)
        beta = np.arctan2(b * np.sin(lat), a * np.cos(lat))
    sin_lat, cos_lat = np.sin(lat), np.cos(lat)
    rn = prime_vertical_radius_m(lat)
    # This height formula stays well conditioned at every latitude, poles included.
    height = rho * cos_lat + (z + e2 * rn * sin_lat) * sin_lat - rn
    return lat, lon, height


def enu_to_ecef_rotation(latitude_rad: ArrayLike, longitude_rad: ArrayLike) -> np.ndarray:
    """Rotation matrices (..., 3, 3) taking local ENU vector components to ECEF components."""
    lat = np.asarray(latitude_rad, dtype=float)
    lon = np.asarray(longitude_rad, dtype=float)
    sin_lat, cos_lat = np.sin(lat), np.cos(lat)
    sin_lon, cos_lon = np.sin(lon), np.cos(lon)
    zero = np.zeros_like(lat * lon)
    east = np.stack([-sin_lon + zero, cos_lon + zero, zero], axis=-1)
    north = np.stack([-sin_lat * cos_lon, -sin_lat * sin_lon, cos_lat + zero], axis=-1)
    up = np.stack([cos_lat * cos_lon, cos_lat * sin_lon, sin_lat + zero], axis=-1)
    return np.stack([east, north, up], axis=-1)


def geodetic_to_enu_m(
    latitude_rad: ArrayLike,
    longitude_rad: ArrayLike,
    height_m: ArrayLike,
    origin_latitude_rad: float,
    origin_longitude_rad: float,
    origin_height_m: float,
) -> np.ndarray:
    """Position (..., 3), metres, in the tangent-plane ENU frame at the given geodetic origin."""
    ecef = geodetic_to_ecef_m(latitude_rad, longitude_rad, height_m)
    origin = geodetic_to_ecef_m(origin_latitude_rad, origin_longitude_rad, origin_height_m)
    rotation = enu_to_ecef_rotation(origin_latitude_rad, origin_longitude_rad)
    return (ecef - origin) @ rotation


def offset_geodetic(
    latitude_rad: ArrayLike,
    longitude_rad: ArrayLike,
    height_m: ArrayLike,
    offset_enu_m: ArrayLike,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Geodetic position (lat rad, lon rad, h m) of a point displaced by offset_enu_m (..., 3).

    The offset is resolved in the local ENU axes at the starting point; the result is exact
    (through ECEF), not a small-offset approximation.
    """
    ecef = geodetic_to_ecef_m(latitude_rad, longitude_rad, height_m)
    rotation = enu_to_ecef_rotation(latitude_rad, longitude_rad)
    displaced = ecef + np.einsum("...ij,...j->...i", rotation, np.asarray(offset_enu_m, float))
    return ecef_to_geodetic(displaced)
