"""The interface contract as code: topic names, message types, frames, rejection reasons, stamps.

Every node, offline tool, simulator and test takes these names from here, so a topic, a frame or
the name of a rejection reason is spelled once. Topic names are relative (no leading slash), so a
whole buoy can be put in a namespace with ``-r __ns:=/buoy1``.
"""

from __future__ import annotations

import datetime
from enum import IntEnum, StrEnum

# -- sensor topics (published by the simulator, a driver or a bag replay) -----------------------
IMU_RAW_TOPIC = "imu/data_raw"
AHRS_TOPIC = "imu/data"
MAGNETOMETER_TOPIC = "imu/mag"
GNSS_FIX_TOPIC = "gnss/fix"
GNSS_VELOCITY_TOPIC = "gnss/vel"
GNSS_HEADING_TOPIC = "gnss/heading"
GNSS_BASELINE_TOPIC = "gnss/baseline"
GNSS_BASELINE_TERTIARY_TOPIC = "gnss/baseline_tertiary"
WIND_RAW_TOPIC = "anemometer/wind"
SONIC_TEMPERATURE_TOPIC = "anemometer/temperature"
DVL_TOPIC = "dvl/velocity"

# -- truth topics (simulation only) --------------------------------------------------------------
TRUTH_ODOMETRY_TOPIC = "truth/odometry"
TRUTH_WIND_TOPIC = "truth/wind"
TRUTH_CURRENT_TOPIC = "truth/current"
TRUTH_WATER_VELOCITY_TOPIC = "truth/water_velocity"
TRUTH_PREFIX = "truth/"

# -- output topics -------------------------------------------------------------------------------
NAV_ODOMETRY_TOPIC = "nav/odometry"
NAV_FORWARD_ODOMETRY_TOPIC = "nav/forward/odometry"
NAV_IMU_TOPIC = "nav/imu"
NAV_VELOCITY_TOPIC = "nav/velocity"
NAV_FIX_TOPIC = "nav/fix"
WIND_TRUE_TOPIC = "wind/true"
WIND_TRUE_WITH_COVARIANCE_TOPIC = "wind/true_with_covariance"
"""The corrected wind of ``wind/true`` with its covariance (TwistWithCovarianceStamped, ``map``):
rows and columns 0–2 of ``twist.covariance`` in m²/s², the angular part unused (zeros, its
diagonal −1)."""
CURRENT_WITH_COVARIANCE_TOPIC = "current/velocity_with_covariance"
"""The current of ``current/velocity`` with its covariance, as ``wind/true_with_covariance``."""
WIND_MEAN_PREFIX = "wind/mean_"
WIND_STATS_PREFIX = "wind/stats_"
WIND_FLUXES_PREFIX = "wind/fluxes_"
CURRENT_TOPIC = "current/velocity"
CURRENT_MEAN_PREFIX = "current/mean_"
CURRENT_STATS_PREFIX = "current/stats_"
DIAGNOSTICS_TOPIC = "diagnostics"
CLOCK_TOPIC = "/clock"
"""The simulation clock: the one absolute topic, since ROS's ``use_sim_time`` reads ``/clock``
whatever a node's namespace (a whole fleet shares one simulated time)."""
TF_TOPIC = "tf"
"""``map`` → ``base_link`` of each navigation solution. Relative, like every topic here, so each
buoy of a fleet has its own tree under its namespace (tf2 listeners take ``-r /tf:=tf``)."""
TF_STATIC_TOPIC = "tf_static"
"""``base_link`` → each sensor frame, from the shared extrinsics, published once (transient
local). Relative, as :data:`TF_TOPIC` (tf2 listeners take ``-r /tf_static:=tf_static``)."""

