"""Alignment at sea: levelling on a moving buoy, exact heading for any geometry, covariance."""

import math

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from buoy_nav import earth
from buoy_nav.alignment import AlignmentState, InMotionAligner
from buoy_nav.config import FusionConfig
from buoy_nav.error_state_filter import ImuErrorModel
from buoy_nav.rotations import rotation_vector_from_rotation_matrix

LATITUDE = math.radians(20.0)
LONGITUDE = math.radians(115.0)
GRAVITY = earth.normal_gravity_mps2(LATITUDE, 0.0)
EARTH_RATE = earth.earth_rate_enu_rad_s(LATITUDE)
PRIMARY = (0.35, -0.6, 1.2)
SECONDARY = (-0.8, 0.45, 0.9)


def make_aligner(**overrides):
    config = FusionConfig(
        primary_antenna_body_m=PRIMARY, secondary_antenna_body_m=SECONDARY, **overrides
    )
    return InMotionAligner(config, ImuErrorModel.from_config(config))


def rocking(roll_amplitude, pitch_amplitude, yaw0, period=8.0):
    """Analytic rocking about the IMU origin: Euler angles and their rates."""
    w = 2 * math.pi / period

    def euler(t):
        return np.array(
            (
                roll_amplitude * math.sin(w * t),
                pitch_amplitude * math.sin(0.7 * w * t + 1.0),
                yaw0 + 0.05 * math.sin(0.3 * w * t),
            )
        )

    def euler_rate(t):
        return np.array(
            (
                roll_amplitude * w * math.cos(w * t),
                pitch_amplitude * 0.7 * w * math.cos(0.7 * w * t + 1.0),
                0.05 * 0.3 * w * math.cos(0.3 * w * t),
            )
        )

    return euler, euler_rate


def body_rate(euler, euler_rate):
    """ω_nb^b from ZYX Euler rates (independent of the code under test)."""
    roll, pitch, _ = euler
    droll, dpitch, dyaw = euler_rate
    return np.array(
        (
            droll - dyaw * math.sin(pitch),
            dpitch * math.cos(roll) + dyaw * math.sin(roll) * math.cos(pitch),
            -dpitch * math.sin(roll) + dyaw * math.cos(roll) * math.cos(pitch),
        )
    )


def rotation_of(euler):
    return Rotation.from_euler("ZYX", euler[::-1]).as_matrix()


def feed(aligner, euler_at, rate_at, duration, dt=0.01, acceleration_at=None, accel_bias=None):
    """Exact IMU samples of a buoy turning about its IMU (plus an optional ENU acceleration)."""

    def sample(t):
        rotation = rotation_of(euler_at(t))
        specific_force_enu = np.array((0.0, 0.0, GRAVITY))
        if acceleration_at is not None:
            specific_force_enu = specific_force_enu + acceleration_at(t)
        gyro = body_rate(euler_at(t), rate_at(t)) + rotation.T @ EARTH_RATE
        force = rotation.T @ specific_force_enu
        if accel_bias is not None:
            force = force + accel_bias
        return gyro, force

    steps = round(duration / dt)
    gyro0, force0 = sample(0.0)
    for k in range(1, steps + 1):
        gyro1, force1 = sample(k * dt)
        aligner.add_motion(dt, gyro0, gyro1, force0, force1)
        gyro0, force0 = gyro1, force1
    return steps * dt, gyro0


def gnss_at(aligner, rotation, t):
    """Exact antenna fix and velocity (no rotation-induced velocity) and baseline heading."""
    antenna = earth.geodetic_offset(LATITUDE, LONGITUDE, 0.0, rotation @ np.array(PRIMARY))
    aligner.add_fix(t, *antenna, np.eye(3) * 4e-4)
    aligner.add_velocity(t, np.zeros(3), np.eye(3) * 4e-4)
    baseline = rotation @ (np.array(SECONDARY) - np.array(PRIMARY))
    return math.atan2(baseline[1], baseline[0])


def attitude_error(result, true_rotation):
    return rotation_vector_from_rotation_matrix(true_rotation @ result.state.rotation_nb.T)


def test_still_tilted_buoy_aligns_exactly_with_any_antenna_geometry():
    aligner = make_aligner()
    euler = np.radians((10.0, -20.0, 130.0))
    duration, gyro = feed(aligner, lambda t: euler, lambda t: np.zeros(3), 12.0)
    rotation = rotation_of(euler)
    yaw = gnss_at(aligner, rotation, duration)
    result = aligner.add_heading(duration, yaw, 1e-6, gyro)
    assert result is not None
    np.testing.assert_allclose(attitude_error(result, rotation), 0.0, atol=1e-7)
    assert (result.roll_rad, result.pitch_rad, result.yaw_rad) == pytest.approx(
        tuple(euler), abs=1e-7
    )
    # Base position = antenna fix minus the lever arm.
    plane = earth.LocalTangentPlane(LATITUDE, LONGITUDE, 0.0)
    position = plane.enu_from_geodetic(
        result.state.latitude_rad, result.state.longitude_rad, result.state.altitude_m
    )
    np.testing.assert_allclose(position, 0.0, atol=1e-6)
    np.testing.assert_allclose(result.state.velocity_enu_mps, 0.0, atol=1e-12)


