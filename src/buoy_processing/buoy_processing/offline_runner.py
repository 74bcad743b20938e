"""One run of the fusion over a recorded bag, shared by ``fuse_bag`` and ``process_bag``.

:func:`run_fusion` reads the bag's sensor topics in log-time order into an
:class:`~buoy_processing.offline_fusion.OfflineFusion`, which writes ``nav/*`` and ``tf`` to the
output bag (a chunk of the bag at a time, its IMU and anemometer samples decoded together:
:mod:`buoy_processing.chunk_records`); the other topics of the run (the truth, and for
``process_bag`` the anemometer's and the DVL's) are copied to the output unchanged. A
:class:`BagConsumer` (``process_bag``'s corrections) receives every navigation solution and every
copied message in the order the live nodes would: a solution as soon as the fusion has it, a
message when it is read. Without ``smooth`` what follows the fusion is one output side
(:mod:`buoy_processing.output_side`), which the process writing the bag runs when the bag is
written in the background: the fusion keeps the first core.

Without ``smooth`` one pass does it all. With ``smooth`` the run takes two passes
(:mod:`buoy_nav.smoothed_solutions`): the forward filter over the sensor topics, its epochs and
solutions spilled to a temporary directory beside the output; then the smoother's backward pass,
and a second read of the bag for the copied topics, merged in log-time order with the solutions:
``nav/*`` and ``tf`` carry the smoothed solution, ``nav/forward/odometry`` the forward filter's,
and the consumer receives the smoothed one.
"""

from __future__ import annotations

import math
import sys
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import NamedTuple, Protocol

from buoy_common.bag_io import BackgroundBagWriter, BagMessage, BagProgress, BagReader, BagWriter
from buoy_common.contract import (
    TF_STATIC_MSGTYPE,
    TF_STATIC_TOPIC,
    bag_topic,
    ns_to_stamp,
)
from buoy_common.heap import existing_objects_frozen
from buoy_common.namespaces import NamespacedWriter, TopicView
from buoy_common.transform_messages import FrameTransform, tf_cdr
from buoy_nav.config import FusionConfig
from buoy_nav.fusion_messages import NavValues
from buoy_nav.observability import unobserved_quantities
from buoy_nav.solution_rows import SolutionRows
from buoy_processing.chunk_records import chunk_records
from buoy_processing.nav_rows_output import OrderedOutput
from buoy_processing.offline_fusion import OfflineFusion
from buoy_processing.output_side import COPY, SOLUTIONS, HostedOutputSide, OutputSide
from buoy_processing.solution_columns import HeldBackSolutions, Stamp

TF_STATIC_BAG_TOPIC = bag_topic(TF_STATIC_TOPIC)


class BagConsumer(Protocol):
    """What follows the fusion over a bag, fed as the live nodes downstream of it are."""

    def start(
        self,
        writer: NamespacedWriter | OrderedOutput | None,
        held_back: HeldBackSolutions | None = None,
    ) -> None:
        """The run's output is open: what the consumer writes goes to ``writer`` (None: the
        run writes no bag, and the consumer encodes no message); the solutions come through
        ``held_back`` (:meth:`add_solution_rows`; None: as values, :meth:`add_navigation`)."""

    def add_navigation(self, solutions: list[NavValues]) -> None:
        """New navigation solutions, in order (what ``nav/odometry`` and ``nav/fix`` carry)."""

    def add_solution_rows(self, stamps: list[Stamp]) -> None:
        """New navigation solutions, in order, written as rows: their header ``stamps``, to
        hold back (:mod:`buoy_processing.solution_columns`)."""

    @property
    def record_fields(self) -> dict[str, tuple[str, ...]]:
        """Stored name → fields of the copied topics whose messages :meth:`add_message` takes
        read with their chunk (:mod:`buoy_processing.chunk_records`)."""

    @property
    def topics(self) -> list[str]:
        """Stored names of the copied topics whose messages :meth:`add_message` takes (the
        others, such as the truth, are only copied)."""

    def add_message(
        self, reader: BagReader, message: BagMessage, record: tuple | None = None
    ) -> None:
        """A message of one of :attr:`topics`, already written to the output; ``record``: its
        fields of :attr:`record_fields`, None when read alone."""

    def finish(self, log_time_ns: int) -> None:
        """End of the data; ``log_time_ns`` is the log time of the last thing read, ns."""

    def detach(self) -> None:
        """After :meth:`finish`: drop what ties the consumer to the run's output, which stays
        in the process that wrote the bag when the consumer leaves it."""


