"""Rotation conventions and the WGS-84 Earth model against independent references."""

import math

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from buoy_nav import earth
from buoy_nav.rotations import (
    cross,
    cross_components,
    euler_from_rotation_matrix,
    quaternion_from_rotation_matrix,
    quaternion_from_rotation_vector,
    quaternion_multiply,
    rotate_by_quaternion_components,
    rotation_matrix_from_euler,
    rotation_matrix_from_quaternion,
    rotation_matrix_from_rotation_vector,
    rotation_vector_from_rotation_matrix,
    skew,
    wrap_angle,
)

RNG = np.random.default_rng(20240611)


def random_euler(count):
    return np.column_stack(
        (
            RNG.uniform(-math.pi, math.pi, count),
            RNG.uniform(-1.5, 1.5, count),
            RNG.uniform(-math.pi, math.pi, count),
        )
    )


def test_euler_convention_is_scipy_zyx():
    for roll, pitch, yaw in random_euler(50):
        expected = Rotation.from_euler("ZYX", [yaw, pitch, roll]).as_matrix()
        np.testing.assert_allclose(
            rotation_matrix_from_euler(roll, pitch, yaw), expected, atol=1e-14
        )
        np.testing.assert_allclose(
            euler_from_rotation_matrix(expected), (roll, pitch, yaw), atol=1e-10
        )


def test_yaw_zero_points_east_and_grows_counter_clockwise():
    forward = np.array((1.0, 0.0, 0.0))
    np.testing.assert_allclose(rotation_matrix_from_euler(0, 0, 0) @ forward, (1, 0, 0))
    np.testing.assert_allclose(
        rotation_matrix_from_euler(0, 0, math.pi / 2) @ forward, (0, 1, 0), atol=1e-15
    )
    # Positive pitch in FLU lowers the nose (right-handed about the left axis).
    assert (rotation_matrix_from_euler(0, 0.1, 0) @ forward)[2] < 0


def test_quaternions_follow_scipy_order_and_compose_like_matrices():
    rotations = Rotation.random(40, random_state=7)
    for a, b in zip(rotations[:20], rotations[20:], strict=True):
        qa, qb = tuple(a.as_quat()), tuple(b.as_quat())
        np.testing.assert_allclose(rotation_matrix_from_quaternion(qa), a.as_matrix(), atol=1e-14)
        product = rotation_matrix_from_quaternion(quaternion_multiply(qa, qb))
        np.testing.assert_allclose(product, a.as_matrix() @ b.as_matrix(), atol=1e-14)
        recovered = quaternion_from_rotation_matrix(a.as_matrix())
        assert abs(abs(np.dot(recovered, a.as_quat())) - 1.0) < 1e-12


@pytest.mark.parametrize("angle", [0.0, 1e-9, 1e-5, 0.3, 2.0, math.pi - 1e-6])
def test_rotation_vector_round_trip_matches_scipy(angle):
    axis = RNG.normal(size=3)
    vector = axis / np.linalg.norm(axis) * angle
    matrix = rotation_matrix_from_rotation_vector(vector)
    np.testing.assert_allclose(matrix, Rotation.from_rotvec(vector).as_matrix(), atol=1e-14)
    np.testing.assert_allclose(rotation_vector_from_rotation_matrix(matrix), vector, atol=1e-9)
    q = quaternion_from_rotation_vector(*vector)
    assert math.isclose(sum(c * c for c in q), 1.0, rel_tol=1e-15)


def test_skew_and_cross_agree_with_numpy():
    a, b = RNG.normal(size=3), RNG.normal(size=3)
    np.testing.assert_allclose(skew(a) @ b, np.cross(a, b), atol=1e-15)
    np.testing.assert_allclose(cross(a, b), np.cross(a, b), atol=1e-15)


@pytest.mark.parametrize(
    ("angle", "wrapped"),
    [
        (0.0, 0.0),
        (math.pi, math.pi),
        (-math.pi, math.pi),
        (3 * math.pi, math.pi),
        (-0.5, -0.5),
        (2 * math.pi + 0.25, 0.25),
        (-2 * math.pi - 0.25, -0.25),
    ],
)
def test_wrap_angle_into_half_open_interval(angle, wrapped):
    assert math.isclose(wrap_angle(angle), wrapped, abs_tol=1e-12)


