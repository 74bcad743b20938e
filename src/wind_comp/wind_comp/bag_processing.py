"""Fusion and wind compensation over a recorded bag: the offline twin of the two nodes.

:func:`process_bag` runs over the bag's sensor topics, in log-time order, the core of
``fusion_node`` (:class:`buoy_nav.bag_fusion.OfflineFusion`) followed by the core of
``compensation_node`` (:class:`wind_comp.pipeline.CompensationPipeline`): each navigation
solution passes to the compensation as the numbers its ``nav/odometry`` and ``nav/fix`` carry,
in the order the node receives them, and every ``anemometer/wind`` sample yields exactly one
``wind/true`` (NaN when it cannot be corrected). The new bag holds ``nav/*``, ``wind/true``, the
wind products (``wind/mean_<window>``, ``wind/stats_<window>``), the measured
``anemometer/wind`` and any truth topics; every output message carries the log time of the input
message after which it was produced. The wind products are also written to
``<OUT_BAG>_wind_products.csv``. ``process_bag`` is its command line.

With ``smooth`` the fusion runs first over the sensor topics alone (a forward filter whose
epochs and solutions are spilled to a temporary directory beside the output), then the
smoother's backward pass; a second read of the bag feeds the smoothed solutions and the
anemometer samples, in log-time order, to the compensation, so the wind is corrected with the
smoothed attitude and velocity (:func:`buoy_nav.bag_fusion.merged_with_smoothed`).

The compensation runs in this process, on whole stretches of samples at a time; the process
that writes the bag only writes.
"""

from __future__ import annotations

import csv
import math
import time
from collections import Counter, deque
from dataclasses import dataclass, field, fields
from pathlib import Path

import numpy as np
from geometry_msgs.msg import Vector3Stamped
from std_msgs.msg import Float64MultiArray, MultiArrayDimension

from buoy_common.bag_io import (
    BackgroundBagWriter,
    BagMessage,
    BagProgress,
    BagReader,
    BagWriter,
    Recovery,
)
from buoy_common.contract import (
    WIND_RAW_TOPIC,
    WIND_TRUE_TOPIC,
    Reason,
    bag_topic,
    wind_mean_topic,
    wind_stats_topic,
)
from buoy_common.namespaces import NamespacedWriter, TopicView
from buoy_common.safe_output import check_outputs_apart_from_inputs, staged_file
from buoy_nav.bag_fusion import (
    OfflineFusion,
    forward_pass,
    merged_with_smoothed,
    relative_topic,
    sensor_topics_of,
    spill_parent_of,
    truth_topics_of,
)
from buoy_nav.config import FusionConfig
from buoy_nav.fusion_messages import STATUS_FIX, NavValues
from wind_comp.compensation_messages import (
    anemometer_sample,
    anemometer_sample_cdr,
    product_messages,
    true_winds_cdr,
)
from wind_comp.compensator import WindStatus
from wind_comp.config import CompensatorConfig
from wind_comp.pipeline import CompensationOutput, CompensationPipeline
from wind_comp.products import WindProduct

TRUE_WIND_BAG_TOPIC = bag_topic(WIND_TRUE_TOPIC)
VECTOR3_STAMPED = "geometry_msgs/msg/Vector3Stamped"
FLOAT64_MULTI_ARRAY = "std_msgs/msg/Float64MultiArray"
PRODUCTS_CSV_SUFFIX = "_wind_products.csv"
PROGRESS_EVERY_MESSAGES = 2000
# Anemometer samples handed to the compensation at a time: enough to pay numpy's per-call cost
# once per stretch, few enough to keep the memory flat.
SAMPLES_PER_STRETCH = 256


def products_csv_path(out_bag) -> Path:
    """Where the wind products of ``out_bag`` go: beside it, ``<name>_wind_products.csv``."""
    out_bag = Path(out_bag)
    if not out_bag.name:  # "." or "..": named after the directory it stands for
        out_bag = out_bag.resolve()
    return out_bag.with_name(out_bag.name + PRODUCTS_CSV_SUFFIX)


@dataclass
class ProcessSummary:
    """What a run did: counts of outputs and rejections, products, timing."""

    wind_status_counts: dict[WindStatus, int] = field(default_factory=dict)
    rejected_wind_messages: Counter = field(default_factory=Counter)
    wrong_wind_frames: Counter = field(default_factory=Counter)
    """Frames of the ``anemometer/wind`` messages rejected for their frame, with counts."""
    products: list[WindProduct] = field(default_factory=list)
    topic_counts: dict[str, int] = field(default_factory=dict)
    fusion_lines: list[str] = field(default_factory=list)
    duration_s: float = 0.0
    wall_s: float = 0.0
    csv_path: Path | None = None
    recovery: Recovery | None = None