class NoBag:
    """The output of a run that writes no bag (its products alone): takes and drops what a bag
    writer would write."""

    @property
    def counts(self) -> dict[str, int]:
        """Messages written, per topic: none."""
        return {}

    def __enter__(self) -> NoBag:
        return self

    def __exit__(self, *exc_info) -> None:
        pass

    def write_raw(self, topic: str, msgtype: str, log_time_ns: int, raw: bytes) -> None:
        pass

    def write(self, topic: str, msgtype: str, log_time_ns: int, message) -> None:
        pass

    def add_metadata(self, name: str, metadata: dict[str, str]) -> None:
        pass


class NothingFollows:
    """The consumer of a run of the fusion alone (``fuse_bag``)."""

    def start(
        self,
        writer: NamespacedWriter | OrderedOutput | None,
        held_back: HeldBackSolutions | None = None,
    ) -> None:
        self._held_back = held_back

    def add_navigation(self, solutions: list[NavValues]) -> None:
        pass

    def add_solution_rows(self, stamps: list[Stamp]) -> None:
        self._held_back.take(stamps, -math.inf)

    @property
    def topics(self) -> list[str]:
        return []

    @property
    def record_fields(self) -> dict[str, tuple[str, ...]]:
        return {}

    def add_message(
        self, reader: BagReader, message: BagMessage, record: tuple | None = None
    ) -> None:
        pass

    def finish(self, log_time_ns: int) -> None:
        pass

    def detach(self) -> None:
        self._held_back = None


@dataclass
class OfflineRun:
    """What a run reads and writes, and how."""

    reader: BagReader
    out_bag: str | Path
    """The bag directory to create."""
    config: FusionConfig
    sensors: dict[str, str]
    """Relative → stored name of the fusion's input topics
    (:func:`~buoy_processing.offline_fusion.sensor_topics_of`)."""
    label: str
    """Names the run in its progress lines (``fuse_bag IN_BAG``)."""
    view: TopicView = field(default_factory=TopicView)
    """The namespace read and written."""
    copied_topics: list[str] = field(default_factory=list)
    """Stored names of the topics copied to the output and handed to the consumer."""
    smooth: bool = False
    overwrite: bool = False
    nav_rate_hz: float = 0.0
    """Rate of the written ``nav/*`` and ``tf``, Hz (0: every solution); the consumer still
    receives every solution (:mod:`buoy_processing.nav_output_rate`)."""
    write_in_background: bool = True
    """Write the bag from a process of its own, on a second core (False: in this process, for a
    caller that keeps every core busy with bags of its own)."""
    write_bag: bool = True
    """False: no bag is written and no ``nav/*`` or ``tf`` made; the consumer still receives
    every solution and message (a run that writes its products alone)."""
    static_transforms: list[FrameTransform] = field(default_factory=list)
    """``base_link`` → the sensor frames, written once on ``tf_static`` at the input bag's first
    log time, before every other output (:mod:`buoy_common.sensor_frames`)."""
    closing_metadata: Callable[[OfflineFusion, BagConsumer], dict[str, dict[str, str]]] | None = (
        None
    )
    """The MCAP metadata records (name → map of strings) to store in the output bag, made from
    the fusion and the consumer once every message is written (what the run's outputs say of
    it)."""
    say_statements: bool = True
    """Print the start-up statements (what the sensors leave unobserved) on stderr; False for a
    caller that reports them itself (:attr:`FusionRun.statements`), as an archive does once
    for all its bags."""

    @property
    def relative_of(self) -> dict[str, str]:
        """Stored → relative name of the sensor topics."""
        return {stored: relative for relative, stored in self.sensors.items()}

    def open_writer(self, preload: tuple[str, ...] = ()) -> BackgroundBagWriter | BagWriter | NoBag:
        """The output bag's writer; ``preload``: the modules a writing process of its own
        imports first (those of what it will host)."""
        if not self.write_bag:
            return NoBag()
        if self.write_in_background:
            return BackgroundBagWriter(self.out_bag, overwrite=self.overwrite, preload=preload)
        return BagWriter(self.out_bag, overwrite=self.overwrite)

    def store_closing_metadata(
        self,
        writer: BackgroundBagWriter | BagWriter | NoBag,
        fusion: OfflineFusion,
        consumer: BagConsumer,
    ) -> None:
        """The records of :attr:`closing_metadata` into ``writer``'s bag, before it closes."""
        if self.closing_metadata is None:
            return
        for name, metadata in self.closing_metadata(fusion, consumer).items():
            writer.add_metadata(name, metadata)

    def static_transform_records(self) -> list[tuple[str, str, int, bytes]]:
        """The one ``tf_static`` message of :attr:`static_transforms` (none without
        transforms), stamped and logged at the input bag's first log time, as a record (topic,
        msgtype, log time ns, CDR bytes), to be written before anything else."""
        if not self.static_transforms:
            return []
        start_ns = self.reader.start_ns
        raw = tf_cdr(*ns_to_stamp(start_ns), self.static_transforms)
        return [(TF_STATIC_BAG_TOPIC, TF_STATIC_MSGTYPE, start_ns, raw)]


