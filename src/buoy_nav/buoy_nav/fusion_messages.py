"""Contract messages of the fusion: sensor messages into the engine, solutions into ``nav/*``.

The live ``fusion_node`` and the offline tools (``fuse_bag``, ``process_bag``) convert through
this module, so a message is accepted, rejected or produced identically in both. Messages are
read by attribute access only: rclpy message objects and rosbags' decoded objects both work.
Output messages are built from the message classes handed in (the ROS Python message classes,
which :class:`buoy_common.bag_io.BagWriter` also serialises).

Inputs (interface contract); frame ids are not checked, so drivers that name their frames
differently still work:

- ``imu/data_raw`` (sensor_msgs/Imu): raw body rate ω_ib (rad/s) and specific force (m/s²).
- ``gnss/fix`` (sensor_msgs/NavSatFix): primary antenna WGS-84 position, ENU
  ``position_covariance`` (m²). ``status.status < 0`` (no fix) is skipped and counted.
- ``gnss/vel`` (geometry_msgs/TwistWithCovarianceStamped): primary antenna ENU velocity over
  ground, covariance (m²/s²) from the linear 3×3 block of the 6×6 twist covariance.
- ``gnss/heading`` (sensor_msgs/Imu): yaw of the orientation quaternion = azimuth of the
  primary→secondary baseline (ENU, rad); ``orientation_covariance[8]`` = yaw variance (rad²).
- ``gnss/baseline`` (geometry_msgs/Vector3Stamped): primary→secondary antenna vector (ENU, m);
  its error is a parameter (the message has no covariance).

Each aiding source converts its own message (:mod:`buoy_nav.aiding`); this module dispatches by
topic.

Outputs (one set per navigation solution, all with the solution's stamp):

- ``nav/odometry`` (nav_msgs/Odometry, ``map`` → ``base_link``): position in ``map`` (m),
  attitude body→ENU, 6×6 pose covariance (position, then attitude as rotation-vector error in
  ENU, rad²); twist in ``base_link``: linear = R_nbᵀ·v_ENU with covariance R_nbᵀ·P_v·R_nb,
  angular = bias-corrected body rate ω_ib with the gyro bias estimate's covariance (rad²/s²).
- ``nav/imu`` (sensor_msgs/Imu, ``base_link``): attitude with its covariance, bias-corrected
  ω_ib with the gyro bias estimate's covariance, and specific force.
- ``nav/velocity`` (geometry_msgs/TwistWithCovarianceStamped, ``map``): ENU velocity of the
  ``base_link`` origin with covariance.

Covariances not estimated (the specific force, the angular part of ``nav/velocity``) are all
zeros, the ROS convention for "unknown".
- ``nav/fix`` (sensor_msgs/NavSatFix, ``base_link``): WGS-84 position of the ``base_link``
  origin, ENU covariance (known), status FIX, service GPS.
- ``tf`` (tf2_msgs/TFMessage): the transform ``map`` → ``base_link`` (position in ``map``, m;
  attitude body→ENU), laid out by rosbags' Jazzy typestore (:func:`transform_cdr`), so bags
  carry it without tf2 installed and the node publishes the same bytes where it is.
"""

from __future__ import annotations

import math
import struct
from collections import deque
from typing import NamedTuple

from buoy_common import cdr
from buoy_common.bag_io import jazzy_typestore
from buoy_common.contract import (
    BODY_FRAME,
    IMU_RAW_TOPIC,
    MAP_FRAME,
    NAV_FIX_TOPIC,
    NAV_IMU_TOPIC,
    NAV_ODOMETRY_TOPIC,
    NAV_VELOCITY_TOPIC,
    SENSOR_MSGTYPES,
    TF_MSGTYPE,
    Reason,
    header_seconds,
    seconds_to_stamp,
)
from buoy_common.transform_messages import FrameTransform, tf_message
from buoy_nav.aiding import TOPIC_SOURCES
from buoy_nav.aiding.base import vector_of
from buoy_nav.aiding.gnss_fix import STATUS_FIX
from buoy_nav.engine import IMU, FusionEngine, NavSolution
from buoy_nav.imu_stretches import MeasurementInput
from buoy_nav.nav_numbers import (
    ATTITUDE_COVARIANCE,
    BODY_TWIST_COVARIANCE,
    ENU_TWIST_COVARIANCE,
    GYRO_BIAS_COVARIANCE,
    POSE_COVARIANCE,
    POSITION_COVARIANCE,
    VELOCITY_BODY,
    body_numbers,
    covariance_numbers,
)
from buoy_nav.solution import Emitted

