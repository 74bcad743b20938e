"""Reading and writing rosbag2 bags (metadata.yaml version 9, one MCAP file).

A bag is a directory holding ``metadata.yaml`` and one ``.mcap`` file with the ``ros2`` profile
and ``ros2msg`` schemas, as ``ros2 bag record`` writes and ``ros2 bag play`` reads. Messages are
kept as CDR bytes; log times are integer nanoseconds. rosbags opens bags (metadata.yaml, topics,
message types), decodes messages and supplies the message definitions and type hashes. The MCAP
file is written here, and the messages of a bag with one indexed MCAP file are read here by its
chunk index (other bags through rosbags, in the same order): the offline tools pass millions of
messages, and general-purpose readers and writers spend several times longer per message than
packing or unpacking a record of an open chunk.

Chunks of the MCAP file are zstd-compressed (storage-level compression, the same layout
``ros2 bag record --storage-preset-profile zstd_fast`` produces): metadata.yaml then declares no
compression, and both the rosbag2 MCAP plugin and the ``mcap`` readers decompress chunks
transparently. Sensor bags shrink several-fold. The file carries the records rosbag2's own MCAP
storage writes: schemas and channels, chunks with their message indexes, the ``rosbag2``
metadata record, and a summary (schemas, channels, chunk indexes, statistics, offsets).

This module never imports rclpy: it is used offline as well as by the recorder and player nodes.
"""

from __future__ import annotations

import contextlib
import functools
import heapq
import multiprocessing
import re
import shutil
import struct
import zlib
from collections import Counter
from collections.abc import Iterable, Iterator
from pathlib import Path
from typing import BinaryIO, NamedTuple

import numpy as np
import yaml
import zstandard
from rosbags.interfaces import MessageDefinitionFormat, Nodetype
from rosbags.rosbag2 import Reader
from rosbags.typesys import Stores, get_types_from_msg, get_typestore
from rosbags.typesys.base import normalize_fieldname

BAG_VERSION = 9
METADATA_FILE = "metadata.yaml"
ROS_DISTRO = "jazzy"

# numpy dtypes rosbags uses for arrays of each primitive type.
_ARRAY_DTYPES = {
    "bool": np.bool_,
    "byte": np.int8,
    "char": np.uint8,
    "int8": np.int8,
    "int16": np.int16,
    "int32": np.int32,
    "int64": np.int64,
    "uint8": np.uint8,
    "uint16": np.uint16,
    "uint32": np.uint32,
    "uint64": np.uint64,
    "float32": np.float32,
    "float64": np.float64,
}
_STRING_TYPES = {"string", "wstring"}
_RCLPY_MESSAGE_MODULE = re.compile(r"^(?P<package>\w+)\.msg\._\w+$")

# MCAP records (https://mcap.dev/spec): opcode, content length (u64), content; little endian.
_MCAP_MAGIC = b"\x89MCAP0\r\n"
_OP_HEADER = 0x01
_OP_FOOTER = 0x02
_OP_SCHEMA = 0x03
_OP_CHANNEL = 0x04
_OP_MESSAGE = 0x05
_OP_CHUNK = 0x06
_OP_MESSAGE_INDEX = 0x07
_OP_CHUNK_INDEX = 0x08
_OP_STATISTICS = 0x0B
_OP_METADATA = 0x0C
_OP_METADATA_INDEX = 0x0D
_OP_SUMMARY_OFFSET = 0x0E
_OP_DATA_END = 0x0F
_RECORD_HEADER = struct.Struct("<BQ")
# Opcode, length, channel id, sequence, log time, publish time: what precedes a message's data.
_MESSAGE_HEADER = struct.Struct("<BQHIQQ")
_MESSAGE_HEADER_CONTENT = _MESSAGE_HEADER.size - _RECORD_HEADER.size
_MESSAGE_CHANNEL_AND_LOG_TIME = struct.Struct("<HIQ")
_FOOTER_WITH_MAGIC = struct.Struct("<BQQQI8s")
_CHUNK_INDEX_TIMES_AND_OFFSET = struct.Struct("<QQQQ")
_CHUNK_FIXED_FIELDS = struct.Struct("<QQQI")
_U16 = struct.Struct("<H")
_U32 = struct.Struct("<I")
_U64 = struct.Struct("<Q")
# rosbag2 closes a chunk once it holds about this many uncompressed bytes.
_CHUNK_TARGET_BYTES = 1 << 20
_ROSBAG2_METADATA_NAME = "rosbag2"


class BagError(Exception):
    """A bag cannot be read or written; the message names the bag path and the problem."""


class TopicInfo(NamedTuple):
    """One topic of a bag: its message type ('pkg/msg/Type') and message count."""

    msgtype: str
    count: int


class BagMessage(NamedTuple):
    """One recorded message: topic name, type, log time (ns since the epoch) and CDR bytes."""

    topic: str
    msgtype: str
    log_time_ns: int
    raw: bytes


@functools.cache
def jazzy_typestore():
    """The rosbags typestore of ROS 2 Jazzy's message types (shared, do not register into it)."""
    return get_typestore(Stores.ROS2_JAZZY)


def _one_line(error: BaseException) -> str:
    """An error's text on one line (YAML parser messages span several)."""
    return " ".join(str(error).split())


def _find_topic(available: Iterable[str], name: str) -> str | None:
    """The stored topic name for ``name``, which may omit the leading slash of a root topic."""
    available = set(available)
    for candidate in (name, "/" + name.lstrip("/")):
        if candidate in available:
            return candidate
    return None


class _ChunkIndex(NamedTuple):
    """Where one chunk of an MCAP file lies and the log times (ns) of its first and last message."""

    start_ns: int
    end_ns: int
    offset: int
    length: int


