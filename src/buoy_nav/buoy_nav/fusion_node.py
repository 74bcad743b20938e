"""fusion_node: the strapdown INS fused with its aiding sensors (GNSS, magnetometer, motion
pack, mooring), live.

    fusion_node [--ros-args --params-file buoy.yaml --params-file fusion.yaml ...]

Subscribes (reliable, deep queue):

- ``imu/data_raw`` (sensor_msgs/Imu): raw body rate (rad/s) and specific force (m/s²)
- ``gnss/fix`` (sensor_msgs/NavSatFix): primary antenna WGS-84 position, ENU covariance (m²)
- ``gnss/vel`` (geometry_msgs/TwistWithCovarianceStamped): primary antenna ENU velocity (m/s)
- ``gnss/heading`` (sensor_msgs/Imu): azimuth of the primary→secondary baseline (yaw, rad)
- ``gnss/baseline`` (geometry_msgs/Vector3Stamped): the primary→secondary antenna vector (ENU,
  m), unless ``fusion.use_gnss_baseline`` is false; it replaces the heading of the same stamp

Publishes, once aligned, one set per navigation solution, all with the solution's stamp:

- ``nav/odometry`` (nav_msgs/Odometry, ``map`` → ``base_link``)
- ``nav/imu`` (sensor_msgs/Imu, ``base_link``)
- ``nav/velocity`` (geometry_msgs/TwistWithCovarianceStamped, ``map``)
- ``nav/fix`` (sensor_msgs/NavSatFix, ``base_link``)
- ``tf`` (tf2_msgs/TFMessage, ``map`` → ``base_link``) where tf2_msgs is installed (a full ROS
  install; the PyPI wheels lack it, and the node then says so at start-up and goes without);
  the bytes ``fuse_bag`` writes to its bags
- ``tf_static`` (tf2_msgs/TFMessage, transient local), once at start where tf2_msgs is
  installed: ``base_link`` → ``imu_link`` and the antennas' frames from the shared parameters
  (:mod:`buoy_common.sensor_frames`)
- ``diagnostics`` (1 s): alignment state, coasting flags, the sensor set in use
  (``sensor_set``, :mod:`buoy_nav.sensor_sets`) and the sources that coast (``coasting_sources``:
  accepted before, not now), per input kind the accepted, aligning,
  superseded and rejected (by reason) counts, resets and mean NIS, covariance repairs, IMU gaps;
  the integrity of the filter (``navigation_trusted``, ``integrity_events``, ``realignments``,
  ``untrusted_s``) and IMU clock steps undone (``imu_clock_steps``, ``imu_clock_correction_s``);
  once aligned the filter's 1σ of attitude (``attitude_sigma_deg[east|north|up]``) and velocity
  (``velocity_sigma_mps[...]``) and its bias estimates (``gyro_bias_deg_s[x|y|z]``,
  ``accel_bias_mg[x|y|z]``); input rates per topic, solutions published, and in wall-clock time
  the IMU callback up to its solution's publishing (``latency_*``) and the filtering after it
  (``filtering_*``), mean and max over the period, and how often that filtering was still undone
  when the next IMU sample came (``filtering_overdue``, a sign of an overloaded machine). Level
  warn while not aligned, while the navigation is not trusted, while a GNSS kind is coasting or
  when no IMU sample came in the period.

Messages are converted and fed to :class:`buoy_nav.engine.FusionEngine` by
:mod:`buoy_nav.fusion_messages`, the code the offline ``fuse_bag`` uses, so a bag replayed to
this node gives the solutions ``fuse_bag`` writes. Only header stamps drive the fusion; the wall
clock serves the diagnostics alone. With ``fusion.realtime_output`` (default) each IMU sample's
solution is published by the callback that receives it, before the filter updates and covariance
propagation that sample makes due; otherwise solutions leave
``fusion.max_measurement_delay_s`` of stamps late. That filtering, and the feeding of the GNSS
messages received meanwhile, runs ``FILTERING_DELAY_S`` (at most half an IMU interval) after
the publishing, so that the nodes taking the solution (``compensation_node`` above all, whose
wind samples share the GNSS epochs) get the cores first; a GNSS message is converted only then
(or at the next diagnostics report when no IMU sample comes), since the engine needs it only
``max_measurement_delay_s`` later. An IMU sample after a gap in the IMU stamps is the exception:
the GNSS messages received before it go to the engine first, which tells an IMU outage from a
step of the IMU's clock by the aiding stamps it has seen, as ``fuse_bag`` does in log-time
order. The solutions do not depend on this timing: they depend on the stamps alone.

Parameters: ``gnss.primary_antenna``, ``gnss.secondary_antenna`` (double[3], m, in
``base_link``) and ``origin.latitude_deg``, ``origin.longitude_deg``, ``origin.altitude_m``
(deg, deg, m; NaN or absent = the position at alignment) of the shared buoy file; every other
:class:`buoy_nav.config.FusionConfig` field as ``fusion.<field>`` (see ``config/fusion.yaml``).
A bad value stops the node at start-up with exit code 2 and a message naming the parameter.
At start-up the node logs the sensors it fuses, the antennas, the map origin and its output;
once aligned, the stamp, attitude and position of its first solution.

Rejected input (malformed, non-finite, out of range, stamps not increasing, no fix, ...) is
counted by topic and reason and warned about (rate-limited); it never reaches the state. On
SIGINT or SIGTERM the engine is flushed, its last solutions published, and the node exits 0.
"""