FUSION_INPUT_MSGTYPES = {
    IMU_RAW_TOPIC: SENSOR_MSGTYPES[IMU_RAW_TOPIC],
    **{source.topic: source.msgtype() for source in TOPIC_SOURCES},
}
"""The fusion's input topics (relative names) and their message types: the IMU and the topic of
every registered aiding source."""

# sensor_msgs/NavSatStatus and NavSatFix constants.
SERVICE_GPS = 1
COVARIANCE_TYPE_KNOWN = 3


class StampBook:
    """The exact header stamps of recent IMU samples, to stamp their solutions with.

    The engine works in float seconds, which resolve about 0.24 µs at present-day epoch times;
    a solution's stamp is looked up here by its float stamp so that ``nav/*`` carry the IMU
    message's own (sec, nanosec). Solutions come out in stamp order, so the book is a queue;
    it keeps the newest ``capacity`` samples (delayed output needs
    ``max_measurement_delay_s`` × IMU rate of them).

    A sample the engine re-stamped after a step of the IMU's clock (``clock_steps``, the
    engine's :attr:`~buoy_nav.engine.FusionEngine.imu_clock_steps`) has no header stamp of its
    own: its stamp is rounded to the nanosecond. Looked up, it could meet another sample's
    header of the same float stamp (after a step back, the stamps of the seconds that follow
    run over again), found or not depending on how far the input had been read: live and
    offline would stamp it differently.
    """

    def __init__(self, clock_steps=(), capacity: int = 8192):
        self._stamps: deque[tuple[float, int, int]] = deque(maxlen=capacity)
        self._clock_steps = clock_steps

    def remember(self, t_s: float, sec: int, nanosec: int) -> None:
        self._stamps.append((t_s, sec, nanosec))

    def exact(self, t_s: float) -> tuple[int, int]:
        """(sec, nanosec) of the sample stamped ``t_s`` (s); rounded from ``t_s`` if unknown
        or re-stamped."""
        stamps = self._stamps
        while stamps and stamps[0][0] < t_s:
            stamps.popleft()
        if stamps and stamps[0][0] == t_s and not self._restamped(t_s):
            return stamps[0][1], stamps[0][2]
        return seconds_to_stamp(t_s)

    def _restamped(self, t_s: float) -> bool:
        """Whether the sample the engine stamped ``t_s`` (s) was moved off its header stamp by
        the steps of the IMU's clock undone before it (their offsets summed as the engine's
        clock sums them)."""
        offset_s = 0.0
        for first_s, step_s in self._clock_steps:
            if t_s >= first_s:
                offset_s -= step_s
        return offset_s != 0.0


def feed_message(
    engine: FusionEngine, topic: str, message, stamps: StampBook | None = None
) -> tuple[list[Emitted], str | None]:
    """Give one sensor message of ``topic`` to ``engine``: an IMU sample, or a measurement of
    the aiding source that reads ``topic`` (which converts the message).

    Returns the navigation solutions that became available (IMU messages only) and the reason
    the message was rejected, None when it was accepted. Rejected input never reaches the
    state; the engine counts every rejection by input and reason (see
    :meth:`FusionEngine.health`). IMU stamps go into ``stamps`` when given. Raises ValueError
    for a topic the fusion does not take.
    """
    if topic == IMU_RAW_TOPIC:
        try:
            t_s = header_seconds(message.header)
            gyro = vector_of(message.angular_velocity)
            force = vector_of(message.linear_acceleration)
        except (AttributeError, TypeError, ValueError):
            engine.reject_input(IMU, Reason.MALFORMED)
            return [], Reason.MALFORMED
        if stamps is not None:
            stamps.remember(t_s, message.header.stamp.sec, message.header.stamp.nanosec)
        solutions = engine.add_imu(t_s, gyro, force)
        return solutions, engine.last_input_rejection
    source = engine.source_of_topic(topic)
    try:
        t_s = header_seconds(message.header)
        measurement = source.measurement_from_message(message)
    except (AttributeError, TypeError, ValueError):
        t_s, measurement = math.nan, Reason.MALFORMED
    return _add_measurement(engine, source, t_s, measurement)