def _string_at(buffer: bytes, position: int) -> tuple[str, int]:
    """An MCAP string starting at ``position``, and the position after it."""
    (length,) = _U32.unpack_from(buffer, position)
    end = position + _U32.size + length
    return buffer[position + _U32.size : end].decode(), end


def _read_mcap_summary(stream: BinaryIO) -> tuple[dict[int, str], list[_ChunkIndex]] | None:
    """Topics by channel id and the chunk indexes of an MCAP file, from its summary.

    None when the messages cannot be read by chunk index here (no summary, no chunk index, a
    chunk compression other than zstd); they are then read through rosbags.
    """
    size = stream.seek(0, 2)
    if size < len(_MCAP_MAGIC) + _FOOTER_WITH_MAGIC.size:
        return None
    stream.seek(size - _FOOTER_WITH_MAGIC.size)
    opcode, _, summary_start, _, _, magic = _FOOTER_WITH_MAGIC.unpack(
        stream.read(_FOOTER_WITH_MAGIC.size)
    )
    if opcode != _OP_FOOTER or magic != _MCAP_MAGIC or summary_start == 0:
        return None
    stream.seek(summary_start)
    summary = stream.read(size - _FOOTER_WITH_MAGIC.size - summary_start)
    topics: dict[int, str] = {}
    chunks: list[_ChunkIndex] = []
    position = 0
    while position < len(summary):
        opcode, length = _RECORD_HEADER.unpack_from(summary, position)
        content = position + _RECORD_HEADER.size
        position = content + length
        if opcode == _OP_CHANNEL:
            (channel_id,) = _U16.unpack_from(summary, content)
            topics[channel_id], _ = _string_at(summary, content + 2 * _U16.size)
        elif opcode == _OP_CHUNK_INDEX:
            start_ns, end_ns, offset, length = _CHUNK_INDEX_TIMES_AND_OFFSET.unpack_from(
                summary, content
            )
            offsets_at = content + _CHUNK_INDEX_TIMES_AND_OFFSET.size
            (offsets_length,) = _U32.unpack_from(summary, offsets_at)
            # After the message index offsets: their total length (u64), then the compression.
            compression_at = offsets_at + _U32.size + offsets_length + _U64.size
            compression, _ = _string_at(summary, compression_at)
            if compression not in ("", "zstd"):
                return None
            chunks.append(_ChunkIndex(start_ns, end_ns, offset, length))
    return (topics, chunks) if chunks else None


def _chunk_records(stream: BinaryIO, chunk: _ChunkIndex, decompressor) -> bytes:
    """The uncompressed records of one chunk, checked against its size and checksum."""
    stream.seek(chunk.offset)
    record = stream.read(chunk.length)
    if len(record) != chunk.length or record[0] != _OP_CHUNK:
        raise BagError(f"no chunk at offset {chunk.offset}")
    _, _, uncompressed_size, checksum = _CHUNK_FIXED_FIELDS.unpack_from(record, _RECORD_HEADER.size)
    compression, position = _string_at(record, _RECORD_HEADER.size + _CHUNK_FIXED_FIELDS.size)
    (stored_size,) = _U64.unpack_from(record, position)
    stored = record[position + _U64.size : position + _U64.size + stored_size]
    if compression == "zstd":
        records = decompressor.decompress(stored, max_output_size=uncompressed_size)
    else:
        records = stored
    if len(records) != uncompressed_size:
        raise BagError(
            f"chunk at offset {chunk.offset} holds {len(records)} bytes, not {uncompressed_size}"
        )
    if checksum and zlib.crc32(records) != checksum:
        raise BagError(f"chunk at offset {chunk.offset} fails its checksum")
    return records


def _log_time_ns(message: BagMessage) -> int:
    return message.log_time_ns


def _chunk_messages(records: bytes, channels: dict[int, tuple[str, str]]) -> list[BagMessage]:
    """The messages of ``channels`` (id → topic, type) in a chunk's records, in log-time order
    (stable: equal log times keep their order in the chunk)."""
    messages = []
    append = messages.append
    unpack_record = _RECORD_HEADER.unpack_from
    unpack_message = _MESSAGE_CHANNEL_AND_LOG_TIME.unpack_from
    data_offset = _RECORD_HEADER.size + _MESSAGE_HEADER_CONTENT
    position, end = 0, len(records)
    while position < end:
        opcode, length = unpack_record(records, position)
        record_end = position + _RECORD_HEADER.size + length
        if opcode == _OP_MESSAGE:
            channel_id, _, log_time_ns = unpack_message(records, position + _RECORD_HEADER.size)
            channel = channels.get(channel_id)
            if channel is not None:
                append(
                    BagMessage(
                        channel[0],
                        channel[1],
                        log_time_ns,
                        records[position + data_offset : record_end],
                    )
                )
        position = record_end
    if position != end:
        raise BagError("a record of a chunk runs past its end")
    messages.sort(key=_log_time_ns)
    return messages


def _merged_chunk_entries(stream, chunk: _ChunkIndex, channels, decompressor):
    """(log time, chunk offset, index, message) of a chunk's messages, after a placeholder at
    the chunk's start time so that :func:`heapq.merge` reads the chunk only when due."""
    yield chunk.start_ns, chunk.offset, -1, None
    messages = _chunk_messages(_chunk_records(stream, chunk, decompressor), channels)
    for index, message in enumerate(messages):
        yield message.log_time_ns, chunk.offset, index, message


