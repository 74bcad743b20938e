"""Contract messages of the wind compensation as arrays, and arrays as contract messages.

The live ``compensation_node`` and offline bag processing both convert through this module, so
a message is accepted, rejected or transformed identically in both. Messages are read by
attribute access only: rclpy message objects and rosbags' decoded objects both work. Messages
are built from default-constructible message classes (the ROS Python message classes, which
:class:`buoy_common.bag_io.BagWriter` also serialises).

Inputs (interface contract):

- ``anemometer/wind`` (geometry_msgs/Vector3Stamped, frame ``anemometer_link``): air velocity
  relative to the sensor in anemometer axes, m/s.
- ``nav/odometry`` (nav_msgs/Odometry, frame ``map``, child ``base_link``):
  ``pose.pose.orientation`` = body→ENU attitude R_nb, ``twist.twist.angular`` = bias-corrected
  body rate ω_ib (body axes, rad/s), ``twist.twist.linear`` = velocity of the body origin in body
  axes (m/s), so the ENU velocity is R_nb · linear.
- ``nav/fix`` (sensor_msgs/NavSatFix): WGS-84 latitude of the body origin, used to remove the
  Earth's rotation from the body rate (:func:`remove_earth_rate`).

Outputs:

- ``wind/true`` (geometry_msgs/Vector3Stamped, frame ``map``): corrected ENU wind, m/s, with the
  anemometer sample's own header stamp; NaN components when the sample could not be corrected.
- ``wind/mean_<window>`` (geometry_msgs/Vector3Stamped, frame ``map``): vector mean of the ENU
  wind over one averaging window, stamped with the window end.
- ``wind/stats_<window>`` (std_msgs/Float64MultiArray): the statistics of the same window,
  ``data[i]`` named by ``layout.dim[i].label`` (one dimension of size 1 per field), in the order
  of :data:`STATS_FIELDS`.

Windows are named by :func:`window_label`: ``1min`` for 60 s, ``10min`` for 600 s.
"""

from __future__ import annotations

import math
import struct
from collections.abc import Iterable
from typing import NamedTuple

import numpy as np

from buoy_common.contract import (
    ANEMOMETER_FRAME,
    BODY_FRAME,
    MAP_FRAME,
    Reason,
    seconds_to_stamp,
    stamp_to_seconds,
)
from wind_comp.miller import cross_components
from wind_comp.nav_interpolation import MIN_QUATERNION_NORM, quaternion_norm
from wind_comp.products import WindProduct

EARTH_RATE_RAD_S = 7.292115e-5
"""Earth's rotation rate relative to inertial space (WGS-84), rad/s."""


STATS_FIELDS = (
    "scalar_mean_speed_mps",
    "vector_mean_speed_mps",
    "vector_mean_direction_deg",
    "gust_mps",
    "std_u_mps",
    "std_v_mps",
    "std_w_mps",
    "n_valid",
    "n_invalid",
    "window_start_s",
    "window_end_s",
    "first_sample_s",
    "last_sample_s",
)
"""Layout of ``wind/stats_<window>``: speeds m/s (horizontal), direction meteorological deg
(blowing FROM, clockwise from true North), standard deviations of the ENU components m/s,
sample counts, window bounds and first/last sample stamps in s since the epoch (a window closed
at shutdown may end before ``window_end_s``). Conventions: :mod:`wind_comp.products`."""


class MalformedMessageError(ValueError):
    """A message is malformed. ``reason`` is a short label for counting; the text details it."""

    def __init__(self, reason: str, detail: str):
        super().__init__(f"{reason}: {detail}")
        self.reason = reason


class WindSample(NamedTuple):
    """One anemometer sample as the compensator takes it."""

    t_s: float
    """Header stamp, s since the epoch."""
    wind_sensor_mps: np.ndarray
    """(3,) air velocity in anemometer axes, m/s; NaN when the message was rejected."""
    rejection: str | None
    """Reason the message was rejected (its output is then invalid), None when accepted."""