def test_radii_and_gravity_reference_values():
    meridian, prime_vertical = earth.radii_of_curvature_m(0.0)
    assert prime_vertical == pytest.approx(earth.SEMI_MAJOR_AXIS_M, abs=1e-6)
    assert meridian == pytest.approx(
        earth.SEMI_MAJOR_AXIS_M * (1 - earth.ECCENTRICITY_SQ), abs=1e-6
    )
    # At the pole both radii equal a² / b.
    meridian, prime_vertical = earth.radii_of_curvature_m(math.pi / 2)
    polar = earth.SEMI_MAJOR_AXIS_M**2 / earth.SEMI_MINOR_AXIS_M
    assert meridian == pytest.approx(polar, abs=1e-6)
    assert prime_vertical == pytest.approx(polar, abs=1e-6)
    # WGS-84 (NIMA TR8350.2) normal gravity at the equator and at the poles.
    assert earth.normal_gravity_mps2(0.0, 0.0) == pytest.approx(9.7803253359, abs=1e-10)
    assert earth.normal_gravity_mps2(math.pi / 2, 0.0) == pytest.approx(9.8321849378, abs=1e-9)
    # Free-air gradient near the surface is about −3.086e-6 s⁻² .
    gradient = (earth.normal_gravity_mps2(0.7, 100.0) - earth.normal_gravity_mps2(0.7, 0.0)) / 100
    assert gradient == pytest.approx(-3.086e-6, rel=2e-3)


def test_ecef_reference_points_and_round_trip():
    np.testing.assert_allclose(
        earth.ecef_from_geodetic(0.0, 0.0, 0.0), (earth.SEMI_MAJOR_AXIS_M, 0, 0), atol=1e-9
    )
    np.testing.assert_allclose(
        earth.ecef_from_geodetic(math.pi / 2, 0.3, 10.0),
        (0, 0, earth.SEMI_MINOR_AXIS_M + 10.0),
        atol=1e-6,
    )
    latitude = RNG.uniform(-1.5, 1.5, 200)
    longitude = RNG.uniform(-math.pi, math.pi, 200)
    altitude = RNG.uniform(-500, 10000, 200)
    ecef = earth.ecef_from_geodetic(latitude, longitude, altitude)
    lat2, lon2, alt2 = earth.geodetic_from_ecef(ecef)
    np.testing.assert_allclose(lat2, latitude, atol=1e-12)
    np.testing.assert_allclose(wrap_all(lon2 - longitude), 0, atol=1e-12)
    np.testing.assert_allclose(alt2, altitude, atol=1e-6)
    for i in range(5):
        scalar = earth.ecef_from_geodetic_scalar(latitude[i], longitude[i], altitude[i])
        np.testing.assert_allclose(scalar, ecef[i], atol=1e-8)


def wrap_all(angles):
    return (np.asarray(angles) + math.pi) % (2 * math.pi) - math.pi


def test_tangent_plane_axes_and_distances():
    lat0, lon0, alt0 = math.radians(35.0), math.radians(120.0), 5.0
    plane = earth.LocalTangentPlane(lat0, lon0, alt0)
    meridian, prime_vertical = earth.radii_of_curvature_m(lat0)
    # A small step north / east / up appears on the matching axis with the local radii; the
    # plane drops below the curved surface by d² / 2R, and a parallel of latitude bends
    # towards the pole by d² tan(lat) / 2R.
    north = plane.enu_from_geodetic(lat0 + 1e-6, lon0, alt0)
    east = plane.enu_from_geodetic(lat0, lon0 + 1e-6, alt0)
    up = plane.enu_from_geodetic(lat0, lon0, alt0 + 3.0)
    north_distance = 1e-6 * (meridian + alt0)
    east_distance = 1e-6 * (prime_vertical + alt0) * math.cos(lat0)
    np.testing.assert_allclose(
        north, (0, north_distance, -(north_distance**2) / (2 * meridian)), atol=1e-8
    )
    np.testing.assert_allclose(
        east,
        (
            east_distance,
            east_distance**2 * math.tan(lat0) / (2 * prime_vertical),
            -(east_distance**2) / (2 * prime_vertical),
        ),
        atol=1e-8,
    )
    np.testing.assert_allclose(up, (0, 0, 3.0), atol=1e-9)
    # Round trip, and the scalar fast paths agree with the array path.
    points = RNG.uniform(-2000, 2000, (20, 3))
    lat, lon, alt = plane.geodetic_from_enu(points)
    np.testing.assert_allclose(plane.enu_from_geodetic(lat, lon, alt), points, atol=1e-6)
    for k in range(20):
        np.testing.assert_allclose(
            plane.enu_from_geodetic_scalar(lat[k], lon[k], alt[k]), points[k], atol=1e-6
        )
        np.testing.assert_allclose(
            earth.enu_offset_scalar(lat0, lon0, alt0, lat[k], lon[k], alt[k]), points[k], atol=1e-6
        )
    offset = earth.geodetic_offset(lat0, lon0, alt0, (3.0, -4.0, 1.0))
    np.testing.assert_allclose(plane.enu_from_geodetic(*offset), (3, -4, 1), atol=1e-8)