def _mcap_messages(
    path: Path, chunks: list[_ChunkIndex], channels: dict[int, tuple[str, str]]
) -> Iterator[BagMessage]:
    """Messages of ``channels`` in log-time order, equal log times in the order rosbags reads
    them: by the chunk's place in the file, then by the place in the chunk.

    Chunks are taken in order of their first log time. A chunk that starts after the ones
    before it end (or at their last log time, and later in the file) follows them whole; only
    chunks whose time ranges overlap are merged message by message.
    """
    chunks = sorted(chunks, key=lambda chunk: (chunk.start_ns, chunk.offset))
    decompressor = zstandard.ZstdDecompressor()
    with path.open("rb") as stream:
        index = 0
        while index < len(chunks):
            group = [chunks[index]]
            group_end_ns = chunks[index].end_ns
            group_last_offset = chunks[index].offset
            index += 1
            while index < len(chunks) and (
                chunks[index].start_ns < group_end_ns
                or (
                    chunks[index].start_ns == group_end_ns
                    and chunks[index].offset < group_last_offset
                )
            ):
                group.append(chunks[index])
                group_end_ns = max(group_end_ns, chunks[index].end_ns)
                group_last_offset = max(group_last_offset, chunks[index].offset)
                index += 1
            if len(group) == 1:
                yield from _chunk_messages(_chunk_records(stream, group[0], decompressor), channels)
                continue
            entries = [
                _merged_chunk_entries(stream, chunk, channels, decompressor) for chunk in group
            ]
            for *_, message in heapq.merge(*entries):
                if message is not None:
                    yield message


class BagReader:
    """Read a rosbag2 bag directory; a context manager.

    Topic names may be given with or without the leading slash (``imu/data_raw`` finds
    ``/imu/data_raw``). ``start_ns``/``end_ns`` are the log times (ns) of the first and last
    message, both 0 for an empty bag.
    """

    def __init__(self, path: str | Path):
        self.path = Path(path)
        self._check_layout()
        try:
            self._reader = Reader(self.path)
            self._reader.open()
        except Exception as error:
            raise BagError(f"bag {self.path}: unreadable or corrupt: {_one_line(error)}") from error
        try:
            self._connections = list(self._reader.connections)
            self.topics: dict[str, TopicInfo] = {
                topic: TopicInfo(info.msgtype or "", info.msgcount)
                for topic, info in self._reader.topics.items()
            }
            if self._reader.message_count:
                self.start_ns = int(self._reader.start_time)
                self.end_ns = int(self._reader.end_time) - 1
            else:
                self.start_ns = self.end_ns = 0
            self._typestore = self._typestore_for_bag()
            self._indexed_mcap = self._find_indexed_mcap()
        except BagError:
            self.close()
            raise
        except Exception as error:
            self.close()
            raise BagError(f"bag {self.path}: corrupt: {_one_line(error)}") from error

    def _find_indexed_mcap(self) -> tuple[Path, dict[int, str], list[_ChunkIndex]] | None:
        """The bag's single MCAP file with its channel topics and chunk indexes, when messages
        can be read from it by chunk index here; None leaves reading to rosbags."""
        if self._reader.compression_mode:
            return None
        information = yaml.safe_load((self.path / METADATA_FILE).read_text())
        information = information["rosbag2_bagfile_information"]
        files = information["relative_file_paths"]
        if information["storage_identifier"] != "mcap" or len(files) != 1:
            return None
        path = self.path / Path(files[0]).name
        with path.open("rb") as stream:
            summary = _read_mcap_summary(stream)
        return None if summary is None else (path, *summary)

    def _check_layout(self) -> None:
        if not self.path.exists():
            raise BagError(f"bag {self.path} does not exist")
        if not self.path.is_dir():
            raise BagError(
                f"bag {self.path} is not a bag: a rosbag2 bag is a directory holding "
                f"{METADATA_FILE} and an .mcap file"
            )
        if not (self.path / METADATA_FILE).is_file():
            if any(self.path.glob("*.mcap")):
                raise BagError(
                    f"bag {self.path} is incomplete: it has no {METADATA_FILE} "
                    "(its writer was aborted before closing the bag)"
                )
            raise BagError(f"bag {self.path} is not a bag: it has no {METADATA_FILE}")

    def _typestore_for_bag(self):
        """Jazzy's typestore, or a private copy extended by types the bag defines itself."""
        typestore = jazzy_typestore()
        unknown = [c for c in self._connections if c.msgtype not in typestore.fielddefs]
        if not unknown:
            return typestore
        typestore = get_typestore(Stores.ROS2_JAZZY)
        for connection in unknown:
            if connection.msgdef.format != MessageDefinitionFormat.MSG:
                continue  # undecodable; raw bytes stay readable and decode() says why
            try:
                typestore.register(get_types_from_msg(connection.msgdef.data, connection.msgtype))
            except Exception as error:
                raise BagError(
                    f"bag {self.path}: topic {connection.topic}: cannot parse the definition "
                    f"of {connection.msgtype}: {_one_line(error)}"
                ) from error
        return typestore

    @property
    def duration_s(self) -> float:
        """Time between the first and the last message's log time, s."""
        return (self.end_ns - self.start_ns) * 1e-9

    def _topic_listing(self) -> str:
        if not self.topics:
            return "it has no topics"
        return "it has " + ", ".join(
            f"{name} ({info.msgtype}, {info.count})" for name, info in sorted(self.topics.items())
        )

    def _resolve_topics(self, topics: Iterable[str]) -> list[str]:
        resolved, missing = [], []
        for name in topics:
            found = _find_topic(self.topics, name)
            if found is None:
                missing.append(name)
            else:
                resolved.append(found)
        if missing:
            raise BagError(
                f"bag {self.path} lacks topic(s) {', '.join(missing)}; {self._topic_listing()}"
            )
        return resolved

    def require(self, *topics: str) -> None:
        """Raise BagError naming every missing topic and listing the bag's topics."""
        self._resolve_topics(topics)

    def messages(self, topics: Iterable[str] | None = None) -> Iterator[BagMessage]:
        """Messages of ``topics`` (all when None) in log-time order across topics.

        Once the iteration has completed, the per-topic counts are checked against metadata.yaml,
        so a bag whose data were cut short raises BagError instead of passing for a short bag.
        """
        wanted = set(self.topics if topics is None else self._resolve_topics(topics))
        connections = [c for c in self._connections if c.topic in wanted]
        return self._iterate(connections, wanted)

    def _iterate(self, connections: list, wanted: set[str]) -> Iterator[BagMessage]:
        if not connections:
            return
        seen: Counter[str] = Counter()
        try:
            for message in self._read(connections, wanted):
                seen[message.topic] += 1
                yield message
        except Exception as error:
            raise BagError(f"bag {self.path}: corrupt message data: {_one_line(error)}") from error
        short = {
            t: (seen[t], self.topics[t].count) for t in wanted if seen[t] != self.topics[t].count
        }
        if short:
            detail = ", ".join(
                f"{t}: {got} read, {want} listed" for t, (got, want) in short.items()
            )
            raise BagError(
                f"bag {self.path}: corrupt data: message counts differ from "
                f"{METADATA_FILE} ({detail})"
            )

    def _read(self, connections: list, wanted: set[str]) -> Iterator[BagMessage]:
        if self._indexed_mcap is None:
            for connection, log_time_ns, raw in self._reader.messages(connections=connections):
                yield BagMessage(connection.topic, connection.msgtype, log_time_ns, bytes(raw))
            return
        path, topics, chunks = self._indexed_mcap
        channels = {
            channel_id: (topic, self.topics[topic].msgtype)
            for channel_id, topic in topics.items()
            if topic in wanted
        }
        yield from _mcap_messages(path, chunks, channels)

    def decode(self, message: BagMessage):
        """The rosbags message object of ``message`` (fields named as in ROS, arrays as numpy)."""
        try:
            return self._typestore.deserialize_cdr(message.raw, message.msgtype)
        except Exception as error:
            raise BagError(
                f"bag {self.path}: cannot decode {message.msgtype} on {message.topic} at log time "
                f"{message.log_time_ns} ns: {_one_line(error)}"
            ) from error

    def close(self) -> None:
        reader, self._reader = getattr(self, "_reader", None), None
        if reader is not None and reader.is_open:
            reader.close()

    def __enter__(self) -> BagReader:
        return self

    def __exit__(self, *exc_info) -> None:
        self.close()


