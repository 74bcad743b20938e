"""Contract messages of the wind compensation and the current estimate as values, and values as
contract messages.

The live ``compensation_node`` and ``current_node`` and offline bag processing all convert
through this module, so a message is accepted, rejected or built identically in each. Decoded
messages are read by attribute access only: rclpy message objects and rosbags' decoded objects
both work; the ``*_cdr`` readers take a message's CDR bytes straight (:mod:`buoy_common.cdr`).

Inputs (interface contract):

- ``anemometer/wind`` (geometry_msgs/Vector3Stamped, frame ``anemometer_link``): air velocity
  relative to the sensor in anemometer axes, m/s.
- ``dvl/velocity`` (geometry_msgs/TwistWithCovarianceStamped, frame ``dvl_link``):
  ``twist.twist.linear`` = velocity of the DVL relative to the water (water track) in DVL axes,
  m/s; NaN components for a ping the DVL flags invalid.
- ``nav/odometry`` (nav_msgs/Odometry, frame ``map``, child ``base_link``):
  ``pose.pose.orientation`` = body→ENU attitude R_nb, ``twist.twist.angular`` = bias-corrected
  body rate ω_ib (body axes, rad/s), ``twist.twist.linear`` = velocity of the body origin in body
  axes (m/s).
- ``nav/fix`` (sensor_msgs/NavSatFix): WGS-84 latitude of the body origin, which removes the
  Earth's rotation from the body rate (:mod:`wind_comp.pipeline`).

Outputs:

- ``wind/true`` (geometry_msgs/Vector3Stamped, frame ``map``): corrected ENU wind, m/s, with the
  anemometer sample's own header stamp; NaN components when the sample could not be corrected.
- ``wind/true_with_covariance`` (geometry_msgs/TwistWithCovarianceStamped, frame ``map``): the
  same wind in ``twist.linear`` and its ENU covariance (m²/s²) in rows and columns 0–2 of
  ``covariance``; the angular part unused (zeros, its diagonal −1); NaN where ``wind/true`` is.
- ``wind/mean_<window>`` (geometry_msgs/Vector3Stamped, frame ``map``): vector mean of the ENU
  wind over one averaging window, stamped with the window end.
- ``wind/stats_<window>`` (std_msgs/Float64MultiArray): the statistics of the same window,
  ``data[i]`` named by ``layout.dim[i].label`` (one dimension of size 1 per field), in the order
  of :data:`STATS_FIELDS`.
- ``wind/fluxes_<window>`` (std_msgs/Float64MultiArray): the eddy-covariance fluxes of one
  window, in the order of :data:`FLUX_FIELDS`.
- ``current/velocity`` (geometry_msgs/Vector3Stamped, frame ``map``): the current, ENU, m/s
  (where the water flows TOWARD), with the DVL sample's own header stamp; NaN components when
  it could not be computed.
- ``current/velocity_with_covariance``: the current with its covariance, as the wind's.
- ``current/mean_<window>``, ``current/stats_<window>``: as the wind's, the statistics in the
  order of :data:`CURRENT_STATS_FIELDS`.

Windows are named by :func:`buoy_common.contract.window_label`: ``1min`` for 60 s, ``10min`` for
600 s.
"""

from __future__ import annotations

import dataclasses
import math
from typing import NamedTuple

import numpy as np

from buoy_common import cdr, cdr_bulk
from buoy_common.contract import (
    ANEMOMETER_FRAME,
    BODY_FRAME,
    DVL_FRAME,
    MAP_FRAME,
    TWIST_COVARIANCE_MSGTYPE,
    Reason,
    seconds_to_stamp,
    stamp_to_seconds,
)
from wind_comp.flux_products import FluxProduct
from wind_comp.nav_interpolation import MIN_QUATERNION_NORM, quaternion_norm
from wind_comp.products import CurrentProduct, WindProduct

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
    "coverage",
    "quality_flag",
    "mean_u_standard_error_mps",
    "mean_v_standard_error_mps",
    "mean_w_standard_error_mps",
)
"""Layout of ``wind/stats_<window>``: speeds m/s (horizontal), direction meteorological deg
(blowing FROM, clockwise from true North), standard deviations of the ENU components m/s,
sample counts, window bounds and first/last sample stamps in s since the epoch (a window closed
at shutdown may end before ``window_end_s``), the coverage (share of a full window's samples
held valid), the QARTOD quality flag (1 good, 2 not evaluated, 3 suspect, 4 bad, 9 missing) and
the standard errors (1σ, m/s) of the ENU components of the window's vector mean, from the
samples' covariances (not σ/√N: the navigation's errors stay alike over minutes).
Conventions: :mod:`wind_comp.products`. New fields are only ever appended: a reader takes the
fields by their labels."""