def feed_measurement_record(
    engine: FusionEngine, topic: str, sec: int, nanosec: int, *fields
) -> tuple[list[Emitted], str | None]:
    """:func:`feed_message` of a message of an aiding source's ``topic`` read elsewhere, with
    the others of its chunk (:mod:`buoy_common.cdr_bulk`): header stamp ``sec``, ``nanosec``
    and the values of the source's ``record_fields``."""
    source = engine.source_of_topic(topic)
    t_s = sec + nanosec * 1e-9
    return _add_measurement(engine, source, t_s, source.measurement_from_record(t_s, *fields))


def _add_measurement(
    engine: FusionEngine, source, t_s: float, measurement
) -> tuple[list[Emitted], str | None]:
    """Give ``source``'s ``measurement`` stamped ``t_s`` (s) to ``engine``, or count the
    :class:`Reason` it is none."""
    if isinstance(measurement, Reason):
        engine.reject_input(source.kind, measurement)
        return [], measurement
    engine.add_measurement(t_s, measurement)
    return [], engine.last_input_rejection


def feed_imu_cdr(
    engine: FusionEngine, raw: bytes, stamps: StampBook | None = None
) -> tuple[list[Emitted], str | None] | None:
    """:func:`feed_message` of an ``imu/data_raw`` message straight from its CDR bytes.

    Offline tools read IMU samples this way, several times faster than decoding a message
    object; the engine receives the same numbers. Returns None for bytes this reader does not
    handle (big-endian or short data): decode the message and use :func:`feed_message`.
    """
    fields = cdr.read_imu_rate_and_acceleration(raw)
    if fields is None:
        return None
    return feed_imu_fields(engine, *fields, stamps)


def feed_imu_fields(
    engine: FusionEngine,
    sec: int,
    nanosec: int,
    angular_velocity,
    linear_acceleration,
    stamps: StampBook | None = None,
) -> tuple[list[Emitted], str | None]:
    """:func:`feed_message` of an ``imu/data_raw`` message read elsewhere (its CDR bytes,
    alone or with the others of its chunk): header stamp ``sec``, ``nanosec``; angular velocity
    (rad/s) and linear acceleration (m/s²), x, y, z in the IMU's frame."""
    t_s = sec + nanosec * 1e-9
    if stamps is not None:
        stamps.remember(t_s, sec, nanosec)
    solutions = engine.add_imu(t_s, angular_velocity, linear_acceleration)
    return solutions, engine.last_input_rejection


def feed_records(
    engine: FusionEngine, topics: list[str], records: list[tuple], stamps: StampBook | None = None
) -> list[tuple[list[Emitted], str | None]]:
    """:func:`feed_imu_fields` and :func:`feed_measurement_record` of consecutive messages of
    ``topics`` (``imu/data_raw`` and those of :attr:`FusionEngine.stretched_sources`), nothing
    else between them, in one call (:meth:`FusionEngine.add_inputs`): each one's record
    ``(sec, nanosec, *fields)``; each one's solutions and rejection."""
    inputs: list = []
    records_of: dict = {}  # source → its records' (place among the inputs, stamp s, fields)
    for topic, record in zip(topics, records, strict=True):
        sec, nanosec, *fields = record
        t_s = sec + nanosec * 1e-9
        if topic == IMU_RAW_TOPIC:
            if stamps is not None:
                stamps.remember(t_s, sec, nanosec)
            inputs.append((t_s, *fields))
        else:
            records_of.setdefault(engine.source_of_topic(topic), []).append(
                (len(inputs), t_s, fields)
            )
            inputs.append(None)
    for source, source_records in records_of.items():
        places, stamps_s, fields = zip(*source_records, strict=True)
        for place, t_s, measurement in zip(
            places, stamps_s, measurements_from_records(source, stamps_s, fields), strict=True
        ):
            inputs[place] = MeasurementInput(source, t_s, measurement)
    return engine.add_inputs(inputs)


def measurements_from_records(source, stamps_s, fields) -> list:
    """Each record's measurement of ``source`` (or the :class:`Reason` it is none), in order,
    of records stamped ``stamps_s`` (s) with the values of its ``record_fields`` in ``fields``
    (a tuple a record): at once where the source can (its ``measurements_from_records``), else
    one by one. A source's records are made only after each other: what it keeps between them
    is its own."""
    at_once = getattr(source, "measurements_from_records", None)
    made = None if at_once is None else at_once(list(stamps_s), *zip(*fields, strict=True))
    if made is not None:
        return made
    return [
        source.measurement_from_record(t_s, *record_fields)
        for t_s, record_fields in zip(stamps_s, fields, strict=True)
    ]