@functools.cache
def _message_definition(msgtype: str) -> tuple[str, str]:
    """(ros2msg definition text, RIHS01 type hash) of a Jazzy message type, as rosbag2 stores."""
    typestore = jazzy_typestore()
    definition, _ = typestore.generate_msgdef(msgtype, ros_version=2)
    return definition, typestore.hash_rihs01(msgtype)


def _record(opcode: int, content: bytes) -> bytes:
    return struct.pack("<BQ", opcode, len(content)) + content


def _string(text: str) -> bytes:
    encoded = text.encode()
    return struct.pack("<I", len(encoded)) + encoded


def _string_map(entries: dict[str, str]) -> bytes:
    content = b"".join(_string(key) + _string(value) for key, value in entries.items())
    return struct.pack("<I", len(content)) + content


def _time_span(start_ns: int, end_ns: int) -> dict:
    """metadata.yaml's start and duration of messages logged from ``start_ns`` to ``end_ns``
    (fresh dicts each time: shared ones would be dumped as YAML aliases)."""
    return {
        "starting_time": {"nanoseconds_since_epoch": start_ns},
        "duration": {"nanoseconds": max(0, end_ns - start_ns)},
    }


class _Channel:
    """A topic of the bag being written: MCAP channel id, type and messages written so far."""

    __slots__ = ("count", "id", "msgtype", "topic")

    def __init__(self, channel_id: int, topic: str, msgtype: str):
        self.id = channel_id
        self.topic = topic
        self.msgtype = msgtype
        self.count = 0


