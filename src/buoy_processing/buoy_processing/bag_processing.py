"""Fusion, wind compensation and current estimate over a recorded bag: the offline twin of the
nodes.

:func:`process_bag` runs over the bag's sensor topics, in log-time order, the core of
``fusion_node`` (:func:`buoy_processing.offline_runner.run_fusion`, as ``fuse_bag`` does)
followed by the cores of ``compensation_node`` (when the bag has ``anemometer/wind``) and
``current_node`` (when it has ``dvl/velocity``),
:class:`wind_comp.pipeline.CompensationPipeline` both (:class:`BagCorrections`): each navigation
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
are computed with the smoothed attitude and velocity.

The compensation runs in this process, on whole stretches of samples at a time; the process
that writes the bag only writes.
"""

from __future__ import annotations

import csv
import math
import re
import time
from collections import Counter, deque
from dataclasses import dataclass, field, fields
from pathlib import Path
from typing import NamedTuple

import numpy as np
from geometry_msgs.msg import Vector3Stamped
from std_msgs.msg import Float64MultiArray, MultiArrayDimension

from buoy_common.bag_io import BagError, BagMessage, BagReader, Recovery
from buoy_common.contract import (
    CURRENT_TOPIC,
    CURRENT_WITH_COVARIANCE_TOPIC,
    DVL_TOPIC,
    FLOAT64_ARRAY_MSGTYPE,
    SONIC_TEMPERATURE_TOPIC,
    TEMPERATURE_MSGTYPE,
    TWIST_COVARIANCE_MSGTYPE,
    VECTOR3_MSGTYPE,
    WIND_RAW_TOPIC,
    WIND_TRUE_TOPIC,
    WIND_TRUE_WITH_COVARIANCE_TOPIC,
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
from buoy_common.record_facts import ImportedRecord, read_imported_record
from buoy_common.safe_output import check_outputs_apart_from_inputs, staged_file
from buoy_common.sensor_frames import sensor_transforms, shared_values
from buoy_nav.config import FusionConfig
from buoy_nav.fusion_messages import STATUS_FIX, NavValues
from buoy_processing.nav_rows_output import OrderedOutput
from buoy_processing.offline_fusion import (
    OfflineFusion,
    relative_topic,
    sensor_topics_of,
    truth_topics_of,
)
from buoy_processing.offline_runner import OfflineRun, run_fusion
from buoy_processing.output_facts import OutputFacts, output_facts, source_use_of
from buoy_processing.output_series import NANOSECONDS, FlowSeries, NavigationSeries
from buoy_processing.solution_columns import HeldBackSolutions, SolutionColumns, Stamp
from wind_comp.compensation_messages import (
    FlowSample,
    anemometer_sample,
    anemometer_sample_cdr,
    anemometer_sample_fields,
    dvl_sample,
    flows_cdr,
    flows_with_covariance_cdr,
    flux_message,
    product_messages,
    temperature_sample,
    temperature_sample_fields,
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
# Sensor samples handed to the compensation at a time: enough to pay numpy's per-call cost
# once per stretch, few enough to keep the memory flat and, in a bag, to log each corrected
# sample within a stretch of its record. Without a bag only the memory bounds it: a stretch
# eight times longer took 4 % off a motion-pack hour.
SAMPLES_PER_STRETCH = 256
SAMPLES_PER_STRETCH_WITHOUT_BAG = 2048
# Navigation solutions held for a correction at most (20 MB): while its sensor is silent no
# stretch fills, and the solutions, which only its samples would take, must not pile up.
NAV_SOLUTIONS_HELD_AT_MOST = 65_536


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
    facts: OutputFacts | None = None
    """What the outputs say about the run: north reference, sensors used, site, data span
    (:mod:`buoy_processing.output_facts`)."""
    statements: list[str] = field(default_factory=list)
    """What the sensors leave unobserved, said at the start (printed unless the caller asked
    to report them itself)."""


ANEMOMETER_RECORD_FIELDS = ("frame_id", "vector")
"""What :func:`_anemometer_record` reads of an ``anemometer/wind`` message read with its chunk,
after the header stamp (:mod:`buoy_processing.chunk_records`)."""

TEMPERATURE_RECORD_FIELDS = ("frame_id", "temperature")
"""What :meth:`OfflineCorrection.add_temperature` reads of an ``anemometer/temperature`` message
read with its chunk, after the header stamp."""


def _anemometer_record(
    reader: BagReader, message: BagMessage, expected_frame_id: str, record: tuple | None = None
) -> tuple[FlowSample, int, int]:
    if record is not None:
        sec, nanosec, frame_id, vector = record
        return anemometer_sample_fields(sec, nanosec, frame_id, tuple(vector), expected_frame_id)
    parsed = anemometer_sample_cdr(message.raw, expected_frame_id)
    if parsed is None:
        decoded = reader.decode(message)
        stamp = decoded.header.stamp
        parsed = (anemometer_sample(decoded, expected_frame_id), stamp.sec, stamp.nanosec)
    return parsed


def _dvl_record(
    reader: BagReader, message: BagMessage, expected_frame_id: str, record: None = None
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
        writer: NamespacedWriter | None,
        output_topic: str,
        covariance_topic: str,
        product_topics,
        read_record,
        expected_frame_id: str,
        keep_series: bool = False,
        temperature_topic: str | None = None,
        samples_per_stretch: int = SAMPLES_PER_STRETCH,
    ):
        """pipeline: the node's pipeline; writer: where the outputs go (None: no bag, nothing
        encoded); output_topic: one vector per sample; covariance_topic:
        the same with its covariance; product_topics:
        (mean topic, statistics topic) of a window length, s; read_record: a sensor record, the
        frame expected of it and the record's fields when its chunk was read together (or None)
        as (sample, header sec, header nanosec); keep_series: keep the
        corrected samples (:attr:`series`) for the NetCDF file; temperature_topic: the stored
        ``anemometer/temperature`` whose records go to the fluxes (None: no temperature);
        samples_per_stretch: sensor records after which the decided samples are written."""
        self.pipeline = pipeline
        self.writer = writer
        self.rejected: Counter[str] = Counter()
        self.valid_samples = 0
        """Sensor records that passed the input checks (the others are counted by reason in
        :attr:`rejected`)."""
        self.wrong_frames: Counter[str] = Counter()
        self._expected_frame_id = expected_frame_id
        self.products: list = []
        self.fluxes: list[FluxProduct] = []
        self.temperature_topic = temperature_topic
        self.rejected_temperatures: Counter[str] = Counter()
        self.valid_temperatures = 0
        """``anemometer/temperature`` records handed to the fluxes."""
        self._output_topic = bag_topic(output_topic)
        self._covariance_topic = bag_topic(covariance_topic)
        self._product_topics = product_topics
        self._read_record = read_record
        self.series = FlowSeries(pipeline.sensor.reason) if keep_series else None
        self._stamps: deque[tuple[int, int]] = deque()
        self._samples_waiting = 0
        self._samples_per_stretch = samples_per_stretch
        self._log_time_ns = 0
        """Log time (ns) of the latest record of the sensor's topics."""
        self.held_back: HeldBackSolutions | None = None
        """The solutions held back for the pipeline, in a run that makes no ``nav/*`` values
        (None: they come one by one, :meth:`add_navigation`)."""

    def add_navigation(self, solutions: list[NavValues]) -> None:
        """The ``nav/odometry`` and ``nav/fix`` of each solution, as the node receives them;
        beyond :data:`NAV_SOLUTIONS_HELD_AT_MOST` held, what they decide is written."""
        pipeline = self.pipeline
        add_odometry, add_fix = pipeline.add_odometry, pipeline.add_fix
        if pipeline.n_navigation_held + len(solutions) > NAV_SOLUTIONS_HELD_AT_MOST:
            self._write(pipeline.ready(), self._log_time_ns)
        for values in solutions:
            pose_covariance = values.pose_covariance
            add_odometry(
                values.sec + values.nanosec * 1e-9,
                values.attitude_xyzw,
                values.angular_rate_body_rad_s,
                values.velocity_body_mps,
                max(pose_covariance[21], pose_covariance[28], pose_covariance[35]),
                values.attitude_covariance_rad2,
                values.body_twist_covariance,
            )
            add_fix(STATUS_FIX, values.latitude_deg)

    @property
    def held(self) -> int:
        """Solutions held, by the pipeline and held back for it."""
        return self.pipeline.n_navigation_held + self.held_back.in_order

    def make_room(self, count: int) -> None:
        """Before ``count`` more solutions are held back: beyond
        :data:`NAV_SOLUTIONS_HELD_AT_MOST` held, what they decide is written."""
        if self.held + count > NAV_SOLUTIONS_HELD_AT_MOST:
            self._write(self._ready(), self._log_time_ns)

    def take_columns(self, columns: SolutionColumns) -> None:
        """Held-back solutions handed over (:class:`HeldBackSolutions`)."""
        self.pipeline.add_navigation_columns(columns.navigation)

    def _ready(self) -> CompensationOutput:
        """What the pipeline decides with every solution taken so far."""
        if self.held_back is not None:
            self.held_back.hand_over()
        return self.pipeline.ready()

    def add_sample(
        self, reader: BagReader, message: BagMessage, record: tuple | None = None
    ) -> None:
        """One sensor record (its fields in ``record`` when its chunk was read together); after
        a stretch of them, the decided samples are written."""
        self._log_time_ns = message.log_time_ns
        sample, sec, nanosec = self._read_record(reader, message, self._expected_frame_id, record)
        held_back = 0 if self.held_back is None else self.held_back.in_order
        rejection = self.pipeline.add_sample(sample, held_back)
        if rejection is None:
            self.valid_samples += 1
        else:
            self.rejected[rejection] += 1
            if rejection == Reason.WRONG_FRAME:
                self.wrong_frames[sample.frame_id] += 1
        self._count_given_up()
        self._stamps.append((sec, nanosec))
        self._samples_waiting += 1
        if self._samples_waiting >= self._samples_per_stretch:
            self._samples_waiting = 0
            self._write(self._ready(), message.log_time_ns)

    def add_temperature(
        self, reader: BagReader, message: BagMessage, record: tuple | None = None
    ) -> None:
        """One ``anemometer/temperature`` record, for the fluxes (its fields in ``record``,
        :data:`TEMPERATURE_RECORD_FIELDS` after the header stamp, when its chunk was read
        together)."""
        self._log_time_ns = message.log_time_ns
        if record is None:
            sample = temperature_sample(reader.decode(message), self._expected_frame_id)
        else:
            sample = temperature_sample_fields(*record, self._expected_frame_id)
        if isinstance(sample, str):
            self.rejected_temperatures[sample] += 1
            return
        self.valid_temperatures += 1
        products = self.pipeline.add_temperature(*sample)
        if products:
            self._write_products(products, message.log_time_ns)

    def finish(self, log_time_ns: int) -> None:
        """End of the data: every sample decided and written, partial windows closed."""
        if self.held_back is not None:
            self.held_back.hand_over()
        self._write(self.pipeline.flush(), log_time_ns)
        self._count_given_up()

    def _count_given_up(self) -> None:
        """Samples held off the sensor's sequence passed the input checks on arrival; those
        given up since (a second stream's) are rejected after all."""
        given_up = self.pipeline.take_given_up()
        if given_up:
            self.valid_samples -= given_up
            self.rejected[Reason.OUT_OF_SEQUENCE] += given_up

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
        if self.writer is not None:
            self._write_samples(secs, nanosecs, output.samples, log_time_ns)
        if self.series is not None:
            self.series.add(secs, nanosecs, output.samples)
        self._write_products(output.products, log_time_ns)

    def _write_samples(self, secs, nanosecs, samples, log_time_ns: int) -> None:
        """The corrected vector of each sample, alone and with its covariance."""
        for raw, with_covariance in zip(
            flows_cdr(secs, nanosecs, samples.flow_enu_mps),
            flows_with_covariance_cdr(
                secs, nanosecs, samples.flow_enu_mps, samples.covariance.total
            ),
            strict=True,
        ):
            self.writer.write_raw(self._output_topic, VECTOR3_MSGTYPE, log_time_ns, raw)
            self.writer.write_raw(
                self._covariance_topic, TWIST_COVARIANCE_MSGTYPE, log_time_ns, with_covariance
            )

    def _write_products(self, products: list, log_time_ns: int) -> None:
        mean_topic, stats_topic = self._product_topics
        writer = self.writer
        for product in products:
            if isinstance(product, FluxProduct):
                self.fluxes.append(product)
                if writer is None:
                    continue
                writer.write(
                    bag_topic(wind_fluxes_topic(product.window_s)),
                    FLOAT64_ARRAY_MSGTYPE,
                    log_time_ns,
                    flux_message(Float64MultiArray, MultiArrayDimension, product),
                )
                continue
            self.products.append(product)
            if writer is None:
                continue
            mean, stats = product_messages(
                Vector3Stamped, Float64MultiArray, MultiArrayDimension, product
            )
            writer.write(
                bag_topic(mean_topic(product.window_s)), VECTOR3_MSGTYPE, log_time_ns, mean
            )
            writer.write(
                bag_topic(stats_topic(product.window_s)), FLOAT64_ARRAY_MSGTYPE, log_time_ns, stats
            )


DIRECTION_FIELD_SUFFIX = "direction_deg"
"""The product fields that are directions: their CSV columns name their north."""

ISO_TIME_COLUMNS = ("window_start_utc", "window_end_utc")
"""The first columns of a products CSV: the window's bounds as ISO 8601 UTC times
(``window_start_s`` and ``window_end_s`` as text a spreadsheet or pandas reads as time)."""


def write_products_csv(
    products: list, product_type: type, path: Path, facts: OutputFacts | None = None
) -> None:
    """One row per closed averaging window: the window's bounds in ISO 8601 UTC
    (:data:`ISO_TIME_COLUMNS`), then the ``WindProduct`` or ``CurrentProduct`` fields, columns
    named with their units, a direction's with its north (:func:`csv_column_name`). The file
    appears only once complete."""
    names = [f.name for f in fields(product_type)]
    with staged_file(path) as stream:
        writer = csv.writer(stream)
        writer.writerow([*ISO_TIME_COLUMNS, *(csv_column_name(name, facts) for name in names)])
        for product in products:
            writer.writerow(
                [
                    seconds_to_iso8601(product.window_start_s),
                    seconds_to_iso8601(product.window_end_s),
                    *(_csv_value(getattr(product, name)) for name in names),
                ]
            )


def csv_column_name(field_name: str, facts: OutputFacts | None) -> str:
    """The CSV column of a product field: its name, a direction's with the north it is
    referenced to before its unit (``vector_mean_direction_true_north_deg``,
    ``direction_magnetic_north_deg``); unchanged without ``facts``."""
    if facts is None or not field_name.endswith(DIRECTION_FIELD_SUFFIX):
        return field_name
    stem = field_name.removesuffix("_deg")
    return f"{stem}_{facts.north_token}_deg"


def product_field_of_csv_column(column: str) -> str:
    """The product field a products CSV column holds: the inverse of :func:`csv_column_name`
    (``vector_mean_direction_magnetic_north_deg`` → ``vector_mean_direction_deg``)."""
    named = re.fullmatch(r"(\w*direction)_[a-z]+_north_deg", column)
    return f"{named.group(1)}_deg" if named else column


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


class FlowTopics(NamedTuple):
    """Stored names of a bag's flow sensor topics; None for those it lacks."""

    wind: str | None
    """``anemometer/wind``."""
    dvl: str | None
    """``dvl/velocity``."""
    temperature: str | None
    """``anemometer/temperature``, for the wind's fluxes."""


def flow_topics_of(reader: BagReader, view: TopicView) -> FlowTopics:
    """The flow sensors of ``reader``'s bag (read in ``view``'s namespace). Raises BagError when
    it has neither ``anemometer/wind`` nor ``dvl/velocity``, or one of them holds another type."""
    flows = FlowTopics(
        _stored_sensor(reader, WIND_RAW_TOPIC, VECTOR3_MSGTYPE),
        _stored_sensor(reader, DVL_TOPIC, TWIST_COVARIANCE_MSGTYPE),
        _stored_sensor(reader, SONIC_TEMPERATURE_TOPIC, TEMPERATURE_MSGTYPE),
    )
    if flows.wind is None and flows.dvl is None:
        where = f" in namespace {view.label}" if view.namespace else ""
        raise BagError(
            f"bag {reader.path} has neither {WIND_RAW_TOPIC} nor {DVL_TOPIC}{where}: "
            "nothing to correct"
        )
    return flows


class BagCorrections:
    """The wind compensation and the current estimate of a bag, following its fusion (a
    :class:`~buoy_processing.offline_runner.BagConsumer`): every solution to each correction,
    every sensor record to the correction that takes it."""

    def __init__(
        self,
        flows: FlowTopics,
        compensator_config: CompensatorConfig,
        current_config: CurrentConfig,
        navigation: NavigationSeries | None = None,
        samples_per_stretch: int = SAMPLES_PER_STRETCH,
    ):
        """navigation: when given, it keeps the solutions and the corrections keep their
        corrected samples, for the NetCDF file; samples_per_stretch: each correction's
        (:class:`OfflineCorrection`)."""
        self.flows = flows
        self._samples_per_stretch = samples_per_stretch
        self.compensator_config = compensator_config
        self.current_config = current_config
        self.navigation = navigation
        self.wind: OfflineCorrection | None = None
        self.current: OfflineCorrection | None = None
        self._running: list[OfflineCorrection] = []
        """The corrections started: every solution goes to each."""
        self._room = 0
        """Solutions that may be held back before the corrections are asked to make room."""

    @property
    def topics(self) -> list[str]:
        """Stored names of the topics the corrections read."""
        flows = self.flows
        topics = [topic for topic in (flows.wind, flows.dvl) if topic is not None]
        if flows.wind is not None and flows.temperature is not None:
            topics.append(flows.temperature)
        return topics

    def start(
        self,
        writer: NamespacedWriter | OrderedOutput | None,
        held_back: HeldBackSolutions | None = None,
    ) -> None:
        """The corrections, writing to ``writer`` (None: no bag), taking the solutions that
        ``held_back`` hands over (None: one by one, :meth:`add_navigation`)."""
        flows = self.flows
        keep = self.navigation is not None
        if flows.wind is not None:
            self.wind = OfflineCorrection(
                wind_pipeline(self.compensator_config),
                writer,
                WIND_TRUE_TOPIC,
                WIND_TRUE_WITH_COVARIANCE_TOPIC,
                (wind_mean_topic, wind_stats_topic),
                _anemometer_record,
                self.compensator_config.anemometer_frame_id,
                keep,
                flows.temperature,
                samples_per_stretch=self._samples_per_stretch,
            )
        if flows.dvl is not None:
            self.current = OfflineCorrection(
                current_pipeline(self.current_config),
                writer,
                CURRENT_TOPIC,
                CURRENT_WITH_COVARIANCE_TOPIC,
                (current_mean_topic, current_stats_topic),
                _dvl_record,
                self.current_config.dvl_frame_id,
                keep,
                samples_per_stretch=self._samples_per_stretch,
            )
        self._running = [c for c in (self.wind, self.current) if c is not None]
        if held_back is not None:
            for correction in self._running:
                correction.held_back = held_back
                held_back.add_taker(correction.take_columns)
            if self.navigation is not None:
                held_back.add_taker(self.navigation.add_columns)

    def add_navigation(self, solutions: list[NavValues]) -> None:
        if self.navigation is not None:
            self.navigation.add(solutions)
        for correction in self._running:
            correction.add_navigation(solutions)

    def add_solution_rows(self, stamps: list[Stamp]) -> None:
        """Solutions written as rows, of header ``stamps``: held back once for every
        correction and the NetCDF file, handed over in bulk (:class:`HeldBackSolutions`)."""
        count = len(stamps)
        if count > self._room:
            for correction in self._running:
                correction.make_room(count)
            # What a correction holds grows by what is held back and by nothing else (the
            # hand-over moves it to the pipeline, which drops some): until this many more are
            # held back, no correction can exceed its bound, and none is asked.
            self._room = NAV_SOLUTIONS_HELD_AT_MOST - max(c.held for c in self._running)
        self._room -= count
        corrections = self._running[0]
        corrections.held_back.take(stamps, corrections.pipeline.latest_navigation_stamp_s)

    @property
    def record_fields(self) -> dict[str, tuple[str, ...]]:
        """Stored name → fields of the topics whose messages are best read a chunk at a time:
        ``anemometer/wind`` and the ``anemometer/temperature`` that goes with it."""
        flows = self.flows
        if flows.wind is None:
            return {}
        fields_of_topic = {flows.wind: ANEMOMETER_RECORD_FIELDS}
        if flows.temperature is not None:
            fields_of_topic[flows.temperature] = TEMPERATURE_RECORD_FIELDS
        return fields_of_topic

    def add_message(
        self, reader: BagReader, message: BagMessage, record: tuple | None = None
    ) -> None:
        """A flow sensor's sample to its correction, the sonic temperature to the wind's
        fluxes; anything else (the truth) is only copied."""
        topic = message.topic
        if topic == self.flows.wind and self.wind is not None:
            self.wind.add_sample(reader, message, record)
        elif topic == self.flows.dvl and self.current is not None:
            self.current.add_sample(reader, message)
        elif topic == self.flows.temperature and self.wind is not None:
            self.wind.add_temperature(reader, message, record)

    def finish(self, log_time_ns: int) -> None:
        for correction in self._running:
            correction.finish(log_time_ns)

    def detach(self) -> None:
        for correction in self._running:
            correction.writer = None
            correction.held_back = None


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
    nav_rate_hz: float = 0.0,
    write_bag: bool = True,
    say_statements: bool = True,
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
    written there as NetCDF-CF (:mod:`buoy_processing.netcdf_output`; ``history`` is the
    command that asked for it, ``netcdf_attributes`` global attributes of the user's); an
    existing file is replaced only with ``overwrite`` (OutputError before anything is read
    otherwise).

    With ``nav_rate_hz`` (Hz) above 0 the bag's ``nav/*`` and ``tf`` and the NetCDF file's
    navigation carry the solutions at that rate only; the corrections still use every solution
    (:mod:`buoy_processing.nav_output_rate`).

    With ``write_bag`` False no bag is written and no ``nav/*`` or ``tf`` made: the products
    CSVs (and the NetCDF file) alone, named after ``out_bag`` as always, hold the same
    products.

    With ``say_statements`` False what the sensors leave unobserved is not printed at the start
    but only returned (:attr:`ProcessSummary.statements`)."""
    started = time.monotonic()
    csv_paths = products_csv_paths(out_bag)
    _check_outputs(in_bag, [out_bag, *csv_paths.values()], netcdf_path, overwrite)
    view = view or TopicView()
    with BagReader(in_bag, view) as reader:
        sensors = sensor_topics_of(reader, fusion_config)
        current_config = current_config or CurrentConfig()
        corrections = BagCorrections(
            flow_topics_of(reader, view),
            compensator_config,
            current_config,
            None if netcdf_path is None else NavigationSeries(nav_rate_hz),
            samples_per_stretch=(
                SAMPLES_PER_STRETCH if write_bag else SAMPLES_PER_STRETCH_WITHOUT_BAG
            ),
        )
        facts_of_run = _FactsOfRun(fusion_config, read_imported_record(reader.path), nav_rate_hz)
        run = OfflineRun(
            reader,
            out_bag,
            fusion_config,
            sensors,
            f"process_bag {in_bag}",
            view,
            # The truth is only copied: a run without a bag need not read it.
            copied_topics=[*corrections.topics, *(truth_topics_of(reader) if write_bag else [])],
            smooth=smooth,
            overwrite=overwrite,
            nav_rate_hz=nav_rate_hz,
            write_in_background=write_in_background,
            write_bag=write_bag,
            static_transforms=sensor_transforms(
                shared_values(fusion_config, compensator_config, current_config), imu_link=True
            ),
            closing_metadata=facts_of_run,
            say_statements=say_statements,
        )
        fusion, topic_counts, statements, corrections = run_fusion(run, corrections)
        duration_s = reader.duration_s
    facts = facts_of_run.facts
    netcdf = _NetcdfRequest(netcdf_path, in_bag, history, netcdf_attributes, overwrite)
    summaries = _write_products(corrections, facts, out_bag, csv_paths, netcdf)
    return ProcessSummary(
        **summaries,
        topic_counts=topic_counts,
        fusion_lines=fusion.summary(),
        duration_s=duration_s,
        wall_s=time.monotonic() - started,
        recovery=reader.recovery,
        facts=facts,
        statements=statements,
    )


class _NetcdfRequest(NamedTuple):
    """What :func:`process_bag` was asked of the NetCDF file (``path`` None: no file)."""

    path: object
    in_bag: object
    history: str
    attributes: dict[str, str] | None
    overwrite: bool


def _write_products(corrections, facts, out_bag, csv_paths, netcdf: _NetcdfRequest) -> dict:
    """The products CSVs beside ``out_bag`` and the NetCDF file ``netcdf`` asks for; the
    products' summaries."""
    # Made by the bag's writer, unless no bag was written.
    Path(out_bag).parent.mkdir(parents=True, exist_ok=True)
    summaries = write_products_csvs(corrections, csv_paths, facts)
    if netcdf.path is not None:
        _write_netcdf(
            netcdf.path,
            corrections,
            facts,
            netcdf.in_bag,
            netcdf.history,
            netcdf.attributes,
            netcdf.overwrite,
        )
    return summaries


@dataclass
class _FactsOfRun:
    """The facts the outputs state, from the parameters, the valid samples of the flow
    sensors, what the fusion used, the stamps of the samples and the imported record; made once
    every message is written, for the output bag's metadata
    (:attr:`OfflineRun.closing_metadata`) and then every other writer."""

    fusion_config: FusionConfig
    record: ImportedRecord | None
    nav_rate_hz: float = 0.0
    facts: OutputFacts | None = None

    def __call__(
        self, fusion: OfflineFusion, corrections: BagCorrections
    ) -> dict[str, dict[str, str]]:
        health = fusion.engine.health()
        self.facts = output_facts(
            self.fusion_config,
            _valid_flow_samples(corrections),
            source_use_of(health),
            _sample_spans_s(corrections),
            self.record,
            aligned=health.alignments > 0,
            nav_rate_hz=self.nav_rate_hz,
        )
        return self.facts.metadata_records()


def _valid_flow_samples(corrections: BagCorrections) -> dict[str, int]:
    """The valid samples of each flow sensor topic the corrections read, by relative name."""
    wind, current = corrections.wind, corrections.current
    valid = {}
    if wind is not None:
        valid[WIND_RAW_TOPIC] = wind.valid_samples
        if wind.temperature_topic is not None:
            valid[SONIC_TEMPERATURE_TOPIC] = wind.valid_temperatures
    if current is not None:
        valid[DVL_TOPIC] = current.valid_samples
    return valid


def _sample_spans_s(corrections: BagCorrections) -> list[tuple[float, float]]:
    """(first, last) stamp in s of each output series: of the kept series when there are, else
    of the samples the products' windows hold."""
    spans = []
    for correction in (corrections.wind, corrections.current):
        if correction is None:
            continue
        if correction.series is not None and len(correction.series):
            stamps_ns = correction.series.columns()[0]
            spans.append((stamps_ns[0] / NANOSECONDS, stamps_ns[-1] / NANOSECONDS))
        elif correction.products:
            spans.append(
                (
                    min(product.first_sample_s for product in correction.products),
                    max(product.last_sample_s for product in correction.products),
                )
            )
    if corrections.navigation is not None and len(corrections.navigation):
        stamps_ns = corrections.navigation.columns()[0]
        spans.append((stamps_ns[0] / NANOSECONDS, stamps_ns[-1] / NANOSECONDS))
    return spans


def products_csv_paths(out_bag) -> dict[str, Path]:
    """The products CSVs beside ``out_bag``: the wind's, the current's and the fluxes'."""
    return {
        name: products_csv_path(out_bag, suffix)
        for name, suffix in (
            ("wind", WIND_PRODUCTS_CSV_SUFFIX),
            ("current", CURRENT_PRODUCTS_CSV_SUFFIX),
            ("fluxes", WIND_FLUXES_CSV_SUFFIX),
        )
    }


def _check_outputs(in_bag, outputs: list, netcdf_path, overwrite: bool) -> None:
    """OutputError, before anything is read, for an output that is, contains or lies inside
    ``in_bag``, or a NetCDF file that exists without ``overwrite``."""
    extra_outputs = [] if netcdf_path is None else [netcdf_path]
    check_outputs_apart_from_inputs([in_bag], [*outputs, *extra_outputs])
    if netcdf_path is not None:
        # Imported for a run that writes NetCDF only: xarray, pandas and the modules they bring
        # cost every other run more than a second of CPU at start-up.
        from buoy_processing import netcdf_output

        netcdf_output.check_netcdf_output(netcdf_path, overwrite)


def write_products_csvs(
    corrections: BagCorrections, csv_paths: dict[str, Path], facts: OutputFacts | None = None
) -> dict[str, CorrectionSummary]:
    """The products CSVs of the corrections that ran, their direction columns named after the
    north of ``facts``; their summaries by name (``wind``, ``current``)."""
    summaries = {}
    wind, current = corrections.wind, corrections.current
    if wind is not None:
        write_products_csv(wind.products, WindProduct, csv_paths["wind"], facts)
        write_products_csv(wind.fluxes, FluxProduct, csv_paths["fluxes"], facts)
        summaries["wind"] = wind.summary(csv_paths["wind"], csv_paths["fluxes"])
    if current is not None:
        write_products_csv(current.products, CurrentProduct, csv_paths["current"], facts)
        summaries["current"] = current.summary(csv_paths["current"])
    return summaries


def _write_netcdf(
    netcdf_path,
    corrections: BagCorrections,
    facts: OutputFacts,
    in_bag,
    history: str,
    attributes: dict[str, str] | None,
    overwrite: bool,
) -> None:
    """The corrected series, the products and the navigation of a run as NetCDF-CF."""
    from buoy_processing import netcdf_output

    wind, current = corrections.wind, corrections.current
    content = netcdf_output.NetcdfContent(
        source=str(in_bag),
        navigation=corrections.navigation,
        wind=None if wind is None else wind.series,
        current=None if current is None else current.series,
        wind_products=[] if wind is None else wind.products,
        fluxes=[] if wind is None else wind.fluxes,
        fluxes_despiked=corrections.compensator_config.flux_despike,
        current_products=[] if current is None else current.products,
        history=history,
        attributes=dict(attributes or {}),
        facts=facts,
    )
    netcdf_output.write_netcdf(netcdf_path, content, overwrite)