# -- message types -------------------------------------------------------------------------------
IMU_MSGTYPE = "sensor_msgs/msg/Imu"
NAV_SAT_FIX_MSGTYPE = "sensor_msgs/msg/NavSatFix"
MAGNETIC_FIELD_MSGTYPE = "sensor_msgs/msg/MagneticField"
TEMPERATURE_MSGTYPE = "sensor_msgs/msg/Temperature"
TWIST_COVARIANCE_MSGTYPE = "geometry_msgs/msg/TwistWithCovarianceStamped"
VECTOR3_MSGTYPE = "geometry_msgs/msg/Vector3Stamped"
ODOMETRY_MSGTYPE = "nav_msgs/msg/Odometry"
FLOAT64_ARRAY_MSGTYPE = "std_msgs/msg/Float64MultiArray"
DIAGNOSTICS_MSGTYPE = "diagnostic_msgs/msg/DiagnosticArray"
CLOCK_MSGTYPE = "rosgraph_msgs/msg/Clock"
TF_MSGTYPE = "tf2_msgs/msg/TFMessage"
TF_STATIC_MSGTYPE = TF_MSGTYPE

SENSOR_MSGTYPES = {
    IMU_RAW_TOPIC: IMU_MSGTYPE,
    AHRS_TOPIC: IMU_MSGTYPE,
    MAGNETOMETER_TOPIC: MAGNETIC_FIELD_MSGTYPE,
    GNSS_FIX_TOPIC: NAV_SAT_FIX_MSGTYPE,
    GNSS_VELOCITY_TOPIC: TWIST_COVARIANCE_MSGTYPE,
    GNSS_HEADING_TOPIC: IMU_MSGTYPE,
    GNSS_BASELINE_TOPIC: VECTOR3_MSGTYPE,
    GNSS_BASELINE_TERTIARY_TOPIC: VECTOR3_MSGTYPE,
    WIND_RAW_TOPIC: VECTOR3_MSGTYPE,
    SONIC_TEMPERATURE_TOPIC: TEMPERATURE_MSGTYPE,
    DVL_TOPIC: TWIST_COVARIANCE_MSGTYPE,
}
"""Every sensor topic of the contract and its message type."""

TRUTH_MSGTYPES = {
    TRUTH_ODOMETRY_TOPIC: ODOMETRY_MSGTYPE,
    TRUTH_WIND_TOPIC: VECTOR3_MSGTYPE,
    TRUTH_CURRENT_TOPIC: VECTOR3_MSGTYPE,
    TRUTH_WATER_VELOCITY_TOPIC: VECTOR3_MSGTYPE,
}

NAV_MSGTYPES = {
    NAV_ODOMETRY_TOPIC: ODOMETRY_MSGTYPE,
    NAV_IMU_TOPIC: IMU_MSGTYPE,
    NAV_VELOCITY_TOPIC: TWIST_COVARIANCE_MSGTYPE,
    NAV_FIX_TOPIC: NAV_SAT_FIX_MSGTYPE,
}
"""The navigation outputs and their message types."""

OUTPUT_MSGTYPES = {
    **NAV_MSGTYPES,
    NAV_FORWARD_ODOMETRY_TOPIC: ODOMETRY_MSGTYPE,
    WIND_TRUE_TOPIC: VECTOR3_MSGTYPE,
    WIND_TRUE_WITH_COVARIANCE_TOPIC: TWIST_COVARIANCE_MSGTYPE,
    CURRENT_TOPIC: VECTOR3_MSGTYPE,
    CURRENT_WITH_COVARIANCE_TOPIC: TWIST_COVARIANCE_MSGTYPE,
    DIAGNOSTICS_TOPIC: DIAGNOSTICS_MSGTYPE,
    TF_TOPIC: TF_MSGTYPE,
    TF_STATIC_TOPIC: TF_STATIC_MSGTYPE,
}
"""Every fixed-name output topic (the wind and current products are named per window, see
:func:`wind_mean_topic`, :func:`wind_stats_topic`, :func:`wind_fluxes_topic`,
:func:`current_mean_topic` and :func:`current_stats_topic`)."""

# -- frames ----------------------------------------------------------------------------------------
MAP_FRAME = "map"
"""Local East-North-Up tangent plane at the map origin."""
BODY_FRAME = "base_link"
"""Forward-left-up body frame, origin at the IMU (REP-103)."""
IMU_FRAME = "imu_link"
"""Coincides with ``base_link``: the IMU defines the body frame."""
GNSS_PRIMARY_FRAME = "gnss_primary"
GNSS_SECONDARY_FRAME = "gnss_secondary"
GNSS_TERTIARY_FRAME = "gnss_tertiary"
"""The third antenna's frame: only where ``gnss.tertiary_antenna`` is configured."""
ANEMOMETER_FRAME = "anemometer_link"
DVL_FRAME = "dvl_link"