class _McapFile:
    """An MCAP file of the ``ros2`` profile being written, one chunk open at a time.

    Schema and channel records go into the chunk open when they are added (and into the
    summary); messages are appended to the chunk as packed records and indexed per channel by
    (log time, offset in the chunk).
    """

    def __init__(self, path: Path, compress: bool):
        self._stream: BinaryIO = path.open("xb")
        self._compressor = zstandard.ZstdCompressor() if compress else None
        self._compression = "zstd" if compress else ""
        self._schema_records: list[bytes] = []
        self._schema_ids: dict[str, int] = {}
        self._channel_records: list[bytes] = []
        self._chunk_index_records: list[bytes] = []
        # Per channel id (index 0 unused): flat (log time, offset) pairs of the open chunk.
        self._chunk_message_offsets: list[list[int]] = [[]]
        self.message_start_ns = 2**63 - 1
        self.message_end_ns = 0
        self._new_chunk()
        self._stream.write(_MCAP_MAGIC)
        self._stream.write(
            _record(_OP_HEADER, _string("ros2") + _string(f"buoy_common.bag_io ({ROS_DISTRO})"))
        )

    def _new_chunk(self) -> None:
        self._chunk = bytearray()
        self._chunk_start_ns = 2**63 - 1
        self._chunk_end_ns = 0

    def add_schema(self, msgtype: str, definition: str) -> int:
        schema_id = self._schema_ids.get(msgtype)
        if schema_id is None:
            schema_id = self._schema_ids[msgtype] = len(self._schema_ids) + 1
            content = struct.pack("<H", schema_id) + _string(msgtype) + _string("ros2msg")
            record = _record(_OP_SCHEMA, content + _string(definition))
            self._schema_records.append(record)
            self._chunk += record
        return schema_id

    def add_channel(self, schema_id: int, topic: str) -> int:
        channel_id = len(self._channel_records) + 1
        content = struct.pack("<HH", channel_id, schema_id) + _string(topic) + _string("cdr")
        record = _record(_OP_CHANNEL, content + _string_map({"offered_qos_profiles": "[]"}))
        self._channel_records.append(record)
        self._chunk_message_offsets.append([])
        self._chunk += record
        return channel_id

    def write(self, channel_id: int, log_time_ns: int, data: bytes) -> None:
        chunk = self._chunk
        offsets = self._chunk_message_offsets[channel_id]
        offsets.append(log_time_ns)
        offsets.append(len(chunk))
        chunk += _MESSAGE_HEADER.pack(
            _OP_MESSAGE,
            _MESSAGE_HEADER_CONTENT + len(data),
            channel_id,
            0,
            log_time_ns,
            log_time_ns,
        )
        chunk += data
        if log_time_ns < self._chunk_start_ns:
            self._chunk_start_ns = log_time_ns
        if log_time_ns > self._chunk_end_ns:
            self._chunk_end_ns = log_time_ns
        if len(chunk) > _CHUNK_TARGET_BYTES:
            self._close_chunk()

    def _close_chunk(self) -> None:
        if not self._chunk:
            return
        start_ns, end_ns = self._chunk_start_ns, self._chunk_end_ns
        if start_ns > end_ns:  # schemas and channels only: no message time range
            start_ns = end_ns = 0
        else:
            self.message_start_ns = min(self.message_start_ns, start_ns)
            self.message_end_ns = max(self.message_end_ns, end_ns)
        message_offsets = [
            (channel_id, offsets)
            for channel_id, offsets in enumerate(self._chunk_message_offsets)
            if offsets
        ]
        self._chunk_message_offsets = [[] for _ in self._chunk_message_offsets]
        records = self._chunk
        self._new_chunk()
        self._write_chunk(records, start_ns, end_ns, message_offsets)

    def _write_chunk(
        self,
        records: bytearray,
        start_ns: int,
        end_ns: int,
        message_offsets: list[tuple[int, list[int]]],
    ) -> None:
        """The chunk record, its message indexes and (kept for the summary) its chunk index."""
        stored = records if self._compressor is None else self._compressor.compress(records)
        stream = self._stream
        chunk_at = stream.tell()
        fields = (
            _CHUNK_FIXED_FIELDS.pack(start_ns, end_ns, len(records), zlib.crc32(records))
            + _string(self._compression)
            + _U64.pack(len(stored))
        )
        stream.write(_RECORD_HEADER.pack(_OP_CHUNK, len(fields) + len(stored)))
        stream.write(fields)
        stream.write(stored)
        indexes_at = stream.tell()
        index_offsets = []
        for channel_id, offsets in message_offsets:
            index_offsets.append(struct.pack("<HQ", channel_id, stream.tell()))
            pairs = struct.pack(f"<{len(offsets)}Q", *offsets)
            stream.write(
                _record(_OP_MESSAGE_INDEX, struct.pack("<HI", channel_id, len(pairs)) + pairs)
            )
        offset_map = b"".join(index_offsets)
        self._chunk_index_records.append(
            _record(
                _OP_CHUNK_INDEX,
                struct.pack(
                    "<QQQQI", start_ns, end_ns, chunk_at, indexes_at - chunk_at, len(offset_map)
                )
                + offset_map
                + _U64.pack(stream.tell() - indexes_at)
                + _string(self._compression)
                + struct.pack("<QQ", len(stored), len(records)),
            )
        )

    def end_data(self) -> tuple[int, int]:
        """Write the open chunk; returns the log times (ns) of the first and last message
        written, both 0 without messages."""
        self._close_chunk()
        if self.message_start_ns > self.message_end_ns:
            self.message_start_ns = self.message_end_ns = 0
        return self.message_start_ns, self.message_end_ns

    def close(self, channel_counts: list[int], serialized_metadata: str) -> None:
        """After :meth:`end_data`: the rosbag2 metadata record, the summary and the footer."""
        stream = self._stream
        metadata_at = stream.tell()
        stream.write(
            _record(
                _OP_METADATA,
                _string(_ROSBAG2_METADATA_NAME)
                + _string_map({"serialized_metadata": serialized_metadata}),
            )
        )
        metadata_end = stream.tell()
        stream.write(_record(_OP_DATA_END, struct.pack("<I", 0)))
        sections = []
        for opcode, records in (
            (_OP_SCHEMA, self._schema_records),
            (_OP_CHANNEL, self._channel_records),
            (_OP_CHUNK_INDEX, self._chunk_index_records),
            (
                _OP_METADATA_INDEX,
                [
                    _record(
                        _OP_METADATA_INDEX,
                        struct.pack("<QQ", metadata_at, metadata_end - metadata_at)
                        + _string(_ROSBAG2_METADATA_NAME),
                    )
                ],
            ),
            (_OP_STATISTICS, [self._statistics_record(channel_counts)]),
        ):
            if records:
                at = stream.tell()
                stream.write(b"".join(records))
                sections.append((opcode, at, stream.tell() - at))
        summary_at = sections[0][1]
        summary_offsets_at = stream.tell()
        for opcode, at, length in sections:
            stream.write(_record(_OP_SUMMARY_OFFSET, struct.pack("<BQQ", opcode, at, length)))
        stream.write(_record(_OP_FOOTER, struct.pack("<QQI", summary_at, summary_offsets_at, 0)))
        stream.write(_MCAP_MAGIC)
        stream.close()

    def _statistics_record(self, channel_counts: list[int]) -> bytes:
        counts = b"".join(
            struct.pack("<HQ", channel_id, count)
            for channel_id, count in enumerate(channel_counts, start=1)
        )
        return _record(
            _OP_STATISTICS,
            struct.pack(
                "<QHIIIIQQI",
                sum(channel_counts),
                len(self._schema_records),
                len(self._channel_records),
                0,  # attachments
                1,  # metadata records
                len(self._chunk_index_records),
                self.message_start_ns,
                self.message_end_ns,
                len(counts),
            )
            + counts,
        )

    def abort(self) -> None:
        """Close the file as it is, without the summary: readers refuse it."""
        self._stream.close()