def test_earth_and_transport_rate():
    latitude = math.radians(35.0)
    rate = earth.earth_rate_enu_rad_s(latitude)
    # The Earth turns about its axis, which points north and, in the northern hemisphere, up:
    # (0, Ω cos L, Ω sin L) in ENU, and in the southern hemisphere the up component turns down.
    np.testing.assert_allclose(
        rate,
        (
            0.0,
            earth.EARTH_RATE_RAD_S * math.cos(latitude),
            earth.EARTH_RATE_RAD_S * math.sin(latitude),
        ),
        rtol=1e-15,
    )
    assert rate[0] == 0.0 and rate[1] > 0 and rate[2] > 0
    south = earth.earth_rate_enu_rad_s(-latitude)
    assert south[1] == pytest.approx(rate[1], rel=1e-15) and south[2] == pytest.approx(-rate[2])
    # Moving east at v on the equator turns the ENU frame about north at v / (a + h).
    transport = earth.transport_rate_enu_rad_s(0.0, 20.0, (10.0, 0.0, 0.0))
    np.testing.assert_allclose(transport, (0, 10.0 / (earth.SEMI_MAJOR_AXIS_M + 20.0), 0))
    # Moving north turns it about west.
    transport = earth.transport_rate_enu_rad_s(latitude, 0.0, (0.0, 5.0, 0.0))
    meridian, _ = earth.radii_of_curvature_m(latitude)
    np.testing.assert_allclose(transport, (-5.0 / meridian, 0, 0))


def test_quaternion_rotation_by_components_keeps_length_and_matches_scipy():
    attitudes = Rotation.random(30, random_state=9)
    vectors = RNG.normal(0, 5, (30, 3))
    scale = RNG.uniform(0.5, 2.0, (30, 1))  # any norm: normalised, not used as given
    rotated = np.stack(
        rotate_by_quaternion_components((scale * attitudes.as_quat()).T, vectors.T), axis=-1
    )
    np.testing.assert_allclose(rotated, attitudes.apply(vectors), atol=1e-12)
    np.testing.assert_allclose(np.linalg.norm(rotated, axis=1), np.linalg.norm(vectors, axis=1))
    # The conjugate rotates back; one vector in floats is the batch's row, bit for bit.
    x, y, z, w = attitudes.as_quat().T
    back = rotate_by_quaternion_components((-x, -y, -z, w), tuple(rotated.T))
    np.testing.assert_allclose(np.stack(back, axis=-1), vectors, atol=1e-12)
    for k in range(30):
        single = rotate_by_quaternion_components(
            tuple((scale[k] * attitudes[k].as_quat()).tolist()), tuple(vectors[k].tolist())
        )
        np.testing.assert_array_equal(single, rotated[k])
    np.testing.assert_array_equal(
        np.stack(cross_components(vectors.T, rotated.T), axis=-1)[0], cross(vectors[0], rotated[0])
    )


def test_earth_rate_components_are_the_earth_rate_alone_or_in_a_batch():
    latitudes = RNG.uniform(-math.pi / 2, math.pi / 2, 25)
    east, north, up = earth.earth_rate_enu_components(latitudes)
    for k, latitude in enumerate(latitudes.tolist()):
        expected = earth.earth_rate_enu_rad_s(latitude)
        np.testing.assert_array_equal((east, north[k], up[k]), expected)
    np.testing.assert_allclose(np.hypot(north, up), earth.EARTH_RATE_RAD_S, rtol=1e-15)
