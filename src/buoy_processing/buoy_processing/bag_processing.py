"""Fusion, wind compensation and current estimate over a recorded bag: the offline twin of the
nodes.

:func:`process_bag` runs over the bag's sensor topics, in log-time order, the core of
``fusion_node`` (:class:`buoy_processing.offline_fusion.OfflineFusion`) followed by the cores of
``compensation_node`` (when the bag has ``anemometer/wind``) and ``current_node`` (when it has
``dvl/velocity``), :class:`wind_comp.pipeline.CompensationPipeline` both: each navigation
solution passes to them as the numbers its ``nav/odometry`` and ``nav/fix`` carry, in the order
the nodes receive them, and every ``anemometer/wind`` sample yields exactly one ``wind/true``,
every ``dvl/velocity`` sample one ``current/velocity`` (NaN when they cannot be computed). The
new bag holds ``nav/*``, those outputs and their products (``wind/mean_<window>``,
``wind/stats_<window>``, ``current/mean_<window>``, ``current/stats_<window>``), the measured
``anemometer/wind`` and ``dvl/velocity`` and any truth topics; every output message carries the
log time of the input message after which it was produced. The products are also written to
``<OUT_BAG>_wind_products.csv`` and ``<OUT_BAG>_current_products.csv``. ``process_bag`` is its
command line.

With ``smooth`` the fusion runs first over the sensor topics alone (a forward filter whose
epochs and solutions are spilled to a temporary directory beside the output), then the
smoother's backward pass; a second read of the bag feeds the smoothed solutions and the
anemometer and DVL samples, in log-time order, to the corrections, so the wind and the current
are computed with the smoothed attitude and velocity
(:func:`buoy_processing.offline_fusion.merged_with_smoothed`).

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
    BagError,
    BagMessage,
    BagProgress,
    BagReader,
    BagWriter,
    Recovery,
)
from buoy_common.contract import (
    CURRENT_TOPIC,
    DVL_TOPIC,
    FLOAT64_ARRAY_MSGTYPE,
    SONIC_TEMPERATURE_TOPIC,
    TEMPERATURE_MSGTYPE,
    TWIST_COVARIANCE_MSGTYPE,
    VECTOR3_MSGTYPE,
    WIND_RAW_TOPIC,
    WIND_TRUE_TOPIC,
    Reason,
    bag_topic,
    current_mean_topic,
    current_stats_topic,
    seconds_to_iso8601,
    wind_fluxes_topic,
    wind_mean_topic,
    wind_stats_topic,
)
from buoy_common.namespaces import NamespacedWriter, TopicView
from buoy_common.safe_output import check_outputs_apart_from_inputs, staged_file
from buoy_nav.config import FusionConfig
from buoy_nav.fusion_messages import STATUS_FIX, NavValues
from buoy_processing.offline_fusion import (
    OfflineFusion,
    forward_pass,
    merged_with_smoothed,
    relative_topic,
    sensor_topics_of,
    spill_parent_of,
    truth_topics_of,
)
from buoy_processing.output_series import FlowSeries, NavigationSeries
from wind_comp.compensation_messages import (
    FlowSample,
    anemometer_sample,
    anemometer_sample_cdr,
    dvl_sample,
    flows_cdr,
    flux_message,
    product_messages,
    temperature_sample,
)
from wind_comp.config import CompensatorConfig, CurrentConfig
from wind_comp.flux_products import FluxProduct
from wind_comp.pipeline import (
    CompensationOutput,
    CompensationPipeline,
    current_pipeline,
    wind_pipeline,
)
from wind_comp.products import CurrentProduct, WindProduct

WIND_PRODUCTS_CSV_SUFFIX = "_wind_products.csv"
WIND_FLUXES_CSV_SUFFIX = "_wind_fluxes.csv"
CURRENT_PRODUCTS_CSV_SUFFIX = "_current_products.csv"
PROGRESS_EVERY_MESSAGES = 2000
# Sensor samples handed to the compensation at a time: enough to pay numpy's per-call cost
# once per stretch, few enough to keep the memory flat.
SAMPLES_PER_STRETCH = 256


def products_csv_path(out_bag, suffix: str = WIND_PRODUCTS_CSV_SUFFIX) -> Path:
    """Where the products of ``out_bag`` go: beside it, ``<name>_wind_products.csv`` (or the
    ``suffix`` given, ``_current_products.csv`` for the current)."""
    out_bag = Path(out_bag)
    if not out_bag.name:  # "." or "..": named after the directory it stands for
        out_bag = out_bag.resolve()
    return out_bag.with_name(out_bag.name + suffix)


@dataclass
class CorrectionSummary:
    """What one correction (the wind's or the current's) did over a bag."""

    status_counts: dict[str, int] = field(default_factory=dict)
    """Output samples by outcome: ``valid`` or the reason they are invalid."""
    rejected_messages: Counter = field(default_factory=Counter)
    """Input messages rejected, by reason (their outputs are invalid)."""
    wrong_frames: Counter = field(default_factory=Counter)
    """Frames of the input messages rejected for their frame, with counts."""
    products: list = field(default_factory=list)
    csv_path: Path | None = None
    fluxes: list = field(default_factory=list)
    """The eddy-covariance fluxes (:class:`~wind_comp.flux_products.FluxProduct`), wind only."""
    fluxes_csv_path: Path | None = None
    rejected_temperatures: Counter = field(default_factory=Counter)
    """``anemometer/temperature`` messages rejected, by reason."""


@dataclass
class ProcessSummary:
    """What a run did: counts of outputs and rejections, products, timing."""

    wind: CorrectionSummary | None = None
    """The wind compensation; None when the bag has no ``anemometer/wind``."""
    current: CorrectionSummary | None = None
    """The current estimate; None when the bag has no ``dvl/velocity``."""
    topic_counts: dict[str, int] = field(default_factory=dict)
    fusion_lines: list[str] = field(default_factory=list)
    duration_s: float = 0.0
    wall_s: float = 0.0
    recovery: Recovery | None = None
    """How much of a cut input bag was recovered; None for a complete bag."""


def _anemometer_record(
    reader: BagReader, message: BagMessage, expected_frame_id: str
) -> tuple[FlowSample, int, int]:
    parsed = anemometer_sample_cdr(message.raw, expected_frame_id)
    if parsed is None:
        decoded = reader.decode(message)
        stamp = decoded.header.stamp
        parsed = (anemometer_sample(decoded, expected_frame_id), stamp.sec, stamp.nanosec)
    return parsed


def _dvl_record(
    reader: BagReader, message: BagMessage, expected_frame_id: str
) -> tuple[FlowSample, int, int]:
    decoded = reader.decode(message)
    stamp = decoded.header.stamp
    return dvl_sample(decoded, expected_frame_id), stamp.sec, stamp.nanosec


class OfflineCorrection:
    """What ``compensation_node`` or ``current_node`` does, fed from a bag and writing to one.

    Navigation solutions come as the fusion's :class:`~buoy_nav.fusion_messages.NavValues`
    (what ``nav/odometry`` and ``nav/fix`` carry, in that order), sensor samples as the records
    of the sensor's topic; the outputs and the products are written with the log time of the
    record after which they were decided.
    """

    def __init__(
        self,
        pipeline: CompensationPipeline,
        writer: BackgroundBagWriter | NamespacedWriter,
        output_topic: str,
        product_topics,
        read_record,
        expected_frame_id: str,
        keep_series: bool = False,
        temperature_topic: str | None = None,
    ):
        """pipeline: the node's pipeline; output_topic: one vector per sample; product_topics:
        (mean topic, statistics topic) of a window length, s; read_record: a sensor record and
        the frame expected of it as (sample, header sec, header nanosec); keep_series: keep the
        corrected samples (:attr:`series`) for the NetCDF file; temperature_topic: the stored
        ``anemometer/temperature`` whose records go to the fluxes (None: no temperature)."""
        self.pipeline = pipeline
        self.writer = writer
        self.rejected: Counter[str] = Counter()
        self.wrong_frames: Counter[str] = Counter()
        self._expected_frame_id = expected_frame_id
        self.products: list = []
        self.fluxes: list[FluxProduct] = []
        self.temperature_topic = temperature_topic
        self.rejected_temperatures: Counter[str] = Counter()
        self._output_topic = bag_topic(output_topic)
        self._product_topics = product_topics
        self._read_record = read_record
        self.series = FlowSeries(pipeline.sensor.reason) if keep_series else None
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

    def add_sample(self, reader: BagReader, message: BagMessage) -> None:
        """One sensor record; every few hundred, the decided samples are written."""
        sample, sec, nanosec = self._read_record(reader, message, self._expected_frame_id)
        rejection = self.pipeline.add_sample(sample)
        if rejection is not None:
            self.rejected[rejection] += 1
            if rejection == Reason.WRONG_FRAME:
                self.wrong_frames[sample.frame_id] += 1
        self._stamps.append((sec, nanosec))
        self._samples_waiting += 1
        if self._samples_waiting >= SAMPLES_PER_STRETCH:
            self._samples_waiting = 0
            self._write(self.pipeline.ready(), message.log_time_ns)

    def add_temperature(self, reader: BagReader, message: BagMessage) -> None:
        """One ``anemometer/temperature`` record, for the fluxes."""
        sample = temperature_sample(reader.decode(message), self._expected_frame_id)
        if isinstance(sample, str):
            self.rejected_temperatures[sample] += 1
            return
        self._write_products(self.pipeline.add_temperature(*sample), message.log_time_ns)

    def finish(self, log_time_ns: int) -> None:
        """End of the data: every sample decided and written, partial windows closed."""
        self._write(self.pipeline.flush(), log_time_ns)

    def summary(self, csv_path: Path, fluxes_csv_path: Path | None = None) -> CorrectionSummary:
        return CorrectionSummary(
            status_counts=self.pipeline.status_counts(),
            rejected_messages=self.rejected,
            wrong_frames=self.wrong_frames,
            products=self.products,
            csv_path=csv_path,
            fluxes=self.fluxes,
            fluxes_csv_path=fluxes_csv_path,
            rejected_temperatures=self.rejected_temperatures,
        )

    def _write(self, output: CompensationOutput, log_time_ns: int) -> None:
        stamps = [self._stamps.popleft() for _ in range(len(output.samples))]
        secs = np.array([sec for sec, _ in stamps], dtype=np.int64)
        nanosecs = np.array([nanosec for _, nanosec in stamps], dtype=np.int64)
        for raw in flows_cdr(secs, nanosecs, output.samples.flow_enu_mps):
            self.writer.write_raw(self._output_topic, VECTOR3_MSGTYPE, log_time_ns, raw)
        if self.series is not None:
            self.series.add(secs, nanosecs, output.samples)
        self._write_products(output.products, log_time_ns)

    def _write_products(self, products: list, log_time_ns: int) -> None:
        mean_topic, stats_topic = self._product_topics
        for product in products:
            if isinstance(product, FluxProduct):
                self.fluxes.append(product)
                self.writer.write(
                    bag_topic(wind_fluxes_topic(product.window_s)),
                    FLOAT64_ARRAY_MSGTYPE,
                    log_time_ns,
                    flux_message(Float64MultiArray, MultiArrayDimension, product),
                )
                continue
            self.products.append(product)
            mean, stats = product_messages(
                Vector3Stamped, Float64MultiArray, MultiArrayDimension, product
            )
            self.writer.write(
                bag_topic(mean_topic(product.window_s)), VECTOR3_MSGTYPE, log_time_ns, mean
            )
            self.writer.write(
                bag_topic(stats_topic(product.window_s)), FLOAT64_ARRAY_MSGTYPE, log_time_ns, stats
            )


ISO_TIME_COLUMNS = ("window_start_utc", "window_end_utc")
"""The first columns of a products CSV: the window's bounds as ISO 8601 UTC times
(``window_start_s`` and ``window_end_s`` as text a spreadsheet or pandas reads as time)."""


def write_products_csv(products: list, product_type: type, path: Path) -> None:
    """One row per closed averaging window: the window's bounds in ISO 8601 UTC
    (:data:`ISO_TIME_COLUMNS`), then the ``WindProduct`` or ``CurrentProduct`` fields, columns
    named with their units. The file appears only once complete."""
    names = [f.name for f in fields(product_type)]
    with staged_file(path) as stream:
        writer = csv.writer(stream)
        writer.writerow([*ISO_TIME_COLUMNS, *names])
        for product in products:
            writer.writerow(
                [
                    seconds_to_iso8601(product.window_start_s),
                    seconds_to_iso8601(product.window_end_s),
                    *(_csv_value(getattr(product, name)) for name in names),
                ]
            )


def _csv_value(value) -> str:
    if isinstance(value, float):
        return "nan" if math.isnan(value) else f"{value:.6f}"
    return str(value)


def _stored_sensor(reader: BagReader, topic: str, msgtype: str) -> str | None:
    """The stored name of a flow sensor's topic in the bag, None when absent; BagError when it
    holds another type."""
    stored = next((n for n in reader.topics if relative_topic(n) == topic), None)
    if stored is not None and reader.topics[stored].msgtype != msgtype:
        raise BagError(
            f"bag {reader.path}: topic {stored} holds {reader.topics[stored].msgtype}, "
            f"expected {msgtype}"
        )
    return stored


def process_bag(
    in_bag,
    out_bag,
    fusion_config: FusionConfig,
    compensator_config: CompensatorConfig,
    overwrite: bool = False,
    current_config: CurrentConfig | None = None,
    view: TopicView | None = None,
    smooth: bool = False,
    write_in_background: bool = True,
    netcdf_path=None,
    history: str = "",
    netcdf_attributes: dict[str, str] | None = None,
) -> ProcessSummary:
    """Fuse ``in_bag`` and correct its wind and its DVL samples into ``out_bag`` (a new bag;
    replaced with ``overwrite``) and the products CSVs beside it, over the topics of ``view``'s
    namespace (the root when None), writing into the same namespace; with ``smooth`` on the
    smoothed navigation (see the module docstring). ``current_config`` None: the defaults of
    ``current_node`` (``dvl.position`` and ``dvl.rpy_deg`` included). Raises BagError for a
    missing or unreadable bag or one without the fusion's topics and without both
    ``anemometer/wind`` and ``dvl/velocity``, and OutputError, before anything is read or
    written, if an output is, contains or lies inside ``in_bag``.

    The bag is written by a process of its own, on a second core; with ``write_in_background``
    False, the same bag is written in this process, for a caller that keeps every core busy
    with bags of its own (``process_archive``).

    With ``netcdf_path`` the corrected series, the products and the navigation are also
    written there as NetCDF-CF (:mod:`buoy_processing.netcdf_output`; ``history`` is the command
    that asked for it, ``netcdf_attributes`` global attributes of the user's); an existing
    file is replaced only with ``overwrite`` (OutputError before anything is read
    otherwise)."""
    started = time.monotonic()
    csv_paths = {
        name: products_csv_path(out_bag, suffix)
        for name, suffix in (
            ("wind", WIND_PRODUCTS_CSV_SUFFIX),
            ("current", CURRENT_PRODUCTS_CSV_SUFFIX),
            ("fluxes", WIND_FLUXES_CSV_SUFFIX),
        )
    }
    extra_outputs = [] if netcdf_path is None else [netcdf_path]
    check_outputs_apart_from_inputs([in_bag], [out_bag, *csv_paths.values(), *extra_outputs])
    if netcdf_path is not None:
        # Imported for a run that writes NetCDF only: xarray, pandas and the modules they bring
        # cost every other run more than a second of CPU at start-up.
        from buoy_processing import netcdf_output

        netcdf_output.check_netcdf_output(netcdf_path, overwrite)
    keep = netcdf_path is not None
    navigation = NavigationSeries() if keep else None
    view = view or TopicView()
    current_config = current_config or CurrentConfig()
    with BagReader(in_bag, view) as reader:
        sensors = sensor_topics_of(reader, fusion_config)
        stored_wind = _stored_sensor(reader, WIND_RAW_TOPIC, VECTOR3_MSGTYPE)
        stored_dvl = _stored_sensor(reader, DVL_TOPIC, TWIST_COVARIANCE_MSGTYPE)
        stored_temperature = _stored_sensor(reader, SONIC_TEMPERATURE_TOPIC, TEMPERATURE_MSGTYPE)
        if stored_wind is None and stored_dvl is None:
            where = f" in namespace {view.label}" if view.namespace else ""
            raise BagError(
                f"bag {reader.path} has neither {WIND_RAW_TOPIC} nor {DVL_TOPIC}{where}: "
                "nothing to correct"
            )
        truth = truth_topics_of(reader)
        relative_of = {stored: relative for relative, stored in sensors.items()}

        def corrections_into(writer: NamespacedWriter) -> dict[str, OfflineCorrection]:
            """The corrections of the bag's flow sensors, by stored topic."""
            corrections = {}
            if stored_wind is not None:
                corrections[stored_wind] = OfflineCorrection(
                    wind_pipeline(compensator_config),
                    writer,
                    WIND_TRUE_TOPIC,
                    (wind_mean_topic, wind_stats_topic),
                    _anemometer_record,
                    compensator_config.anemometer_frame_id,
                    keep,
                    stored_temperature,
                )
            if stored_dvl is not None:
                corrections[stored_dvl] = OfflineCorrection(
                    current_pipeline(current_config),
                    writer,
                    CURRENT_TOPIC,
                    (current_mean_topic, current_stats_topic),
                    _dvl_record,
                    current_config.dvl_frame_id,
                    keep,
                )
            return corrections

        writer_class = BackgroundBagWriter if write_in_background else BagWriter
        if smooth:
            fusion = OfflineFusion(fusion_config, None, spill_parent_of(out_bag), smooth=True)
            try:
                # The writing process starts during the forward pass: until it is ready the
                # writer keeps what it is given, and the second pass produces fast.
                with writer_class(out_bag, overwrite=overwrite) as bag_writer:
                    writer = NamespacedWriter(bag_writer, view)
                    forward_pass(reader, fusion, sensors, relative_of, f"process_bag {in_bag}")
                    corrections = corrections_into(writer)
                    smoothed_corrections(reader, fusion, corrections, writer, truth, navigation)
            finally:
                fusion.close()
        else:
            with (
                BagProgress(reader, f"process_bag {in_bag}") as progress,
                writer_class(out_bag, overwrite=overwrite) as bag_writer,
            ):
                writer = NamespacedWriter(bag_writer, view)
                fusion = OfflineFusion(fusion_config, writer)
                corrections = corrections_into(writer)
                forward_corrections(
                    reader, fusion, corrections, writer, relative_of, truth, progress, navigation
                )
        duration_s = reader.duration_s
    summaries = {}
    for stored, product_type, name in (
        (stored_wind, WindProduct, "wind"),
        (stored_dvl, CurrentProduct, "current"),
    ):
        if stored is None:
            continue
        correction = corrections[stored]
        write_products_csv(correction.products, product_type, csv_paths[name])
        if name == "wind":
            write_products_csv(correction.fluxes, FluxProduct, csv_paths["fluxes"])
            summaries[name] = correction.summary(csv_paths[name], csv_paths["fluxes"])
        else:
            summaries[name] = correction.summary(csv_paths[name])
    if netcdf_path is not None:
        wind = corrections.get(stored_wind)
        current = corrections.get(stored_dvl)
        content = netcdf_output.NetcdfContent(
            source=str(in_bag),
            navigation=navigation,
            wind=None if wind is None else wind.series,
            current=None if current is None else current.series,
            wind_products=[] if wind is None else wind.products,
            fluxes=[] if wind is None else wind.fluxes,
            fluxes_despiked=compensator_config.flux_despike,
            current_products=[] if current is None else current.products,
            history=history,
            attributes=dict(netcdf_attributes or {}),
        )
        netcdf_output.write_netcdf(netcdf_path, content, overwrite)
    return ProcessSummary(
        **summaries,
        topic_counts=writer.counts,
        fusion_lines=fusion.summary(),
        duration_s=duration_s,
        wall_s=time.monotonic() - started,
        recovery=reader.recovery,
    )


def _temperature_topics(corrections: dict[str, OfflineCorrection]) -> list[str]:
    return [c.temperature_topic for c in corrections.values() if c.temperature_topic]


def _route(corrections: dict[str, OfflineCorrection], reader: BagReader, message) -> None:
    """A sensor record to the correction that takes it: a flow sensor's sample, or the sonic
    temperature of the wind's fluxes."""
    correction = corrections.get(message.topic)
    if correction is not None:
        correction.add_sample(reader, message)
        return
    for correction in corrections.values():
        if message.topic == correction.temperature_topic:
            correction.add_temperature(reader, message)


def smoothed_corrections(
    reader: BagReader,
    fusion: OfflineFusion,
    corrections: dict[str, OfflineCorrection],
    writer: NamespacedWriter,
    truth: list[str],
    navigation: NavigationSeries | None = None,
) -> None:
    """The corrections of a smoothing run, after ``fusion``'s forward pass: the smoothed
    solutions and the sensor samples in log-time order, written to ``writer`` (the solutions
    also kept in ``navigation`` when given)."""
    fusion.writer = writer
    log_time_ns = reader.start_ns
    topics = [*corrections, *_temperature_topics(corrections), *truth]
    for message, solution in merged_with_smoothed(reader, fusion, topics):
        if message is None:
            forward, smoothed, log_time_ns = solution
            fusion.write_smoothed_values(forward, smoothed, log_time_ns)
            if navigation is not None:
                navigation.add([smoothed])
            for correction in corrections.values():
                correction.add_navigation([smoothed])
            continue
        log_time_ns = message.log_time_ns
        writer.write_raw(message.topic, message.msgtype, log_time_ns, message.raw)
        _route(corrections, reader, message)
    for correction in corrections.values():
        correction.finish(log_time_ns)


def forward_corrections(
    reader: BagReader,
    fusion: OfflineFusion,
    corrections: dict[str, OfflineCorrection],
    writer: NamespacedWriter,
    relative_of: dict[str, str],
    truth: list[str],
    progress: BagProgress,
    navigation: NavigationSeries | None = None,
) -> None:
    """Fusion and corrections in one pass over the bag: each solution to every correction as
    it comes (and to ``navigation`` when given), each sensor sample to its correction."""
    log_time_ns = reader.start_ns
    topics = [*relative_of, *corrections, *_temperature_topics(corrections), *truth]
    for index, message in enumerate(reader.messages(topics)):
        log_time_ns = message.log_time_ns
        topic = relative_of.get(message.topic)
        if topic is not None:
            solutions = fusion.add_message(reader, topic, message)
            if solutions:
                if navigation is not None:
                    navigation.add(solutions)
                for correction in corrections.values():
                    correction.add_navigation(solutions)
        else:
            writer.write_raw(message.topic, message.msgtype, log_time_ns, message.raw)
            _route(corrections, reader, message)
        if index % PROGRESS_EVERY_MESSAGES == 0:
            progress.reached(log_time_ns)
    solutions = fusion.finish()
    if navigation is not None:
        navigation.add(solutions)
    for correction in corrections.values():
        correction.add_navigation(solutions)
        correction.finish(log_time_ns)
    progress.done()