class _BagOutput:
    """A bag being written, as a context manager: leaving the block normally finishes the bag
    (``close``); leaving it by an exception aborts it and notes so on the exception."""

    def __enter__(self):
        return self

    def __exit__(self, exc_type, exc, traceback) -> None:
        if exc is None:
            self.close()
            return
        if not self.closed:
            self.abort()
            exc.add_note(
                f"bag {self.path} was aborted and is incomplete "
                f"(no {METADATA_FILE}; {sum(self.counts.values())} messages written)"
            )


def _make_room_for_bag(path: Path, overwrite: bool) -> None:
    """Make sure nothing is at ``path`` for a new bag: refuse if something is there, unless
    ``overwrite``, and even then delete it only if it is a bag, never an arbitrary directory."""
    if not (path.exists() or path.is_symlink()):
        return
    if not overwrite:
        raise BagError(f"bag {path} already exists; refusing to overwrite it")
    if not path.is_dir() or path.is_symlink():
        raise BagError(f"bag {path} exists and is not a bag directory; not removing it")
    unexpected = [p.name for p in path.iterdir() if p.name != METADATA_FILE and p.suffix != ".mcap"]
    if unexpected:
        raise BagError(
            f"bag {path} exists and holds more than a bag ({', '.join(unexpected)}); "
            "not removing it"
        )
    shutil.rmtree(path)


class BagWriter(_BagOutput):
    """Write a rosbag2 bag (version 9, MCAP, zstd chunks); a context manager.

    The bag directory is created at construction. ``close()`` (or leaving the ``with`` block
    normally) writes the index and metadata.yaml. Leaving the block by an exception aborts the
    bag instead: the directory stays without metadata.yaml, BagReader refuses it as incomplete,
    and a note naming the bag is attached to the exception.
    """

    def __init__(self, path: str | Path, overwrite: bool = False, compress: bool = True):
        self.path = Path(path)
        _make_room_for_bag(self.path, overwrite)
        self._typestore = jazzy_typestore()
        self._channels: dict[str, _Channel] = {}
        self._mcap_name = f"{self.path.name}.mcap"
        try:
            self.path.mkdir(mode=0o755, parents=True)
            self._file: _McapFile | None = _McapFile(self.path / self._mcap_name, compress)
        except OSError as error:
            raise BagError(f"bag {self.path}: cannot create: {_one_line(error)}") from error

    @property
    def counts(self) -> dict[str, int]:
        """Messages written so far, per topic."""
        return {topic: channel.count for topic, channel in self._channels.items() if channel.count}

    @property
    def closed(self) -> bool:
        return self._file is None

    def _open_file(self) -> _McapFile:
        if self._file is None:
            raise BagError(f"bag {self.path} is closed")
        return self._file

    def _channel(self, topic: str, msgtype: str) -> _Channel:
        channel = self._channels.get(topic)
        if channel is not None:
            if channel.msgtype != msgtype:
                raise BagError(
                    f"bag {self.path}: topic {topic} holds {channel.msgtype}, "
                    f"cannot also write {msgtype}"
                )
            return channel
        _require_known_type(self._typestore, self.path, topic, msgtype)
        file = self._open_file()
        definition, _ = _message_definition(msgtype)
        channel_id = file.add_channel(file.add_schema(msgtype, definition), topic)
        channel = self._channels[topic] = _Channel(channel_id, topic, msgtype)
        return channel

    def write_raw(self, topic: str, msgtype: str, log_time_ns: int, raw: bytes) -> None:
        """Append one CDR-serialised message with log time ``log_time_ns`` (ns since the epoch)."""
        channel = self._channels.get(topic)
        if channel is None or channel.msgtype != msgtype:
            channel = self._channel(topic, msgtype)
        if log_time_ns < 0:
            raise BagError(f"bag {self.path}: topic {topic}: negative log time {log_time_ns} ns")
        self._open_file().write(channel.id, int(log_time_ns), raw)
        channel.count += 1

    def write(self, topic: str, msgtype: str, log_time_ns: int, message) -> None:
        """Serialise ``message`` (a rosbags or an rclpy message of ``msgtype``) and append it.

        rclpy messages are copied field by field into rosbags' classes, which also converts
        what rclpy holds differently: ``byte`` as ``bytes``, ``char`` as ``str``, sequences as
        ``array.array`` or lists.
        """
        self._channel(topic, msgtype)
        raw = _serialize(self._typestore, self.path, topic, msgtype, message)
        self.write_raw(topic, msgtype, log_time_ns, raw)

    def _metadata(self, start_ns: int, end_ns: int) -> dict:
        """The ``rosbag2_bagfile_information`` of the bag as written so far."""
        channels = list(self._channels.values())
        count = sum(channel.count for channel in channels)
        return {
            "version": BAG_VERSION,
            "storage_identifier": "mcap",
            "relative_file_paths": [self._mcap_name],
            **_time_span(start_ns, end_ns),
            "message_count": count,
            "topics_with_message_count": [
                {
                    "topic_metadata": {
                        "name": channel.topic,
                        "type": channel.msgtype,
                        "serialization_format": "cdr",
                        "offered_qos_profiles": [],
                        "type_description_hash": _message_definition(channel.msgtype)[1],
                    },
                    "message_count": channel.count,
                }
                for channel in channels
            ],
            "compression_format": "",
            "compression_mode": "",
            "files": [
                {"path": self._mcap_name, **_time_span(start_ns, end_ns), "message_count": count}
            ],
            "custom_data": None,
            "ros_distro": ROS_DISTRO,
        }

    def close(self) -> None:
        """Finish the bag: write the MCAP index and metadata.yaml. Idempotent."""
        file, self._file = self._file, None
        if file is None:
            return
        try:
            information = self._metadata(*file.end_data())
            file.close(
                [channel.count for channel in self._channels.values()],
                yaml.safe_dump(information, default_flow_style=False).strip(),
            )
            staged = self.path / f"{METADATA_FILE}.tmp"
            staged.write_text(
                yaml.safe_dump(
                    {"rosbag2_bagfile_information": information}, default_flow_style=False
                ),
                "utf8",
            )
            staged.replace(self.path / METADATA_FILE)
        except Exception as error:
            file.abort()
            raise BagError(
                f"bag {self.path}: failed to finish, bag is incomplete: {_one_line(error)}"
            ) from error

    def abort(self) -> None:
        """Stop writing without finishing: the bag stays incomplete (no metadata.yaml)."""
        file, self._file = self._file, None
        if file is not None:
            file.abort()


