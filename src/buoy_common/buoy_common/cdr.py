"""Fast CDR codecs of the messages the suite reads and writes at the sensor rates.

ROS 2 serialises a message as CDR (XCDR1): a 4-byte encapsulation header (``00 01`` for little
endian) followed by the fields in declaration order, each primitive aligned to its own size
counted from the end of the encapsulation header; a string is a uint32 length (with its NUL)
followed by its bytes and the NUL. The messages below have fixed layouts once their frame ids
are known, so one ``struct`` call reads or writes one of them, several times faster than
building a message object and serialising it, or deserialising one and reading its attributes.

Readers take the bytes of one message and return plain tuples, or None for bytes they do not
handle (big-endian, truncated, strings that are not UTF-8): the caller then decodes the message
the ordinary way. Writers are built once for their frame ids and return exactly the bytes
``rclpy.serialization.serialize_message`` gives for the same message (padding zeroed). The tests
hold both against rclpy.
"""

from __future__ import annotations

import struct

import numpy as np

ENCAPSULATION_LITTLE_ENDIAN = b"\x00\x01\x00\x00"
"""Encapsulation header of little-endian CDR, as rclpy writes it."""

_LITTLE_ENDIAN = ENCAPSULATION_LITTLE_ENDIAN[:2]
_DATA_START = len(ENCAPSULATION_LITTLE_ENDIAN)
_STAMP = struct.Struct("<iI")
_STAMP_AND_FRAME_LENGTH = struct.Struct("<iII")
_U32 = struct.Struct("<I")
_I8 = struct.Struct("<b")
_U16 = struct.Struct("<H")
_VECTOR3 = struct.Struct("<3d")
# geometry_msgs/Pose: position (3), orientation (4); Twist: linear (3), angular (3). Each
# *WithCovariance follows its fields with a 6×6 float64 covariance.
_POSE = struct.Struct("<7d")
_TWIST = struct.Struct("<6d")
_COVARIANCE = struct.Struct("<36d")
_POSE_WITH_COVARIANCE_SIZE = _POSE.size + _COVARIANCE.size
# sensor_msgs/Imu after its header, up to what the reader returns: orientation (4), its
# covariance (9), angular velocity (3), its covariance (9), linear acceleration (3).
_IMU_FIELDS = struct.Struct("<4d9d3d9d3d")


def _aligned(position: int, size: int) -> int:
    """``position`` (from the start of the bytes) moved to the next multiple of ``size``
    counted from the end of the encapsulation header."""
    return position + (-(position - _DATA_START) % size)


def _string_at(raw: bytes, position: int) -> tuple[str, int]:
    """The CDR string at ``position`` and the position after it; ValueError (or
    UnicodeDecodeError) for bytes that do not hold one."""
    position = _aligned(position, 4)
    (length,) = _U32.unpack_from(raw, position)
    start = position + _U32.size
    if length == 0 or start + length > len(raw):
        raise ValueError("string runs past the message")
    return raw[start : start + length - 1].decode(), start + length


# -- readers -----------------------------------------------------------------------------------


def read_stamp(raw: bytes) -> tuple[int, int] | None:
    """Header stamp (sec, nanosec) of a message that starts with a std_msgs/Header."""
    if raw[:2] != _LITTLE_ENDIAN or len(raw) < _DATA_START + _STAMP.size:
        return None
    return _STAMP.unpack_from(raw, _DATA_START)


def read_vector3_stamped(raw: bytes) -> tuple[int, int, str, tuple[float, float, float]] | None:
    """(sec, nanosec, frame_id, (x, y, z)) of a geometry_msgs/Vector3Stamped."""
    if raw[:2] != _LITTLE_ENDIAN:
        return None
    try:
        sec, nanosec = _STAMP.unpack_from(raw, _DATA_START)
        frame_id, position = _string_at(raw, _DATA_START + _STAMP.size)
        vector = _VECTOR3.unpack_from(raw, _aligned(position, 8))
    except (struct.error, ValueError):
        return None
    return sec, nanosec, frame_id, vector


def read_imu_rate_and_acceleration(
    raw: bytes,
) -> tuple[int, int, tuple[float, float, float], tuple[float, float, float]] | None:
    """(sec, nanosec, angular velocity (x, y, z), linear acceleration (x, y, z)) of a
    sensor_msgs/Imu; the frame id is skipped, not read, and nothing after the acceleration."""
    if raw[:2] != _LITTLE_ENDIAN or len(raw) < _DATA_START + _STAMP_AND_FRAME_LENGTH.size:
        return None
    sec, nanosec, frame_length = _STAMP_AND_FRAME_LENGTH.unpack_from(raw, _DATA_START)
    fields_at = _aligned(_DATA_START + _STAMP_AND_FRAME_LENGTH.size + frame_length, 8)
    if len(raw) < fields_at + _IMU_FIELDS.size:
        return None
    values = _IMU_FIELDS.unpack_from(raw, fields_at)
    return sec, nanosec, values[13:16], values[25:28]


