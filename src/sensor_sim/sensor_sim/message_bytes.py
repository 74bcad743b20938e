"""The contract's messages from simulated samples as CDR bytes, for the offline generator.

Each function here has the name, arguments and fields of its namesake in
:mod:`sensor_sim.messages`, which builds the message objects the live nodes publish, and
returns what ``rclpy`` serialises those objects to, written with the suite's fixed-layout
writers (:mod:`buoy_common.cdr`) instead: building and serialising a message object costs far
more than the sample behind it, and ``simulate_bag`` writes millions of them. The tests hold
the bytes of the two modules equal, message by message.
"""

from __future__ import annotations

import math

import numpy as np
from scipy.spatial.transform import Rotation
from sensor_msgs.msg import NavSatFix, NavSatStatus

from buoy_common import cdr
from buoy_common.contract import (
    ANEMOMETER_FRAME,
    BODY_FRAME,
    DVL_FRAME,
    GNSS_PRIMARY_FRAME,
    IMU_FRAME,
    MAP_FRAME,
)
from sensor_sim.messages import UNKNOWN_ANGLE_VARIANCE_RAD2
from sensor_sim.sensor_models import GnssSample
from sensor_sim.truth import TruthState

NANOSECONDS_PER_SECOND = 1_000_000_000
_ZEROS_3 = (0.0, 0.0, 0.0)
_ZEROS_9 = (0.0,) * 9
_ZEROS_36 = (0.0,) * 36
_IDENTITY_QUATERNION_XYZW = (0.0, 0.0, 0.0, 1.0)
# A covariance whose first element is -1: the quantity is not measured (sensor_msgs/Imu).
_NOT_MEASURED_9 = (-1.0, *(0.0,) * 8)

_IMU = cdr.ImuWriter(IMU_FRAME)
_GNSS_HEADING = cdr.ImuWriter(GNSS_PRIMARY_FRAME)
_GNSS_FIX = cdr.NavSatFixWriter(GNSS_PRIMARY_FRAME)
_GNSS_VELOCITY = cdr.TwistWithCovarianceStampedWriter(GNSS_PRIMARY_FRAME)
_MAP_VECTOR = cdr.Vector3StampedWriter(MAP_FRAME)
_ANEMOMETER_VECTOR = cdr.Vector3StampedWriter(ANEMOMETER_FRAME)
_MAGNETIC_FIELD = cdr.MagneticFieldWriter(IMU_FRAME)
_TEMPERATURE = cdr.TemperatureWriter(ANEMOMETER_FRAME)
_DVL_VELOCITY = cdr.TwistWithCovarianceStampedWriter(DVL_FRAME)
_TRUTH_ODOMETRY = cdr.OdometryWriter(MAP_FRAME, BODY_FRAME)


def _split_stamps(stamps_ns: list[int]) -> list[tuple[int, int]]:
    """(sec, nanosec) of each stamp (ns)."""
    return [divmod(time_ns, NANOSECONDS_PER_SECOND) for time_ns in stamps_ns]


def _diagonal_9(diagonal) -> tuple[float, ...]:
    """A row-major 3×3 covariance holding ``diagonal`` (one value for all three, or three)."""
    x, y, z = np.broadcast_to(np.asarray(diagonal, dtype=float), (3,)).tolist()
    return (x, 0.0, 0.0, 0.0, y, 0.0, 0.0, 0.0, z)


def _vector_messages(writer: cdr.Vector3StampedWriter, stamps_ns, vectors) -> list[bytes]:
    seconds, nanoseconds = np.divmod(np.asarray(stamps_ns, dtype=np.int64), NANOSECONDS_PER_SECOND)
    return writer.write_many(seconds, nanoseconds, vectors)


def imu_messages(
    stamps_ns: list[int],
    gyro_rad_s: np.ndarray,
    specific_force_mps2: np.ndarray,
    gyro_variance_rad2_s2: float,
    accel_variance_m2_s4: float,
) -> list[bytes]:
    """``imu/data_raw``: body rate (rad/s) and specific force (m/s²) in imu_link; no attitude."""
    gyro_covariance = _diagonal_9(gyro_variance_rad2_s2)
    accel_covariance = _diagonal_9(accel_variance_m2_s4)
    return [
        _IMU.write(
            sec,
            nanosec,
            _IDENTITY_QUATERNION_XYZW,
            _NOT_MEASURED_9,
            gyro,
            gyro_covariance,
            force,
            accel_covariance,
        )
        for (sec, nanosec), gyro, force in zip(
            _split_stamps(stamps_ns),
            np.asarray(gyro_rad_s, dtype=float).tolist(),
            np.asarray(specific_force_mps2, dtype=float).tolist(),
            strict=True,
        )
    ]


