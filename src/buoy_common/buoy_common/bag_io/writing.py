"""Writing rosbag2 bags: metadata.yaml (version 9) beside one MCAP file.

The MCAP file is written by the ``mcap`` library (its messages packed by
:mod:`~buoy_common.bag_io.mcap_writer`) with the ``ros2`` profile, as the rosbag2 MCAP
storage plugin writes it: ``ros2msg`` schemas (definitions and RIHS01 hashes from rosbags'
Jazzy typestore), ``cdr`` channels, zstd-compressed chunks of about 1 MiB with their CRCs and
message indexes, the ``rosbag2`` metadata record and a summary. metadata.yaml then declares no
compression (it is inside the chunks), and ``ros2 bag``, rosbags and the ``mcap`` readers read
the bag as it is.

A bag is written under a temporary name beside its final one and renamed when closed (see
:mod:`buoy_common.safe_output`). A recorder writes ``in_place`` instead and calls
:meth:`BagWriter.flush` now and then, so that what it recorded stays readable if it is killed.
"""

from __future__ import annotations

import os
import shutil
from pathlib import Path
from typing import TYPE_CHECKING

import yaml
from mcap.writer import CompressionType

from buoy_common.bag_io.common import (
    BAG_VERSION,
    MCAP_SUFFIX,
    METADATA_FILE,
    ROS_DISTRO,
    BagError,
    TypeDescription,
    jazzy_typestore,
    one_line,
    type_description,
)
from buoy_common.bag_io.mcap_writer import McapWriter
from buoy_common.safe_output import OutputError, move_into_place, staging_path

if TYPE_CHECKING:
    # Not imported by the offline tools' writing process until a stretch comes: numpy.
    from buoy_common.bag_io.stretch import Stretch

# Uncompressed bytes after which a chunk is closed: rosbag2's and mcap's default. Larger chunks
# compress no better and cost more to hold; smaller ones add index records (measured; the bag
# format: docs/bags.md).
CHUNK_BYTES = 1 << 20
_ROSBAG2_METADATA_NAME = "rosbag2"
_LIBRARY = f"buoy_common ({ROS_DISTRO})"


def check_bag_destination(path: Path, overwrite: bool) -> None:
    """BagError unless a bag may be written at ``path``: nothing is there, or ``overwrite`` is
    given and a bag is there (never an arbitrary file or directory)."""
    if not (path.exists() or path.is_symlink()):
        return
    if not overwrite:
        raise BagError(f"bag {path} already exists; refusing to overwrite it")
    if not path.is_dir() or path.is_symlink():
        raise BagError(f"bag {path} exists and is not a bag directory; not removing it")
    unexpected = [
        p.name for p in path.iterdir() if p.name != METADATA_FILE and p.suffix != MCAP_SUFFIX
    ]
    if unexpected:
        raise BagError(
            f"bag {path} exists and holds more than a bag ({', '.join(sorted(unexpected))}); "
            "not removing it"
        )


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


class BagOutput:
    """A bag being written, as a context manager: leaving the block normally finishes the bag
    (``close``); leaving it by an exception abandons it (``abort``) and notes so on the
    exception."""

    path: Path

    def __enter__(self):
        return self

    def __exit__(self, exc_type, exc, traceback) -> None:
        if exc is None:
            self.close()
            return
        if not self.closed:
            self.abort()
            exc.add_note(self._abandoned_note())

    def _abandoned_note(self) -> str:
        return (
            f"bag {self.path} was not written: abandoned after {sum(self.counts.values())} messages"
        )

    def write_stretch(self, stretch: Stretch) -> None:
        """:meth:`write_raw` of each message of ``stretch`` (:mod:`~buoy_common.bag_io.stretch`),
        encoded here, in order."""
        for record in stretch.encoded():
            self.write_raw(*record)


