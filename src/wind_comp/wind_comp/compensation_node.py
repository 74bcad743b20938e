"""compensation_node: Miller motion correction of every anemometer sample, live.

    compensation_node [--ros-args --params-file buoy.yaml --params-file compensation.yaml ...]

Subscribes (reliable, deep queue):

- ``anemometer/wind`` (geometry_msgs/Vector3Stamped, frame ``anemometer_link``)
- ``nav/odometry`` (nav_msgs/Odometry): attitude, bias-corrected body rate ω_ib, body velocity
- ``nav/fix`` (sensor_msgs/NavSatFix): its latitude removes the Earth's rotation from the body
  rate (ω_nb = ω_ib − R_nb^T·ω_ie). Until the first fix the rate is used as received: at a 3 m
  lever arm that is an error below 3e-4 m/s of wind. The latest valid latitude is kept while
  the fix is lost.
- ``anemometer/temperature`` (sensor_msgs/Temperature, °C, optional): the sonic temperature of
  the fluxes (w'Ts', air density).

Publishes:

- ``wind/true`` (geometry_msgs/Vector3Stamped, frame ``map``): the corrected ENU wind, m/s,
  exactly one message per ``anemometer/wind`` message, with the same header stamp, in arrival
  order. A sample that cannot be corrected (malformed, out of range, no navigation around its
  stamp, an uncertainty beyond ``compensation.max_wind_sigma_*_mps``) is published with NaN
  components, never dropped.
- ``wind/true_with_covariance`` (geometry_msgs/TwistWithCovarianceStamped, frame ``map``): the
  same wind, one per ``wind/true``, with its ENU covariance (m²/s², from the navigation's
  covariances and ``compensation.anemometer_noise_sigma_mps``) in rows and columns 0–2 of
  ``twist.covariance``; the angular part unused (zeros, its diagonal −1); NaN where
  ``wind/true`` is.
- ``wind/mean_1min``, ``wind/mean_10min`` (geometry_msgs/Vector3Stamped, frame ``map``): vector
  mean of the ENU wind over each window, stamped with the window end.
- ``wind/stats_1min``, ``wind/stats_10min`` (std_msgs/Float64MultiArray): statistics of the same
  windows; ``layout.dim[i].label`` names ``data[i]``, in the order of
  :data:`wind_comp.compensation_messages.STATS_FIELDS` (scalar_mean_speed_mps,
  vector_mean_speed_mps, vector_mean_direction_deg (meteorological, FROM), gust_mps, std_u_mps,
  std_v_mps, std_w_mps, n_valid, n_invalid, window_start_s, window_end_s, first_sample_s,
  last_sample_s, coverage, quality_flag: the share of a full window's samples held valid and
  its QARTOD flag, :mod:`wind_comp.products`; mean_u_standard_error_mps,
  mean_v_standard_error_mps, mean_w_standard_error_mps: the 1σ of the window's vector mean).
  Windows come from ``compensation.product_windows_s`` (60 and 600 s by default; a window of
  other length W is named ``W s``, e.g. ``wind/mean_30s``). A window is published when the
  first sample of the next one is corrected, and the partial windows at shutdown.
- ``wind/fluxes_30min`` (std_msgs/Float64MultiArray): the eddy-covariance fluxes of each
  window of ``compensation.flux_window_s`` (:mod:`wind_comp.flux_products`), labelled in the
  order of :data:`wind_comp.compensation_messages.FLUX_FIELDS`.
- ``diagnostics``: samples in and out, valid and invalid by reason, navigation samples seen,
  input rates, processing latency, rejected messages by reason.
- ``tf_static`` (tf2_msgs/TFMessage, transient local), once at start where tf2_msgs is
  installed: ``base_link`` → ``anemometer_link`` from the shared parameters (``current_node``:
  ``dvl_link``).

Parameters: ``anemometer.position`` (double[3], m, default [0, 0, 3]) and
``anemometer.rpy_deg`` (double[3], deg, default [0, 0, 0]) of the shared buoy file; every
other :class:`wind_comp.config.CompensatorConfig` field as ``compensation.<field>``; and
``compensation.nav_timeout_s`` (s, default 1.0), the latency budget: a wind sample still without
navigation on both sides once the newest anemometer stamp is this much later, and that has also
waited this long in wall-clock time, is published invalid (navigation timeout) instead of
waiting longer. The wall-clock condition keeps a backlog of queued messages (both topics are
taken alternately, so wind stamps can run ahead of navigation stamps) or a fast replay from
timing out samples whose navigation is only queued, not missing.

Malformed messages (non-finite values, zero quaternion, wrong frame, stamps not increasing) are
counted and warned about (rate-limited). A rejected anemometer message still yields its NaN
``wind/true``. On SIGINT or SIGTERM the samples still waiting for navigation are published
(invalid) before the node exits with code 0.

:class:`CorrectionNode` is the shape this node shares with ``current_node``, which corrects
``dvl/velocity`` into ``current/velocity`` the same way.
"""

