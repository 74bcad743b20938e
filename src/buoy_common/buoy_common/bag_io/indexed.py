"""The messages of a finished MCAP file, read chunk by chunk through its index.

rosbags hands out each message through a chain of generators, a ``BytesIO`` per record and a
merge of every chunk's messages: about 7 µs a message, 5 % of ``process_bag``'s CPU time on a
bag of 100 Hz IMU data. A finished MCAP file whose messages are in chunks (as this suite and
``ros2 bag record`` write them) indexes its chunks in its summary. :class:`IndexedMcap` reads
that index and the chunks with the ``mcap`` library, which also decompresses each chunk and
checks its CRC, and splits the chunk's message records with one ``struct`` call each: about
2.5 µs a message. :class:`~buoy_common.bag_io.reading.BagReader` uses it for a bag of one such
file and rosbags for anything else; the messages, their order and their bytes are rosbags'
(``test_bag_io`` compares the two).

Order: log time, then, for equal log times, the chunk's place in the file and the place in the
chunk, as rosbags merges chunks. Chunks are taken in order of their first log time; a chunk that
cannot hold a message due before the end of the ones before it follows them whole, and only
chunks whose time ranges overlap are merged message by message. Memory holds one chunk, or one
run of overlapping chunks.
"""

from __future__ import annotations

import heapq
import io
import struct
from collections.abc import Iterator
from operator import attrgetter
from pathlib import Path
from typing import NamedTuple

from mcap.data_stream import ReadDataStream
from mcap.exceptions import McapError
from mcap.opcode import Opcode
from mcap.reader import make_reader
from mcap.records import Chunk, ChunkIndex
from mcap.stream_reader import get_chunk_data_stream

from buoy_common.bag_io.common import BagMessage, TopicInfo

# Chunk compressions this reads (what rosbag2 and the mcap writer use); others go to rosbags.
_COMPRESSIONS = ("", "zstd")
# Record header: opcode (u8), length of the record's content (u64).
_RECORD_HEADER = struct.Struct("<BQ")
# Start of a message record's content: channel id (u16), sequence (u32), log time (u64); the
# publish time (u64) follows, then the data.
_MESSAGE_START = struct.Struct("<HIQ")
_MESSAGE_DATA_OFFSET = _RECORD_HEADER.size + _MESSAGE_START.size + 8
_OPCODE_MESSAGE = int(Opcode.MESSAGE)
_OPCODE_CHUNK = int(Opcode.CHUNK)
_log_time_ns = attrgetter("log_time_ns")


class _ChunkSpan(NamedTuple):
    """Where a chunk is in the file and which log times it holds (ns)."""

    offset: int
    length: int
    start_ns: int
    end_ns: int


