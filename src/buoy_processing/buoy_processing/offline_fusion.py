"""The core of ``fusion_node`` fed from a recorded bag, ``nav/*`` and ``tf`` written to another.

The sensor topics ``imu/data_raw`` (required), one heading reference at least (``gnss/heading``,
``gnss/baseline``, ``imu/mag`` or ``imu/data``), and ``gnss/fix``, ``gnss/vel``, the others
(used when present) are read in log-time order and go through the same
conversion (:mod:`buoy_nav.fusion_messages`) and engine as in the live node. Every solution's
``nav/odometry``, ``nav/imu``, ``nav/velocity`` and ``nav/fix`` carry the log time of the IMU
message that produced it, and so does its ``tf`` (``map`` → ``base_link``, for 3-D views in
Foxglove or RViz). Truth topics (``truth/*``) are copied unchanged, so the output carries
its own answer. :mod:`buoy_processing.offline_runner` runs :class:`OfflineFusion` over a bag,
alone (``fuse_bag``) or ahead of the wind and current corrections (``process_bag``).
"""

from __future__ import annotations

import dataclasses
import math
from collections import Counter
from collections.abc import Iterable, Iterator
from pathlib import Path

from buoy_common.bag_io import BackgroundBagWriter, BagError, BagMessage, BagReader, BagWriter
from buoy_common.contract import (
    IMU_RAW_TOPIC,
    NAV_FORWARD_ODOMETRY_TOPIC,
    NAV_MSGTYPES,
    ODOMETRY_MSGTYPE,
    TF_MSGTYPE,
    TF_TOPIC,
    TRUTH_PREFIX,
    bag_topic,
)
from buoy_common.namespaces import NamespacedWriter
from buoy_nav.aiding import HEADING_REFERENCE_TOPICS, disabled_topics
from buoy_nav.config import FusionConfig
from buoy_nav.engine import FusionEngine
from buoy_nav.fusion_messages import (
    FUSION_INPUT_MSGTYPES,
    NavValues,
    StampBook,
    feed_imu_cdr,
    feed_imu_fields,
    feed_measurement_record,
    feed_message,
    feed_records,
    nav_values,
    odometry_cdr,
    solution_cdr,
    transform_cdr,
)
from buoy_nav.solution import Emitted
from buoy_nav.solution_rows import SolutionRows
from buoy_nav.source_health import HealthTransition, SourceStatus
from buoy_processing.nav_output_rate import NavOutputRate
from buoy_processing.solution_columns import Stamp

REQUIRED_TOPICS = (IMU_RAW_TOPIC,)
"""The fusion needs one of these at least: without a heading reference it cannot align."""
OPTIONAL_TOPICS = tuple(topic for topic in FUSION_INPUT_MSGTYPES if topic not in REQUIRED_TOPICS)
FUSION_TOPICS_HELP = (
    f"{' and '.join(REQUIRED_TOPICS)} (required), at least one heading reference of "
    f"{', '.join(HEADING_REFERENCE_TOPICS)}, and whichever of "
    f"{', '.join(t for t in OPTIONAL_TOPICS if t not in HEADING_REFERENCE_TOPICS)} it has "
    "(GNSS is optional: a moored buoy needs none)"
)
"""The fusion's input topics as the commands' help states them, from the registry."""


IMU_RECORD_FIELDS = ("angular_velocity", "linear_acceleration")
"""What :meth:`OfflineFusion.add_message` reads of an IMU sample read with its chunk, after the
header stamp (:mod:`buoy_processing.chunk_records`)."""


def relative_topic(name: str) -> str:
    """A bag topic name without its leading slash (topic names of the contract are relative)."""
    return name.lstrip("/")


# Relative nav topic → (name stored in the bag, message type).
NAV_BAG_TOPICS = {topic: (bag_topic(topic), msgtype) for topic, msgtype in NAV_MSGTYPES.items()}
FORWARD_ODOMETRY_BAG_TOPIC = bag_topic(NAV_FORWARD_ODOMETRY_TOPIC)
TF_BAG_TOPIC = bag_topic(TF_TOPIC)