class OfflineCompensation:
    """What ``compensation_node`` does, fed from a bag and writing to one.

    Navigation solutions come as the fusion's :class:`~buoy_nav.fusion_messages.NavValues`
    (what ``nav/odometry`` and ``nav/fix`` carry, in that order), anemometer samples as the
    records of ``anemometer/wind``; ``wind/true`` and the products are written with the log
    time of the record after which they were decided.
    """

    def __init__(self, config: CompensatorConfig, writer: BackgroundBagWriter | NamespacedWriter):
        self.config = config
        self.pipeline = CompensationPipeline(config)
        self.writer = writer
        self.rejected: Counter[str] = Counter()
        self.wrong_frames: Counter[str] = Counter()
        self.products: list[WindProduct] = []
        self._stamps: deque[tuple[int, int]] = deque()
        self._samples_waiting = 0

    def add_navigation(self, solutions: list[NavValues]) -> None:
        """The ``nav/odometry`` and ``nav/fix`` of each solution, as the node receives them."""
        pipeline = self.pipeline
        for values in solutions:
            pipeline.add_odometry(
                values.sec + values.nanosec * 1e-9,
                values.attitude_xyzw,
                values.angular_rate_body_rad_s,
                values.velocity_body_mps,
                max(
                    values.pose_covariance[21],
                    values.pose_covariance[28],
                    values.pose_covariance[35],
                ),
            )
            pipeline.add_fix(STATUS_FIX, values.latitude_deg)

    def add_wind(self, reader: BagReader, message: BagMessage) -> None:
        """One ``anemometer/wind`` record; every few hundred, the decided samples are written."""
        expected_frame_id = self.config.anemometer_frame_id
        parsed = anemometer_sample_cdr(message.raw, expected_frame_id)
        if parsed is None:
            decoded = reader.decode(message)
            stamp = decoded.header.stamp
            parsed = (anemometer_sample(decoded, expected_frame_id), stamp.sec, stamp.nanosec)
        sample, sec, nanosec = parsed
        rejection = self.pipeline.add_wind(sample)
        if rejection is not None:
            self.rejected[rejection] += 1
            if rejection == Reason.WRONG_FRAME:
                self.wrong_frames[sample.frame_id] += 1
        self._stamps.append((sec, nanosec))
        self._samples_waiting += 1
        if self._samples_waiting >= SAMPLES_PER_STRETCH:
            self._samples_waiting = 0
            self._write(self.pipeline.ready(), message.log_time_ns)

    def finish(self, log_time_ns: int) -> None:
        """End of the data: every sample decided and written, partial windows closed."""
        self._write(self.pipeline.flush(), log_time_ns)

    def _write(self, output: CompensationOutput, log_time_ns: int) -> None:
        stamps = [self._stamps.popleft() for _ in range(len(output.wind))]
        secs = np.array([sec for sec, _ in stamps], dtype=np.int64)
        nanosecs = np.array([nanosec for _, nanosec in stamps], dtype=np.int64)
        for raw in true_winds_cdr(secs, nanosecs, output.wind.true_wind_enu_mps):
            self.writer.write_raw(TRUE_WIND_BAG_TOPIC, VECTOR3_STAMPED, log_time_ns, raw)
        for product in output.products:
            self.products.append(product)
            mean, stats = product_messages(
                Vector3Stamped, Float64MultiArray, MultiArrayDimension, product
            )
            self.writer.write(
                bag_topic(wind_mean_topic(product.window_s)), VECTOR3_STAMPED, log_time_ns, mean
            )
            self.writer.write(
                bag_topic(wind_stats_topic(product.window_s)),
                FLOAT64_MULTI_ARRAY,
                log_time_ns,
                stats,
            )


def write_products_csv(products: list[WindProduct], path: Path) -> None:
    """One row per closed averaging window; columns named with their units. The file appears
    only once complete."""
    names = [f.name for f in fields(WindProduct)]
    with staged_file(path) as stream:
        writer = csv.writer(stream)
        writer.writerow(names)
        for product in products:
            writer.writerow([_csv_value(getattr(product, name)) for name in names])


def _csv_value(value) -> str:
    if isinstance(value, float):
        return "nan" if math.isnan(value) else f"{value:.6f}"
    return str(value)