class IndexedMcap:
    """The messages of one finished, chunked MCAP file (``ros2`` profile, ``cdr`` messages).

    Build it with :meth:`open`, which returns None for a file this does not read (no summary or
    no chunk index, a compression other than zstd, channels that disagree with the bag's
    topics): rosbags reads those. Messages outside chunks are not read, as rosbags does not
    read them from an indexed file; the reader's count check then fails the bag.
    """

    def __init__(self, path: Path, channels: dict[int, tuple[str, str]], chunks: list[_ChunkSpan]):
        self.path = path
        self._channels = channels
        self._chunks = sorted(chunks, key=lambda chunk: (chunk.start_ns, chunk.offset))

    @classmethod
    def open(cls, path: Path, topics: dict[str, TopicInfo]) -> IndexedMcap | None:
        """The index of MCAP file ``path``, whose channels must be among ``topics`` (stored
        name → type and count, as rosbags lists them) with the same types; None when rosbags
        should read the file instead."""
        try:
            with path.open("rb") as stream:
                summary = make_reader(stream).get_summary()
        except (McapError, struct.error, ValueError):
            return None  # rosbags, which opened the file, says what is wrong with it
        if summary is None or not summary.chunk_indexes:
            return None
        if any(index.compression not in _COMPRESSIONS for index in summary.chunk_indexes):
            return None
        channels = {}
        for channel_id, channel in summary.channels.items():
            schema = summary.schemas.get(channel.schema_id)
            info = topics.get(channel.topic)
            if schema is None or info is None or info.msgtype != schema.name:
                return None
            channels[channel_id] = (channel.topic, schema.name)
        return cls(path, channels, [_span(index) for index in summary.chunk_indexes])

    def messages(self, names: dict[str, str]) -> Iterator[BagMessage]:
        """The messages of the stored topics in ``names`` in log-time order, each under the
        name ``names`` gives its stored topic."""
        for batch in self.batches(names):
            yield from batch

    def batches(self, names: dict[str, str]) -> Iterator[list[BagMessage]]:
        """:meth:`messages` a list at a time: those of a chunk, or of a run of chunks whose
        log times overlap."""
        channels = {
            channel_id: (names[topic], msgtype)
            for channel_id, (topic, msgtype) in self._channels.items()
            if topic in names
        }
        if not channels:
            return
        chunks = self._chunks
        with self.path.open("rb") as stream:
            index = 0
            while index < len(chunks):
                run = [chunks[index]]
                run_end_ns, run_last_offset = chunks[index].end_ns, chunks[index].offset
                index += 1
                while index < len(chunks) and (
                    chunks[index].start_ns < run_end_ns
                    or (
                        chunks[index].start_ns == run_end_ns
                        and chunks[index].offset < run_last_offset
                    )
                ):
                    run.append(chunks[index])
                    run_end_ns = max(run_end_ns, chunks[index].end_ns)
                    run_last_offset = max(run_last_offset, chunks[index].offset)
                    index += 1
                if len(run) == 1:
                    yield _chunk_messages(_chunk_records(stream, run[0]), channels)
                    continue
                entries = [
                    [
                        (message.log_time_ns, chunk.offset, position, message)
                        for position, message in enumerate(
                            _chunk_messages(_chunk_records(stream, chunk), channels)
                        )
                    ]
                    for chunk in run
                ]
                yield [message for *_, message in heapq.merge(*entries)]


def _span(index: ChunkIndex) -> _ChunkSpan:
    return _ChunkSpan(
        index.chunk_start_offset,
        index.chunk_length,
        index.message_start_time,
        index.message_end_time,
    )


def _chunk_records(stream, chunk: _ChunkSpan) -> bytes:
    """The uncompressed records of a chunk, checked against its size and CRC by the library."""
    stream.seek(chunk.offset)
    record = stream.read(chunk.length)
    if len(record) != chunk.length or record[0] != _OPCODE_CHUNK:
        raise ValueError(f"no chunk at byte {chunk.offset}")
    parsed = Chunk.read(ReadDataStream(io.BytesIO(record[_RECORD_HEADER.size :])))
    data, size = get_chunk_data_stream(parsed, validate_crc=True)
    if size != parsed.uncompressed_size:
        raise ValueError(
            f"chunk at byte {chunk.offset} holds {size} bytes, not {parsed.uncompressed_size}"
        )
    return data.read(size)


def _chunk_messages(records: bytes, channels: dict[int, tuple[str, str]]) -> list[BagMessage]:
    """The messages of ``channels`` (id → name, type) among a chunk's records, in log-time
    order, equal log times in their order in the chunk."""
    messages = []
    append = messages.append
    unpack_header = _RECORD_HEADER.unpack_from
    unpack_message = _MESSAGE_START.unpack_from
    position, end = 0, len(records)
    while position < end:
        opcode, length = unpack_header(records, position)
        record_end = position + _RECORD_HEADER.size + length
        if opcode == _OPCODE_MESSAGE:
            channel_id, _, log_time_ns = unpack_message(records, position + _RECORD_HEADER.size)
            channel = channels.get(channel_id)
            if channel is not None:
                append(
                    BagMessage(
                        channel[0],
                        channel[1],
                        log_time_ns,
                        records[position + _MESSAGE_DATA_OFFSET : record_end],
                    )
                )
        position = record_end
    if position != end:
        raise ValueError("a record of a chunk runs past its end")
    messages.sort(key=_log_time_ns)
    return messages