from __future__ import annotations

import collections
import math
import time

from geometry_msgs.msg import TwistWithCovarianceStamped
from nav_msgs.msg import Odometry
from rclpy.qos import QoSProfile
from rclpy.serialization import deserialize_message
from sensor_msgs.msg import Imu, NavSatFix

try:  # tf2_msgs comes with a full ROS install, not with the PyPI wheels
    from tf2_msgs.msg import TFMessage
except ImportError:
    TFMessage = None

from buoy_common.base_node import (
    DATA_QOS,
    REJECTION_LOG_PERIOD_S,
    DiagnosticsPublisher,
    FlushingNode,
    main_for,
    message_class,
)
from buoy_common.cdr import read_stamp
from buoy_common.contract import (
    IMU_RAW_TOPIC,
    NAV_FIX_TOPIC,
    NAV_IMU_TOPIC,
    NAV_ODOMETRY_TOPIC,
    NAV_VELOCITY_TOPIC,
    TF_TOPIC,
    Reason,
)
from buoy_common.sensor_frames import sensor_transforms, shared_values
from buoy_nav.aiding import disabled_topics
from buoy_nav.config import (
    FUSION_FIELDS_NOT_PARAMETERS,
    FUSION_NODE_NAME,
    FUSION_PARAMETER_PREFIX,
    FusionConfig,
)
from buoy_nav.engine import FusionEngine, NavSolution
from buoy_nav.error_state_filter import STANDARD_GRAVITY_MPS2
from buoy_nav.fusion_messages import (
    FUSION_INPUT_MSGTYPES,
    StampBook,
    feed_imu_cdr,
    feed_message,
    nav_values,
    solution_cdr,
    transform_cdr,
)
from buoy_nav.health import diagnostic_values, health_status
from buoy_nav.observability import unobserved_quantities
from buoy_nav.rotations import euler_from_rotation_matrix, rotation_matrix_from_quaternion

OUTPUT_CLASSES = {
    NAV_ODOMETRY_TOPIC: Odometry,
    NAV_IMU_TOPIC: Imu,
    NAV_VELOCITY_TOPIC: TwistWithCovarianceStamped,
    NAV_FIX_TOPIC: NavSatFix,
}
INPUT_CLASSES = {topic: message_class(msgtype) for topic, msgtype in FUSION_INPUT_MSGTYPES.items()}
DIAGNOSTICS_PERIOD_S = 1.0
# How long after publishing a solution the node feeds the GNSS messages and lets the filter
# catch up (s): long enough for the nodes and recorders that take the solution to run first;
# at most half the interval between IMU samples, so that it is done before the next one, whose
# prediction needs it.
FILTERING_DELAY_S = 0.003
# tf2_ros's broadcaster profile: reliable, volatile, 100 deep.
TF_QOS = QoSProfile(depth=100)


SECOND_STREAM_SAMPLES = 10
"""Samples off an input's sequence, given up when it went on, that say a second stream is
there."""