CURRENT_STATS_FIELDS = (
    "speed_mps",
    "direction_deg",
    "std_u_mps",
    "std_v_mps",
    "std_w_mps",
    "n_valid",
    "n_invalid",
    "window_start_s",
    "window_end_s",
    "first_sample_s",
    "last_sample_s",
    "coverage",
    "quality_flag",
    "mean_u_standard_error_mps",
    "mean_v_standard_error_mps",
    "mean_w_standard_error_mps",
)
"""Layout of ``current/stats_<window>``: horizontal speed of the vector mean m/s, its direction
oceanographic deg (flowing TOWARD, clockwise from true North), standard deviations of the ENU
components m/s (over a window of wave periods, mostly the waves' orbital motion), sample counts,
window bounds and first/last sample stamps, coverage, quality flag and the standard errors of
the mean as in :data:`STATS_FIELDS`."""


FLUX_FIELDS = tuple(field.name for field in dataclasses.fields(FluxProduct))
"""Layout of ``wind/fluxes_<window>``, the fields of
:class:`~wind_comp.flux_products.FluxProduct` in order: window bounds and sample stamps s since
the epoch, counts, mean speed m/s, tilt deg, u'w' and v'w' m²/s² (frame of the mean wind),
u* m/s, stress N/m², air density kg/m³, w'Ts' K·m/s, Vickers–Mahrt spike counts, invalid share,
Foken–Wichura non-stationarity %, coverage and QARTOD quality flag (the worst of the named
tests); then the wave motion left in the corrected w (:mod:`wind_comp.wave_motion_left`): the
window's wave band (low, high) Hz, the coherence of w with the platform's vertical velocity
over the band and the coherence above which it counts, the share of that velocity left in w
over the band, and the QARTOD flag of the "motion left" test; then the stress along and across
the mean wind N/m², σw m/s, σT K, z/L, the ITC deviation %, the drag coefficient and its COARE
3.5 reference, |v'w'|/|u'w'|, r_wT, T* K, and the flag of each other test of
:data:`wind_comp.flux_quality.FLUX_FLAG_TESTS`. Fields are only ever appended."""


class MalformedMessageError(ValueError):
    """A message is malformed. ``reason`` is a short label for counting; the text details it."""

    def __init__(self, reason: str, detail: str):
        super().__init__(f"{reason}: {detail}")
        self.reason = reason


class FlowSample(NamedTuple):
    """One anemometer or DVL sample as the compensation takes it."""

    t_s: float
    """Header stamp, s since the epoch."""
    flow_sensor_mps: tuple[float, float, float]
    """The fluid's velocity relative to the sensor, in the sensor's axes, m/s; NaN when the
    message was rejected."""
    rejection: str | None
    """Reason the message was rejected (its output is then invalid), None when accepted."""
    frame_id: str = ""
    """The frame of a message rejected for its frame (which the rejection reports); empty
    otherwise."""
    noise_covariance_m2s2: tuple | None = None
    """The sample's own noise covariance in the sensor's axes, m²/s², 9 row-major values (a
    DVL states it); None: the sensor's configured noise."""


def anemometer_sample(message, expected_frame_id: str = ANEMOMETER_FRAME) -> FlowSample:
    """``anemometer/wind`` as a :class:`FlowSample`: the air's velocity past the sensor.

    A message in another frame than ``expected_frame_id`` (the parameter
    ``compensation.anemometer_frame_id``) or with a non-finite component is rejected: its wind
    becomes NaN so that the compensation still returns one (invalid) output for it, in order.
    Stamp order is checked by the compensation itself.
    """
    vector = message.vector
    return _flow_sample(
        stamp_to_seconds(message.header.stamp),
        message.header.frame_id,
        (float(vector.x), float(vector.y), float(vector.z)),
        expected_frame_id,
    )