def gnss_fix_messages(stamps_ns: list[int], sample: GnssSample) -> list[bytes]:
    """``gnss/fix``: primary antenna WGS-84 position; status NO_FIX (and NaN) during outages."""
    covariances = sample.position_covariance_enu_m2.reshape(-1, 9).tolist()
    rows = zip(
        _split_stamps(stamps_ns),
        sample.fix_valid.tolist(),
        sample.latitude_deg.tolist(),
        sample.longitude_deg.tolist(),
        sample.altitude_m.tolist(),
        covariances,
        strict=True,
    )
    return [
        _GNSS_FIX.write(
            sec,
            nanosec,
            NavSatStatus.STATUS_GBAS_FIX,
            NavSatStatus.SERVICE_GPS,
            latitude,
            longitude,
            altitude,
            covariance,
            NavSatFix.COVARIANCE_TYPE_KNOWN,
        )
        if valid
        else _GNSS_FIX.write(
            sec,
            nanosec,
            NavSatStatus.STATUS_NO_FIX,
            NavSatStatus.SERVICE_GPS,
            math.nan,
            math.nan,
            math.nan,
            _ZEROS_9,
            NavSatFix.COVARIANCE_TYPE_UNKNOWN,
        )
        for (sec, nanosec), valid, latitude, longitude, altitude, covariance in rows
    ]


def gnss_velocity_messages(stamps_ns: list[int], sample: GnssSample) -> list[bytes | None]:
    """``gnss/vel``: primary antenna ENU velocity over ground (m/s); None while there is no fix."""
    covariances = np.zeros((len(stamps_ns), 6, 6))
    covariances[:, :3, :3] = sample.velocity_covariance_enu_m2s2
    covariances[:, 3:, 3:] = -np.eye(3)  # angular part not measured
    rows = zip(
        _split_stamps(stamps_ns),
        sample.velocity_valid.tolist(),
        sample.velocity_enu_mps.tolist(),
        covariances.reshape(-1, 36).tolist(),
        strict=True,
    )
    return [
        _GNSS_VELOCITY.write(sec, nanosec, velocity, _ZEROS_3, covariance) if valid else None
        for (sec, nanosec), valid, velocity, covariance in rows
    ]


def gnss_heading_messages(stamps_ns: list[int], sample: GnssSample) -> list[bytes | None]:
    """``gnss/heading``: yaw-only quaternion of the baseline azimuth (ENU); None during outages."""
    rows = zip(
        _split_stamps(stamps_ns),
        sample.heading_valid.tolist(),
        sample.heading_yaw_rad.tolist(),
        sample.heading_variance_rad2.tolist(),
        strict=True,
    )
    return [
        _GNSS_HEADING.write(
            sec,
            nanosec,
            (0.0, 0.0, math.sin(0.5 * yaw), math.cos(0.5 * yaw)),
            _diagonal_9((UNKNOWN_ANGLE_VARIANCE_RAD2, UNKNOWN_ANGLE_VARIANCE_RAD2, variance)),
            _ZEROS_3,
            _NOT_MEASURED_9,
            _ZEROS_3,
            _NOT_MEASURED_9,
        )
        if valid
        else None
        for (sec, nanosec), valid, yaw, variance in rows
    ]


def _baseline_messages(stamps_ns, valid: np.ndarray, baseline_enu_m) -> list[bytes | None]:
    written = iter(
        _vector_messages(_MAP_VECTOR, np.asarray(stamps_ns)[valid], baseline_enu_m[valid])
    )
    return [next(written) if is_valid else None for is_valid in valid.tolist()]


def gnss_baseline_messages(stamps_ns: list[int], sample: GnssSample) -> list[bytes | None]:
    """``gnss/baseline``: measured primary→secondary vector in ENU (m); None during outages."""
    return _baseline_messages(stamps_ns, sample.heading_valid, sample.baseline_enu_m)


def gnss_baseline_tertiary_messages(stamps_ns: list[int], sample: GnssSample) -> list[bytes | None]:
    """``gnss/baseline_tertiary``: measured primary→tertiary vector in ENU (m); None during
    outages."""
    return _baseline_messages(stamps_ns, sample.heading_valid, sample.tertiary_baseline_enu_m)