class NavArrays(NamedTuple):
    """Navigation samples of a recording, in message order; (M,), (M, 4), (M, 3), (M, 3)."""

    t_s: np.ndarray
    quat_xyzw: np.ndarray
    angular_rate_body_rad_s: np.ndarray
    velocity_enu_mps: np.ndarray


class StampOrder:
    """Tracks that the stamps of one topic strictly increase."""

    def __init__(self):
        self.latest_s = -math.inf

    def advance(self, t_s: float) -> bool:
        """True and remember ``t_s`` (s) when it is later than every earlier accepted stamp."""
        if not t_s > self.latest_s:
            return False
        self.latest_s = t_s
        return True


def _vector(message_vector) -> tuple[float, float, float]:
    return float(message_vector.x), float(message_vector.y), float(message_vector.z)


def anemometer_sample(message) -> WindSample:
    """``anemometer/wind`` as a :class:`WindSample`.

    A message in another frame than ``anemometer_link`` or with a non-finite component is
    rejected: its wind becomes NaN so that the compensator still returns one (invalid) output
    for it, in order. Stamp order is checked by the compensator itself.
    """
    vector = message.vector
    return _wind_sample(
        stamp_to_seconds(message.header.stamp),
        message.header.frame_id,
        vector.x,
        vector.y,
        vector.z,
    )


def _wind_sample(t_s: float, frame_id: str, x: float, y: float, z: float) -> WindSample:
    wind = np.array([x, y, z], dtype=float)
    rejection = None
    if frame_id != ANEMOMETER_FRAME:
        rejection = Reason.WRONG_FRAME
    elif not np.all(np.isfinite(wind)):
        rejection = Reason.NON_FINITE
    if rejection is not None:
        wind = np.full(3, np.nan)
    return WindSample(t_s, wind, rejection)


# Offline tools read and write Vector3Stamped as CDR bytes (ROS 2 XCDR1, little endian: each
# primitive aligned to its size from the start of the data, which follows a 4-byte
# encapsulation header), several times faster than through message objects.
_CDR_LITTLE_ENDIAN = b"\x00\x01"
_CDR_ENCAPSULATION = b"\x00\x01\x00\x00"
_CDR_STAMP_AND_FRAME_LENGTH = struct.Struct("<iII")
_CDR_VECTOR = struct.Struct("<3d")
_CDR_STAMP = struct.Struct("<iI")
_CDR_U32 = struct.Struct("<I")
_CDR_U16 = struct.Struct("<H")
_CDR_I8 = struct.Struct("<b")
_CDR_F64 = struct.Struct("<d")
# geometry_msgs/Pose (position, orientation) and Twist (linear, angular); each *WithCovariance
# follows its 8-byte-aligned fields with a 6×6 float64 covariance.
_CDR_POSE = struct.Struct("<7d")
_CDR_TWIST = struct.Struct("<6d")
_CDR_POSE_WITH_COVARIANCE_SIZE = _CDR_POSE.size + 36 * 8
_MAP_FRAME_CDR = MAP_FRAME.encode() + b"\0"
_CDR_VECTOR3_STAMPED_IN_MAP = struct.Struct(
    f"<4siII{len(_MAP_FRAME_CDR)}s{-(12 + len(_MAP_FRAME_CDR)) % 8}x3d"
)


def anemometer_sample_cdr(raw: bytes) -> tuple[WindSample, int, int] | None:
    """:func:`anemometer_sample` of an ``anemometer/wind`` message straight from its CDR bytes,
    with the header stamp (sec, nanosec). None for bytes this reader does not handle
    (big-endian, short or not UTF-8): decode the message and use :func:`anemometer_sample`."""
    if raw[:2] != _CDR_LITTLE_ENDIAN or len(raw) < 4 + _CDR_STAMP_AND_FRAME_LENGTH.size:
        return None
    sec, nanosec, frame_length = _CDR_STAMP_AND_FRAME_LENGTH.unpack_from(raw, 4)
    frame_at = 4 + _CDR_STAMP_AND_FRAME_LENGTH.size
    vector_at = frame_at + frame_length
    vector_at += -(vector_at - 4) % 8
    if frame_length == 0 or len(raw) < vector_at + _CDR_VECTOR.size:
        return None
    try:
        frame_id = raw[frame_at : frame_at + frame_length - 1].decode()
    except UnicodeDecodeError:
        return None
    x, y, z = _CDR_VECTOR.unpack_from(raw, vector_at)
    return _wind_sample(sec + nanosec * 1e-9, frame_id, x, y, z), sec, nanosec