def read_odometry(raw: bytes) -> tuple[int, int, str, str, tuple, tuple, tuple, tuple] | None:
    """(sec, nanosec, frame_id, child_frame_id, pose, twist, pose_covariance, twist_covariance)
    of a nav_msgs/Odometry: ``pose`` = position (x, y, z) then orientation (x, y, z, w),
    ``twist`` = linear (x, y, z) then angular (x, y, z), the covariances 36 row-major values
    each."""
    if raw[:2] != _LITTLE_ENDIAN:
        return None
    try:
        sec, nanosec = _STAMP.unpack_from(raw, _DATA_START)
        frame_id, position = _string_at(raw, _DATA_START + _STAMP.size)
        child_frame_id, position = _string_at(raw, position)
        position = _aligned(position, 8)
        pose = _POSE.unpack_from(raw, position)
        pose_covariance = _COVARIANCE.unpack_from(raw, position + _POSE.size)
        position += _POSE_WITH_COVARIANCE_SIZE
        twist = _TWIST.unpack_from(raw, position)
        twist_covariance = _COVARIANCE.unpack_from(raw, position + _TWIST.size)
    except (struct.error, ValueError):
        return None
    return sec, nanosec, frame_id, child_frame_id, pose, twist, pose_covariance, twist_covariance


def read_nav_sat_fix(
    raw: bytes,
) -> tuple[int, int, str, int, int, float, float, float] | None:
    """(sec, nanosec, frame_id, status, service, latitude, longitude, altitude) of a
    sensor_msgs/NavSatFix; the covariance is skipped."""
    if raw[:2] != _LITTLE_ENDIAN:
        return None
    try:
        sec, nanosec = _STAMP.unpack_from(raw, _DATA_START)
        frame_id, position = _string_at(raw, _DATA_START + _STAMP.size)
        (status,) = _I8.unpack_from(raw, position)
        position = _aligned(position + _I8.size, 2)
        (service,) = _U16.unpack_from(raw, position)
        position = _aligned(position + _U16.size, 8)
        latitude, longitude, altitude = _VECTOR3.unpack_from(raw, position)
    except (struct.error, ValueError):
        return None
    return sec, nanosec, frame_id, status, service, latitude, longitude, altitude


# -- writers -----------------------------------------------------------------------------------


class _Layout:
    """Builds the ``struct`` format of a fixed CDR layout, inserting the alignment padding."""

    def __init__(self):
        self._format = ["<4s"]
        self._offset = 0  # from the end of the encapsulation header

    def add(self, code: str, size: int, count: int = 1) -> None:
        padding = -self._offset % size
        if padding:
            self._format.append(f"{padding}x")
        self._format.append(f"{count}{code}")
        self._offset += padding + size * count

    def string(self, text: str) -> bytes:
        """A string field of fixed ``text``; returns what to pack for it after its length."""
        encoded = text.encode() + b"\0"
        self.add("I", 4)
        self._format.append(f"{len(encoded)}s")
        self._offset += len(encoded)
        return encoded

    def header(self, frame_id: str) -> bytes:
        self.add("i", 4)
        self.add("I", 4)
        return self.string(frame_id)

    def struct(self) -> struct.Struct:
        return struct.Struct("".join(self._format))


class _StampedWriter:
    """A fixed-layout message with a ``std_msgs/Header`` in frame ``frame_id``: the layout of the
    header, then the fields a subclass adds in :meth:`_add_fields`. ``self._header`` is what to
    pack after the encapsulation header and the stamp (the frame id's length and bytes)."""

    def __init__(self, frame_id: str):
        layout = _Layout()
        frame = layout.header(frame_id)
        self._header = (len(frame), frame)
        self._add_fields(layout)
        self._struct = layout.struct()

    def _add_fields(self, layout: _Layout) -> None:
        raise NotImplementedError


class Vector3StampedWriter(_StampedWriter):
    """geometry_msgs/Vector3Stamped in frame ``frame_id``."""

    def _add_fields(self, layout: _Layout) -> None:
        layout.add("d", 8, 3)

    def write(self, sec: int, nanosec: int, x: float, y: float, z: float) -> bytes:
        return self._struct.pack(
            ENCAPSULATION_LITTLE_ENDIAN,
            sec,
            nanosec,
            *self._header,
            x,
            y,
            z,
        )

    def write_many(self, sec, nanosec, vectors) -> list[bytes]:
        """:meth:`write` of (N,) stamps and (N, 3) vectors at once, in order."""
        vectors = np.asarray(vectors, dtype=float).reshape(-1, 3)
        size = self._struct.size
        template = np.frombuffer(self.write(0, 0, 0.0, 0.0, 0.0), dtype=np.uint8)
        packed = np.tile(template, (vectors.shape[0], 1))
        packed[:, 4:8] = np.asarray(sec, dtype="<i4").reshape(-1, 1).view(np.uint8)
        packed[:, 8:12] = np.asarray(nanosec, dtype="<u4").reshape(-1, 1).view(np.uint8)
        packed[:, size - 24 :] = vectors.astype("<f8").view(np.uint8)
        data = packed.tobytes()
        return [data[start : start + size] for start in range(0, len(data), size)]


