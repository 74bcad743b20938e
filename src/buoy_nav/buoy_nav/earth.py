"""WGS-84 Earth model and the coordinate conversions of the navigation core.

Geodetic coordinates are latitude/longitude (rad unless the name says ``_deg``) and ellipsoidal
height (m). ECEF is the WGS-84 Earth-centred Earth-fixed frame (m). A local tangent plane is the
East-North-Up frame whose origin is a geodetic point; the ``map`` frame is such a plane.

Scalar functions use :mod:`math` because the strapdown integrator calls them at the IMU rate;
the ``*_ecef`` / tangent-plane conversions accept numpy arrays (broadcasting) as well.
"""

import math

import numpy as np
from numba.extending import register_jitable

SEMI_MAJOR_AXIS_M = 6378137.0
FLATTENING = 1.0 / 298.257223563
ECCENTRICITY_SQ = FLATTENING * (2.0 - FLATTENING)
SEMI_MINOR_AXIS_M = SEMI_MAJOR_AXIS_M * (1.0 - FLATTENING)
EARTH_RATE_RAD_S = 7.292115e-5
GRAVITATIONAL_CONSTANT_M3_S2 = 3.986004418e14

# Somigliana's closed form of WGS-84 normal gravity on the ellipsoid (NIMA TR8350.2, eq. 4-1).
_EQUATORIAL_GRAVITY_MPS2 = 9.7803253359
_SOMIGLIANA_K = 0.00193185265241
# m = ω² a² b / GM, used by the second-order free-air correction (TR8350.2, eq. 4-3).
_GRAVITY_M = (
    EARTH_RATE_RAD_S**2 * SEMI_MAJOR_AXIS_M**2 * SEMI_MINOR_AXIS_M / GRAVITATIONAL_CONSTANT_M3_S2
)


def radii_of_curvature_m(latitude_rad: float) -> tuple[float, float]:
    """Meridian (north-south) and prime-vertical (east-west) radii of curvature (m)."""
    sin_lat = math.sin(latitude_rad)
    w_sq = 1.0 - ECCENTRICITY_SQ * sin_lat * sin_lat
    prime_vertical = SEMI_MAJOR_AXIS_M / math.sqrt(w_sq)
    meridian = prime_vertical * (1.0 - ECCENTRICITY_SQ) / w_sq
    return meridian, prime_vertical


def normal_gravity_mps2(latitude_rad: float, altitude_m: float) -> float:
    """Magnitude of WGS-84 normal gravity (m/s², gravitation plus centrifugal) at a geodetic point.

    It points down the ellipsoid normal: the gravity vector in ENU is (0, 0, −g).
    """
    # A product, not a power: the interpreter's ``** 2`` is the C library's pow, which the
    # compiled copies of this function (a product) differ from in the last bit now and then.
    sin_latitude = math.sin(latitude_rad)
    sin_sq = sin_latitude * sin_latitude
    surface = (
        _EQUATORIAL_GRAVITY_MPS2
        * (1.0 + _SOMIGLIANA_K * sin_sq)
        / math.sqrt(1.0 - ECCENTRICITY_SQ * sin_sq)
    )
    h_over_a = altitude_m / SEMI_MAJOR_AXIS_M
    return surface * (
        1.0
        - 2.0 * (1.0 + FLATTENING + _GRAVITY_M - 2.0 * FLATTENING * sin_sq) * h_over_a
        + 3.0 * h_over_a * h_over_a
    )


def earth_rate_enu_components(latitude_rad) -> tuple:
    """Earth rotation rate ω_ie in the local ENU frame (rad/s) at geodetic latitude φ (rad):
    (0, Ω cos φ, Ω sin φ) as (east, north, up). φ may be a float or an array (elementwise:
    one latitude alone and a batch give bit-identical components)."""
    return (
        0.0,
        EARTH_RATE_RAD_S * np.cos(latitude_rad),
        EARTH_RATE_RAD_S * np.sin(latitude_rad),
    )


def earth_rate_enu_rad_s(latitude_rad: float) -> np.ndarray:
    """Earth rotation rate ω_ie expressed in the local ENU frame (rad/s), as a (3,) array."""
    return np.array(earth_rate_enu_components(latitude_rad), dtype=float)


def transport_rate_enu_rad_s(
    latitude_rad: float, altitude_m: float, velocity_enu_mps
) -> np.ndarray:
    """Transport rate ω_en of the ENU frame moving over the ellipsoid (rad/s, ENU)."""
    meridian, prime_vertical = radii_of_curvature_m(latitude_rad)
    v_east, v_north = float(velocity_enu_mps[0]), float(velocity_enu_mps[1])
    east_radius = prime_vertical + altitude_m
    return np.array(
        (
            -v_north / (meridian + altitude_m),
            v_east / east_radius,
            v_east * math.tan(latitude_rad) / east_radius,
        )
    )