def _require_known_type(typestore, path: Path, topic: str, msgtype: str) -> None:
    if msgtype not in typestore.fielddefs:
        raise BagError(
            f"bag {path}: topic {topic}: unknown message type {msgtype!r} "
            "(not a ROS 2 Jazzy type; expected 'package/msg/Type')"
        )


def _serialize(typestore, path: Path, topic: str, msgtype: str, message) -> bytes:
    """CDR bytes of a rosbags or rclpy ``message`` of ``msgtype``; BagError naming the bag and
    topic when it does not fit the type."""
    _require_known_type(typestore, path, topic, msgtype)
    try:
        typed = _as_typestore_message(typestore, msgtype, message)
        return bytes(typestore.serialize_cdr(typed, msgtype))
    except BagError:
        raise
    except Exception as error:
        raise BagError(
            f"bag {path}: topic {topic}: cannot serialise "
            f"{type(message).__name__} as {msgtype}: {_one_line(error)}"
        ) from error


# Messages handed to the writing process at a time: large enough that sending costs a fraction
# of a microsecond per message, small enough to keep both processes busy.
_BATCH_MESSAGES = 2048


class BackgroundBagWriter(_BagOutput):
    """A :class:`BagWriter` in a process of its own, for the offline tools: packing records,
    compressing and writing the file then take the second core instead of the tool's.

    Same interface and bag as :class:`BagWriter`. Messages are handed over in batches through a
    pipe; an error of the writing process (a full disk, a type conflict) is raised as BagError
    at the next hand-over or at :meth:`close`. Leaving the ``with`` block by an exception aborts
    the bag, as :class:`BagWriter` does. What is at ``path`` is checked (and with ``overwrite``
    removed) at construction; the tool does not wait for the writing process to start (about a
    second of imports) but keeps the first batches until it is ready.

    ``tap`` = (factory, arguments) puts more of the work in the writing process: it builds
    ``factory(bag_writer, *arguments)`` there, an object with a set ``topics``,
    ``take(topic, log_time_ns, raw)`` for each record of those topics as it is written (it may
    write records of its own) and ``finish(log_time_ns)`` at the end of the input (the log
    time given to :meth:`end_of_input`, else the latest written), whose result becomes
    :attr:`tap_result` once the bag is closed.
    """

    def __init__(
        self,
        path: str | Path,
        overwrite: bool = False,
        compress: bool = True,
        tap: tuple | None = None,
    ):
        self.path = Path(path)
        self.tap_result = None
        _make_room_for_bag(self.path, overwrite)
        self._typestore = jazzy_typestore()
        self._counts: Counter[str] = Counter()
        self._batch: list[tuple[str, str, int, bytes]] = []
        self._waiting_batches: list[list[tuple[str, str, int, bytes]]] = []
        self._writer_ready = False
        # Spawned, not forked: the tools may run inside processes with middleware threads.
        context = multiprocessing.get_context("spawn")
        self._connection, child_end = context.Pipe()
        self._process = context.Process(
            target=_write_bag_from_pipe,
            args=(child_end, str(self.path), compress, tap),
            name=f"bag writer {self.path.name}",
            daemon=True,
        )
        self._process.start()
        child_end.close()
        self._open = True

    @property
    def counts(self) -> dict[str, int]:
        """Messages handed over so far, per topic; once closed, all the bag holds (with what
        the tap wrote)."""
        return dict(self._counts)

    @property
    def closed(self) -> bool:
        return not self._open

    def write_raw(self, topic: str, msgtype: str, log_time_ns: int, raw: bytes) -> None:
        """Append one CDR-serialised message with log time ``log_time_ns`` (ns since the epoch)."""
        if not self._open:
            raise BagError(f"bag {self.path} is closed")
        self._batch.append((topic, msgtype, log_time_ns, raw))
        self._counts[topic] += 1
        if len(self._batch) >= _BATCH_MESSAGES:
            self._send_batch()

    def write(self, topic: str, msgtype: str, log_time_ns: int, message) -> None:
        """Serialise ``message`` (a rosbags or an rclpy message of ``msgtype``) and append it."""
        raw = _serialize(self._typestore, self.path, topic, msgtype, message)
        self.write_raw(topic, msgtype, log_time_ns, raw)

    def end_of_input(self, log_time_ns: int) -> None:
        """The log time (ns) of the last input message, at which the tap finishes."""
        self._batch.append(("", "", log_time_ns, b""))

    def close(self) -> None:
        """Finish the bag (index and metadata.yaml) and wait for the writing process."""
        if not self._open:
            return
        self._send_batch(wait_for_writer=True)
        self.tap_result, counts = self._finish("close")
        self._counts = Counter(counts)

    def abort(self) -> None:
        """Stop writing without finishing: the bag stays incomplete (no metadata.yaml). Never
        raises: it runs while an error is already on its way."""
        if self._open:
            self._batch.clear()
            self._waiting_batches.clear()
            with contextlib.suppress(BagError):
                self._finish("abort")

    def _send_batch(self, wait_for_writer: bool = False) -> None:
        """Hand the batch over, or keep it while the writing process is still starting (unless
        ``wait_for_writer``)."""
        if self._batch:
            self._waiting_batches.append(self._batch)
            self._batch = []
        if not self._writer_ready:
            if not (wait_for_writer or self._connection.poll()):
                return
            self._await_writer()
        try:
            for batch in self._waiting_batches:
                self._connection.send(batch)
        except (BrokenPipeError, ConnectionResetError, EOFError):
            self._open = False
            self._raise_if_failed(self._receive())
            raise BagError(f"bag {self.path}: the writing process stopped") from None
        self._waiting_batches.clear()

    def _finish(self, command: str):
        """Send ``command``; the result the writing process reports."""
        self._open = False
        if not self._writer_ready:
            self._await_writer()
        try:
            self._connection.send(command)
            reply = self._receive()
        except (BrokenPipeError, ConnectionResetError):
            reply = self._receive()
        finally:
            self._process.join(timeout=_WRITER_EXIT_TIMEOUT_S)
            if self._process.is_alive():
                self._process.kill()
            self._connection.close()
        self._raise_if_failed(reply)
        return reply[1:]

    def _await_writer(self) -> None:
        """Wait for the writing process to report that it has created the bag; raise its
        error if it could not."""
        reply = self._receive()
        if reply[0] == "error":
            self._open = False
            self._process.join(timeout=_WRITER_EXIT_TIMEOUT_S)
            self._connection.close()
            raise BagError(reply[1])
        self._writer_ready = True

    def _receive(self):
        try:
            return self._connection.recv()
        except (EOFError, ConnectionResetError):
            return ("error", f"bag {self.path}: the writing process ended unexpectedly")

    @staticmethod
    def _raise_if_failed(reply) -> None:
        if reply[0] == "error":
            raise BagError(reply[1])