def anemometer_sample_cdr(
    raw: bytes, expected_frame_id: str = ANEMOMETER_FRAME
) -> tuple[FlowSample, int, int] | None:
    """:func:`anemometer_sample` of an ``anemometer/wind`` message straight from its CDR bytes,
    with the header stamp (sec, nanosec). None for bytes the CDR reader does not handle: decode
    the message and use :func:`anemometer_sample`."""
    fields = cdr.read_vector3_stamped(raw)
    if fields is None:
        return None
    return anemometer_sample_fields(*fields, expected_frame_id)


def anemometer_sample_fields(
    sec: int,
    nanosec: int,
    frame_id: str,
    vector: tuple[float, float, float],
    expected_frame_id: str = ANEMOMETER_FRAME,
) -> tuple[FlowSample, int, int]:
    """:func:`anemometer_sample` of an ``anemometer/wind`` message read elsewhere (its CDR
    bytes, alone or with the others of its chunk): header stamp ``sec``, ``nanosec``,
    ``frame_id``, and the wind ``vector`` (m/s, x, y, z in the anemometer's frame); with the
    header stamp (sec, nanosec)."""
    return _flow_sample(sec + nanosec * 1e-9, frame_id, vector, expected_frame_id), sec, nanosec


_NAN_VECTOR = (math.nan, math.nan, math.nan)


def _flow_sample(
    t_s: float, frame_id: str, flow_sensor_mps: tuple[float, float, float], expected_frame_id: str
) -> FlowSample:
    """A sensor sample (stamp s, the fluid's velocity past the sensor in its axes m/s), rejected
    with NaN in another frame than ``expected_frame_id`` or when not finite."""
    if frame_id != expected_frame_id:
        return FlowSample(t_s, _NAN_VECTOR, Reason.WRONG_FRAME, frame_id)
    x, y, z = flow_sensor_mps
    if not (math.isfinite(x) and math.isfinite(y) and math.isfinite(z)):
        return FlowSample(t_s, _NAN_VECTOR, Reason.NON_FINITE)
    return FlowSample(t_s, flow_sensor_mps, None)


def dvl_sample(message, expected_frame_id: str = DVL_FRAME) -> FlowSample:
    """``dvl/velocity`` as a :class:`FlowSample`: the water's velocity past the DVL, the
    negative of the DVL's velocity through the water it reports.

    A message in another frame than ``expected_frame_id`` (the parameter
    ``current.dvl_frame_id``) or with a non-finite component (a ping the DVL
    flags invalid) is rejected: its flow becomes NaN so that the estimate still returns one
    (invalid) output for it, in order. Speed and stamp order are checked by the compensation.
    """
    linear = message.twist.twist.linear
    sample = _flow_sample(
        stamp_to_seconds(message.header.stamp),
        message.header.frame_id,
        (-float(linear.x), -float(linear.y), -float(linear.z)),
        expected_frame_id,
    )
    return sample._replace(noise_covariance_m2s2=dvl_noise_covariance(message.twist.covariance))


def dvl_noise_covariance(twist_covariance) -> tuple:
    """A ``dvl/velocity`` message's noise covariance, DVL axes, m²/s², 9 row-major values: the
    linear block of its twist covariance (negating the reading leaves it as it is). A negative
    variance is ROS's "not known": then NaN, and no sample is valid with it."""
    block = tuple(float(twist_covariance[index]) for index in _LINEAR_BLOCK)
    if min(block[0], block[4], block[8]) < 0.0:
        return (math.nan,) * 9
    return block


def anemometer_record(
    raw: bytes, decode, expected_frame_id: str = ANEMOMETER_FRAME
) -> tuple[FlowSample, int, int]:
    """An ``anemometer/wind`` message's CDR bytes as (:func:`anemometer_sample`, header sec,
    header nanosec): read straight from the bytes where the CDR reader handles them, else from
    ``decode(raw)``, the decoded message (rclpy's or a bag reader's)."""
    parsed = anemometer_sample_cdr(raw, expected_frame_id)
    if parsed is None:
        message = decode(raw)
        stamp = message.header.stamp
        parsed = anemometer_sample(message, expected_frame_id), stamp.sec, stamp.nanosec
    return parsed