class BagWriter(BagOutput):
    """Write a rosbag2 bag (version 9, one MCAP file, zstd chunks); a context manager.

    The bag is written under ``<path>.partial-<pid>`` and renamed to ``path`` by ``close()`` (or
    by leaving the ``with`` block normally). An existing bag at ``path`` is refused, or with
    ``overwrite`` replaced once the new one is complete; anything else at ``path`` is never
    replaced. ``abort()`` (or leaving the block by an exception) deletes the partial bag.

    ``in_place`` is for recorders: the bag is written under ``path`` itself (which must not
    exist), :meth:`flush` makes what was written so far readable should the process die, and
    ``abort()`` finishes the bag rather than deleting it.

    Each message type's definition and hash come from rosbags' Jazzy typestore when the type is
    first written, unless :meth:`describe` gave them (a writer that writes CDR bytes only then
    does without the typestore).
    """

    def __init__(self, path: str | Path, overwrite: bool = False, *, in_place: bool = False):
        self.path = Path(path)
        self._overwrite = overwrite
        self._in_place = in_place
        check_bag_destination(self.path, overwrite and not in_place)
        self._directory = self.path if in_place else staging_path(self.path)
        self._descriptions: dict[str, TypeDescription] = {}
        self._channels: dict[str, _Channel] = {}
        self._schema_ids: dict[str, int] = {}
        self._mcap_name = f"{self.path.name}{MCAP_SUFFIX}"
        self._start_ns = 2**63 - 1
        self._end_ns = 0
        self._metadata_records: list[tuple[str, dict[str, str]]] = []
        try:
            self._directory.mkdir(mode=0o755, parents=True)
            self._stream = (self._directory / self._mcap_name).open("xb")
        except OSError as error:
            raise BagError(f"bag {self.path}: cannot create: {one_line(error)}") from error
        self._writer: McapWriter | None = McapWriter(
            self._stream,
            chunk_size=CHUNK_BYTES,
            compression=CompressionType.ZSTD,
            enable_crcs=True,
        )
        self._writer.start(profile="ros2", library=_LIBRARY)

    @property
    def counts(self) -> dict[str, int]:
        """Messages written so far, per topic."""
        return {topic: channel.count for topic, channel in self._channels.items() if channel.count}

    @property
    def closed(self) -> bool:
        return self._writer is None

    def describe(self, descriptions: dict[str, TypeDescription]) -> None:
        """The definitions and hashes of message types to be written, by type name (as
        :func:`~buoy_common.bag_io.common.type_description` gives them)."""
        self._descriptions.update(descriptions)

    def _open_writer(self) -> McapWriter:
        if self._writer is None:
            raise BagError(f"bag {self.path} is closed")
        return self._writer

    def _channel(self, topic: str, msgtype: str) -> _Channel:
        channel = self._channels.get(topic)
        if channel is not None:
            if channel.msgtype != msgtype:
                raise BagError(
                    f"bag {self.path}: topic {topic} holds {channel.msgtype}, "
                    f"cannot also write {msgtype}"
                )
            return channel
        description = self._descriptions.get(msgtype)
        if description is None:
            description = self._descriptions[msgtype] = type_description(self.path, topic, msgtype)
        writer = self._open_writer()
        schema_id = self._schema_ids.get(msgtype)
        if schema_id is None:
            schema_id = writer.register_schema(msgtype, "ros2msg", description.definition.encode())
            self._schema_ids[msgtype] = schema_id
        channel_id = writer.register_channel(topic, "cdr", schema_id, {"offered_qos_profiles": ""})
        channel = self._channels[topic] = _Channel(channel_id, topic, msgtype)
        return channel

    def write_raw(self, topic: str, msgtype: str, log_time_ns: int, raw: bytes) -> None:
        """Append one CDR-serialised message with log time ``log_time_ns`` (ns since the epoch)."""
        channel = self._channels.get(topic)
        if channel is None or channel.msgtype != msgtype:
            channel = self._channel(topic, msgtype)
        if log_time_ns < 0:
            raise BagError(f"bag {self.path}: topic {topic}: negative log time {log_time_ns} ns")
        if self._writer is None:
            raise BagError(f"bag {self.path} is closed")
        self._writer.add_message(channel.id, log_time_ns, raw, log_time_ns)
        channel.count += 1
        if log_time_ns < self._start_ns:
            self._start_ns = log_time_ns
        if log_time_ns > self._end_ns:
            self._end_ns = log_time_ns

    def write(self, topic: str, msgtype: str, log_time_ns: int, message) -> None:
        """Serialise ``message`` (a rosbags or an rclpy message of ``msgtype``) and append it."""
        # Imported here: numpy and rosbags' message classes, which serialising needs, are no
        # part of a writer that is handed CDR bytes (the offline tools' writing process).
        from buoy_common.bag_io.conversion import serialize

        self._channel(topic, msgtype)
        raw = serialize(jazzy_typestore(), self.path, topic, msgtype, message)
        self.write_raw(topic, msgtype, log_time_ns, raw)

    def add_metadata(self, name: str, metadata: dict[str, str]) -> None:
        """An MCAP metadata record ``name`` (a map of strings), written when the bag is
        finished, beside rosbag2's own: what every MCAP reader lists besides the messages."""
        self._open_writer()
        self._metadata_records.append((name, dict(metadata)))

    def flush(self) -> None:
        """Close the open chunk and hand everything written so far to the disk (fsync): a
        reader recovers it even if this process is killed or the machine loses power."""
        self._open_writer().flush()
        os.fsync(self._stream.fileno())

    def _metadata(self) -> dict:
        """The ``rosbag2_bagfile_information`` of the bag as written."""
        channels = list(self._channels.values())
        count = sum(channel.count for channel in channels)
        start_ns, end_ns = (self._start_ns, self._end_ns) if count else (0, 0)
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
                        "type_description_hash": self._descriptions[channel.msgtype].hash,
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
        """Finish the bag (MCAP summary, metadata.yaml) and move it into place. Idempotent."""
        writer, self._writer = self._writer, None
        if writer is None:
            return
        try:
            information = self._metadata()
            writer.flush()
            for name, metadata in self._metadata_records:
                writer.add_metadata(name, metadata)
            writer.add_metadata(
                _ROSBAG2_METADATA_NAME,
                {
                    "serialized_metadata": yaml.safe_dump(
                        information, default_flow_style=False
                    ).strip()
                },
            )
            writer.finish()
            self._stream.close()
            (self._directory / METADATA_FILE).write_text(
                yaml.safe_dump(
                    {"rosbag2_bagfile_information": information}, default_flow_style=False
                ),
                "utf8",
            )
            if not self._in_place:
                check_bag_destination(self.path, self._overwrite)
                move_into_place(self._directory, self.path, replace=self._overwrite)
        except (OSError, OutputError, BagError) as error:
            self._discard()
            raise BagError(
                f"bag {self.path}: failed to finish, not written: {one_line(error)}"
            ) from error

    def abort(self) -> None:
        """Stop writing: the partial bag is deleted (an ``in_place`` bag is finished instead,
        keeping what it holds). Never raises: it runs while an error is on its way."""
        if self._writer is None:
            return
        if self._in_place:
            try:
                self.close()
            except BagError:
                self._writer = None
            return
        self._writer = None
        self._discard()

    def _discard(self) -> None:
        if self._in_place:
            return
        self._stream.close()
        shutil.rmtree(self._directory, ignore_errors=True)

    def _abandoned_note(self) -> str:
        if self._in_place:
            return f"bag {self.path} was closed after {sum(self.counts.values())} messages"
        return super()._abandoned_note()