def sensor_topics_of(
    reader: BagReader, config: FusionConfig, extra_required: Iterable[str] = ()
) -> dict[str, str]:
    """Relative → stored name of the fusion's input topics in ``reader``'s bag (those of the
    aiding sources ``config`` switches off left out, e.g. ``gnss/baseline``).

    Raises BagError naming what is missing or of the wrong type.
    """
    reader.require(*REQUIRED_TOPICS, *extra_required)
    stored = {relative_topic(name): name for name in reader.topics}
    found = {}
    disabled = disabled_topics(config)
    usable_headings = [t for t in HEADING_REFERENCE_TOPICS if t in stored and t not in disabled]
    if not usable_headings:
        raise BagError(
            f"bag {reader.path}: no heading reference to align with: it needs one of "
            f"{', '.join(HEADING_REFERENCE_TOPICS)} (not switched off by a parameter)"
        )
    for topic in (*REQUIRED_TOPICS, *OPTIONAL_TOPICS):
        if topic not in stored or topic in disabled:
            continue
        msgtype = reader.topics[stored[topic]].msgtype
        if msgtype != FUSION_INPUT_MSGTYPES[topic]:
            raise BagError(
                f"bag {reader.path}: topic {stored[topic]} holds {msgtype}, "
                f"expected {FUSION_INPUT_MSGTYPES[topic]}"
            )
        found[topic] = stored[topic]
    return found


def truth_topics_of(reader: BagReader) -> list[str]:
    """Stored names of the truth topics in ``reader``'s bag."""
    return sorted(n for n in reader.topics if relative_topic(n).startswith(TRUTH_PREFIX))


HandedOver = list[NavValues] | list[Stamp]
"""New solutions as a run hands them on: their ``nav/*`` values, or their header stamps, the
solutions themselves written as rows (``solution_rows``)."""