class NavValues(NamedTuple):
    """The numbers of the four ``nav/*`` messages of one solution (flat, row-major)."""

    t_s: float
    sec: int
    nanosec: int
    position_map_m: tuple
    attitude_xyzw: tuple
    pose_covariance: tuple
    velocity_body_mps: tuple
    angular_rate_body_rad_s: tuple
    body_twist_covariance: tuple
    attitude_covariance_rad2: tuple
    gyro_bias_covariance_rad2_s2: tuple
    specific_force_body_mps2: tuple
    velocity_enu_mps: tuple
    enu_twist_covariance: tuple
    latitude_deg: float
    longitude_deg: float
    altitude_m: float
    position_covariance_m2: tuple


_ZEROS3 = (0.0, 0.0, 0.0)
_ZEROS9 = (0.0,) * 9


class _CovarianceFields(NamedTuple):
    """The ``nav/*`` fields that depend on a solution's covariance blocks alone."""

    pose_covariance: tuple
    attitude_covariance_rad2: tuple
    enu_twist_covariance: tuple
    position_covariance_m2: tuple
    gyro_bias_covariance_rad2_s2: tuple


class _CovarianceFieldCache:
    """:class:`_CovarianceFields` of the latest covariance blocks seen.

    The engine hands consecutive solutions the same read-only covariance arrays until the
    filter changes them, so at the IMU rate with aiding at a lower rate most solutions reuse
    the fields of the one before. Writable arrays could change in place and are never taken
    from the cache.
    """

    def __init__(self):
        self._latest: tuple | None = None

    def fields(self, attitude, velocity, position, gyro_bias) -> _CovarianceFields:
        latest = self._latest  # one read: the blocks and their fields stay a consistent pair
        if (
            latest is not None
            and latest[0] is attitude
            and latest[1] is velocity
            and latest[2] is position
            and latest[3] is gyro_bias
        ):
            return latest[4]
        numbers = covariance_numbers(attitude, velocity, position, gyro_bias)
        fields = _CovarianceFields(
            pose_covariance=tuple(numbers[POSE_COVARIANCE : POSE_COVARIANCE + 36]),
            attitude_covariance_rad2=tuple(numbers[ATTITUDE_COVARIANCE : ATTITUDE_COVARIANCE + 9]),
            enu_twist_covariance=tuple(numbers[ENU_TWIST_COVARIANCE : ENU_TWIST_COVARIANCE + 36]),
            position_covariance_m2=tuple(numbers[POSITION_COVARIANCE : POSITION_COVARIANCE + 9]),
            gyro_bias_covariance_rad2_s2=tuple(
                numbers[GYRO_BIAS_COVARIANCE : GYRO_BIAS_COVARIANCE + 9]
            ),
        )
        if not (
            attitude.flags.writeable
            or velocity.flags.writeable
            or position.flags.writeable
            or gyro_bias.flags.writeable
        ):
            self._latest = (attitude, velocity, position, gyro_bias, fields)
        return fields


_COVARIANCE_FIELDS = _CovarianceFieldCache()


