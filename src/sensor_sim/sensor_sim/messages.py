"""Build the contract's ROS messages from simulated samples.

The live sensor nodes build their messages here; the offline bag generator writes the same
messages as CDR bytes (:mod:`sensor_sim.message_bytes`, held equal to these by the tests), so a
bag recorded from the nodes and a bag generated offline hold the same messages. Only the
message packages are imported (no rclpy): the resulting objects are published by the nodes.
"""

from __future__ import annotations

import math
from collections.abc import Iterator

import numpy as np
from geometry_msgs.msg import TwistWithCovarianceStamped, Vector3Stamped
from nav_msgs.msg import Odometry
from scipy.spatial.transform import Rotation
from sensor_msgs.msg import Imu, MagneticField, NavSatFix, NavSatStatus, Temperature

from buoy_common.contract import (
    ANEMOMETER_FRAME,
    BODY_FRAME,
    DVL_FRAME,
    GNSS_PRIMARY_FRAME,
    IMU_FRAME,
    MAP_FRAME,
)
from sensor_sim.sensor_models import GnssSample
from sensor_sim.truth import TruthState

# Heading messages carry yaw only; roll and pitch are marked as unknown with a huge variance.
UNKNOWN_ANGLE_VARIANCE_RAD2 = 1.0e6


def stamp_ns(start_time_ns: int, t_s: float) -> int:
    """Sensor-time stamp (ns) of scenario time ``t_s`` (s), rounded to the nanosecond."""
    return start_time_ns + round(t_s * 1e9)


def _set_stamp(header, time_ns: int, frame_id: str) -> None:
    header.stamp.sec, header.stamp.nanosec = divmod(time_ns, 1_000_000_000)
    header.frame_id = frame_id


def _set_vector(target, values) -> None:
    target.x, target.y, target.z = (float(v) for v in values)


def _set_quaternion(target, xyzw) -> None:
    target.x, target.y, target.z, target.w = (float(v) for v in xyzw)


def imu_messages(
    stamps_ns: list[int],
    gyro_rad_s: np.ndarray,
    specific_force_mps2: np.ndarray,
    gyro_variance_rad2_s2: float,
    accel_variance_m2_s4: float,
) -> Iterator[Imu]:
    """``imu/data_raw``: body rate (rad/s) and specific force (m/s²) in imu_link; no attitude."""
    for time_ns, gyro, force in zip(stamps_ns, gyro_rad_s, specific_force_mps2, strict=True):
        message = Imu()
        _set_stamp(message.header, time_ns, IMU_FRAME)
        message.orientation_covariance[0] = -1.0
        _set_vector(message.angular_velocity, gyro)
        _set_vector(message.linear_acceleration, force)
        message.angular_velocity_covariance[0::4] = gyro_variance_rad2_s2
        message.linear_acceleration_covariance[0::4] = accel_variance_m2_s4
        yield message


def gnss_fix_messages(stamps_ns: list[int], sample: GnssSample) -> Iterator[NavSatFix]:
    """``gnss/fix``: primary antenna WGS-84 position; status NO_FIX (and NaN) during outages."""
    for i, time_ns in enumerate(stamps_ns):
        message = NavSatFix()
        _set_stamp(message.header, time_ns, GNSS_PRIMARY_FRAME)
        message.status.service = NavSatStatus.SERVICE_GPS
        if sample.fix_valid[i]:
            message.status.status = NavSatStatus.STATUS_GBAS_FIX
            message.latitude = float(sample.latitude_deg[i])
            message.longitude = float(sample.longitude_deg[i])
            message.altitude = float(sample.altitude_m[i])
            message.position_covariance = sample.position_covariance_enu_m2[i].ravel().astype(float)
            message.position_covariance_type = NavSatFix.COVARIANCE_TYPE_KNOWN
        else:
            message.status.status = NavSatStatus.STATUS_NO_FIX
            message.latitude = message.longitude = message.altitude = math.nan
            message.position_covariance_type = NavSatFix.COVARIANCE_TYPE_UNKNOWN
        yield message