def process_bag(
    in_bag,
    out_bag,
    fusion_config: FusionConfig,
    compensator_config: CompensatorConfig,
    overwrite: bool = False,
    view: TopicView | None = None,
    smooth: bool = False,
    write_in_background: bool = True,
) -> ProcessSummary:
    """Fuse and correct ``in_bag`` into ``out_bag`` (a new bag; replaced with ``overwrite``)
    and the products CSV beside it, over the topics of ``view``'s namespace (the root when
    None), writing into the same namespace; with ``smooth`` on the smoothed navigation (see the
    module docstring). Raises BagError for a missing or unreadable bag or one
    without the required topics, and OutputError, before anything is read or written, if an
    output is, contains or lies inside ``in_bag``.

    The bag is written by a process of its own, on a second core; with ``write_in_background``
    False, the same bag is written in this process, for a caller that keeps every core busy
    with bags of its own (``process_archive``)."""
    started = time.monotonic()
    csv_path = products_csv_path(out_bag)
    check_outputs_apart_from_inputs([in_bag], [out_bag, csv_path])
    view = view or TopicView()
    with BagReader(in_bag, view) as reader:
        sensors = sensor_topics_of(reader, fusion_config, extra_required=(WIND_RAW_TOPIC,))
        stored_wind = next(n for n in reader.topics if relative_topic(n) == WIND_RAW_TOPIC)
        truth = truth_topics_of(reader)
        relative_of = {stored: relative for relative, stored in sensors.items()}
        writer_class = BackgroundBagWriter if write_in_background else BagWriter
        if smooth:
            fusion = OfflineFusion(fusion_config, None, spill_parent_of(out_bag), smooth=True)
            try:
                # The writing process starts during the forward pass: until it is ready the
                # writer keeps what it is given, and the second pass produces fast.
                with writer_class(out_bag, overwrite=overwrite) as bag_writer:
                    writer = NamespacedWriter(bag_writer, view)
                    forward_pass(reader, fusion, sensors, relative_of, f"process_bag {in_bag}")
                    compensation = smoothed_compensation(
                        reader, fusion, compensator_config, writer, stored_wind, truth
                    )
            finally:
                fusion.close()
        else:
            fusion, compensation, writer = forward_compensation(
                reader,
                in_bag,
                out_bag,
                overwrite,
                view,
                fusion_config,
                compensator_config,
                sensors,
                relative_of,
                stored_wind,
                truth,
                writer_class,
            )
        duration_s = reader.duration_s
    write_products_csv(compensation.products, csv_path)
    return ProcessSummary(
        wind_status_counts=compensation.pipeline.counts,
        rejected_wind_messages=compensation.rejected,
        wrong_wind_frames=compensation.wrong_frames,
        products=compensation.products,
        topic_counts=writer.counts,
        fusion_lines=fusion.summary(),
        duration_s=duration_s,
        wall_s=time.monotonic() - started,
        csv_path=csv_path,
        recovery=reader.recovery,
    )


def smoothed_compensation(
    reader: BagReader,
    fusion: OfflineFusion,
    compensator_config: CompensatorConfig,
    writer: NamespacedWriter,
    stored_wind: str,
    truth: list[str],
) -> OfflineCompensation:
    """The compensation of a smoothing run, after ``fusion``'s forward pass: the smoothed
    solutions and the anemometer samples in log-time order, written to ``writer``."""
    fusion.writer = writer
    compensation = OfflineCompensation(compensator_config, writer)
    log_time_ns = reader.start_ns
    for message, solution in merged_with_smoothed(reader, fusion, [stored_wind, *truth]):
        if message is None:
            forward, smoothed, log_time_ns = solution
            fusion.write_smoothed_values(forward, smoothed, log_time_ns)
            compensation.add_navigation([smoothed])
            continue
        log_time_ns = message.log_time_ns
        writer.write_raw(message.topic, message.msgtype, log_time_ns, message.raw)
        if message.topic == stored_wind:
            compensation.add_wind(reader, message)
    compensation.finish(log_time_ns)
    return compensation


def forward_compensation(
    reader: BagReader,
    in_bag,
    out_bag,
    overwrite: bool,
    view: TopicView,
    fusion_config: FusionConfig,
    compensator_config: CompensatorConfig,
    sensors: dict[str, str],
    relative_of: dict[str, str],
    stored_wind: str,
    truth: list[str],
    writer_class: type[BackgroundBagWriter] | type[BagWriter] = BackgroundBagWriter,
) -> tuple[OfflineFusion, OfflineCompensation, NamespacedWriter]:
    """Fusion and compensation in one pass over the bag, the output bag written into
    ``view``'s namespace by ``writer_class``."""
    with (
        BagProgress(reader, f"process_bag {in_bag}") as progress,
        writer_class(out_bag, overwrite=overwrite) as bag_writer,
    ):
        writer = NamespacedWriter(bag_writer, view)
        fusion = OfflineFusion(fusion_config, writer)
        compensation = OfflineCompensation(compensator_config, writer)
        log_time_ns = reader.start_ns
        for index, message in enumerate(reader.messages([*sensors.values(), stored_wind, *truth])):
            log_time_ns = message.log_time_ns
            topic = relative_of.get(message.topic)
            if topic is not None:
                solutions = fusion.add_message(reader, topic, message)
                if solutions:
                    compensation.add_navigation(solutions)
            else:
                writer.write_raw(message.topic, message.msgtype, log_time_ns, message.raw)
                if message.topic == stored_wind:
                    compensation.add_wind(reader, message)
            if index % PROGRESS_EVERY_MESSAGES == 0:
                progress.reached(log_time_ns)
        compensation.add_navigation(fusion.finish())
        compensation.finish(log_time_ns)
        progress.done()
    return fusion, compensation, writer