def nav_values(solution: NavSolution, stamps: StampBook | None = None) -> NavValues:
    """What the ``nav/*`` messages of ``solution`` carry (see the module docstring), stamped
    with the exact IMU stamp from ``stamps`` when given."""
    t_s = solution.t_s
    sec, nanosec = seconds_to_stamp(t_s) if stamps is None else stamps.exact(t_s)
    x, y, z, w = solution.attitude_xyzw.tolist()
    velocity_covariance = solution.velocity_covariance_m2s2
    gyro_bias_covariance = solution.gyro_bias_covariance_rad2_s2
    covariances = _COVARIANCE_FIELDS.fields(
        solution.attitude_covariance_rad2,
        velocity_covariance,
        solution.position_covariance_m2,
        gyro_bias_covariance,
    )
    body = body_numbers(
        solution.attitude_xyzw,
        solution.velocity_enu_mps,
        velocity_covariance,
        gyro_bias_covariance,
    )
    return NavValues(
        t_s=t_s,
        sec=sec,
        nanosec=nanosec,
        position_map_m=tuple(solution.position_map_m.tolist()),
        attitude_xyzw=(x, y, z, w),
        pose_covariance=covariances.pose_covariance,
        velocity_body_mps=tuple(body[VELOCITY_BODY : VELOCITY_BODY + 3]),
        angular_rate_body_rad_s=tuple(solution.angular_rate_body_rad_s.tolist()),
        body_twist_covariance=tuple(body[BODY_TWIST_COVARIANCE : BODY_TWIST_COVARIANCE + 36]),
        attitude_covariance_rad2=covariances.attitude_covariance_rad2,
        gyro_bias_covariance_rad2_s2=covariances.gyro_bias_covariance_rad2_s2,
        specific_force_body_mps2=tuple(solution.specific_force_body_mps2.tolist()),
        velocity_enu_mps=tuple(solution.velocity_enu_mps.tolist()),
        enu_twist_covariance=covariances.enu_twist_covariance,
        latitude_deg=float(solution.latitude_deg),
        longitude_deg=float(solution.longitude_deg),
        altitude_m=float(solution.altitude_m),
        position_covariance_m2=covariances.position_covariance_m2,
    )


class NavMessageClasses(NamedTuple):
    """The message classes :func:`solution_messages` builds (the ROS Python classes)."""

    odometry: type
    imu: type
    twist_with_covariance_stamped: type
    nav_sat_fix: type


def _set_header(message, sec: int, nanosec: int, frame_id: str) -> None:
    message.header.stamp.sec = sec
    message.header.stamp.nanosec = nanosec
    message.header.frame_id = frame_id


def _set_vector(target, values) -> None:
    target.x, target.y, target.z = values


def _set_quaternion(target, values) -> None:
    target.x, target.y, target.z, target.w = values


def solution_messages(
    solution: NavSolution, classes: NavMessageClasses, stamps: StampBook | None = None
) -> dict[str, object]:
    """The four ``nav/*`` messages of one solution, by topic (see the module docstring), built
    from the message classes handed in: for code that embeds the engine in a node of its own.
    The suite's node and tools publish :func:`solution_cdr` instead, which the tests hold
    byte-identical to these messages serialised."""
    values = nav_values(solution, stamps)
    sec, nanosec = values.sec, values.nanosec

    odometry = classes.odometry()
    _set_header(odometry, sec, nanosec, MAP_FRAME)
    odometry.child_frame_id = BODY_FRAME
    _set_vector(odometry.pose.pose.position, values.position_map_m)
    _set_quaternion(odometry.pose.pose.orientation, values.attitude_xyzw)
    odometry.pose.covariance = values.pose_covariance
    _set_vector(odometry.twist.twist.linear, values.velocity_body_mps)
    _set_vector(odometry.twist.twist.angular, values.angular_rate_body_rad_s)
    odometry.twist.covariance = values.body_twist_covariance

    imu = classes.imu()
    _set_header(imu, sec, nanosec, BODY_FRAME)
    _set_quaternion(imu.orientation, values.attitude_xyzw)
    imu.orientation_covariance = values.attitude_covariance_rad2
    _set_vector(imu.angular_velocity, values.angular_rate_body_rad_s)
    imu.angular_velocity_covariance = values.gyro_bias_covariance_rad2_s2
    _set_vector(imu.linear_acceleration, values.specific_force_body_mps2)

    velocity = classes.twist_with_covariance_stamped()
    _set_header(velocity, sec, nanosec, MAP_FRAME)
    _set_vector(velocity.twist.twist.linear, values.velocity_enu_mps)
    velocity.twist.covariance = values.enu_twist_covariance

    fix = classes.nav_sat_fix()
    _set_header(fix, sec, nanosec, BODY_FRAME)
    fix.status.status = STATUS_FIX
    fix.status.service = SERVICE_GPS
    fix.latitude = values.latitude_deg
    fix.longitude = values.longitude_deg
    fix.altitude = values.altitude_m
    fix.position_covariance = values.position_covariance_m2
    fix.position_covariance_type = COVARIANCE_TYPE_KNOWN

    return {
        NAV_ODOMETRY_TOPIC: odometry,
        NAV_IMU_TOPIC: imu,
        NAV_VELOCITY_TOPIC: velocity,
        NAV_FIX_TOPIC: fix,
    }


