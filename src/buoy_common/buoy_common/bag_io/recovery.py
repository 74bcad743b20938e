"""The readable part of an MCAP file that was never finished.

A recorder that is killed or loses power leaves an MCAP file without its summary and footer,
which indexed readers (rosbags among them) refuse. Its complete chunks are still valid, so the
file is read here from the start, record by record, with the ``mcap`` library's stream reader,
up to the first record that is cut short or damaged. The records are read twice: once when the
bag is opened, for its topics, counts and time span, and again when the messages are iterated,
so that memory holds about one chunk at a time.

Messages come in log-time order across chunks, equal log times in the order of the file, as
rosbags orders those of a finished file. A message is held back only until no later chunk can
hold an earlier one, which the first pass knows from each chunk's earliest log time.
"""

from __future__ import annotations

import heapq
from collections import Counter
from collections.abc import Iterator
from pathlib import Path

from mcap.exceptions import EndOfFile, McapError
from mcap.records import Channel, Chunk, Footer, Message, Schema
from mcap.stream_reader import StreamReader, breakup_chunk

from buoy_common.bag_io.common import BagMessage, TopicInfo, one_line

# Longest record the scan accepts: a length beyond it is read as damage, not as a huge chunk.
_RECORD_SIZE_LIMIT = 1 << 30
_NO_MESSAGES = 2**63


class _WholeReads:
    """A binary file whose reads return every byte asked for or raise EndOfFile, and which counts
    the bytes consumed: the stream reader would take the short read at a cut for a record."""

    def __init__(self, stream):
        self._stream = stream
        self.position = 0

    def read(self, size: int = -1) -> bytes:
        data = self._stream.read(size)
        if size >= 0 and len(data) < size:
            raise EndOfFile()
        self.position += len(data)
        return data


class RecoveredMcap:
    """The complete records of an unfinished MCAP file (``ros2`` profile, ``cdr`` messages).

    ``topics``, ``start_ns``, ``end_ns``, ``message_count`` and ``definitions`` describe what was
    readable; ``stop`` says where and why reading stopped.
    """

    def __init__(self, path: Path):
        self.path = path
        self._channels: dict[int, tuple[str, str]] = {}
        self.definitions: dict[str, tuple[str, str]] = {}
        counts: Counter[int] = Counter()
        unit_starts: list[int] = []
        self.start_ns = _NO_MESSAGES
        self.end_ns = 0
        schemas: dict[int, Schema] = {}
        for records in self._units():
            unit_start = _NO_MESSAGES
            for record in records:
                if isinstance(record, Schema):
                    schemas[record.id] = record
                elif isinstance(record, Channel):
                    schema = schemas.get(record.schema_id)
                    msgtype = "" if schema is None else schema.name
                    self._channels[record.id] = (record.topic, msgtype)
                    if schema is not None:
                        self.definitions[msgtype] = (schema.encoding, schema.data.decode())
                elif isinstance(record, Message) and record.channel_id in self._channels:
                    counts[record.channel_id] += 1
                    unit_start = min(unit_start, record.log_time)
                    self.start_ns = min(self.start_ns, record.log_time)
                    self.end_ns = max(self.end_ns, record.log_time)
            unit_starts.append(unit_start)
        self._unit_count = len(unit_starts)
        # The earliest log time of the units after each one: what may still come before.
        self._later_start = [_NO_MESSAGES] * (len(unit_starts) + 1)
        for index in range(len(unit_starts) - 1, -1, -1):
            self._later_start[index] = min(unit_starts[index], self._later_start[index + 1])
        self.message_count = sum(counts.values())
        if not self.message_count:
            self.start_ns = self.end_ns = 0
        topic_counts: Counter[str] = Counter()
        self.topics: dict[str, TopicInfo] = {}
        for channel_id, (topic, msgtype) in self._channels.items():
            topic_counts[topic] += counts[channel_id]
            self.topics[topic] = TopicInfo(msgtype, topic_counts[topic])

    def _units(self) -> Iterator[list]:
        """The records of each complete chunk (or loose record) in file order, until the end of
        the readable part; sets :attr:`stop` to what ended it."""
        self.stop = "the file ends before its summary"
        with self.path.open("rb") as raw:
            stream = _WholeReads(raw)
            reader = StreamReader(
                stream, emit_chunks=True, record_size_limit=_RECORD_SIZE_LIMIT
            ).records
            while True:
                read_up_to = stream.position
                try:
                    record = next(reader)
                    records = (
                        breakup_chunk(record, validate_crc=True)
                        if isinstance(record, Chunk)
                        else [record]
                    )
                except StopIteration:
                    return
                except EndOfFile:
                    where = "after" if stream.position == read_up_to else "within the record at"
                    self.stop = f"cut {where} byte {read_up_to}"
                    return
                except (McapError, ValueError, OSError) as error:
                    self.stop = f"unreadable record at byte {read_up_to} ({one_line(error)})"
                    return
                if isinstance(record, Footer):
                    return
                yield records

    def messages(self, topics: set[str]) -> Iterator[BagMessage]:
        """The readable messages of ``topics`` in log-time order (ties in file order)."""
        wanted = {
            channel_id: channel
            for channel_id, channel in self._channels.items()
            if channel[0] in topics
        }
        pending: list[tuple[int, int, int, BagMessage]] = []
        for unit, records in zip(range(self._unit_count), self._units(), strict=False):
            for position, record in enumerate(records):
                if isinstance(record, Message) and record.channel_id in wanted:
                    topic, msgtype = wanted[record.channel_id]
                    message = BagMessage(topic, msgtype, record.log_time, record.data)
                    heapq.heappush(pending, (record.log_time, unit, position, message))
            release_before = self._later_start[unit + 1]
            while pending and pending[0][0] < release_before:
                yield heapq.heappop(pending)[3]
        while pending:
            yield heapq.heappop(pending)[3]