from __future__ import annotations

import collections
import functools
import math
import time

from geometry_msgs.msg import TwistWithCovarianceStamped, Vector3Stamped
from nav_msgs.msg import Odometry
from rclpy.serialization import deserialize_message
from sensor_msgs.msg import NavSatFix, Temperature
from std_msgs.msg import Float64MultiArray, MultiArrayDimension

try:  # tf2_msgs comes with a full ROS install, not with the PyPI wheels
    from tf2_msgs.msg import TFMessage
except ImportError:
    TFMessage = None

from buoy_common.base_node import (
    DATA_QOS,
    DiagnosticsPublisher,
    FlushingNode,
    StartupError,
    main_for,
)
from buoy_common.contract import (
    NAV_FIX_TOPIC,
    NAV_ODOMETRY_TOPIC,
    SONIC_TEMPERATURE_TOPIC,
    WIND_RAW_TOPIC,
    WIND_TRUE_TOPIC,
    WIND_TRUE_WITH_COVARIANCE_TOPIC,
    Reason,
    wind_fluxes_topic,
    wind_mean_topic,
    wind_stats_topic,
)
from buoy_common.parameter_declarations import DeclaredParameter
from buoy_common.sensor_frames import sensor_transforms, shared_values
from wind_comp.compensation_messages import (
    MalformedMessageError,
    anemometer_record,
    fix_record,
    flow_cdr,
    flows_with_covariance_cdr,
    flux_message,
    odometry_record,
    product_messages,
    temperature_sample,
)
from wind_comp.compensator import SampleStatus
from wind_comp.config import (
    COMPENSATION_NODE_NAME,
    COMPENSATION_PARAMETER_PREFIX,
    NAV_TIMEOUT,
    CompensatorConfig,
)
from wind_comp.flux_products import FluxProduct
from wind_comp.pipeline import (
    CompensationOutput,
    CompensationPipeline,
    mostly_invalid_warning,
    wind_pipeline,
    wrong_frame_message,
)

DIAGNOSTICS_PERIOD_S = 1.0


def _decoder(message_type: type):
    """What decodes a message of ``message_type`` from its CDR bytes."""
    return functools.partial(deserialize_message, message_type=message_type)


_DECODE_ODOMETRY = _decoder(Odometry)
_DECODE_FIX = _decoder(NavSatFix)


class PendingStamp:
    """Header stamp and wall arrival time of a sensor sample awaiting its output."""

    __slots__ = ("arrival_s", "nanosec", "sec", "t_s")

    def __init__(self, sec: int, nanosec: int, t_s: float, arrival_s: float):
        self.sec = sec
        self.nanosec = nanosec
        self.t_s = t_s
        self.arrival_s = arrival_s