# Longest wait for the writing process to exit once the bag is finished (s).
_WRITER_EXIT_TIMEOUT_S = 60.0


def _write_bag_from_pipe(connection, path: str, compress: bool, tap) -> None:
    """The writing process: a BagWriter fed batches of records until "close" or "abort"; an
    empty topic marks the end of the input (see :meth:`BackgroundBagWriter.end_of_input`)."""
    try:
        writer = BagWriter(path, compress=compress)
    except BagError as error:
        connection.send(("error", str(error)))
        return
    connection.send(("ok",))
    result = None
    try:
        taker = None if tap is None else tap[0](writer, *tap[1])
        tapped = set() if taker is None else taker.topics
        end_ns = latest_ns = 0
        while True:
            batch = connection.recv()
            if batch == "abort":
                writer.abort()
                connection.send(("aborted",))
                return
            if batch == "close":
                break
            for topic, msgtype, log_time_ns, raw in batch:
                if not topic:
                    end_ns = log_time_ns
                    continue
                writer.write_raw(topic, msgtype, log_time_ns, raw)
                latest_ns = log_time_ns
                if topic in tapped:
                    taker.take(topic, log_time_ns, raw)
        if taker is not None:
            result = taker.finish(end_ns or latest_ns)
        counts = writer.counts
        writer.close()
    except EOFError:
        writer.abort()
        return
    except Exception as error:  # reported to the tool, which raises it as a BagError
        writer.abort()
        connection.send(("error", f"bag {path}: {type(error).__name__}: {_one_line(error)}"))
        return
    connection.send(("ok", result, counts))


def _as_typestore_message(typestore, msgtype: str, source):
    """``source`` as an instance of the typestore's class for ``msgtype``."""
    if getattr(source, "__msgtype__", None) == msgtype:
        return source
    module_match = _RCLPY_MESSAGE_MODULE.match(type(source).__module__)
    if module_match:
        source_type = f"{module_match['package']}/msg/{type(source).__name__}"
        if source_type != msgtype:
            raise BagError(f"message is a {source_type}, not a {msgtype}")
    _, fields = typestore.fielddefs[msgtype]
    values = {}
    for name, description in fields:
        python_name = normalize_fieldname(name)
        value = getattr(source, name) if hasattr(source, name) else getattr(source, python_name)
        values[python_name] = _as_typestore_value(typestore, description, value)
    return typestore.types[msgtype](**values)


def _as_typestore_value(typestore, description, value):
    kind, detail = description
    if kind == Nodetype.NAME:
        return _as_typestore_message(typestore, detail, value)
    if kind == Nodetype.BASE:
        return _as_typestore_scalar(detail[0], value)
    element, _ = detail
    element_kind, element_detail = element
    if element_kind == Nodetype.NAME:
        return [_as_typestore_message(typestore, element_detail, item) for item in value]
    basename = element_detail[0]
    if basename in _STRING_TYPES:
        return [str(item) for item in value]
    dtype = _ARRAY_DTYPES[basename]
    if isinstance(value, (bytes, bytearray, memoryview)):
        return np.frombuffer(bytes(value), dtype=dtype).copy()
    items = list(value)
    if items and isinstance(items[0], (bytes, bytearray)):
        return np.frombuffer(b"".join(items), dtype=dtype).copy()
    if items and isinstance(items[0], str):
        items = [ord(item) for item in items]
    return np.asarray(items, dtype=dtype)


def _as_typestore_scalar(basename: str, value):
    if isinstance(value, (bytes, bytearray)):
        # rosbags holds `byte` as a signed octet.
        return int.from_bytes(value[:1], "little", signed=True)
    if basename == "char" and isinstance(value, str):
        return ord(value)
    return value
