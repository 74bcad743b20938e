"""What follows the fusion in an offline run, here or in the process that writes the bag.

The fusion hands on two kinds of event, in the order the output bag holds them: the solutions
that a sensor message made (their header stamps; their ``nav/*`` and ``tf`` logged at that
message's log time) and each copied message (the truth, the flow sensors' samples).
:class:`OutputSide` makes the output of them: a place for each solution's messages
(:class:`~buoy_processing.nav_rows_output.OrderedOutput`, at the navigation output's rate),
the copies, and the consumer (``process_bag``'s corrections) fed as the live nodes downstream of
the fusion are, the solutions' rows held back for it and handed over in bulk
(:class:`~buoy_processing.solution_columns.HeldBackSolutions`).

The output side feeds nothing back to the fusion. For a bag written in the background it runs in
the writing process (:meth:`~buoy_common.bag_io.BackgroundBagWriter.host`), fed the events in
batches with the rows the engine wrote for them (:class:`HostedOutputSide`): the fusion has the
first core to itself, and the corrections, the ordering and the writing share the second.
There it makes the same calls in the same order as here, so the bag, the products and the
NetCDF file are the same to the bit; a test holds them equal.
"""

from __future__ import annotations

from pathlib import Path

from buoy_common.bag_io import BackgroundBagWriter, BagMessage, BagReader
from buoy_common.namespaces import NamespacedWriter, TopicView
from buoy_nav.solution_rows import SolutionRows
from buoy_processing.nav_output_rate import NavOutputRate
from buoy_processing.nav_rows_output import OrderedOutput
from buoy_processing.solution_columns import HeldBackSolutions, Stamp

SOLUTIONS = 0
"""An event of the solutions one sensor message made: (SOLUTIONS, its log time ns, their header
stamps); their rows are written where :meth:`OutputSide.start` was told."""
COPY = 1
"""An event of a copied message: (COPY, its topic, type, log time ns and CDR bytes as a tuple,
its record: its fields when its chunk was read together, else None)."""


class OutputSide:
    """The output of an offline run after the fusion (see the module docstring).

    consumer: what follows the fusion (a
    :class:`~buoy_processing.offline_runner.BagConsumer`); view: the namespace written;
    nav_rate_hz: the rate of the written ``nav/*`` and ``tf`` (0: every solution); write_bag:
    False for a run that writes its products alone; first_records: (topic, msgtype, log time ns,
    CDR bytes) written before anything else (the sensors' ``tf_static``); in_bag: the bag read,
    which the consumer's messages read alone are decoded by.
    """

    def __init__(
        self,
        consumer,
        view: TopicView,
        nav_rate_hz: float,
        write_bag: bool,
        first_records: list[tuple[str, str, int, bytes]],
        in_bag: Path,
    ):
        self.consumer = consumer
        self._view = view
        self._nav_output = NavOutputRate(nav_rate_hz)
        self._write_bag = write_bag
        self._first_records = first_records
        self._in_bag = in_bag
        self._taken = frozenset(consumer.topics)
        self._reader: BagReader | None = None
        self._opened_reader = False
        self._rows: SolutionRows | None = None
        self._writer: NamespacedWriter | None = None
        self._output: OrderedOutput | None = None
        self._held_back: HeldBackSolutions | None = None

    def start(self, writer, rows: SolutionRows | None = None, reader: BagReader | None = None):
        """The run's bag is open in ``writer`` (a bag writer, or a NoBag); ``rows``: where the
        solutions' rows are (None: here, filled by :meth:`take`); ``reader``: the bag read
        (None: opened here when a message must be decoded)."""
        self._writer = NamespacedWriter(writer, self._view)
        for record in self._first_records:
            self._writer.write_raw(*record)
        self._output = OrderedOutput(self._writer) if self._write_bag else None
        self._rows = SolutionRows() if rows is None else rows
        self._reader = reader
        self._held_back = HeldBackSolutions(
            self._rows, [] if self._output is None else [self._output.take_columns]
        )
        self.consumer.start(self._output, self._held_back)

    def hand_over(self, events: list[tuple]) -> None:
        """The pass's ``events`` (:data:`SOLUTIONS`, :data:`COPY`), in order."""
        self.take((None, events, None))

    def finish_run(self, events: list[tuple], log_time_ns: int):
        """The last ``events`` and the end of the data, ``log_time_ns`` the log time of the last
        thing read (ns); the consumer and the messages written per topic."""
        self.take((None, events, log_time_ns))
        return self.consumer, self._writer.counts

    def take(self, content: tuple) -> None:
        """(rows, events, end): the rows of the events' solutions when they were written
        elsewhere (None: where :meth:`start` was told), the events in order, and at the end of
        the data the log time of the last thing read (ns; None before)."""
        rows, events, end_log_time_ns = content
        if rows is not None:
            self._rows.extend(rows)
        solutions, copy = self._solutions, self._copy
        for kind, first, second in events:
            if kind == SOLUTIONS:
                solutions(first, second)
            else:
                copy(first, second)
        if end_log_time_ns is not None:
            self._end(end_log_time_ns)

    def _solutions(self, log_time_ns: int, stamps: list[Stamp]) -> None:
        output = self._output
        if output is not None:
            due_at = self._nav_output.due_at
            for sec, nanosec in stamps:
                output.add_solution(log_time_ns, due_at(sec, nanosec))
        self.consumer.add_solution_rows(stamps)

    def _copy(self, fields: tuple[str, str, int, bytes], record: tuple | None) -> None:
        if self._output is not None:
            self._output.write_raw(*fields)
        if fields[0] in self._taken:
            self.consumer.add_message(self._decoding_reader(), BagMessage._make(fields), record)

    def _end(self, log_time_ns: int) -> None:
        """End of the data: every solution handed over, the consumer finished, every place
        written."""
        self._held_back.hand_over()
        self.consumer.finish(log_time_ns)
        # The consumer and the hand-over hold each other: a cycle that would keep the run's
        # arrays until the collector's next full pass (a worker running bag after bag grew).
        self.consumer.detach()
        if self._output is not None:
            self._output.finish()
        if self._opened_reader:
            self._reader.close()

    def finish(self):
        """In the writing process, after the end of the data: the consumer, without its ties
        to the output (:meth:`_end` cut them), to go back to the tool."""
        return self.consumer

    def _decoding_reader(self) -> BagReader:
        if self._reader is None:
            self._reader = BagReader(self._in_bag, self._view)
            self._opened_reader = True
        return self._reader


class HostedOutputSide:
    """An :class:`OutputSide` run by the process writing the bag (``writer``), handed the
    pass's events with the rows the engine wrote for them in ``rows``; the same calls as the
    output side's."""

    def __init__(self, side: OutputSide, writer: BackgroundBagWriter, rows: SolutionRows):
        self._writer = writer
        self._rows = rows
        writer.host(side)

    def hand_over(self, events: list[tuple]) -> None:
        self._writer.to_host((self._rows.take(self._rows.count), events, None), len(events))

    def finish_run(self, events: list[tuple], log_time_ns: int):
        """See :meth:`OutputSide.finish_run`: the consumer comes back from the writing
        process."""
        content = (self._rows.take(self._rows.count), events, log_time_ns)
        self._writer.to_host(content, len(events))
        consumer = self._writer.finish_host()
        return consumer, self._writer.counts