def navigation_frame_rate_enu_rad_s(
    latitude_rad: float, altitude_m: float, velocity_enu_mps
) -> np.ndarray:
    """ω_in = ω_ie + ω_en: rotation rate of the ENU frame with respect to inertial space (rad/s)."""
    return earth_rate_enu_rad_s(latitude_rad) + transport_rate_enu_rad_s(
        latitude_rad, altitude_m, velocity_enu_mps
    )


def ecef_from_geodetic(latitude_rad, longitude_rad, altitude_m) -> np.ndarray:
    """WGS-84 ECEF position (m, last axis xyz) of geodetic coordinates (rad, rad, m)."""
    lat = np.asarray(latitude_rad, dtype=float)
    lon = np.asarray(longitude_rad, dtype=float)
    alt = np.asarray(altitude_m, dtype=float)
    sin_lat, cos_lat = np.sin(lat), np.cos(lat)
    prime_vertical = SEMI_MAJOR_AXIS_M / np.sqrt(1.0 - ECCENTRICITY_SQ * sin_lat**2)
    horizontal = (prime_vertical + alt) * cos_lat
    return np.stack(
        (
            horizontal * np.cos(lon),
            horizontal * np.sin(lon),
            (prime_vertical * (1.0 - ECCENTRICITY_SQ) + alt) * sin_lat,
        ),
        axis=-1,
    )


@register_jitable
def ecef_from_geodetic_scalar(
    latitude_rad: float, longitude_rad: float, altitude_m: float
) -> tuple[float, float, float]:
    """Same as :func:`ecef_from_geodetic` for one point, with plain floats (fast path); compiled
    code calls the same source (:func:`enu_offset_scalar` compiled)."""
    sin_lat, cos_lat = math.sin(latitude_rad), math.cos(latitude_rad)
    prime_vertical = SEMI_MAJOR_AXIS_M / math.sqrt(1.0 - ECCENTRICITY_SQ * sin_lat * sin_lat)
    horizontal = (prime_vertical + altitude_m) * cos_lat
    return (
        horizontal * math.cos(longitude_rad),
        horizontal * math.sin(longitude_rad),
        (prime_vertical * (1.0 - ECCENTRICITY_SQ) + altitude_m) * sin_lat,
    )


def enu_offset_scalar(
    origin_latitude_rad: float,
    origin_longitude_rad: float,
    origin_altitude_m: float,
    latitude_rad: float,
    longitude_rad: float,
    altitude_m: float,
) -> tuple[float, float, float]:
    """ENU coordinates (m) of a geodetic point in the tangent plane at an origin (exact)."""
    ox, oy, oz = ecef_from_geodetic_scalar(
        origin_latitude_rad, origin_longitude_rad, origin_altitude_m
    )
    x, y, z = ecef_from_geodetic_scalar(latitude_rad, longitude_rad, altitude_m)
    dx, dy, dz = x - ox, y - oy, z - oz
    sin_lat, cos_lat = math.sin(origin_latitude_rad), math.cos(origin_latitude_rad)
    sin_lon, cos_lon = math.sin(origin_longitude_rad), math.cos(origin_longitude_rad)
    horizontal = cos_lon * dx + sin_lon * dy
    return (
        -sin_lon * dx + cos_lon * dy,
        -sin_lat * horizontal + cos_lat * dz,
        cos_lat * horizontal + sin_lat * dz,
    )