class FusionRun(NamedTuple):
    """What :func:`run_fusion` did."""

    fusion: OfflineFusion
    """The fusion that ran (its :meth:`OfflineFusion.summary` reports it)."""
    topic_counts: dict[str, int]
    """Messages written, per topic."""
    statements: list[str]
    """What the configured and present sensors leave unobserved, said before the run
    (:func:`buoy_nav.observability.unobserved_quantities`)."""
    consumer: BagConsumer
    """The consumer as the run left it: what it kept (a bag written in the background has
    it run in the writing process, whence it came back: not the object given)."""


def run_fusion(run: OfflineRun, consumer: BagConsumer | None = None) -> FusionRun:
    """The fusion over ``run``'s bag into its output, followed by ``consumer`` (see the module
    docstring)."""
    consumer = consumer or NothingFollows()
    # Said before the long pass over the bag, from the topics it holds.
    statements = unobserved_quantities(run.config, run.sensors)
    if run.say_statements:
        for sentence in statements:
            print(f"{run.label}: warning: {sentence}", file=sys.stderr)
    run_pass = _smoothed_run if run.smooth else _forward_run
    fusion, topic_counts, consumer = run_pass(run, consumer)
    return FusionRun(fusion, topic_counts, statements, consumer)


def _forward_run(
    run: OfflineRun, consumer: BagConsumer
) -> tuple[OfflineFusion, dict[str, int], BagConsumer]:
    """Fusion, copies and consumer in one pass over the bag: the output side
    (:mod:`buoy_processing.output_side`) in the process writing the bag when it is written in
    the background, else here."""
    preload = (OutputSide.__module__, type(consumer).__module__)
    with (
        BagProgress(run.reader, run.label) as progress,
        run.open_writer(preload) as bag_writer,
    ):
        rows = SolutionRows()
        side = OutputSide(
            consumer,
            run.view,
            run.nav_rate_hz,
            run.write_bag,
            run.static_transform_records(),
            run.reader.path,
        )
        # The output side first: its tf_static leaves before the engine is built.
        if isinstance(bag_writer, BackgroundBagWriter):
            side = HostedOutputSide(side, bag_writer, rows)
        else:
            side.start(bag_writer, rows, run.reader)
        fusion = OfflineFusion(run.config, None, solution_rows=rows)
        fields_of_topic = {**fusion.record_fields(run.sensors), **consumer.record_fields}
        # What the set-up built (the engine, the compiled kernels) lives through the pass.
        with existing_objects_frozen():
            log_time_ns = _fusing_pass(run, fusion, side, fields_of_topic, progress)
        last = [(SOLUTIONS, fusion.last_log_time_ns, fusion.finish())]
        consumer, topic_counts = side.finish_run(last, log_time_ns)
        run.store_closing_metadata(bag_writer, fusion, consumer)
        progress.done()
    return fusion, topic_counts, consumer


