"""The fast CDR codecs against rclpy's own serialisation: each reader decodes what rclpy
encodes, each writer encodes what rclpy decodes to an equal message, byte for byte."""

import math

import numpy as np
import pytest
from geometry_msgs.msg import TwistWithCovarianceStamped, Vector3Stamped
from nav_msgs.msg import Odometry
from rclpy.serialization import deserialize_message, serialize_message
from sensor_msgs.msg import Imu, MagneticField, NavSatFix, Temperature

from buoy_common import cdr

RNG = np.random.default_rng(5)
# Frame ids of every length modulo 8 move the fields after them through every alignment.
FRAMES = ("", "m", "map", "base_link", "anemometer_link", "a_frame_with_a_much_longer_name")
STAMPS = ((1_767_225_600, 123_456_789), (0, 0), (-5, 999_999_999))


def same_bytes_but_padding(written: bytes, serialized: bytes) -> bool:
    """``written`` equals rclpy's ``serialized`` except where it holds zeros: the alignment
    padding, which rclpy may leave holding whatever its buffer held before."""
    return len(written) == len(serialized) and all(
        ours in (theirs, 0) for ours, theirs in zip(written, serialized, strict=True)
    )


def values(count: int) -> list[float]:
    return RNG.normal(0.0, 10.0, count).tolist()


def set_header(message, stamp, frame_id):
    message.header.stamp.sec, message.header.stamp.nanosec = stamp
    message.header.frame_id = frame_id
    return message


def vector3_stamped(stamp, frame_id, xyz) -> Vector3Stamped:
    message = set_header(Vector3Stamped(), stamp, frame_id)
    message.vector.x, message.vector.y, message.vector.z = xyz
    return message


def odometry(stamp, frame_id, child_frame_id) -> Odometry:
    message = set_header(Odometry(), stamp, frame_id)
    message.child_frame_id = child_frame_id
    pose = message.pose.pose
    pose.position.x, pose.position.y, pose.position.z = values(3)
    o = pose.orientation
    o.x, o.y, o.z, o.w = values(4)
    message.pose.covariance = values(36)
    twist = message.twist.twist
    twist.linear.x, twist.linear.y, twist.linear.z = values(3)
    twist.angular.x, twist.angular.y, twist.angular.z = values(3)
    message.twist.covariance = values(36)
    return message


def imu(stamp, frame_id) -> Imu:
    message = set_header(Imu(), stamp, frame_id)
    o = message.orientation
    o.x, o.y, o.z, o.w = values(4)
    message.orientation_covariance = values(9)
    w = message.angular_velocity
    w.x, w.y, w.z = values(3)
    message.angular_velocity_covariance = values(9)
    a = message.linear_acceleration
    a.x, a.y, a.z = values(3)
    message.linear_acceleration_covariance = values(9)
    return message


def nav_sat_fix(stamp, frame_id, status=0, service=1) -> NavSatFix:
    message = set_header(NavSatFix(), stamp, frame_id)
    message.status.status, message.status.service = status, service
    message.latitude, message.longitude, message.altitude = values(3)
    message.position_covariance = values(9)
    message.position_covariance_type = 2
    return message


def xyz(vector) -> tuple[float, float, float]:
    return vector.x, vector.y, vector.z


def xyzw(quaternion) -> tuple[float, float, float, float]:
    return quaternion.x, quaternion.y, quaternion.z, quaternion.w


@pytest.mark.parametrize("frame_id", FRAMES)
@pytest.mark.parametrize("stamp", STAMPS)
def test_vector3_stamped(frame_id, stamp):
    message = vector3_stamped(stamp, frame_id, values(3))
    raw = serialize_message(message)
    assert cdr.read_stamp(raw) == stamp
    assert cdr.read_vector3_stamped(raw) == (*stamp, frame_id, xyz(message.vector))
    written = cdr.Vector3StampedWriter(frame_id).write(*stamp, *xyz(message.vector))
    assert same_bytes_but_padding(written, raw)
    assert deserialize_message(written, Vector3Stamped) == message


@pytest.mark.parametrize("frame_id", FRAMES)
def test_vector3_stamped_written_at_once_equals_one_by_one(frame_id):
    writer = cdr.Vector3StampedWriter(frame_id)
    secs = np.array([1_767_225_600, 1_767_225_601, -3])
    nanosecs = np.array([0, 999_999_999, 50_000_000])
    vectors = np.array([values(3), [math.nan] * 3, [-0.0, math.inf, 1e-300]])
    written = writer.write_many(secs, nanosecs, vectors)
    expected = [
        writer.write(int(s), int(n), *v) for s, n, v in zip(secs, nanosecs, vectors, strict=True)
    ]
    assert written == expected
    assert writer.write_many([], [], np.empty((0, 3))) == []


@pytest.mark.parametrize(
    ("frame_id", "child_frame_id"),
    [("map", "base_link"), ("", "b"), *zip(FRAMES, reversed(FRAMES), strict=True)],
)
def test_odometry(frame_id, child_frame_id):
    message = odometry(STAMPS[0], frame_id, child_frame_id)
    raw = serialize_message(message)
    pose, twist = message.pose.pose, message.twist.twist
    assert cdr.read_odometry(raw) == (
        *STAMPS[0],
        frame_id,
        child_frame_id,
        (*xyz(pose.position), *xyzw(pose.orientation)),
        (*xyz(twist.linear), *xyz(twist.angular)),
        tuple(float(value) for value in message.pose.covariance),
        tuple(float(value) for value in message.twist.covariance),
    )
    written = cdr.OdometryWriter(frame_id, child_frame_id).write(
        *STAMPS[0],
        xyz(pose.position),
        xyzw(pose.orientation),
        message.pose.covariance.tolist(),
        xyz(twist.linear),
        xyz(twist.angular),
        message.twist.covariance.tolist(),
    )
    assert same_bytes_but_padding(written, raw)
    assert deserialize_message(written, Odometry) == message