DEFAULT_PRODUCT_WINDOWS_S = (60.0, 600.0)
"""Averaging windows of the wind products unless configured otherwise, s (WMO practice)."""


def window_label(window_s: float) -> str:
    """Name of an averaging window in topic names: ``1min`` for 60 s, ``10min`` for 600 s,
    ``30s`` for 30 s, ``2p5s`` for 2.5 s."""
    if window_s % 60.0 == 0.0:
        return f"{int(window_s // 60)}min"
    return f"{window_s:g}s".replace(".", "p")


def wind_mean_topic(window_s: float) -> str:
    """Topic of the vector-mean wind of windows of ``window_s`` seconds."""
    return WIND_MEAN_PREFIX + window_label(window_s)


def wind_stats_topic(window_s: float) -> str:
    """Topic of the wind statistics of windows of ``window_s`` seconds: a Float64MultiArray
    whose ``layout.dim[i].label`` names ``data[i]`` (``wind_comp.compensation_messages.
    STATS_FIELDS``). Fields are only appended: ``coverage`` and ``quality_flag``
    (:class:`QualityFlag`) came after ``last_sample_s``."""
    return WIND_STATS_PREFIX + window_label(window_s)


def wind_fluxes_topic(window_s: float) -> str:
    """Topic of the eddy-covariance fluxes of windows of ``window_s`` seconds
    (``wind/fluxes_30min``): a Float64MultiArray labelled like the statistics
    (``wind_comp.compensation_messages.FLUX_FIELDS``)."""
    return WIND_FLUXES_PREFIX + window_label(window_s)


def current_mean_topic(window_s: float) -> str:
    """Topic of the vector-mean current of windows of ``window_s`` seconds."""
    return CURRENT_MEAN_PREFIX + window_label(window_s)


def current_stats_topic(window_s: float) -> str:
    """Topic of the current statistics of windows of ``window_s`` seconds, laid out as the
    wind's (``wind_comp.compensation_messages.CURRENT_STATS_FIELDS``)."""
    return CURRENT_STATS_PREFIX + window_label(window_s)


def bag_topic(topic: str) -> str:
    """A relative topic as a bag stores it: fully qualified, like ``ros2 bag record``."""
    return topic if topic.startswith("/") else "/" + topic


class QualityFlag(IntEnum):
    """IOOS QARTOD flags (Manual for Real-Time Quality Control of In-situ Data, 2017): the
    ``quality_flag`` of every averaged window on the statistics topics, in the products CSVs
    and in the NetCDF files."""

    GOOD = 1
    NOT_EVALUATED = 2
    SUSPECT = 3
    BAD = 4
    MISSING = 9