def test_rocking_buoy_levels_as_well_as_a_still_one():
    """Rotation during the window is taken out with the gyro: ±15° roll costs no accuracy."""
    aligner = make_aligner()
    euler_at, rate_at = rocking(math.radians(15.0), math.radians(8.0), 1.0)
    duration, gyro = feed(aligner, euler_at, rate_at, 10.5)
    rotation = rotation_of(euler_at(duration))
    yaw = gnss_at(aligner, rotation, duration)
    result = aligner.add_heading(duration, yaw, 1e-6, gyro)
    assert result is not None
    # Rounding and the second-order Earth-rate term only.
    assert np.linalg.norm(attitude_error(result, rotation)) < math.radians(0.002)


def test_wave_accelerations_tilt_the_levelling_within_its_covariance():
    """A horizontal wave acceleration biases the window mean; the covariance, sized from the
    specific-force variance in the window, covers the resulting tilt error."""
    aligner = make_aligner()
    euler_at, rate_at = rocking(math.radians(8.0), math.radians(5.0), 0.3)
    w = 2 * math.pi / 7.0

    def acceleration(t):
        return np.array((1.2 * math.sin(w * t + 0.4), 0.8 * math.cos(w * t), 0.5 * math.sin(w * t)))

    duration, gyro = feed(aligner, euler_at, rate_at, 10.5, acceleration_at=acceleration)
    rotation = rotation_of(euler_at(duration))
    yaw = gnss_at(aligner, rotation, duration)
    result = aligner.add_heading(duration, yaw, 1e-6, gyro)
    error = attitude_error(result, rotation)
    # The mean wave acceleration over the window, over g, is the tilt error.
    mean_acceleration = np.mean([acceleration(t) for t in np.arange(0, duration, 0.01)], axis=0)
    expected_tilt = np.array((-mean_acceleration[1], mean_acceleration[0])) / GRAVITY
    np.testing.assert_allclose(error[:2], expected_tilt, atol=math.radians(0.05))
    assert abs(expected_tilt).max() > math.radians(1.0)  # a real, degree-level error
    covariance = result.covariance[0:2, 0:2]
    assert error[:2] @ np.linalg.solve(covariance, error[:2]) < 9.0  # within 3 σ
    assert result.tilt_sigma_rad > np.linalg.norm(expected_tilt) / 3


def test_accelerometer_bias_tilt_error_is_carried_by_the_bias_correlation():
    """On a still buoy the levelling mistakes the horizontal accelerometer bias for tilt; the
    initial covariance holds exactly that correlation, so the bias-explained part of the error
    is P_φb P_bb⁻¹ b."""
    aligner = make_aligner()
    euler = np.radians((3.0, -4.0, 60.0))
    bias = np.array((0.04, -0.03, 0.02))
    duration, gyro = feed(aligner, lambda t: euler, lambda t: np.zeros(3), 10.5, accel_bias=bias)
    rotation = rotation_of(euler)
    yaw = gnss_at(aligner, rotation, duration)
    result = aligner.add_heading(duration, yaw, 1e-6, gyro)
    error = attitude_error(result, rotation)
    p = result.covariance
    explained = p[0:3, 12:15] @ np.linalg.solve(p[12:15, 12:15], bias)
    np.testing.assert_allclose(error[:2], explained[:2], atol=math.radians(0.002))
    assert np.linalg.norm(error[:2]) > math.radians(0.2)


def test_alignment_waits_for_window_fix_and_usable_baseline():
    aligner = make_aligner(alignment_window_s=5.0)
    assert aligner.state is AlignmentState.WAITING_FOR_IMU
    euler = np.radians((0.0, 0.0, 45.0))
    rotation = rotation_of(euler)
    duration, gyro = feed(aligner, lambda t: euler, lambda t: np.zeros(3), 2.0)
    assert aligner.state is AlignmentState.LEVELLING
    assert aligner.add_heading(duration, 0.0, 1e-6, gyro) is None
    duration, gyro = feed(aligner, lambda t: euler, lambda t: np.zeros(3), 4.0)
    assert aligner.state is AlignmentState.WAITING_FOR_GNSS
    assert aligner.add_heading(duration, 0.0, 1e-6, gyro) is None  # no fix yet
    gnss_at(aligner, rotation, duration - 2.0)
    assert aligner.add_heading(duration, 0.0, 1e-6, gyro) is None  # fix too old (> 1 s)
    yaw = gnss_at(aligner, rotation, duration)
    assert aligner.add_heading(duration, yaw, 1e-6, gyro) is not None


def test_vertical_baseline_cannot_give_a_heading():
    config = FusionConfig(primary_antenna_body_m=(0, 0, 0.5), secondary_antenna_body_m=(0, 0, 1.5))
    aligner = InMotionAligner(config, ImuErrorModel.from_config(config))
    euler = np.zeros(3)
    duration, gyro = feed(aligner, lambda t: euler, lambda t: np.zeros(3), 11.0)
    aligner.add_fix(duration, LATITUDE, LONGITUDE, 0.0, np.eye(3) * 4e-4)
    assert aligner.add_heading(duration, 0.3, 1e-6, gyro) is None