def _fusing_pass(
    run: OfflineRun,
    fusion: OfflineFusion,
    side: OutputSide | HostedOutputSide,
    fields_of_topic: dict[str, tuple[str, ...]],
    progress: BagProgress,
) -> int:
    """``run``'s bag in log-time order: the sensor messages into ``fusion``, and its solutions
    and the copied topics' messages to ``side`` as events (:mod:`buoy_processing.output_side`),
    a chunk at a time, as is what ``fields_of_topic`` names of them; the last log time (ns)."""
    reader = run.reader
    relative_of = run.relative_of
    log_time_ns = reader.start_ns
    for batch in reader.message_batches([*relative_of, *run.copied_topics]):
        records = chunk_records(batch, fields_of_topic)
        events: list[tuple | None] = []
        add = events.append
        # The IMU messages read with their chunk (and the messages the fusion takes with them)
        # wait, their events' places kept, until another sensor message comes: the fusion
        # takes them in one call.
        run = _FusionRun(fusion, events)
        run_topics = fusion.run_topics
        for position, message in enumerate(batch):
            log_time_ns = message.log_time_ns
            topic = relative_of.get(message.topic)
            record = records.get(position)
            if topic is None:
                # A plain tuple pickles several times faster than the named one.
                add((COPY, tuple(message), record))
            elif topic in run_topics and record is not None:
                run.wait(topic, record, log_time_ns)
            else:
                run.fuse()
                stamps = fusion.add_message(reader, topic, message, record)
                if stamps:
                    add((SOLUTIONS, log_time_ns, stamps))
        run.fuse()
        side.hand_over([event for event in events if event is not None])
        progress.reached(log_time_ns)
    return log_time_ns


class _FusionRun:
    """Sensor messages of a chunk waiting for the fusion, their places kept in ``events``."""

    def __init__(self, fusion: OfflineFusion, events: list[tuple | None]):
        self._fusion = fusion
        self._events = events
        self._places: list[int] = []
        self._topics: list[str] = []
        self._records: list[tuple] = []
        self._log_times_ns: list[int] = []

    def wait(self, topic: str, record: tuple, log_time_ns: int) -> None:
        """One more message of (relative) ``topic`` (its record and log time, ns); its event's
        place kept."""
        self._places.append(len(self._events))
        self._events.append(None)
        self._topics.append(topic)
        self._records.append(record)
        self._log_times_ns.append(log_time_ns)

    def fuse(self) -> None:
        """The waiting messages into the fusion, the events of their solutions into their
        places (None stays where a message made none)."""
        if not self._places:
            return
        events = self._events
        log_times = self._log_times_ns
        handed_over = self._fusion.add_records(self._topics, self._records, log_times)
        for place, log_time_ns, stamps in zip(self._places, log_times, handed_over, strict=True):
            if stamps:
                events[place] = (SOLUTIONS, log_time_ns, stamps)
        self._places, self._topics, self._records, self._log_times_ns = [], [], [], []


def _smoothed_run(
    run: OfflineRun, consumer: BagConsumer
) -> tuple[OfflineFusion, dict[str, int], BagConsumer]:
    """The forward filter, the smoother's backward pass, then the smoothed solutions merged
    with the copies, fed to the consumer."""
    reader = run.reader
    fusion = OfflineFusion(
        run.config, None, spill_parent_of(run.out_bag), smooth=True, nav_rate_hz=run.nav_rate_hz
    )
    try:
        # The writing process starts during the forward pass: until it is ready the writer
        # keeps what it is given, and the second pass produces fast.
        with run.open_writer() as bag_writer:
            writer = NamespacedWriter(bag_writer, run.view)
            for record in run.static_transform_records():
                writer.write_raw(*record)
            # What the set-up built (the engine, the compiled kernels) lives through the passes.
            with existing_objects_frozen():
                forward_pass(reader, fusion, run.sensors, run.relative_of, run.label)
                output = writer if run.write_bag else None
                fusion.writer = output
                consumer.start(output)
                log_time_ns = _merged_pass(reader, fusion, run.copied_topics, consumer, output)
            consumer.finish(log_time_ns)
            run.store_closing_metadata(bag_writer, fusion, consumer)
    finally:
        fusion.close()
    return fusion, writer.counts, consumer