def body_to_enu(quat_xyzw, vectors_body) -> np.ndarray:
    """Rotate body-frame vectors into ENU with body→ENU quaternions (normalised here).

    Args:
        quat_xyzw: (N, 4) or (4,) attitude R_nb, scipy order.
        vectors_body: (N, 3) or (3,) vectors in body axes (any unit, kept).

    :func:`body_to_enu_components` on the columns.
    """
    quats = np.asarray(quat_xyzw, dtype=float)
    vectors = np.asarray(vectors_body, dtype=float)
    rotated = body_to_enu_components(
        tuple(np.moveaxis(quats, -1, 0)), tuple(np.moveaxis(vectors, -1, 0))
    )
    return np.stack(np.broadcast_arrays(*rotated), axis=-1)


def body_to_enu_components(quat_xyzw, vector_body) -> tuple:
    """R(q)·v of a body→ENU quaternion (x, y, z, w), normalised here, and a body vector
    (x, y, z), by components: floats or equally shaped arrays, so that one sample (live) and a
    batch (offline) give bit-identical results."""
    x, y, z, w = quat_xyzw
    norm = quaternion_norm(x, y, z, w)
    axis = (x / norm, y / norm, z / norm)
    scalar = w / norm
    twice_cross = tuple(2.0 * component for component in cross_components(axis, vector_body))
    return tuple(
        vector + scalar * first + second
        for vector, first, second in zip(
            vector_body, twice_cross, cross_components(axis, twice_cross), strict=True
        )
    )


def odometry_fields(message) -> tuple[float, tuple, tuple, tuple]:
    """Stamp (s), attitude quaternion (x, y, z, w), body rate ω_ib and body velocity (tuples of
    floats) of an Odometry, after the frame, finiteness and quaternion checks."""
    orientation = message.pose.pose.orientation
    return _checked_odometry(
        stamp_to_seconds(message.header.stamp),
        message.header.frame_id,
        message.child_frame_id,
        (
            float(orientation.x),
            float(orientation.y),
            float(orientation.z),
            float(orientation.w),
        ),
        _vector(message.twist.twist.angular),
        _vector(message.twist.twist.linear),
    )


def _checked_odometry(t_s, frame_id, child_frame_id, quat, rate, velocity_body):
    if frame_id != MAP_FRAME or child_frame_id != BODY_FRAME:
        raise MalformedMessageError(
            Reason.WRONG_FRAME,
            f"odometry must be of {BODY_FRAME} in {MAP_FRAME}, got "
            f"'{child_frame_id}' in '{frame_id}'",
        )
    if not all(math.isfinite(value) for value in (*quat, *rate, *velocity_body)):
        raise MalformedMessageError(Reason.NON_FINITE, "odometry orientation, rate or velocity")
    if quaternion_norm(*quat) < MIN_QUATERNION_NORM:
        raise MalformedMessageError(Reason.ZERO_QUATERNION, "odometry orientation has zero length")
    return t_s, quat, rate, velocity_body


def _cdr_string(raw: bytes, position: int) -> tuple[str, int]:
    """A CDR string (length with its NUL, 4-byte aligned) at ``position``, and the position
    after it; ValueError for bytes that do not hold one."""
    position += -(position - 4) % 4
    (length,) = _CDR_U32.unpack_from(raw, position)
    start = position + _CDR_U32.size
    if length == 0 or start + length > len(raw):
        raise ValueError("string runs past the message")
    return raw[start : start + length - 1].decode(), start + length