# -- rejection reasons ---------------------------------------------------------------------------
class Reason(StrEnum):
    """Why an input was rejected or an output could not be computed.

    The same words appear in ``diagnostics`` (``rejected[input:reason]``), in the offline
    summaries and in the counters of the cores.
    """

    MALFORMED = "malformed"
    """The message cannot be read as its type (wrong shape, undecodable bytes)."""
    NON_FINITE = "non_finite"
    OUT_OF_RANGE = "out_of_range"
    """A value no instrument of this kind can report (absurd magnitude)."""
    IMPLAUSIBLE_CHANGE = "implausible_change"
    """A change from the previous sample that the platform cannot make in the time between them
    (an angular acceleration or jerk beyond the platform's limits)."""
    NON_POSITIVE_VARIANCE = "non_positive_variance"
    ZERO_QUATERNION = "zero_quaternion"
    NON_UNIT_QUATERNION = "non_unit_quaternion"
    """An orientation quaternion whose norm is not 1 (a driver's error, not a rotation)."""
    WRONG_FRAME = "wrong_frame"
    NO_FIX = "no_fix"
    """``gnss/fix`` with ``status.status < 0``."""
    STAMP_NOT_INCREASING = "stamp_not_increasing"
    OUT_OF_SEQUENCE = "out_of_sequence"
    """A sample ahead of the previous one by more than its stream's rate allows: an IMU sample
    or aiding measurement while the sensor's own samples went on, a second stream on the topic
    (another buoy's); a flow sensor's sample, whose output cannot wait to tell, also the first
    samples after an outage (:mod:`buoy_nav.stream_sequence`)."""
    DUPLICATE_STAMP = "duplicate_stamp"
    TOO_LATE = "too_late"
    """Arrived after the filter had processed past its stamp."""
    BEYOND_IMU_DATA = "beyond_imu_data"
    """Stamped further ahead of the IMU data than the filter waits for."""
    GATE = "gate"
    """Failed the chi-square innovation gate."""
    GEOMETRY = "geometry"
    """The measurement's geometry carries no information (a vertical antenna baseline)."""
    SINGULAR = "singular_innovation_covariance"
    DISABLED = "disabled"
    """The input is switched off by a parameter."""
    LATITUDE_OUT_OF_RANGE = "latitude_out_of_range"
    # Outcomes of the correction of one anemometer or DVL sample.
    NO_NAVIGATION = "no_navigation"
    NAV_GAP = "nav_gap"
    NAVIGATION_TIMEOUT = "navigation_timeout"
    NAV_HISTORY_EXCEEDED = "nav_history_exceeded"
    INVALID_WIND = "invalid_wind"
    WIND_SPEED_OUT_OF_RANGE = "wind_speed_out_of_range"
    INVALID_STAMP = "invalid_stamp"
    INVALID_DVL = "invalid_dvl"
    DVL_SPEED_OUT_OF_RANGE = "dvl_speed_out_of_range"
    NAVIGATION_NOT_TRUSTED = "navigation_not_trusted"
    """The navigation's attitude is too uncertain to correct the wind with: the fusion has
    found itself inconsistent with its aiding, or has not converged yet."""
    UNCERTAINTY_TOO_LARGE = "uncertainty_too_large"
    """The corrected sample's own standard deviation (from the navigation's covariance and the
    sensor's noise) exceeds its documented limit: horizontally or vertically."""
    SUSPENDED = "suspended"
    """The aiding source keeps failing its gate over a window and is taken out until it agrees
    with the filter again."""
    MAGNETIC_FIELD_INCONSISTENT = "magnetic_field_inconsistent"
    """The calibrated magnetic field differs from the Earth's (the World Magnetic Model at the
    position) in strength or dip by more than the fusion tolerates: an uncalibrated or disturbed
    magnetometer, whose heading would be wrong."""


# -- stamps ----------------------------------------------------------------------------------------
NANOSECONDS_PER_SECOND = 1_000_000_000


def stamp_to_seconds(stamp) -> float:
    """A ``builtin_interfaces/Time`` (``sec``, ``nanosec``) as float seconds since the epoch."""
    return stamp.sec + stamp.nanosec * 1e-9


def header_seconds(header) -> float:
    """A message header's stamp as float seconds since the epoch."""
    stamp = header.stamp
    return stamp.sec + stamp.nanosec * 1e-9


def stamp_to_ns(stamp) -> int:
    """A ``builtin_interfaces/Time`` as integer nanoseconds since the epoch."""
    return stamp.sec * NANOSECONDS_PER_SECOND + stamp.nanosec


def seconds_to_stamp(t_s: float) -> tuple[int, int]:
    """(sec, nanosec) of a time in float seconds, rounded to the nanosecond."""
    return divmod(round(t_s * NANOSECONDS_PER_SECOND), NANOSECONDS_PER_SECOND)


def ns_to_stamp(t_ns: int) -> tuple[int, int]:
    """(sec, nanosec) of a time in integer nanoseconds."""
    return divmod(t_ns, NANOSECONDS_PER_SECOND)


def seconds_to_iso8601(t_s: float) -> str:
    """ISO 8601 UTC time of ``t_s`` (s since the epoch), millisecond resolution (truncated):
    ``2026-01-01T00:00:00.050Z``. The time of the CSV products and of human-facing lines."""
    moment = datetime.datetime.fromtimestamp(t_s, tz=datetime.UTC)
    return moment.strftime("%Y-%m-%dT%H:%M:%S.") + f"{moment.microsecond // 1000:03d}Z"
