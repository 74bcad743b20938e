"""A stretch of a bag's messages handed to its writer at once: some already CDR bytes, the
others still columns, a group of messages of several topics a row, encoded where they are
written.

An offline run writes five messages for each of its navigation solutions. Handed to the writing
process (:mod:`~buoy_common.bag_io.background`) as their columns rather than as 2.7 million
byte strings, their encoding (:func:`buoy_common.cdr_bulk.encode`) and the records' hand-over
cost the second core instead of the processing's. The stretch says where each row's group goes
among the records already encoded, so the bag holds every message in the order, and with the
log time, in which it was given.
"""

from __future__ import annotations

from dataclasses import dataclass
from itertools import repeat

import numpy as np

from buoy_common import cdr_bulk

Record = tuple[str, str, int, bytes]
"""A message already encoded: (topic, msgtype, log time ns, CDR bytes)."""


@dataclass(frozen=True)
class ColumnMessages:
    """Messages of one topic, one a row, as the columns :func:`buoy_common.cdr_bulk.encode`
    takes (values in the units of the message definition)."""

    topic: str
    msgtype: str
    columns: dict[str, object]


@dataclass(frozen=True)
class Stretch:
    """Rows of messages of several topics and records already encoded, in the order written.

    Row ``i``'s group (a message of each of ``groups``, in that order, logged at
    ``log_times_ns[i]`` ns) comes after the first ``records_before[i]`` of ``records`` (never
    decreasing), the rest of ``records`` after the last group.
    """

    groups: tuple[ColumnMessages, ...]
    log_times_ns: list[int]
    records: list[Record]
    records_before: list[int]

    @property
    def rows(self) -> int:
        return len(self.log_times_ns)

    @property
    def messages(self) -> int:
        """How many messages the stretch writes."""
        return self.rows * len(self.groups) + len(self.records)

    def encoded(self) -> list[Record]:
        """Every message of the stretch as a record, in the order written: the groups' columns
        encoded together, each type at once."""
        if not self.rows:
            return list(self.records)
        encoded_by_topic = (
            zip(
                repeat(group.topic),
                repeat(group.msgtype),
                self.log_times_ns,
                cdr_bulk.encode(group.msgtype, group.columns),
            )
            for group in self.groups
        )
        records = self.records
        ordered: list[Record] = []
        written = 0
        for before, group in zip(
            self.records_before, zip(*encoded_by_topic, strict=True), strict=True
        ):
            if before > written:
                ordered += records[written:before]
                written = before
            ordered += group
        ordered += records[written:]
        return ordered

    def split(self, at: int) -> tuple[Stretch, Stretch]:
        """The stretch before record ``at`` and the one after it (that record in neither): the
        groups whose rows come before it go with the first."""
        rows = int(np.searchsorted(self.records_before, at, side="right"))
        first = Stretch(
            tuple(_rows_of(group, slice(None, rows)) for group in self.groups),
            self.log_times_ns[:rows],
            self.records[:at],
            self.records_before[:rows],
        )
        second = Stretch(
            tuple(_rows_of(group, slice(rows, None)) for group in self.groups),
            self.log_times_ns[rows:],
            self.records[at + 1 :],
            [before - at - 1 for before in self.records_before[rows:]],
        )
        return first, second


def _rows_of(group: ColumnMessages, rows: slice) -> ColumnMessages:
    """``group``'s messages of ``rows``: its array columns sliced, a constant one kept."""
    columns = {
        name: value[rows] if isinstance(value, np.ndarray) else value
        for name, value in group.columns.items()
    }
    return ColumnMessages(group.topic, group.msgtype, columns)