class CorrectionNode(FlushingNode):
    """What ``compensation_node`` and ``current_node`` share: the navigation (``nav/odometry``,
    ``nav/fix``) and one flow sensor's samples in, exactly one corrected sample per sensor
    sample out with the sensor sample's stamp, the products of the averaging windows, and
    ``diagnostics``. A subclass names its topics and how its sensor's messages are read."""

    def __init__(
        self,
        node_name: str,
        parameter_prefix: str,
        config_type: type,
        make_pipeline,
        sensor_topic: str,
        sensor_message_type: type,
        read_record,
        output_topic: str,
        covariance_topic: str,
        product_topics,
        samples_name: str,
        frame_field: str,
        nav_timeout: DeclaredParameter,
    ):
        """Args:
        node_name, parameter_prefix: the node's name and the prefix of its own parameters.
        config_type, make_pipeline: the configuration dataclass, declared as parameters, and
            what makes the pipeline of such a configuration.
        sensor_topic, sensor_message_type: the flow sensor's input.
        read_record: a sensor message's CDR bytes, a decoder of them and the frame expected as
            (sample, header sec, header nanosec) (:func:`anemometer_record`,
            :func:`dvl_record` of :mod:`wind_comp.compensation_messages`).
        output_topic: one corrected sample per input, frame ``map``.
        covariance_topic: the same sample with its covariance.
        product_topics: (mean topic, statistics topic) of a window length (s).
        samples_name: what the diagnostics call the input samples (``wind``, ``dvl``).
        frame_field: the configuration field naming the sensor's ``frame_id`` (a message in
            another frame is rejected as ``wrong_frame``).
        nav_timeout: the live-only latency budget's declaration (name, default, s).
        """
        super().__init__(node_name)
        self.config = self.declare_config(config_type, prefix=parameter_prefix)
        self.nav_timeout_s = self.declare_value(
            nav_timeout.name, nav_timeout.default, nav_timeout.description
        )
        if not (math.isfinite(self.nav_timeout_s) and self.nav_timeout_s > 0):
            raise StartupError(
                f"parameter '{nav_timeout.name}' must be positive, got {self.nav_timeout_s}"
            )
        self.sensor_topic = sensor_topic
        self._read_record = read_record
        self._decode_sample = _decoder(sensor_message_type)
        self.samples_name = samples_name
        self.expected_frame_id: str = getattr(self.config, frame_field)
        self._frame_parameter = parameter_prefix + frame_field
        self.pipeline: CompensationPipeline = make_pipeline(self.config)
        self._pending: collections.deque[PendingStamp] = collections.deque()
        self._counters = collections.Counter()
        self._counters_at_last_report = collections.Counter()
        self._last_report_s = time.monotonic()
        self._latencies_s: list[float] = []
        self._wrong_frames: set[str] = set()

        self._output_publisher = self.create_publisher(Vector3Stamped, output_topic, DATA_QOS)
        self._covariance_publisher = self.create_publisher(
            TwistWithCovarianceStamped, covariance_topic, DATA_QOS
        )
        mean_topic, stats_topic = product_topics
        self._product_publishers = {
            window_s: (
                self.create_publisher(Vector3Stamped, mean_topic(window_s), DATA_QOS),
                self.create_publisher(Float64MultiArray, stats_topic(window_s), DATA_QOS),
            )
            for window_s in self.config.product_windows_s
        }
        # Raw: sensor samples are read from their CDR bytes where a fast reader exists and the
        # outputs written as CDR bytes, the arithmetic process_bag runs.
        self.create_subscription(
            sensor_message_type, sensor_topic, self.on_sample, DATA_QOS, raw=True
        )
        # Raw: 100 Hz each, read straight from CDR as process_bag reads them.
        self.create_subscription(Odometry, NAV_ODOMETRY_TOPIC, self.on_odometry, DATA_QOS, raw=True)
        self.create_subscription(NavSatFix, NAV_FIX_TOPIC, self.on_fix, DATA_QOS, raw=True)
        self.broadcast_static_transforms(TFMessage, sensor_transforms(shared_values(self.config)))
        self._diagnostics = DiagnosticsPublisher(self, self.report, DIAGNOSTICS_PERIOD_S)
        sensor = self.pipeline.sensor
        self.get_logger().info(
            f"correcting {sensor_topic} with {NAV_ODOMETRY_TOPIC} into {output_topic}: sensor at "
            f"{list(sensor.position_body_m)} m, rpy {list(sensor.rpy_deg)} deg; products over "
            f"{[averager.window_s for averager in self.pipeline.averagers]} s"
        )

    # -- inputs -----------------------------------------------------------------------------

    def on_sample(self, raw: bytes) -> None:
        self._counters["samples_in"] += 1
        sample, sec, nanosec = self._read_record(raw, self._decode_sample, self.expected_frame_id)
        rejection = self.pipeline.add_sample(sample)
        if rejection is not None:
            self.reject(self.sensor_topic, rejection)
            if rejection == Reason.WRONG_FRAME and sample.frame_id not in self._wrong_frames:
                self._wrong_frames.add(sample.frame_id)
                self.get_logger().error(
                    wrong_frame_message(
                        self.sensor_topic,
                        sample.frame_id,
                        self.expected_frame_id,
                        self._frame_parameter,
                    )
                )
        self._reject_given_up()
        self._pending.append(PendingStamp(sec, nanosec, sample.t_s, time.monotonic()))
        self.publish(self.pipeline.expire(self._timeout_horizon_s()))

    def _reject_given_up(self) -> None:
        """Count the samples held off the sensor's sequence and given up since (a second
        stream's): rejected after their arrival."""
        for _ in range(self.pipeline.take_given_up()):
            self.reject(self.sensor_topic, Reason.OUT_OF_SEQUENCE)

    def _timeout_horizon_s(self) -> float:
        """Stamp (s) before which samples still without navigation are given up: older than
        the newest sensor stamp by ``nav_timeout_s`` and waiting that long in wall time."""
        waited_enough_before_s = time.monotonic() - self.nav_timeout_s
        horizon_s = -math.inf
        for pending in self._pending:
            if pending.arrival_s > waited_enough_before_s:
                break
            horizon_s = max(horizon_s, math.nextafter(pending.t_s, math.inf))
        return min(horizon_s, self.pipeline.latest_sample_stamp_s - self.nav_timeout_s)

    def on_odometry(self, raw: bytes) -> None:
        self._counters["nav_in"] += 1
        try:
            fields = odometry_record(raw, _DECODE_ODOMETRY)
        except MalformedMessageError as error:
            self.reject(NAV_ODOMETRY_TOPIC, error.reason)
            return
        rejection = self.pipeline.add_odometry(*fields)
        if rejection is not None:
            self.reject(NAV_ODOMETRY_TOPIC, rejection)
            return
        self.publish(self.pipeline.ready())

    def on_fix(self, raw: bytes) -> None:
        self._counters["fix_in"] += 1
        rejection = self.pipeline.add_fix(*fix_record(raw, _DECODE_FIX))
        if rejection is not None:
            self.reject(NAV_FIX_TOPIC, rejection)

    # -- outputs ----------------------------------------------------------------------------

    def publish(self, output: CompensationOutput) -> None:
        """Publish decided samples in order, each with the stamp of its sensor message, and
        the averaging windows they closed."""
        now_s = time.monotonic()
        samples = output.samples
        stamps = [self._pending.popleft() for _ in range(len(samples))]
        with_covariance = flows_with_covariance_cdr(
            [pending.sec for pending in stamps],
            [pending.nanosec for pending in stamps],
            samples.flow_enu_mps,
            samples.covariance.total,
        )
        for pending, flow, raw in zip(
            stamps, samples.flow_enu_mps.tolist(), with_covariance, strict=True
        ):
            self._output_publisher.publish(flow_cdr(pending.sec, pending.nanosec, flow))
            self._covariance_publisher.publish(raw)
            self._counters["samples_out"] += 1
            self._latencies_s.append(now_s - pending.arrival_s)
        for product in output.products:
            self.publish_product(product)

    def publish_product(self, product) -> None:
        """One closed averaging window, on its mean and statistics topics."""
        mean_publisher, stats_publisher = self._product_publishers[product.window_s]
        mean, stats = product_messages(
            Vector3Stamped, Float64MultiArray, MultiArrayDimension, product
        )
        mean_publisher.publish(mean)
        stats_publisher.publish(stats)

    def flush_held_back(self) -> list:
        """End of input: publish every pending sample and the partial product windows."""
        self.publish(self.pipeline.flush())
        self._reject_given_up()
        warning = mostly_invalid_warning(self.pipeline.status_counts(), self.samples_name)
        if warning is not None:
            self.get_logger().error(warning)
        publishers = [self._output_publisher, self._covariance_publisher]
        for pair in self._product_publishers.values():
            publishers.extend(pair)
        return publishers

    # -- diagnostics ------------------------------------------------------------------------

    def report(self):
        now_s = time.monotonic()
        period_s = max(now_s - self._last_report_s, 1e-9)
        new = self._counters - self._counters_at_last_report
        self._counters_at_last_report = collections.Counter(self._counters)
        self._last_report_s = now_s
        latencies, self._latencies_s = self._latencies_s, []
        counts = self.pipeline.counts
        n_invalid = sum(n for status, n in counts.items() if status != SampleStatus.VALID)
        name = self.samples_name
        values = {
            f"{name}_samples_in": self._counters["samples_in"],
            f"{name}_samples_out": self._counters["samples_out"],
            f"{name}_samples_pending": self.pipeline.n_pending,
            "valid": counts[SampleStatus.VALID],
            "invalid": n_invalid,
        }
        for status in SampleStatus:
            if status != SampleStatus.VALID:
                values[f"invalid[{self.pipeline.sensor.reason(status)}]"] = counts[status]
        values.update(
            {
                "nav_samples_in": self._counters["nav_in"],
                "nav_samples_accepted": self.pipeline.n_nav_accepted,
                "fix_messages_in": self._counters["fix_in"],
                "latitude_deg": self.pipeline.latitude_deg,
                f"{name}_rate_hz": new["samples_in"] / period_s,
                "nav_rate_hz": new["nav_in"] / period_s,
                "latency_mean_s": sum(latencies) / len(latencies) if latencies else math.nan,
                "latency_max_s": max(latencies) if latencies else math.nan,
            }
        )
        if new["samples_in"] == 0:
            return "warn", f"no {self.sensor_topic} samples", values
        if new["nav_in"] == 0:
            return "warn", f"no {NAV_ODOMETRY_TOPIC} samples: nothing can be corrected", values
        return (
            "ok",
            f"{counts[SampleStatus.VALID]} valid, {n_invalid} invalid {name} samples",
            values,
        )