class OdometryWriter(_StampedWriter):
    """nav_msgs/Odometry in frame ``frame_id`` of child frame ``child_frame_id``."""

    def __init__(self, frame_id: str, child_frame_id: str):
        self._child_frame_id = child_frame_id
        super().__init__(frame_id)

    def _add_fields(self, layout: _Layout) -> None:
        child_frame = layout.string(self._child_frame_id)
        self._child_frame = (len(child_frame), child_frame)
        layout.add("d", 8, 7 + 36 + 6 + 36)

    def write(
        self,
        sec: int,
        nanosec: int,
        position,
        orientation_xyzw,
        pose_covariance,
        linear,
        angular,
        twist_covariance,
    ) -> bytes:
        """Vectors as 3 values, the quaternion as 4, the covariances as 36 (row-major)."""
        return self._struct.pack(
            ENCAPSULATION_LITTLE_ENDIAN,
            sec,
            nanosec,
            *self._header,
            *self._child_frame,
            *position,
            *orientation_xyzw,
            *pose_covariance,
            *linear,
            *angular,
            *twist_covariance,
        )


class ImuWriter(_StampedWriter):
    """sensor_msgs/Imu in frame ``frame_id``."""

    def _add_fields(self, layout: _Layout) -> None:
        layout.add("d", 8, 4 + 9 + 3 + 9 + 3 + 9)

    def write(
        self,
        sec: int,
        nanosec: int,
        orientation_xyzw,
        orientation_covariance,
        angular_velocity,
        angular_velocity_covariance,
        linear_acceleration,
        linear_acceleration_covariance,
    ) -> bytes:
        """Vectors as 3 values, the quaternion as 4, the covariances as 9 (row-major)."""
        return self._struct.pack(
            ENCAPSULATION_LITTLE_ENDIAN,
            sec,
            nanosec,
            *self._header,
            *orientation_xyzw,
            *orientation_covariance,
            *angular_velocity,
            *angular_velocity_covariance,
            *linear_acceleration,
            *linear_acceleration_covariance,
        )


class TwistWithCovarianceStampedWriter(_StampedWriter):
    """geometry_msgs/TwistWithCovarianceStamped in frame ``frame_id``."""

    def _add_fields(self, layout: _Layout) -> None:
        layout.add("d", 8, 6 + 36)

    def write(self, sec: int, nanosec: int, linear, angular, covariance) -> bytes:
        """Vectors as 3 values, the covariance as 36 (row-major)."""
        return self._struct.pack(
            ENCAPSULATION_LITTLE_ENDIAN,
            sec,
            nanosec,
            *self._header,
            *linear,
            *angular,
            *covariance,
        )


class NavSatFixWriter(_StampedWriter):
    """sensor_msgs/NavSatFix in frame ``frame_id``."""

    def _add_fields(self, layout: _Layout) -> None:
        layout.add("b", 1)
        layout.add("H", 2)
        layout.add("d", 8, 3 + 9)
        layout.add("B", 1)

    def write(
        self,
        sec: int,
        nanosec: int,
        status: int,
        service: int,
        latitude_deg: float,
        longitude_deg: float,
        altitude_m: float,
        position_covariance,
        position_covariance_type: int,
    ) -> bytes:
        """The covariance as 9 values (row-major, m²)."""
        return self._struct.pack(
            ENCAPSULATION_LITTLE_ENDIAN,
            sec,
            nanosec,
            *self._header,
            status,
            service,
            latitude_deg,
            longitude_deg,
            altitude_m,
            *position_covariance,
            position_covariance_type,
        )


class MagneticFieldWriter(_StampedWriter):
    """sensor_msgs/MagneticField in frame ``frame_id``."""

    def _add_fields(self, layout: _Layout) -> None:
        layout.add("d", 8, 3 + 9)

    def write(self, sec: int, nanosec: int, magnetic_field_t, covariance_t2) -> bytes:
        """The field as 3 values (T), its covariance as 9 (row-major, T²)."""
        return self._struct.pack(
            ENCAPSULATION_LITTLE_ENDIAN,
            sec,
            nanosec,
            *self._header,
            *magnetic_field_t,
            *covariance_t2,
        )


class TemperatureWriter(_StampedWriter):
    """sensor_msgs/Temperature in frame ``frame_id``."""

    def _add_fields(self, layout: _Layout) -> None:
        layout.add("d", 8, 2)

    def write(self, sec: int, nanosec: int, temperature_degc: float, variance_k2: float) -> bytes:
        return self._struct.pack(
            ENCAPSULATION_LITTLE_ENDIAN,
            sec,
            nanosec,
            *self._header,
            temperature_degc,
            variance_k2,
        )