# -- CDR ------------------------------------------------------------------------------------------
# The node and the offline tools write the nav messages straight from the values: packing four
# fixed layouts is several times faster than building and serialising message objects.

_ODOMETRY_CDR = cdr.OdometryWriter(MAP_FRAME, BODY_FRAME)
_IMU_CDR = cdr.ImuWriter(BODY_FRAME)
_TWIST_CDR = cdr.TwistWithCovarianceStampedWriter(MAP_FRAME)
_FIX_CDR = cdr.NavSatFixWriter(BODY_FRAME)


def odometry_cdr(v: NavValues) -> bytes:
    """The ``nav/odometry`` message of one solution's :func:`nav_values` as CDR bytes (also
    the forward filter's ``nav/forward/odometry`` of a smoothed run)."""
    return _ODOMETRY_CDR.write(
        v.sec,
        v.nanosec,
        v.position_map_m,
        v.attitude_xyzw,
        v.pose_covariance,
        v.velocity_body_mps,
        v.angular_rate_body_rad_s,
        v.body_twist_covariance,
    )


def solution_cdr(v: NavValues) -> dict[str, bytes]:
    """The four ``nav/*`` messages of one solution's :func:`nav_values` as CDR bytes, by topic:
    what ROS serialises for :func:`solution_messages`."""
    sec, nanosec = v.sec, v.nanosec
    return {
        NAV_ODOMETRY_TOPIC: odometry_cdr(v),
        NAV_IMU_TOPIC: _IMU_CDR.write(
            sec,
            nanosec,
            v.attitude_xyzw,
            v.attitude_covariance_rad2,
            v.angular_rate_body_rad_s,
            v.gyro_bias_covariance_rad2_s2,
            v.specific_force_body_mps2,
            _ZEROS9,
        ),
        NAV_VELOCITY_TOPIC: _TWIST_CDR.write(
            sec, nanosec, v.velocity_enu_mps, _ZEROS3, v.enu_twist_covariance
        ),
        NAV_FIX_TOPIC: _FIX_CDR.write(
            sec,
            nanosec,
            STATUS_FIX,
            SERVICE_GPS,
            v.latitude_deg,
            v.longitude_deg,
            v.altitude_m,
            v.position_covariance_m2,
            COVARIANCE_TYPE_KNOWN,
        ),
    }


def transform_message(sec: int, nanosec: int, position_map_m, attitude_xyzw):
    """The ``tf`` message of one solution as a rosbags message object: the transform ``map`` →
    ``base_link`` at stamp (sec, nanosec), translation ``position_map_m`` (m, in ``map``),
    rotation ``attitude_xyzw`` (body→ENU)."""
    pose = FrameTransform(MAP_FRAME, BODY_FRAME, tuple(position_map_m), tuple(attitude_xyzw))
    return tf_message(sec, nanosec, [pose])


# One transform of fixed frame ids has a fixed layout: rosbags serialises it once, and each
# solution's stamp and seven numbers are packed between its fixed bytes (80 µs → 0.5 µs per
# solution).
_TF_TEMPLATE = bytes(
    jazzy_typestore().serialize_cdr(
        transform_message(0, 0, (0.0, 0.0, 0.0), (0.0, 0.0, 0.0, 1.0)), TF_MSGTYPE
    )
)
_TF_STAMP_OFFSET = 8  # after the encapsulation header and the length of the transforms sequence
_TF_POSE_OFFSET = len(_TF_TEMPLATE) - 7 * 8  # the translation and rotation end the message
_TF_HEAD = _TF_TEMPLATE[:_TF_STAMP_OFFSET]
_TF_FRAME_IDS = _TF_TEMPLATE[_TF_STAMP_OFFSET + 8 : _TF_POSE_OFFSET]  # with their padding
_TF_MESSAGE = struct.Struct(f"<{len(_TF_HEAD)}siI{len(_TF_FRAME_IDS)}s7d")


def transform_cdr(v: NavValues) -> bytes:
    """The ``tf`` message of one solution's :func:`nav_values` as CDR bytes: what rosbags
    (and rclpy) serialise for its :func:`transform_message`."""
    return _TF_MESSAGE.pack(
        _TF_HEAD, v.sec, v.nanosec, _TF_FRAME_IDS, *v.position_map_m, *v.attitude_xyzw
    )