def geodetic_from_ecef(ecef_m) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Geodetic latitude (rad), longitude (rad), ellipsoidal height (m) of ECEF points (m, xyz).

    Bowring's initial guess refined by Newton-like fixed-point iterations; converged to
    below 1e-12 rad and 1e-6 m for points within a few hundred kilometres of the surface.
    """
    ecef = np.asarray(ecef_m, dtype=float)
    x, y, z = ecef[..., 0], ecef[..., 1], ecef[..., 2]
    longitude = np.arctan2(y, x)
    p = np.hypot(x, y)
    second_eccentricity_sq = ECCENTRICITY_SQ / (1.0 - ECCENTRICITY_SQ)
    beta = np.arctan2(z * SEMI_MAJOR_AXIS_M, p * SEMI_MINOR_AXIS_M)
    latitude = np.arctan2(
        z + second_eccentricity_sq * SEMI_MINOR_AXIS_M * np.sin(beta) ** 3,
        p - ECCENTRICITY_SQ * SEMI_MAJOR_AXIS_M * np.cos(beta) ** 3,
    )
    for _ in range(3):
        beta = np.arctan2((1.0 - FLATTENING) * np.sin(latitude), np.cos(latitude))
        latitude = np.arctan2(
            z + second_eccentricity_sq * SEMI_MINOR_AXIS_M * np.sin(beta) ** 3,
            p - ECCENTRICITY_SQ * SEMI_MAJOR_AXIS_M * np.cos(beta) ** 3,
        )
    sin_lat, cos_lat = np.sin(latitude), np.cos(latitude)
    prime_vertical = SEMI_MAJOR_AXIS_M / np.sqrt(1.0 - ECCENTRICITY_SQ * sin_lat**2)
    altitude = p * cos_lat + z * sin_lat - SEMI_MAJOR_AXIS_M**2 / prime_vertical
    return latitude, longitude, altitude


def rotation_enu_to_ecef(latitude_rad: float, longitude_rad: float) -> np.ndarray:
    """3×3 rotation taking ENU vectors at a geodetic point into ECEF axes (columns = E, N, U)."""
    sin_lat, cos_lat = math.sin(latitude_rad), math.cos(latitude_rad)
    sin_lon, cos_lon = math.sin(longitude_rad), math.cos(longitude_rad)
    return np.array(
        (
            (-sin_lon, -sin_lat * cos_lon, cos_lat * cos_lon),
            (cos_lon, -sin_lat * sin_lon, cos_lat * sin_lon),
            (0.0, cos_lat, sin_lat),
        )
    )


class LocalTangentPlane:
    """East-North-Up tangent plane at a geodetic origin (e.g. the ``map`` frame).

    Conversions are exact (through ECEF), not a flat-Earth approximation.
    """

    def __init__(self, latitude_rad: float, longitude_rad: float, altitude_m: float):
        self.latitude_rad = float(latitude_rad)
        self.longitude_rad = float(longitude_rad)
        self.altitude_m = float(altitude_m)
        self._origin_ecef = ecef_from_geodetic(latitude_rad, longitude_rad, altitude_m)
        self._enu_to_ecef = rotation_enu_to_ecef(latitude_rad, longitude_rad)
        origin = ecef_from_geodetic_scalar(latitude_rad, longitude_rad, altitude_m)
        self.scalar_terms = np.array([*origin, *self._enu_to_ecef.T.ravel()])
        """The ECEF origin (m) and the rows of the ECEF → ENU rotation (row-major), one array
        of 12: the plane as :func:`enu_from_ecef_scalar` takes it, in compiled code too."""

    def enu_from_geodetic(self, latitude_rad, longitude_rad, altitude_m) -> np.ndarray:
        """ENU coordinates (m, last axis E, N, U) of geodetic points (rad, rad, m)."""
        delta = ecef_from_geodetic(latitude_rad, longitude_rad, altitude_m) - self._origin_ecef
        return delta @ self._enu_to_ecef

    def geodetic_from_enu(self, enu_m) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Geodetic latitude (rad), longitude (rad), height (m) of ENU points (m)."""
        ecef = np.asarray(enu_m, dtype=float) @ self._enu_to_ecef.T + self._origin_ecef
        return geodetic_from_ecef(ecef)

    def enu_from_geodetic_scalar(
        self, latitude_rad: float, longitude_rad: float, altitude_m: float
    ) -> tuple[float, float, float]:
        """Same as :meth:`enu_from_geodetic` for one point, by the scalar arithmetic that the
        solutions' compiled code runs (:func:`enu_from_ecef_scalar`)."""
        return enu_from_ecef_scalar(
            *ecef_from_geodetic_scalar(latitude_rad, longitude_rad, altitude_m),
            self.scalar_terms,
        )


def enu_from_ecef_scalar(x_m: float, y_m: float, z_m: float, plane_terms) -> tuple:
    """ENU coordinates (m) of the ECEF point (``x_m``, ``y_m``, ``z_m``, m) in the tangent
    plane whose :attr:`LocalTangentPlane.scalar_terms` are ``plane_terms``. Scalars only, so
    that compiled code (numba) runs the same source, sum for sum."""
    t = plane_terms
    dx, dy, dz = x_m - t[0], y_m - t[1], z_m - t[2]
    return (
        t[3] * dx + t[4] * dy + t[5] * dz,
        t[6] * dx + t[7] * dy + t[8] * dz,
        t[9] * dx + t[10] * dy + t[11] * dz,
    )


def geodetic_offset(
    latitude_rad: float, longitude_rad: float, altitude_m: float, offset_enu_m
) -> tuple[float, float, float]:
    """Geodetic point (rad, rad, m) reached from a point by an ENU offset (m) of that point."""
    plane = LocalTangentPlane(latitude_rad, longitude_rad, altitude_m)
    lat, lon, alt = plane.geodetic_from_enu(offset_enu_m)
    return float(lat), float(lon), float(alt)