class OfflineFusion:
    """Feeds sensor messages to a :class:`FusionEngine` and writes its ``nav/*`` to a bag."""

    def __init__(
        self,
        config: FusionConfig,
        writer: BagWriter | BackgroundBagWriter | NamespacedWriter | None,
        smoother_spill_parent: str | Path | None = None,
        smooth: bool = False,
        nav_rate_hz: float = 0.0,
        solution_rows: SolutionRows | None = None,
    ):
        """``writer`` receives the ``nav/*`` and ``tf`` messages, of every solution or, with
        ``nav_rate_hz`` (Hz) above 0, of a subset at that rate
        (:mod:`buoy_processing.nav_output_rate`; every solution is still returned); None: none
        is made (a run that writes its products alone). The solutions are returned as their
        ``nav/*`` values or, given ``solution_rows``, as their header stamps, the engine writing
        the solutions there (:mod:`buoy_nav.solution_rows`), for what follows to write and
        correct in bulk (:mod:`buoy_processing.output_side`); the writer is then None. With
        ``smooth`` (the filter's own solutions, ``realtime_output`` off) nothing is written: the
        solutions are kept by :attr:`smoother` (its records in a temporary directory in
        ``smoother_spill_parent``) and written smoothed by :meth:`write_smoothed_values` after
        :meth:`finish`."""
        if smooth:
            config = dataclasses.replace(config, realtime_output=False)
        self.solution_rows = None if smooth else solution_rows
        """Where the engine writes the solutions (None: it makes
        :class:`~buoy_nav.solution.NavSolution`, which a smoothing run keeps)."""
        if self.solution_rows is not None and writer is not None:
            raise ValueError("solutions written as rows are written out by what follows")
        self.engine = FusionEngine(config, solution_rows=self.solution_rows)
        self.smoother = None
        if smooth:
            # Imported for a smoothing run only: scipy's rotations, which the smoother needs,
            # would cost every other run a tenth of a second of start-up.
            from buoy_nav.smoothed_solutions import FixedIntervalSmoother

            self.smoother = FixedIntervalSmoother(self.engine, smoother_spill_parent)
        self.stamps = StampBook(self.engine.imu_clock_steps)
        self.writer = writer
        self.nav_output = NavOutputRate(nav_rate_hz)
        self.rejections: Counter[str] = Counter()
        self.first_solution_s: float | None = None
        self.last_log_time_ns = 0
        self.source_transitions: list[HealthTransition] = []
        """The sources suspended and resumed, oldest first."""

    def add(self, topic: str, message, log_time_ns: int) -> HandedOver:
        """One decoded sensor message of relative ``topic``; returns the new solutions (their
        ``nav/*`` values, which are written with log time ``log_time_ns``, or their stamps with
        ``solution_rows``)."""
        return self._take(
            topic, feed_message(self.engine, topic, message, self.stamps), log_time_ns
        )

    def add_message(
        self, reader: BagReader, topic: str, message: BagMessage, record: tuple | None = None
    ) -> HandedOver:
        """:meth:`add` of a bag message of relative ``topic``: from ``record`` when its chunk
        was read together (:meth:`record_fields`, :mod:`buoy_processing.chunk_records`), else
        an IMU sample from its CDR bytes and any other message decoded alone."""
        if record is not None:
            if topic == IMU_RAW_TOPIC:
                fed = feed_imu_fields(self.engine, *record, self.stamps)
            else:
                fed = feed_measurement_record(self.engine, topic, *record)
        elif topic == IMU_RAW_TOPIC:
            fed = feed_imu_cdr(self.engine, message.raw, self.stamps)
        else:
            fed = None
        if fed is None:
            return self.add(topic, reader.decode(message), message.log_time_ns)
        return self._take(topic, fed, message.log_time_ns)

    @property
    def run_topics(self) -> frozenset[str]:
        """The topics whose messages, read with their chunk, :meth:`add_records` takes in runs:
        the IMU's and those of the sources the engine takes in its stretches."""
        return frozenset(
            (IMU_RAW_TOPIC, *(source.topic for source in self.engine.stretched_sources))
        )

    def add_records(
        self, topics: list[str], records: list[tuple], log_times_ns: list[int]
    ) -> list[HandedOver]:
        """:meth:`add_message` of consecutive messages of :attr:`run_topics` read with their
        chunk, no other sensor message between them: each one's (relative) topic, record
        (:meth:`record_fields`) and log time (ns); what each one handed over, in order. One
        call to the engine for them all (:meth:`~buoy_nav.engine.FusionEngine.add_inputs`)."""
        fed = feed_records(self.engine, topics, records, self.stamps)
        for topic, (_, rejection) in zip(topics, fed, strict=True):
            if rejection is not None:
                self._count_rejection(topic, rejection)
        # As :meth:`_take` after each message: no other input came between them.
        self.source_transitions.extend(self.engine.take_source_transitions())
        self.last_log_time_ns = log_times_ns[-1]
        write = self._write
        return [
            write(solutions, log_time_ns)
            for (solutions, _), log_time_ns in zip(fed, log_times_ns, strict=True)
        ]

    def record_fields(self, sensors: dict[str, str]) -> dict[str, tuple[str, ...]]:
        """Stored name → the fields :meth:`add_message` reads of a message read with its chunk
        (:mod:`buoy_processing.chunk_records`), for the topics of ``sensors`` (relative →
        stored names) read so: the IMU's and those of the aiding sources that read records
        (``record_fields``)."""
        fields = {sensors[IMU_RAW_TOPIC]: IMU_RECORD_FIELDS}
        for topic, stored in sensors.items():
            if topic == IMU_RAW_TOPIC:
                continue
            source_fields = self.engine.source_of_topic(topic).record_fields
            if source_fields:
                fields[stored] = source_fields
        return fields

    def _count_rejection(self, topic: str, rejection: str) -> None:
        self.rejections[f"{topic}: {rejection}"] += 1

    def _take(self, topic: str, fed, log_time_ns: int) -> HandedOver:
        solutions, rejection = fed
        if rejection is not None:
            self._count_rejection(topic, rejection)
        self.source_transitions.extend(self.engine.take_source_transitions())
        self.last_log_time_ns = log_time_ns
        return self._write(solutions, log_time_ns)

    def finish(self) -> HandedOver:
        """End of the data: the solutions still held back by the engine (written too)."""
        written = self._write(self.engine.flush(), self.last_log_time_ns)
        self.source_transitions.extend(self.engine.take_source_transitions())
        return written

    def _write(self, solutions: list[Emitted], log_time_ns: int) -> HandedOver:
        if self.solution_rows is not None:
            return self._stamps_of(solutions)
        written = []
        smoother = self.smoother
        for solution in solutions:
            if self.first_solution_s is None:
                self.first_solution_s = solution.t_s
            if smoother is not None:
                smoother.add(solution, *self.stamps.exact(solution.t_s), log_time_ns)
                continue
            values = nav_values(solution, self.stamps)
            if self.writer is not None and self.nav_output.due(values):
                self._write_nav(values, log_time_ns)
            written.append(values)
        return written

    def _stamps_of(self, stamps_s: list[float]) -> list[Stamp]:
        """The header stamps of the solutions the engine wrote as rows, stamped ``stamps_s``
        (s)."""
        if stamps_s and self.first_solution_s is None:
            self.first_solution_s = stamps_s[0]
        exact = self.stamps.exact
        return [exact(t_s) for t_s in stamps_s]

    def _write_nav(self, values: NavValues, log_time_ns: int) -> None:
        """``nav/*`` and ``tf`` of one solution."""
        writer = self.writer
        for topic, raw in solution_cdr(values).items():
            stored_topic, msgtype = NAV_BAG_TOPICS[topic]
            writer.write_raw(stored_topic, msgtype, log_time_ns, raw)
        writer.write_raw(TF_BAG_TOPIC, TF_MSGTYPE, log_time_ns, transform_cdr(values))

    def smoothed_values(self) -> Iterator[tuple[NavValues, NavValues, int]]:
        """After :meth:`finish` of a smoothing run: (forward values, smoothed values, log time)
        of every solution, in order."""
        for pair in self.smoother.smoothed():
            forward = nav_values(pair.forward)._replace(sec=pair.sec, nanosec=pair.nanosec)
            smoothed = nav_values(pair.smoothed)._replace(sec=pair.sec, nanosec=pair.nanosec)
            yield forward, smoothed, pair.log_time_ns

    def write_smoothed_values(self, forward: NavValues, smoothed: NavValues, log_time_ns: int):
        """``nav/forward/odometry`` of ``forward``; ``nav/*`` and ``tf`` of ``smoothed``; nothing
        for a solution the navigation output rate leaves out, nor without a writer."""
        if self.writer is None or not self.nav_output.due(smoothed):
            return
        self.writer.write_raw(
            FORWARD_ODOMETRY_BAG_TOPIC, ODOMETRY_MSGTYPE, log_time_ns, odometry_cdr(forward)
        )
        self._write_nav(smoothed, log_time_ns)

    def close(self) -> None:
        """Remove the smoother's temporary records (nothing to do without smoothing)."""
        if self.smoother is not None:
            self.smoother.close()

    def summary(self) -> list[str]:
        """Human-readable lines: alignment, measurement use and rejections."""
        health = self.engine.health()
        lines = []
        if self.first_solution_s is None:
            lines.append(f"never aligned (alignment state: {health.alignment_state.name})")
        else:
            lines.append(f"first navigation solution at stamp {self.first_solution_s:.3f} s")
            lines.append(f"sensor set at the end: {health.sensor_set}")
            lines.append(
                "coasting sources at the end: " + (", ".join(health.coasting_sources) or "none")
            )
        for kind, counters in health.counters.items():
            rejected = ", ".join(f"{r} {n}" for r, n in sorted(counters.rejected.items()))
            lines.append(
                f"{kind:14s} accepted {counters.accepted:7d}  "
                f"alignment {counters.used_for_alignment:4d}  "
                f"superseded {counters.superseded:6d}  resets {counters.resets:3d}  "
                f"mean NIS {counters.mean_nis:6.2f}  rejected: {rejected or 'none'}"
                + _suspension_note(health.source_health.get(kind))
            )
        for transition in self.source_transitions:
            lines.append(f"stamp {transition.t_s:.3f} s: {transition.message}")
        for event in health.integrity_events:
            ended = (
                "still at the end"
                if math.isnan(event.end_s)
                else f"{event.duration_s:.2f} s, ended by "
                + ("a new alignment" if event.realigned else "agreement with the aiding")
            )
            lines.append(
                f"navigation not trusted from stamp {event.start_s:.3f} s ({event.reason}): {ended}"
            )
        for t_s, step_s in health.imu_clock_steps:
            lines.append(
                f"IMU clock stepped by {step_s:+.6f} s before stamp {t_s:.3f} s: "
                "later IMU samples re-stamped onto the GNSS clock"
            )
        for key, count in sorted(self.rejections.items()):
            lines.append(f"rejected message {key}: {count}")
        for source in self.engine.sources:
            if source.enabled and source.configuration_problem is not None:
                lines.append(f"warning: {source.kind}: {source.configuration_problem}")
        return lines


def _suspension_note(status: SourceStatus | None) -> str:
    """What a source's summary line says of its health (nothing for one never suspended)."""
    if status is None or not status.suspensions:
        return ""
    state = f"suspended ({status.reason})" if status.suspended else "not suspended at the end"
    return f"  suspensions {status.suspensions}: {state}"