def gnss_velocity_messages(
    stamps_ns: list[int], sample: GnssSample
) -> Iterator[TwistWithCovarianceStamped | None]:
    """``gnss/vel``: primary antenna ENU velocity over ground (m/s); None while there is no fix."""
    for i, time_ns in enumerate(stamps_ns):
        if not sample.velocity_valid[i]:
            yield None
            continue
        message = TwistWithCovarianceStamped()
        _set_stamp(message.header, time_ns, GNSS_PRIMARY_FRAME)
        _set_vector(message.twist.twist.linear, sample.velocity_enu_mps[i])
        covariance = np.zeros((6, 6))
        covariance[:3, :3] = sample.velocity_covariance_enu_m2s2[i]
        covariance[3:, 3:] = -np.eye(3)  # angular part not measured
        message.twist.covariance = covariance.ravel()
        yield message


def gnss_heading_messages(stamps_ns: list[int], sample: GnssSample) -> Iterator[Imu | None]:
    """``gnss/heading``: yaw-only quaternion of the baseline azimuth (ENU); None during outages."""
    for i, time_ns in enumerate(stamps_ns):
        if not sample.heading_valid[i]:
            yield None
            continue
        message = Imu()
        _set_stamp(message.header, time_ns, GNSS_PRIMARY_FRAME)
        half_yaw = 0.5 * float(sample.heading_yaw_rad[i])
        _set_quaternion(message.orientation, (0.0, 0.0, math.sin(half_yaw), math.cos(half_yaw)))
        message.orientation_covariance[0] = UNKNOWN_ANGLE_VARIANCE_RAD2
        message.orientation_covariance[4] = UNKNOWN_ANGLE_VARIANCE_RAD2
        message.orientation_covariance[8] = float(sample.heading_variance_rad2[i])
        message.angular_velocity_covariance[0] = -1.0
        message.linear_acceleration_covariance[0] = -1.0
        yield message


def gnss_baseline_messages(
    stamps_ns: list[int], sample: GnssSample
) -> Iterator[Vector3Stamped | None]:
    """``gnss/baseline``: measured primary→secondary vector in ENU (m); None during outages."""
    for i, time_ns in enumerate(stamps_ns):
        if not sample.heading_valid[i]:
            yield None
            continue
        message = Vector3Stamped()
        _set_stamp(message.header, time_ns, MAP_FRAME)
        _set_vector(message.vector, sample.baseline_enu_m[i])
        yield message


def gnss_baseline_tertiary_messages(
    stamps_ns: list[int], sample: GnssSample
) -> Iterator[Vector3Stamped | None]:
    """``gnss/baseline_tertiary``: measured primary→tertiary vector in ENU (m); None during
    outages."""
    for i, time_ns in enumerate(stamps_ns):
        if not sample.heading_valid[i]:
            yield None
            continue
        message = Vector3Stamped()
        _set_stamp(message.header, time_ns, MAP_FRAME)
        _set_vector(message.vector, sample.tertiary_baseline_enu_m[i])
        yield message


def magnetic_field_messages(
    stamps_ns: list[int], field_body_t: np.ndarray, noise_variance_t2: float
) -> Iterator[MagneticField]:
    """``imu/mag``: uncalibrated magnetic field in imu_link (tesla)."""
    for time_ns, field in zip(stamps_ns, field_body_t, strict=True):
        message = MagneticField()
        _set_stamp(message.header, time_ns, IMU_FRAME)
        _set_vector(message.magnetic_field, field)
        message.magnetic_field_covariance[0::4] = noise_variance_t2
        yield message