class CompensationNode(CorrectionNode):
    """The wind's :class:`CorrectionNode`, with the eddy-covariance fluxes of the corrected
    wind and the sonic temperature (``anemometer/temperature``) on ``wind/fluxes_<window>``."""

    def __init__(self):
        super().__init__(
            COMPENSATION_NODE_NAME,
            COMPENSATION_PARAMETER_PREFIX,
            CompensatorConfig,
            wind_pipeline,
            WIND_RAW_TOPIC,
            Vector3Stamped,
            anemometer_record,
            WIND_TRUE_TOPIC,
            WIND_TRUE_WITH_COVARIANCE_TOPIC,
            (wind_mean_topic, wind_stats_topic),
            "wind",
            "anemometer_frame_id",
            NAV_TIMEOUT,
        )
        self._flux_publishers = {
            averager.window_s: self.create_publisher(
                Float64MultiArray, wind_fluxes_topic(averager.window_s), DATA_QOS
            )
            for averager in self.pipeline.flux_averagers
        }
        self.create_subscription(
            Temperature, SONIC_TEMPERATURE_TOPIC, self.on_temperature, DATA_QOS
        )

    def on_temperature(self, message) -> None:
        self._counters["temperature_in"] += 1
        sample = temperature_sample(message, self.expected_frame_id)
        if isinstance(sample, str):
            self.reject(SONIC_TEMPERATURE_TOPIC, sample)
            return
        for product in self.pipeline.add_temperature(*sample):
            self.publish_product(product)

    def publish_product(self, product) -> None:
        if isinstance(product, FluxProduct):
            self._flux_publishers[product.window_s].publish(
                flux_message(Float64MultiArray, MultiArrayDimension, product)
            )
            return
        super().publish_product(product)

    def flush_held_back(self) -> list:
        return [*super().flush_held_back(), *self._flux_publishers.values()]

    def report(self):
        level, text, values = super().report()
        values["temperature_messages_in"] = self._counters["temperature_in"]
        return level, text, values


main = main_for(CompensationNode, __doc__)