@pytest.mark.parametrize("frame_id", FRAMES)
def test_imu(frame_id):
    message = imu(STAMPS[0], frame_id)
    raw = serialize_message(message)
    assert cdr.read_imu_rate_and_acceleration(raw) == (
        *STAMPS[0],
        xyz(message.angular_velocity),
        xyz(message.linear_acceleration),
    )
    written = cdr.ImuWriter(frame_id).write(
        *STAMPS[0],
        xyzw(message.orientation),
        message.orientation_covariance.tolist(),
        xyz(message.angular_velocity),
        message.angular_velocity_covariance.tolist(),
        xyz(message.linear_acceleration),
        message.linear_acceleration_covariance.tolist(),
    )
    assert same_bytes_but_padding(written, raw)
    assert deserialize_message(written, Imu) == message


@pytest.mark.parametrize("frame_id", FRAMES)
def test_twist_with_covariance_stamped(frame_id):
    message = set_header(TwistWithCovarianceStamped(), STAMPS[0], frame_id)
    twist = message.twist.twist
    twist.linear.x, twist.linear.y, twist.linear.z = values(3)
    twist.angular.x, twist.angular.y, twist.angular.z = values(3)
    message.twist.covariance = values(36)
    written = cdr.TwistWithCovarianceStampedWriter(frame_id).write(
        *STAMPS[0], xyz(twist.linear), xyz(twist.angular), message.twist.covariance.tolist()
    )
    assert same_bytes_but_padding(written, serialize_message(message))
    assert deserialize_message(written, TwistWithCovarianceStamped) == message


@pytest.mark.parametrize("frame_id", FRAMES)
@pytest.mark.parametrize(("status", "service"), [(0, 1), (-1, 0), (2, 15)])
def test_nav_sat_fix(frame_id, status, service):
    message = nav_sat_fix(STAMPS[0], frame_id, status, service)
    raw = serialize_message(message)
    assert cdr.read_nav_sat_fix(raw) == (
        *STAMPS[0],
        frame_id,
        status,
        service,
        message.latitude,
        message.longitude,
        message.altitude,
    )
    written = cdr.NavSatFixWriter(frame_id).write(
        *STAMPS[0],
        status,
        service,
        message.latitude,
        message.longitude,
        message.altitude,
        message.position_covariance.tolist(),
        message.position_covariance_type,
    )
    assert same_bytes_but_padding(written, raw)
    assert deserialize_message(written, NavSatFix) == message


@pytest.mark.parametrize("frame_id", FRAMES)
def test_magnetic_field(frame_id):
    message = set_header(MagneticField(), STAMPS[2], frame_id)
    field = message.magnetic_field
    field.x, field.y, field.z = values(3)
    message.magnetic_field_covariance = values(9)
    written = cdr.MagneticFieldWriter(frame_id).write(
        *STAMPS[2], xyz(field), message.magnetic_field_covariance.tolist()
    )
    assert same_bytes_but_padding(written, serialize_message(message))
    assert deserialize_message(written, MagneticField) == message


@pytest.mark.parametrize("frame_id", FRAMES)
def test_temperature(frame_id):
    message = set_header(Temperature(), STAMPS[0], frame_id)
    message.temperature, message.variance = values(2)
    written = cdr.TemperatureWriter(frame_id).write(
        *STAMPS[0], message.temperature, message.variance
    )
    assert same_bytes_but_padding(written, serialize_message(message))
    assert deserialize_message(written, Temperature) == message


def test_readers_decline_what_they_do_not_handle():
    raws = {
        cdr.read_stamp: serialize_message(vector3_stamped(STAMPS[0], "map", (1.0, 2.0, 3.0))),
        cdr.read_vector3_stamped: serialize_message(vector3_stamped(STAMPS[0], "map", (1, 2, 3))),
        cdr.read_imu_rate_and_acceleration: serialize_message(imu(STAMPS[0], "imu_link")),
        cdr.read_odometry: serialize_message(odometry(STAMPS[0], "map", "base_link")),
        cdr.read_nav_sat_fix: serialize_message(nav_sat_fix(STAMPS[0], "base_link")),
    }
    for read, raw in raws.items():
        assert read(raw) is not None, read.__name__
        assert read(b"\x00\x00" + raw[2:]) is None, f"{read.__name__}: big-endian"
        assert read(raw[:10]) is None, f"{read.__name__}: truncated"
    for read in (cdr.read_vector3_stamped, cdr.read_odometry, cdr.read_nav_sat_fix):
        raw = bytearray(raws[read])
        raw[16] = 0xFF  # the first byte of the frame id: not UTF-8
        assert read(bytes(raw)) is None, f"{read.__name__}: frame id"
        truncated = raws[read][:24]
        assert read(truncated) is None, f"{read.__name__}: string runs past the end"