def magnetic_field_messages(
    stamps_ns: list[int], field_body_t: np.ndarray, noise_variance_t2: float
) -> list[bytes]:
    """``imu/mag``: uncalibrated magnetic field in imu_link (tesla)."""
    covariance = _diagonal_9(noise_variance_t2)
    return [
        _MAGNETIC_FIELD.write(sec, nanosec, field, covariance)
        for (sec, nanosec), field in zip(
            _split_stamps(stamps_ns), np.asarray(field_body_t, dtype=float).tolist(), strict=True
        )
    ]


def ahrs_messages(
    stamps_ns: list[int],
    attitude: Rotation,
    gyro_rad_s: np.ndarray,
    specific_force_mps2: np.ndarray,
    orientation_variance_rad2: float | np.ndarray,
) -> list[bytes]:
    """``imu/data``: the motion pack's attitude (body→ENU of its yaw reference) with its
    covariance (small rotation about the ENU axes, rad²: one for all three, or x, y, z), rates
    and specific force."""
    orientation_covariance = _diagonal_9(orientation_variance_rad2)
    return [
        _IMU.write(
            sec, nanosec, quaternion, orientation_covariance, gyro, _ZEROS_9, force, _ZEROS_9
        )
        for (sec, nanosec), quaternion, gyro, force in zip(
            _split_stamps(stamps_ns),
            attitude.as_quat().tolist(),
            np.asarray(gyro_rad_s, dtype=float).tolist(),
            np.asarray(specific_force_mps2, dtype=float).tolist(),
            strict=True,
        )
    ]


def anemometer_messages(stamps_ns: list[int], wind_sensor_mps: np.ndarray) -> list[bytes]:
    """``anemometer/wind``: air velocity relative to the sensor in anemometer axes (m/s)."""
    return _vector_messages(_ANEMOMETER_VECTOR, stamps_ns, wind_sensor_mps)


def temperature_messages(
    stamps_ns: list[int], temperature_degc: np.ndarray, noise_variance_k2: float
) -> list[bytes]:
    """``anemometer/temperature``: the sonic temperature (°C) of each anemometer record, with
    its stamp, frame ``anemometer_link``; the variance is the noise's."""
    variance = float(noise_variance_k2)
    return [
        _TEMPERATURE.write(sec, nanosec, value, variance)
        for (sec, nanosec), value in zip(
            _split_stamps(stamps_ns),
            np.asarray(temperature_degc, dtype=float).tolist(),
            strict=True,
        )
    ]


def dvl_messages(
    stamps_ns: list[int], velocity_dvl_mps: np.ndarray, noise_variance_m2s2: float
) -> list[bytes]:
    """``dvl/velocity``: the DVL's velocity through the water in DVL axes (m/s), NaN for a lost
    ping; the linear covariance is the ping noise, the angular part is not measured (-1)."""
    covariance = np.zeros((6, 6))
    covariance[:3, :3] = noise_variance_m2s2 * np.eye(3)
    covariance[3:, 3:] = -np.eye(3)
    flat_covariance = covariance.ravel().tolist()
    return [
        _DVL_VELOCITY.write(sec, nanosec, velocity, _ZEROS_3, flat_covariance)
        for (sec, nanosec), velocity in zip(
            _split_stamps(stamps_ns),
            np.asarray(velocity_dvl_mps, dtype=float).tolist(),
            strict=True,
        )
    ]


def truth_odometry_messages(
    stamps_ns: list[int], truth: TruthState, position_map_m: np.ndarray
) -> list[bytes]:
    """``truth/odometry``: true pose of base_link in map, true twist in base_link.

    Twist follows the Odometry convention: linear = velocity over ground in body axes, angular =
    body rate relative to the local-level frame (rad/s).
    """
    body_velocity = truth.attitude.inv().apply(truth.velocity_enu_mps)
    rows = zip(
        _split_stamps(stamps_ns),
        np.asarray(position_map_m, dtype=float).tolist(),
        truth.attitude.as_quat().tolist(),
        body_velocity.tolist(),
        np.asarray(truth.angular_rate_body_rad_s, dtype=float).tolist(),
        strict=True,
    )
    return [
        _TRUTH_ODOMETRY.write(
            sec, nanosec, position, quaternion, _ZEROS_36, linear, angular, _ZEROS_36
        )
        for (sec, nanosec), position, quaternion, linear, angular in rows
    ]


def enu_vector_messages(stamps_ns: list[int], vectors_enu: np.ndarray) -> list[bytes]:
    """ENU vectors in frame map (``truth/wind``, ``truth/current``)."""
    return _vector_messages(_MAP_VECTOR, stamps_ns, vectors_enu)