def dvl_record(
    raw: bytes, decode, expected_frame_id: str = DVL_FRAME
) -> tuple[FlowSample, int, int]:
    """A ``dvl/velocity`` message's CDR bytes as (:func:`dvl_sample`, header sec, header
    nanosec), decoded by ``decode(raw)`` (one ping a second: no CDR reader of its own)."""
    message = decode(raw)
    stamp = message.header.stamp
    return dvl_sample(message, expected_frame_id), stamp.sec, stamp.nanosec


ATTITUDE_VARIANCE_INDICES = (21, 28, 35)
"""Where the roll, pitch and yaw variances sit in the 6x6 row-major pose covariance."""
_ATTITUDE_BLOCK = (21, 22, 23, 27, 28, 29, 33, 34, 35)
"""Where the 3×3 attitude block sits in the 6x6 row-major pose covariance."""
_LINEAR_BLOCK = (0, 1, 2, 6, 7, 8, 12, 13, 14)
"""Where the 3×3 linear block sits in a 6x6 row-major twist covariance."""


def odometry_fields(message) -> tuple:
    """Stamp (s), attitude quaternion (x, y, z, w), body rate ω_ib and body velocity (tuples of
    floats), the largest attitude error variance (rad², from the pose covariance; NaN counts
    as unknown, i.e. infinite), the attitude covariance (9 row-major, rad²) and the twist
    covariance (36 row-major: body velocity m²/s², body rate rad²/s²) of an Odometry, after
    the frame, finiteness and quaternion checks (raises :class:`MalformedMessageError`)."""
    orientation = message.pose.pose.orientation
    angular, linear = message.twist.twist.angular, message.twist.twist.linear
    return _checked_odometry(
        stamp_to_seconds(message.header.stamp),
        message.header.frame_id,
        message.child_frame_id,
        (float(orientation.x), float(orientation.y), float(orientation.z), float(orientation.w)),
        (float(angular.x), float(angular.y), float(angular.z)),
        (float(linear.x), float(linear.y), float(linear.z)),
        tuple(float(value) for value in message.pose.covariance),
        tuple(float(value) for value in message.twist.covariance),
    )


def odometry_fields_cdr(raw: bytes) -> tuple | None:
    """:func:`odometry_fields` of a ``nav/odometry`` message straight from its CDR bytes,
    checked as :func:`odometry_fields` checks them. None for bytes the CDR reader does not
    handle: decode the message instead."""
    fields = cdr.read_odometry(raw)
    if fields is None:
        return None
    sec, nanosec, frame_id, child_frame_id, pose, twist, pose_covariance, twist_covariance = fields
    return _checked_odometry(
        sec + nanosec * 1e-9,
        frame_id,
        child_frame_id,
        pose[3:7],
        twist[3:6],
        twist[0:3],
        pose_covariance,
        twist_covariance,
    )


def odometry_record(raw: bytes, decode) -> tuple:
    """:func:`odometry_fields` of a ``nav/odometry`` message's CDR bytes: read straight from
    the bytes where the CDR reader handles them, else from ``decode(raw)``."""
    fields = odometry_fields_cdr(raw)
    return odometry_fields(decode(raw)) if fields is None else fields


def largest_attitude_variance_rad2(variances) -> float:
    """The largest of the attitude error variances (rad², the pose covariance's diagonal at
    :data:`ATTITUDE_VARIANCE_INDICES`); NaN counts as unknown, i.e. infinite."""
    # max() would pass a NaN over: an unknown variance is an infinite one.
    return max(math.inf if math.isnan(v) else v for v in variances)


def _checked_odometry(
    t_s, frame_id, child_frame_id, quat, rate, velocity_body, pose_covariance, twist_covariance
):
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
    variances = tuple(pose_covariance[index] for index in ATTITUDE_VARIANCE_INDICES)
    return (
        t_s,
        quat,
        rate,
        velocity_body,
        largest_attitude_variance_rad2(variances),
        tuple(pose_covariance[index] for index in _ATTITUDE_BLOCK),
        twist_covariance,
    )