def ahrs_messages(
    stamps_ns: list[int],
    attitude: Rotation,
    gyro_rad_s: np.ndarray,
    specific_force_mps2: np.ndarray,
    orientation_variance_rad2: float | np.ndarray,
) -> Iterator[Imu]:
    """``imu/data``: the motion pack's attitude (body→ENU of its yaw reference) with its
    covariance (small rotation about the ENU axes, rad²: one for all three, or x, y, z), rates
    and specific force."""
    quaternions = attitude.as_quat()
    for time_ns, quaternion, gyro, force in zip(
        stamps_ns, quaternions, gyro_rad_s, specific_force_mps2, strict=True
    ):
        message = Imu()
        _set_stamp(message.header, time_ns, IMU_FRAME)
        _set_quaternion(message.orientation, quaternion)
        message.orientation_covariance[0::4] = orientation_variance_rad2
        _set_vector(message.angular_velocity, gyro)
        _set_vector(message.linear_acceleration, force)
        yield message


def anemometer_messages(
    stamps_ns: list[int], wind_sensor_mps: np.ndarray
) -> Iterator[Vector3Stamped]:
    """``anemometer/wind``: air velocity relative to the sensor in anemometer axes (m/s)."""
    for time_ns, wind in zip(stamps_ns, wind_sensor_mps, strict=True):
        message = Vector3Stamped()
        _set_stamp(message.header, time_ns, ANEMOMETER_FRAME)
        _set_vector(message.vector, wind)
        yield message


def temperature_messages(
    stamps_ns: list[int], temperature_degc: np.ndarray, noise_variance_k2: float
) -> Iterator[Temperature]:
    """``anemometer/temperature``: the sonic temperature (°C) of each anemometer record, with
    its stamp, frame ``anemometer_link``; the variance is the noise's."""
    for time_ns, value in zip(stamps_ns, temperature_degc, strict=True):
        message = Temperature()
        _set_stamp(message.header, time_ns, ANEMOMETER_FRAME)
        message.temperature = float(value)
        message.variance = float(noise_variance_k2)
        yield message


def dvl_messages(
    stamps_ns: list[int], velocity_dvl_mps: np.ndarray, noise_variance_m2s2: float
) -> Iterator[TwistWithCovarianceStamped]:
    """``dvl/velocity``: the DVL's velocity through the water in DVL axes (m/s), NaN for a lost
    ping; the linear covariance is the ping noise, the angular part is not measured (-1)."""
    covariance = np.zeros((6, 6))
    covariance[:3, :3] = noise_variance_m2s2 * np.eye(3)
    covariance[3:, 3:] = -np.eye(3)
    flat_covariance = covariance.ravel()
    for time_ns, velocity in zip(stamps_ns, velocity_dvl_mps, strict=True):
        message = TwistWithCovarianceStamped()
        _set_stamp(message.header, time_ns, DVL_FRAME)
        _set_vector(message.twist.twist.linear, velocity)
        message.twist.covariance = flat_covariance
        yield message


def truth_odometry_messages(
    stamps_ns: list[int], truth: TruthState, position_map_m: np.ndarray
) -> Iterator[Odometry]:
    """``truth/odometry``: true pose of base_link in map, true twist in base_link.

    Twist follows the Odometry convention: linear = velocity over ground in body axes, angular =
    body rate relative to the local-level frame (rad/s).
    """
    quaternions = truth.attitude.as_quat()
    body_velocity = truth.attitude.inv().apply(truth.velocity_enu_mps)
    for i, time_ns in enumerate(stamps_ns):
        message = Odometry()
        _set_stamp(message.header, time_ns, MAP_FRAME)
        message.child_frame_id = BODY_FRAME
        _set_vector(message.pose.pose.position, position_map_m[i])
        _set_quaternion(message.pose.pose.orientation, quaternions[i])
        _set_vector(message.twist.twist.linear, body_velocity[i])
        _set_vector(message.twist.twist.angular, truth.angular_rate_body_rad_s[i])
        yield message


def enu_vector_messages(stamps_ns: list[int], vectors_enu: np.ndarray) -> Iterator[Vector3Stamped]:
    """ENU vectors in frame map (``truth/wind``, ``truth/current``)."""
    for time_ns, vector in zip(stamps_ns, vectors_enu, strict=True):
        message = Vector3Stamped()
        _set_stamp(message.header, time_ns, MAP_FRAME)
        _set_vector(message.vector, vector)
        yield message