class FusionNode(FlushingNode):
    def __init__(self):
        super().__init__(FUSION_NODE_NAME)
        self.config = self._declare_fusion_config()
        self.engine = FusionEngine(self.config)
        self.stamps = StampBook(self.engine.imu_clock_steps)
        self._messages_in = collections.Counter()
        self._messages_in_at_last_report = collections.Counter()
        self._last_report_s = time.monotonic()
        self._imu_callback_durations_s: list[float] = []
        self._filtering_durations_s: list[float] = []
        self._previous_imu_callback_s = -math.inf
        self._previous_imu_stamp_s = math.nan
        self._second_stream_samples: collections.Counter[str] = collections.Counter()
        self.filtering_overdue = 0
        self._gnss_waiting: list[tuple[str, bytes]] = []
        self.solutions_published = 0
        disabled = disabled_topics(self.config)
        self.input_topics = [topic for topic in INPUT_CLASSES if topic not in disabled]

        self._nav_publishers = {
            topic: self.create_publisher(output_class, topic, DATA_QOS)
            for topic, output_class in OUTPUT_CLASSES.items()
        }
        # Raw: the IMU sample is read straight from its CDR bytes, as offline, and saves the
        # building of a message object at 100 Hz; GNSS messages are decoded when their turn
        # comes (see the module docstring).
        self.create_subscription(Imu, IMU_RAW_TOPIC, self.on_imu, DATA_QOS, raw=True)
        for topic in self.input_topics[1:]:
            self.create_subscription(
                INPUT_CLASSES[topic],
                topic,
                lambda raw, topic=topic: self._gnss_waiting.append((topic, raw)),
                DATA_QOS,
                raw=True,
            )
        self._tf_publisher = (
            None if TFMessage is None else self.create_publisher(TFMessage, TF_TOPIC, TF_QOS)
        )
        self.broadcast_static_transforms(
            TFMessage, sensor_transforms(shared_values(self.config), imu_link=True)
        )
        self._diagnostics = DiagnosticsPublisher(self, self.report, DIAGNOSTICS_PERIOD_S)
        config = self.config
        origin = (
            f"({config.origin_latitude_deg} deg, {config.origin_longitude_deg} deg, "
            f"{config.origin_altitude_m} m)"
            if config.has_origin
            else "the position at alignment"
        )
        rate = f"{config.output_rate_hz} Hz" if config.output_rate_hz > 0 else "every IMU sample"
        self.get_logger().info(
            f"fusing {', '.join(self.input_topics)}: antennas "
            f"{list(config.primary_antenna_body_m)} m (primary) and "
            f"{list(config.secondary_antenna_body_m)} m (secondary) in base_link; map origin "
            f"{origin}; output {rate}, "
            f"{'real time' if config.realtime_output else 'delayed'}"
        )
        self.get_logger().info(
            f"broadcasting map -> base_link on {TF_TOPIC}"
            if self._tf_publisher is not None
            else f"tf2_msgs is not installed: map -> base_link is not broadcast on {TF_TOPIC}"
        )
        for source in self.engine.sources:
            if source.enabled and source.configuration_problem is not None:
                self.get_logger().warning(f"{source.kind}: {source.configuration_problem}")
        for sentence in unobserved_quantities(self.config):
            self.get_logger().warning(sentence)

    def _declare_fusion_config(self) -> FusionConfig:
        return self.declare_config(
            FusionConfig,
            prefix=FUSION_PARAMETER_PREFIX,
            skip=FUSION_FIELDS_NOT_PARAMETERS,
        )

    # -- inputs -----------------------------------------------------------------------------

    def on_imu(self, raw: bytes) -> None:
        started_s = time.perf_counter()
        now_s = time.monotonic()
        interval_s, self._previous_imu_callback_s = now_s - self._previous_imu_callback_s, now_s
        self._messages_in[IMU_RAW_TOPIC] += 1
        if self._follows_an_imu_gap(raw) and self._gnss_waiting:
            # The engine tells an IMU outage from a step of the IMU's clock by the aiding stamps
            # it has seen: it must see those received before this sample, as offline.
            self.feed_waiting_gnss()
        fed = feed_imu_cdr(self.engine, raw, self.stamps)
        if fed is None:
            message = _decoded(raw, Imu)
            if message is None:
                self.reject(IMU_RAW_TOPIC, Reason.MALFORMED)
                return
            fed = feed_message(self.engine, IMU_RAW_TOPIC, message, self.stamps)
        self._take(IMU_RAW_TOPIC, fed)
        for reason in self.engine.imu_given_up:
            self.reject(IMU_RAW_TOPIC, reason)
        self._warn_of_second_streams()
        # The solution is out. The GNSS messages that came in and the filtering this sample made
        # due wait a little, so that the nodes that take this solution run first.
        if self.deferred_work_due_s is None:
            self.deferred_work_due_s = now_s + min(FILTERING_DELAY_S, 0.5 * interval_s)
        else:
            # The previous sample's filtering did not get its turn before this sample came.
            self.filtering_overdue += 1
            self.run_deferred_work()
        self._imu_callback_durations_s.append(time.perf_counter() - started_s)

    def _warn_of_second_streams(self) -> None:
        """Say so, rate-limited, while a second stream's samples on an input's topic are
        rejected (another buoy's nodes on the same ROS domain), once there are more than a few
        stale samples would explain."""
        topics = {source.kind: source.topic for source in self.engine.sources}
        for kind, (samples, lead_s) in self.engine.second_streams.items():
            if samples < SECOND_STREAM_SAMPLES or samples == self._second_stream_samples[kind]:
                continue
            self._second_stream_samples[kind] = samples
            lead = f" stamped {lead_s:+.3f} s" if math.isfinite(lead_s) else ""
            self.get_logger().warning(
                f"two streams on {topics.get(kind, IMU_RAW_TOPIC)}: {samples} samples{lead} off "
                "the accepted sequence rejected so far; another buoy's nodes on this ROS domain?",
                throttle_duration_sec=REJECTION_LOG_PERIOD_S,
            )

    def _follows_an_imu_gap(self, raw: bytes) -> bool:
        """Whether this IMU message's stamp lies more than ``max_imu_gap_s`` from the previous
        one's, either way (an outage or a step of the IMU's clock); True when unreadable."""
        stamp = read_stamp(raw)
        if stamp is None:
            return True
        t_s = stamp[0] + stamp[1] * 1e-9
        previous_s, self._previous_imu_stamp_s = self._previous_imu_stamp_s, t_s
        return abs(t_s - previous_s) > self.config.max_imu_gap_s

    def run_deferred_work(self) -> None:
        started_s = time.perf_counter()
        super().run_deferred_work()
        self.feed_waiting_gnss()
        self.engine.catch_up()
        self._reject_out_of_sequence_measurements()
        self._filtering_durations_s.append(time.perf_counter() - started_s)

    def feed_waiting_gnss(self) -> None:
        """Give the GNSS messages received since the last IMU sample to the engine."""
        waiting, self._gnss_waiting = self._gnss_waiting, []
        for topic, raw in waiting:
            message = _decoded(raw, INPUT_CLASSES[topic])
            if message is None:
                self._messages_in[topic] += 1
                self.reject(topic, Reason.MALFORMED)
                continue
            self.feed(topic, message)

    def feed(self, topic: str, message) -> None:
        """Give a sensor message to the engine; publish the solutions it yields."""
        self._messages_in[topic] += 1
        self._take(topic, feed_message(self.engine, topic, message, self.stamps))
        self._reject_out_of_sequence_measurements()

    def _reject_out_of_sequence_measurements(self) -> None:
        """Count and log the measurements of a second stream the engine rejected since the last
        call (when their turn came, or their source's own measurement of their stamp)."""
        rejected = self.engine.take_out_of_sequence()
        for source in rejected:
            self.reject(source.topic, Reason.OUT_OF_SEQUENCE)
        if rejected:
            self._warn_of_second_streams()

    def _take(self, topic: str, fed) -> None:
        solutions, rejection = fed
        if rejection is not None:
            self.reject(topic, rejection)
            return
        self.publish_solutions(solutions)

    # -- outputs ----------------------------------------------------------------------------

    def publish_solutions(self, solutions: list[NavSolution]) -> None:
        """Publish as CDR bytes: the bytes ``fuse_bag`` writes, without building messages."""
        for solution in solutions:
            values = nav_values(solution, self.stamps)
            for topic, raw in solution_cdr(values).items():
                self._nav_publishers[topic].publish(raw)
            if self._tf_publisher is not None:
                self._tf_publisher.publish(transform_cdr(values))
            if self.solutions_published == 0:
                self._log_alignment(values)
            self.solutions_published += 1

    def _log_alignment(self, values) -> None:
        roll, pitch, yaw = (
            math.degrees(angle)
            for angle in euler_from_rotation_matrix(
                rotation_matrix_from_quaternion(values.attitude_xyzw)
            )
        )
        east, north, up = values.position_map_m
        self.get_logger().info(
            f"aligned at stamp {values.t_s:.3f} s: roll {roll:.2f} deg, pitch {pitch:.2f} deg, "
            f"yaw {yaw:.2f} deg (ENU, from East counter-clockwise), position "
            f"({east:.2f}, {north:.2f}, {up:.2f}) m in map, "
            f"({values.latitude_deg:.6f}, {values.longitude_deg:.6f}) deg"
        )

    def flush_held_back(self) -> list:
        """End of input: publish the solutions the engine still holds."""
        self.feed_waiting_gnss()
        self.publish_solutions(self.engine.flush())
        for reason in self.engine.imu_given_up:
            self.reject(IMU_RAW_TOPIC, reason)
        self._reject_out_of_sequence_measurements()
        return list(self._nav_publishers.values())

    # -- diagnostics ------------------------------------------------------------------------

    def report(self):
        self.feed_waiting_gnss()
        now_s = time.monotonic()
        period_s = max(now_s - self._last_report_s, 1e-9)
        new = self._messages_in - self._messages_in_at_last_report
        self._messages_in_at_last_report = collections.Counter(self._messages_in)
        self._last_report_s = now_s
        durations, self._imu_callback_durations_s = self._imu_callback_durations_s, []
        filtering, self._filtering_durations_s = self._filtering_durations_s, []

        for transition in self.engine.take_source_transitions():
            self.get_logger().warning(f"stamp {transition.t_s:.3f} s: {transition.message}")
        health = self.engine.health()
        values = diagnostic_values(health)
        values.update(self._filter_estimates())
        for topic in self.input_topics:
            values[f"messages_in[{topic}]"] = self._messages_in[topic]
            values[f"rate_hz[{topic}]"] = new[topic] / period_s
        values.update(
            {
                "solutions_published": self.solutions_published,
                "latency_mean_s": sum(durations) / len(durations) if durations else math.nan,
                "latency_max_s": max(durations) if durations else math.nan,
                "filtering_mean_s": sum(filtering) / len(filtering) if filtering else math.nan,
                "filtering_max_s": max(filtering) if filtering else math.nan,
                "filtering_overdue": self.filtering_overdue,
            }
        )
        level, message = health_status(
            health, IMU_RAW_TOPIC, new[IMU_RAW_TOPIC], self.solutions_published
        )
        return level, message, values

    def _filter_estimates(self) -> dict[str, float]:
        """The filter's 1σ of attitude (ENU error angles, deg) and velocity (ENU, m/s) and its
        IMU bias estimates (body; gyro deg/s, accelerometer mg, the units of the parameters):
        whether the attitude is good enough yet, and whether the sensor is sane."""
        covariance, state = self.engine.covariance, self.engine.nav_state
        if covariance is None or state is None:
            return {}
        variances = covariance.diagonal()
        states = self.engine.states
        estimates = {}
        for k, axis in enumerate(("east", "north", "up")):
            attitude_variance = variances[states.index("attitude", k)]
            estimates[f"attitude_sigma_deg[{axis}]"] = math.degrees(math.sqrt(attitude_variance))
            estimates[f"velocity_sigma_mps[{axis}]"] = math.sqrt(
                variances[states.index("velocity", k)]
            )
        for k, axis in enumerate("xyz"):
            estimates[f"gyro_bias_deg_s[{axis}]"] = math.degrees(state.gyro_bias_rad_s[k])
            estimates[f"accel_bias_mg[{axis}]"] = (
                1e3 * float(state.accel_bias_mps2[k]) / STANDARD_GRAVITY_MPS2
            )
        return estimates


def _decoded(raw: bytes, message_class):
    """The message of CDR bytes ``raw``, None when they are not one."""
    try:
        return deserialize_message(raw, message_class)
    except RuntimeError:  # rclpy's RMWError: the bytes are not a message of this type
        return None


main = main_for(FusionNode, __doc__)