def odometry_fields_cdr(raw: bytes) -> tuple[float, tuple, tuple, tuple] | None:
    """:func:`odometry_fields` of a ``nav/odometry`` message straight from its CDR bytes,
    checked as :func:`odometry_fields` checks them (raises
    :class:`MalformedMessageError`). None for bytes this reader does not handle (big-endian,
    short): decode the message instead."""
    if raw[:2] != _CDR_LITTLE_ENDIAN:
        return None
    try:
        sec, nanosec = _CDR_STAMP.unpack_from(raw, 4)
        frame_id, position = _cdr_string(raw, 12)
        child_frame_id, position = _cdr_string(raw, position)
        position += -(position - 4) % 8
        pose = _CDR_POSE.unpack_from(raw, position)
        twist = _CDR_TWIST.unpack_from(raw, position + _CDR_POSE_WITH_COVARIANCE_SIZE)
    except (struct.error, ValueError, UnicodeDecodeError):
        return None
    return _checked_odometry(
        sec + nanosec * 1e-9,
        frame_id,
        child_frame_id,
        pose[3:7],
        twist[3:6],
        twist[0:3],
    )


def fix_fields_cdr(raw: bytes) -> tuple[int, float] | None:
    """Status and latitude (deg) of a ``nav/fix`` message straight from its CDR bytes, for
    :func:`checked_fix_latitude_deg`; None for bytes this reader does not handle."""
    if raw[:2] != _CDR_LITTLE_ENDIAN:
        return None
    try:
        _, position = _cdr_string(raw, 12)
        (status,) = _CDR_I8.unpack_from(raw, position)
        position += 1
        position += -(position - 4) % 2 + _CDR_U16.size
        position += -(position - 4) % 8
        (latitude,) = _CDR_F64.unpack_from(raw, position)
    except (struct.error, ValueError, UnicodeDecodeError):
        return None
    return status, latitude


def odometry_arrays(messages: Iterable) -> tuple[NavArrays, dict[str, int]]:
    """Whole-recording :func:`odometry_fields` with the velocity rotated into ENU: arrays of the
    accepted messages, in order, and the number of rejected messages per reason. Stamp order is
    left to the navigation track, which rejects non-increasing stamps exactly as it does live."""
    stamps, quats, rates, velocities_body = [], [], [], []
    rejected: dict[str, int] = {}
    for message in messages:
        try:
            t_s, quat, rate, velocity_body = odometry_fields(message)
        except MalformedMessageError as error:
            rejected[error.reason] = rejected.get(error.reason, 0) + 1
            continue
        stamps.append(t_s)
        quats.append(quat)
        rates.append(rate)
        velocities_body.append(velocity_body)
    quats_array = np.array(quats, dtype=float).reshape(-1, 4)
    velocities = body_to_enu(quats_array, np.array(velocities_body, dtype=float).reshape(-1, 3))
    arrays = NavArrays(
        np.array(stamps, dtype=float),
        quats_array,
        np.array(rates, dtype=float).reshape(-1, 3),
        velocities,
    )
    return arrays, rejected


def fix_latitude_deg(message) -> float | None:
    """Latitude (deg) of a ``nav/fix`` NavSatFix; None when it reports no fix (status < 0).

    Raises :class:`MalformedMessageError` for a fix whose latitude is not finite or beyond ±90°.
    """
    return checked_fix_latitude_deg(message.status.status, float(message.latitude))


def checked_fix_latitude_deg(status: int, latitude_deg: float) -> float | None:
    """:func:`fix_latitude_deg` of a fix's status and latitude (deg)."""
    if status < 0:
        return None
    if not math.isfinite(latitude_deg):
        raise MalformedMessageError(Reason.NON_FINITE, f"fix latitude {latitude_deg}")
    if abs(latitude_deg) > 90.0:
        raise MalformedMessageError(
            Reason.LATITUDE_OUT_OF_RANGE, f"fix latitude {latitude_deg} deg"
        )
    return latitude_deg