def fix_fields(message) -> tuple[int, float]:
    """Status and latitude (deg) of a ``nav/fix`` NavSatFix."""
    return int(message.status.status), float(message.latitude)


def fix_fields_cdr(raw: bytes) -> tuple[int, float] | None:
    """:func:`fix_fields` of a ``nav/fix`` message straight from its CDR bytes; None for bytes
    the CDR reader does not handle."""
    fields = cdr.read_nav_sat_fix(raw)
    if fields is None:
        return None
    return fields[3], fields[5]


def fix_record(raw: bytes, decode) -> tuple[int, float]:
    """:func:`fix_fields` of a ``nav/fix`` message's CDR bytes: read straight from the bytes
    where the CDR reader handles them, else from ``decode(raw)``."""
    fields = fix_fields_cdr(raw)
    return fix_fields(decode(raw)) if fields is None else fields


_MAP_VECTOR_CDR = cdr.Vector3StampedWriter(MAP_FRAME)


def flow_cdr(sec: int, nanosec: int, flow_enu_mps) -> bytes:
    """``wind/true`` or ``current/velocity`` as CDR bytes: the ENU vector (m/s, NaN when
    invalid) in frame ``map``, stamped (sec, nanosec) with the sensor sample's own stamp."""
    x, y, z = flow_enu_mps
    return _MAP_VECTOR_CDR.write(int(sec), int(nanosec), float(x), float(y), float(z))


def flows_cdr(sec, nanosec, flows_enu_mps) -> list[bytes]:
    """:func:`flow_cdr` of (N,) stamps and (N, 3) vectors at once."""
    return _MAP_VECTOR_CDR.write_many(sec, nanosec, flows_enu_mps)


_MAP_TWIST_CDR = cdr.TwistWithCovarianceStampedWriter(MAP_FRAME)
_NO_ANGULAR = (0.0, 0.0, 0.0)
_UNUSED_ANGULAR_COVARIANCE = np.diag([-1.0, -1.0, -1.0])
BULK_ENCODING_FROM_SAMPLES = 16
"""Samples from which :func:`flows_with_covariance_cdr` encodes them all in one numpy call
(about 60 µs however many) rather than one by one (4 µs each): the live node's few samples a
message go one by one, an offline batch of hundreds at once."""


def flows_with_covariance_cdr(sec, nanosec, flows_enu_mps, covariances_enu_m2s2) -> list[bytes]:
    """``wind/true_with_covariance`` or ``current/velocity_with_covariance`` as CDR bytes, one
    per sample of (N,) stamps (sec, nanosec), (N, 3) ENU vectors (m/s) and (N, 3, 3) ENU
    covariances (m²/s²), NaN where invalid: the covariance in rows and columns 0–2, the
    angular part unused (zeros, its diagonal −1)."""
    if len(flows_enu_mps) < BULK_ENCODING_FROM_SAMPLES:
        return _flows_with_covariance_one_by_one(sec, nanosec, flows_enu_mps, covariances_enu_m2s2)
    flows = np.asarray(flows_enu_mps, dtype=float).reshape(-1, 3)
    covariances_6x6 = np.zeros((len(flows), 6, 6))
    covariances_6x6[:, :3, :3] = covariances_enu_m2s2
    covariances_6x6[:, 3:, 3:] = _UNUSED_ANGULAR_COVARIANCE
    return cdr_bulk.encode(
        TWIST_COVARIANCE_MSGTYPE,
        {
            "sec": np.asarray(sec, dtype=np.int64),
            "nanosec": np.asarray(nanosec, dtype=np.int64),
            "frame_id": MAP_FRAME,
            "linear": flows,
            "angular": np.zeros_like(flows),
            "covariance": covariances_6x6.reshape(-1, 36),
        },
    )