def _merged_pass(
    reader: BagReader,
    fusion: OfflineFusion,
    topics: list[str],
    consumer: BagConsumer,
    writer: NamespacedWriter | None,
) -> int:
    """The smoothed solutions of ``fusion`` and the copied ``topics`` (stored names) of
    ``reader``'s bag in log-time order, written (unless ``writer`` is None: no bag) and given
    to ``consumer``; the last log time (ns)."""
    taken = frozenset(consumer.topics)
    log_time_ns = reader.start_ns
    for message, record, solution in merged_with_smoothed(
        reader, fusion, topics, consumer.record_fields
    ):
        if message is None:
            forward, smoothed, log_time_ns = solution
            fusion.write_smoothed_values(forward, smoothed, log_time_ns)
            consumer.add_navigation([smoothed])
            continue
        log_time_ns = message.log_time_ns
        if writer is not None:
            writer.write_raw(message.topic, message.msgtype, log_time_ns, message.raw)
        if message.topic in taken:
            consumer.add_message(reader, message, record)
    return log_time_ns


def spill_parent_of(out_bag) -> Path:
    """Where a smoothing run keeps its temporary records: beside the output bag, on the disk
    the user chose for the output (a day of data needs gigabytes); the nearest existing folder
    above it while the output's own folder (``OUT_BAG/buoy1`` of a fleet) is not made yet."""
    parent = Path(out_bag).resolve().parent
    while not parent.is_dir():
        parent = parent.parent
    return parent


def forward_pass(
    reader: BagReader,
    fusion: OfflineFusion,
    sensors: dict[str, str],
    relative_of: dict[str, str],
    label: str,
) -> None:
    """The forward filter of a smoothing run over the sensor topics of ``reader``'s bag."""
    fields_of_topic = fusion.record_fields(sensors)
    progress_ns = reader.start_ns
    with BagProgress(reader, f"{label} (forward filter)") as progress:
        for batch in reader.message_batches(list(sensors.values())):
            records = chunk_records(batch, fields_of_topic)
            for position, message in enumerate(batch):
                topic = relative_of[message.topic]
                fusion.add_message(reader, topic, message, records.get(position))
                progress_ns = message.log_time_ns
            progress.reached(progress_ns)
        fusion.finish()
        progress.done()


def merged_with_smoothed(
    reader: BagReader,
    fusion: OfflineFusion,
    topics: list[str],
    fields_of_topic: dict[str, tuple[str, ...]],
) -> Iterator[tuple[BagMessage | None, tuple | None, tuple | None]]:
    """The messages of ``topics`` (stored names) of ``reader``'s bag and the smoothed
    solutions of ``fusion`` (forward values, smoothed values, log time) in log-time order, as
    ``(message, its record, None)`` or ``(None, None, solution)``; a solution goes before the
    messages logged after the IMU sample that produced it. The messages are read a chunk at a
    time, those of ``fields_of_topic`` into records (:mod:`buoy_processing.chunk_records`;
    None for a message read alone)."""
    solutions = fusion.smoothed_values()
    pending = next(solutions, None)
    for batch in reader.message_batches(topics) if topics else ():
        records = chunk_records(batch, fields_of_topic)
        for position, message in enumerate(batch):
            while pending is not None and pending[2] <= message.log_time_ns:
                yield None, None, pending
                pending = next(solutions, None)
            yield message, records.get(position), None
    while pending is not None:
        yield None, None, pending
        pending = next(solutions, None)
