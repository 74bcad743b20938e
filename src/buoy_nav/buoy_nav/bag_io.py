"""Reading and writing rosbag2 bags (metadata.yaml version 9, one MCAP file) with rosbags.

A bag is a directory holding ``metadata.yaml`` and one ``.mcap`` file with the ``ros2`` profile
and ``ros2msg`` schemas, as ``ros2 bag record`` writes and ``ros2 bag play`` reads. Messages are
kept as CDR bytes; log times are integer nanoseconds.

Chunks of the MCAP file are zstd-compressed (rosbags' storage-level compression, the same layout
``ros2 bag record --storage-preset-profile zstd_fast`` produces): metadata.yaml then declares no
compression, and both the rosbag2 MCAP plugin and the ``mcap`` readers decompress chunks
transparently. Sensor bags shrink several-fold.

This module never imports rclpy: it is used offline as well as by the recorder and player nodes.
"""

from __future__ import annotations

import functools
import re
import shutil
from collections import Counter
from collections.abc import Iterable, Iterator
from pathlib import Path
from typing import NamedTuple

import numpy as np
from rosbags.interfaces import MessageDefinitionFormat, Nodetype
from rosbags.rosbag2 import CompressionFormat, CompressionMode, Reader, StoragePlugin, Writer
from rosbags.typesys import Stores, get_types_from_msg, get_typestore
from rosbags.typesys.base import normalize_fieldname

BAG_VERSION = 9
METADATA_FILE = "metadata.yaml"

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
        except BagError:
            self.close()
            raise
        except Exception as error:
            self.close()
            raise BagError(f"bag {self.path}: corrupt: {_one_line(error)}") from error

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
            for connection, log_time_ns, raw in self._reader.messages(connections=connections):
                seen[connection.topic] += 1
                yield BagMessage(connection.topic, connection.msgtype, log_time_ns, bytes(raw))
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


class BagWriter:
    """Write a rosbag2 bag (version 9, MCAP, zstd chunks); a context manager.

    The bag directory is created at construction. ``close()`` (or leaving the ``with`` block
    normally) writes the index and metadata.yaml. Leaving the block by an exception aborts the
    bag instead: the directory stays without metadata.yaml, BagReader refuses it as incomplete,
    and a note naming the bag is attached to the exception.
    """

    def __init__(self, path: str | Path, overwrite: bool = False, compress: bool = True):
        self.path = Path(path)
        if self.path.exists() or self.path.is_symlink():
            if not overwrite:
                raise BagError(f"bag {self.path} already exists; refusing to overwrite it")
            self._remove_existing_bag()
        self._typestore = jazzy_typestore()
        self._connections: dict[str, object] = {}
        self._counts: Counter[str] = Counter()
        writer = Writer(self.path, version=BAG_VERSION, storage_plugin=StoragePlugin.MCAP)
        if compress:
            writer.set_compression(CompressionMode.STORAGE, CompressionFormat.ZSTD)
        try:
            writer.open()
        except Exception as error:
            raise BagError(f"bag {self.path}: cannot create: {_one_line(error)}") from error
        self._writer: Writer | None = writer

    def _remove_existing_bag(self) -> None:
        """Delete what is at ``path`` only if it is a bag: never an arbitrary directory."""
        if not self.path.is_dir() or self.path.is_symlink():
            raise BagError(f"bag {self.path} exists and is not a bag directory; not removing it")
        unexpected = [
            p.name for p in self.path.iterdir() if p.name != METADATA_FILE and p.suffix != ".mcap"
        ]
        if unexpected:
            raise BagError(
                f"bag {self.path} exists and holds more than a bag ({', '.join(unexpected)}); "
                "not removing it"
            )
        shutil.rmtree(self.path)

    @property
    def counts(self) -> dict[str, int]:
        """Messages written so far, per topic."""
        return dict(self._counts)

    @property
    def closed(self) -> bool:
        return self._writer is None

    def _connection(self, topic: str, msgtype: str):
        connection = self._connections.get(topic)
        if connection is not None:
            if connection.msgtype != msgtype:
                raise BagError(
                    f"bag {self.path}: topic {topic} holds {connection.msgtype}, "
                    f"cannot also write {msgtype}"
                )
            return connection
        if msgtype not in self._typestore.fielddefs:
            raise BagError(
                f"bag {self.path}: topic {topic}: unknown message type {msgtype!r} "
                "(not a ROS 2 Jazzy type; expected 'package/msg/Type')"
            )
        connection = self._open_writer().add_connection(topic, msgtype, typestore=self._typestore)
        self._connections[topic] = connection
        return connection

    def _open_writer(self) -> Writer:
        if self._writer is None:
            raise BagError(f"bag {self.path} is closed")
        return self._writer

    def write_raw(self, topic: str, msgtype: str, log_time_ns: int, raw: bytes) -> None:
        """Append one CDR-serialised message with log time ``log_time_ns`` (ns since the epoch)."""
        if log_time_ns < 0:
            raise BagError(f"bag {self.path}: topic {topic}: negative log time {log_time_ns} ns")
        connection = self._connection(topic, msgtype)
        self._open_writer().write(connection, int(log_time_ns), raw)
        self._counts[topic] += 1

    def write(self, topic: str, msgtype: str, log_time_ns: int, message) -> None:
        """Serialise ``message`` (a rosbags or an rclpy message of ``msgtype``) and append it.

        rclpy messages are copied field by field into rosbags' classes, which also converts
        what rclpy holds differently: ``byte`` as ``bytes``, ``char`` as ``str``, sequences as
        ``array.array`` or lists.
        """
        self._connection(topic, msgtype)
        try:
            typed = _as_typestore_message(self._typestore, msgtype, message)
            raw = self._typestore.serialize_cdr(typed, msgtype)
        except BagError:
            raise
        except Exception as error:
            raise BagError(
                f"bag {self.path}: topic {topic}: cannot serialise "
                f"{type(message).__name__} as {msgtype}: {_one_line(error)}"
            ) from error
        self.write_raw(topic, msgtype, log_time_ns, bytes(raw))

    def close(self) -> None:
        """Finish the bag: write the MCAP index and metadata.yaml. Idempotent."""
        writer, self._writer = self._writer, None
        if writer is None:
            return
        try:
            writer.close()
        except Exception as error:
            writer.abort()
            raise BagError(
                f"bag {self.path}: failed to finish, bag is incomplete: {_one_line(error)}"
            ) from error

    def abort(self) -> None:
        """Stop writing without finishing: the bag stays incomplete (no metadata.yaml)."""
        writer, self._writer = self._writer, None
        if writer is not None:
            writer.abort()

    def __enter__(self) -> BagWriter:
        return self

    def __exit__(self, exc_type, exc, traceback) -> None:
        if exc is None:
            self.close()
            return
        if not self.closed:
            self.abort()
            exc.add_note(
                f"bag {self.path} was aborted and is incomplete "
                f"(no {METADATA_FILE}; {sum(self._counts.values())} messages written)"
            )


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