def _flows_with_covariance_one_by_one(
    sec, nanosec, flows_enu_mps, covariances_enu_m2s2
) -> list[bytes]:
    """:func:`flows_with_covariance_cdr` a sample at a time: the same bytes."""
    messages = []
    for s, n, flow, covariance in zip(
        np.asarray(sec).tolist(),
        np.asarray(nanosec).tolist(),
        np.asarray(flows_enu_mps).tolist(),
        np.asarray(covariances_enu_m2s2).tolist(),
        strict=True,
    ):
        (c00, c01, c02), (c10, c11, c12), (c20, c21, c22) = covariance
        covariance_6x6 = (
            c00, c01, c02, 0.0, 0.0, 0.0,
            c10, c11, c12, 0.0, 0.0, 0.0,
            c20, c21, c22, 0.0, 0.0, 0.0,
            0.0, 0.0, 0.0, -1.0, 0.0, 0.0,
            0.0, 0.0, 0.0, 0.0, -1.0, 0.0,
            0.0, 0.0, 0.0, 0.0, 0.0, -1.0,
        )  # fmt: skip
        messages.append(_MAP_TWIST_CDR.write(int(s), int(n), flow, _NO_ANGULAR, covariance_6x6))
    return messages


def _set_header(header, sec: int, nanosec: int, frame_id: str) -> None:
    header.stamp.sec = int(sec)
    header.stamp.nanosec = int(nanosec)
    header.frame_id = frame_id


def _set_vector(target, values) -> None:
    target.x, target.y, target.z = (float(value) for value in values)


def product_messages(
    vector_stamped_class,
    multi_array_class,
    dimension_class,
    product: WindProduct | CurrentProduct,
) -> tuple[object, object]:
    """(``<wind|current>/mean_<window>``, ``<wind|current>/stats_<window>``) messages of one
    averaging window.

    The mean is the ENU vector mean (m/s, frame ``map``), stamped with the window end; the
    statistics follow :data:`STATS_FIELDS` (wind) or :data:`CURRENT_STATS_FIELDS` (current).
    """
    fields = CURRENT_STATS_FIELDS if isinstance(product, CurrentProduct) else STATS_FIELDS
    sec, nanosec = seconds_to_stamp(product.window_end_s)
    mean = vector_stamped_class()
    _set_header(mean.header, sec, nanosec, MAP_FRAME)
    _set_vector(
        mean.vector, (product.mean_u_enu_mps, product.mean_v_enu_mps, product.mean_w_enu_mps)
    )
    stats = multi_array_class()
    stats.layout.dim = [dimension_class(label=name, size=1, stride=1) for name in fields]
    stats.layout.data_offset = 0
    stats.data = [float(getattr(product, name)) for name in fields]
    return mean, stats


def flux_message(multi_array_class, dimension_class, product: FluxProduct):
    """``wind/fluxes_<window>`` of one flux window, labelled in the order of
    :data:`FLUX_FIELDS`."""
    message = multi_array_class()
    message.layout.dim = [dimension_class(label=name, size=1, stride=1) for name in FLUX_FIELDS]
    message.layout.data_offset = 0
    message.data = [float(getattr(product, name)) for name in FLUX_FIELDS]
    return message


def temperature_sample(
    message, expected_frame_id: str = ANEMOMETER_FRAME
) -> tuple[float, float] | str:
    """``anemometer/temperature`` (sensor_msgs/Temperature, °C) as (stamp s, °C), or the
    reason it is rejected (another frame than ``expected_frame_id``, a non-finite value)."""
    header = message.header
    return temperature_sample_fields(
        header.stamp.sec,
        header.stamp.nanosec,
        header.frame_id,
        message.temperature,
        expected_frame_id,
    )


def temperature_sample_fields(
    sec: int,
    nanosec: int,
    frame_id: str,
    temperature_degc: float,
    expected_frame_id: str = ANEMOMETER_FRAME,
) -> tuple[float, float] | str:
    """:func:`temperature_sample` of an ``anemometer/temperature`` message read elsewhere
    (with the others of its chunk): header stamp ``sec``, ``nanosec``, ``frame_id`` and the
    temperature, °C."""
    if frame_id != expected_frame_id:
        return Reason.WRONG_FRAME
    value = float(temperature_degc)
    if not math.isfinite(value):
        return Reason.NON_FINITE
    return sec + nanosec * 1e-9, value


def stats_values(stats_message) -> dict[str, float]:
    """A ``wind/stats_<window>`` or ``current/stats_<window>`` message as {field label: value}."""
    labels = [dimension.label for dimension in stats_message.layout.dim]
    return dict(zip(labels, (float(value) for value in stats_message.data), strict=True))