def remove_earth_rate(angular_rate_body_rad_s, quat_xyzw, latitude_deg) -> np.ndarray:
    """Body rate relative to the local-level frame from the rate relative to inertial space.

    ω_nb = ω_ib − R_nb^T · ω_ie^n with ω_ie^n = Ω (0, cos φ, sin φ) in ENU (Ω: Earth rate). The
    transport rate of a buoy (< 1e-7 rad/s) is neglected.

    Args:
        angular_rate_body_rad_s: (N, 3) or (3,) ω_ib, body axes, rad/s.
        quat_xyzw: (N, 4) or (4,) body→ENU attitude.
        latitude_deg: (N,) or scalar geodetic latitude φ, deg; NaN where unknown, which leaves
            the rate unchanged (an error of at most Ω·|B|, < 3e-4 m/s of wind at 3 m).

    Returns ω_nb, body axes, rad/s, shaped like ``angular_rate_body_rad_s``.
    """
    rates = np.asarray(angular_rate_body_rad_s, dtype=float)
    quats = np.asarray(quat_xyzw, dtype=float)
    level_rates = rate_relative_to_level_components(
        tuple(np.moveaxis(rates, -1, 0)),
        tuple(np.moveaxis(quats, -1, 0)),
        np.asarray(latitude_deg, dtype=float),
    )
    return np.stack(np.broadcast_arrays(*level_rates), axis=-1)


def rate_relative_to_level_components(angular_rate_body_rad_s, quat_xyzw, latitude_deg) -> tuple:
    """:func:`remove_earth_rate` by components: rate (x, y, z) rad/s, quaternion (x, y, z, w),
    latitude deg; floats or equally shaped arrays, so that one sample (live) and a batch
    (offline) give bit-identical results."""
    latitude_rad = np.radians(latitude_deg)
    earth_rate_enu = (
        0.0,
        EARTH_RATE_RAD_S * np.cos(latitude_rad),
        EARTH_RATE_RAD_S * np.sin(latitude_rad),
    )
    x, y, z, w = quat_xyzw
    earth_rate_body = body_to_enu_components((-x, -y, -z, w), earth_rate_enu)
    known = np.isfinite(latitude_rad)
    return tuple(
        np.where(known, rate - np.where(known, earth, 0.0), rate)
        for rate, earth in zip(angular_rate_body_rad_s, earth_rate_body, strict=True)
    )


def _set_header(header, sec: int, nanosec: int, frame_id: str) -> None:
    header.stamp.sec = int(sec)
    header.stamp.nanosec = int(nanosec)
    header.frame_id = frame_id


def _set_vector(target, values) -> None:
    target.x, target.y, target.z = (float(value) for value in values)


def true_wind_cdr(sec: int, nanosec: int, wind_enu_mps) -> bytes:
    """``wind/true`` as CDR bytes: the ENU wind (m/s, NaN when invalid) in frame ``map``,
    stamped (sec, nanosec) with the anemometer sample's own stamp."""
    x, y, z = wind_enu_mps
    return _CDR_VECTOR3_STAMPED_IN_MAP.pack(
        _CDR_ENCAPSULATION,
        int(sec),
        int(nanosec),
        len(_MAP_FRAME_CDR),
        _MAP_FRAME_CDR,
        float(x),
        float(y),
        float(z),
    )


def product_messages(
    vector_stamped_class, multi_array_class, dimension_class, product: WindProduct
) -> tuple[object, object]:
    """(``wind/mean_<window>``, ``wind/stats_<window>``) messages of one averaging window.

    The mean is the ENU vector mean (m/s, frame ``map``), stamped with the window end; the
    statistics follow :data:`STATS_FIELDS`.
    """
    sec, nanosec = seconds_to_stamp(product.window_end_s)
    mean = vector_stamped_class()
    _set_header(mean.header, sec, nanosec, MAP_FRAME)
    _set_vector(
        mean.vector, (product.mean_u_enu_mps, product.mean_v_enu_mps, product.mean_w_enu_mps)
    )
    stats = multi_array_class()
    stats.layout.dim = [dimension_class(label=name, size=1, stride=1) for name in STATS_FIELDS]
    stats.layout.data_offset = 0
    stats.data = [float(getattr(product, name)) for name in STATS_FIELDS]
    return mean, stats


def stats_values(stats_message) -> dict[str, float]:
    """A ``wind/stats_<window>`` message as {field label: value}."""
    labels = [dimension.label for dimension in stats_message.layout.dim]
    return dict(zip(labels, (float(value) for value in stats_message.data), strict=True))
