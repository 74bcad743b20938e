"""Reading rosbag2 bags: through rosbags, and a damaged bag as far as it is readable.

A bag is a directory holding ``metadata.yaml`` and its storage files; rosbags opens it, reads
its messages in log-time order and decodes them. The messages of a bag of one finished MCAP
file are read through the file's chunk index instead (:mod:`buoy_common.bag_io.indexed`): the
same messages in the same order at a third of the cost. Two kinds of damage are read rather
than refused, and :attr:`BagReader.recovery` tells the tool, which warns:

- an MCAP file without its index (the recorder was killed or lost power, or the file was cut):
  its complete chunks are read (:mod:`buoy_common.bag_io.recovery`), whatever metadata.yaml
  says;
- a bag directory without metadata.yaml whose single MCAP file is whole: rosbags reads that
  file alone (it carries its own topics, types and counts).
"""

from __future__ import annotations

import itertools
from collections import Counter
from collections.abc import Iterable, Iterator
from pathlib import Path

import yaml
from rosbags.interfaces import MessageDefinitionFormat
from rosbags.rosbag2 import Reader
from rosbags.typesys import Stores, get_types_from_msg, get_typestore

from buoy_common.bag_io.common import (
    MCAP_MAGIC,
    MCAP_SUFFIX,
    METADATA_FILE,
    BagError,
    BagMessage,
    Recovery,
    TopicInfo,
    TopicSelection,
    find_topic,
    jazzy_typestore,
    one_line,
)
from buoy_common.bag_io.indexed import IndexedMcap
from buoy_common.bag_io.recovery import RecoveredMcap

# libyaml's loader where PyYAML was built with it: a bag's metadata.yaml is parsed here at every
# opening (besides rosbags' own parse), 14 ms of the opening's 70 ms with the pure-Python
# loader, 1 ms with libyaml's; the tools open their input twice before the first message.
_YAML_LOADER = getattr(yaml, "CSafeLoader", yaml.SafeLoader)
# Messages a batch of a bag read through rosbags holds (a chunk of the suite's bags holds
# thousands).
BATCH_MESSAGES = 4096


def _metadata(path: Path) -> dict:
    """The parsed metadata.yaml of bag ``path``."""
    return yaml.load((path / METADATA_FILE).read_text(), Loader=_YAML_LOADER)


def _is_finished_mcap(path: Path) -> bool:
    """Whether an MCAP file ends as a finished one does (with the magic after its footer)."""
    with path.open("rb") as stream:
        if stream.read(len(MCAP_MAGIC)) != MCAP_MAGIC:
            raise BagError(f"{path} is not an MCAP file")
        size = stream.seek(0, 2)
        if size < 2 * len(MCAP_MAGIC):
            return False
        stream.seek(size - len(MCAP_MAGIC))
        return stream.read() == MCAP_MAGIC


def _listed_message_count(path: Path) -> int | None:
    """The message count metadata.yaml of bag ``path`` gives, None if it gives none."""
    try:
        information = _metadata(path)
        return int(information["rosbag2_bagfile_information"]["message_count"])
    except (OSError, yaml.YAMLError, TypeError, KeyError, ValueError):
        return None


def _lists_only(path: Path, mcap_file: Path) -> bool:
    """Whether metadata.yaml of bag ``path`` names ``mcap_file`` as its one MCAP storage file,
    uncompressed as a file or per message (its chunks may be)."""
    try:
        information = _metadata(path)["rosbag2_bagfile_information"]
        files = [Path(name).name for name in information["relative_file_paths"]]
        compression = str(information.get("compression_mode") or "").lower()
        return (
            information["storage_identifier"] == "mcap"
            and files == [mcap_file.name]
            and compression in ("", "none")
        )
    except (OSError, yaml.YAMLError, TypeError, KeyError, ValueError):
        return False


def _in_lists(messages: Iterator[BagMessage], size: int) -> Iterator[list[BagMessage]]:
    """``messages`` in lists of ``size`` (the last one shorter)."""
    while batch := list(itertools.islice(messages, size)):
        yield batch


class BagReader:
    """Read a rosbag2 bag directory; a context manager.

    Topic names may be given with or without the leading slash (``imu/data_raw`` finds
    ``/imu/data_raw``). With a ``view`` (:class:`~buoy_common.namespaces.TopicView`), the reader
    shows only that namespace's topics, under their contract names (``/buoy1/imu/data_raw`` as
    ``/imu/data_raw``, remapped topics under the names they stand for); ``stored_topics`` keeps
    every topic under its stored name. ``start_ns``/``end_ns`` are the log times (ns) of the
    first and last message, both 0 for an empty bag. ``recovery`` is None for a sound bag; for
    a damaged one it says what was wrong and how many messages could be read.
    """

    def __init__(self, path: str | Path, view: TopicSelection | None = None):
        self.path = Path(path)
        self.view = view
        self.recovery: Recovery | None = None
        self._reader: Reader | None = None
        self._indexed: IndexedMcap | None = None
        self._recovered: RecoveredMcap | None = None
        try:
            self._open()
            self._typestore = self._typestore_for_bag()
            self.stored_topics: dict[str, TopicInfo] = self.topics
            self._stored_of = {name: name for name in self.topics}
            if view is not None:
                self._stored_of = view.visible(self.stored_topics)
                self.topics = {name: self.stored_topics[s] for name, s in self._stored_of.items()}
        except BagError:
            self.close()
            raise
        except Exception as error:
            self.close()
            raise BagError(f"bag {self.path}: unreadable or corrupt: {one_line(error)}") from error

    def _open(self) -> None:
        if not self.path.exists():
            raise BagError(f"bag {self.path} does not exist")
        if not self.path.is_dir():
            raise BagError(
                f"bag {self.path} is not a bag: a rosbag2 bag is a directory holding "
                f"{METADATA_FILE} and an {MCAP_SUFFIX} file"
            )
        has_metadata = (self.path / METADATA_FILE).is_file()
        mcap_files = sorted(self.path.glob(f"*{MCAP_SUFFIX}"))
        if not has_metadata and not mcap_files:
            raise BagError(f"bag {self.path} is not a bag: it has no {METADATA_FILE}")
        unfinished = [file for file in mcap_files if not _is_finished_mcap(file)]
        if unfinished:
            if len(mcap_files) > 1:
                raise BagError(
                    f"bag {self.path}: {unfinished[0].name} is unfinished and the bag has "
                    f"{len(mcap_files)} {MCAP_SUFFIX} files; only a single-file bag is recovered"
                )
            self._recover(unfinished[0], has_metadata)
        elif has_metadata:
            self._open_with_rosbags(self.path)
            if len(mcap_files) == 1 and _lists_only(self.path, mcap_files[0]):
                self._indexed = IndexedMcap.open(mcap_files[0], self.topics)
        elif len(mcap_files) == 1:
            self._open_with_rosbags(mcap_files[0])
            self._indexed = IndexedMcap.open(mcap_files[0], self.topics)
            self.recovery = Recovery(
                f"it has no {METADATA_FILE}; its {MCAP_SUFFIX} file was read alone",
                truncated=False,
                messages=sum(info.count for info in self.topics.values()),
                listed_messages=None,
            )
        else:
            raise BagError(
                f"bag {self.path} has no {METADATA_FILE} and several {MCAP_SUFFIX} files"
            )

    def _open_with_rosbags(self, source: Path) -> None:
        try:
            self._reader = Reader(source)
            self._reader.open()
        except Exception as error:
            raise BagError(f"bag {self.path}: unreadable or corrupt: {one_line(error)}") from error
        self.topics: dict[str, TopicInfo] = {
            topic: TopicInfo(info.msgtype or "", info.msgcount)
            for topic, info in self._reader.topics.items()
        }
        if self._reader.message_count:
            self.start_ns = int(self._reader.start_time)
            self.end_ns = int(self._reader.end_time) - 1
        else:
            self.start_ns = self.end_ns = 0

    def _recover(self, mcap_file: Path, has_metadata: bool) -> None:
        self._recovered = RecoveredMcap(mcap_file)
        self.topics = self._recovered.topics
        self.start_ns, self.end_ns = self._recovered.start_ns, self._recovered.end_ns
        self.recovery = Recovery(
            f"{mcap_file.name} ends before its index ({self._recovered.stop}; its writer was "
            "stopped before closing it, or the file was cut)",
            truncated=True,
            messages=self._recovered.message_count,
            listed_messages=_listed_message_count(self.path) if has_metadata else None,
        )

    def _definitions(self) -> Iterator[tuple[str, str, str | None]]:
        """(topic, type, ros2msg definition or None) of each stored topic."""
        if self._reader is not None:
            for connection in self._reader.connections:
                is_msg = connection.msgdef.format == MessageDefinitionFormat.MSG
                yield (
                    connection.topic,
                    connection.msgtype,
                    (connection.msgdef.data if is_msg else None),
                )
            return
        for topic, info in self.topics.items():
            encoding, text = self._recovered.definitions.get(info.msgtype, ("", ""))
            yield topic, info.msgtype, text if encoding == "ros2msg" else None

    def _typestore_for_bag(self):
        """Jazzy's typestore, or a private copy extended by types the bag defines itself."""
        typestore = jazzy_typestore()
        unknown = [d for d in self._definitions() if d[1] not in typestore.fielddefs]
        if not unknown:
            return typestore
        typestore = get_typestore(Stores.ROS2_JAZZY)
        for topic, msgtype, definition in unknown:
            if definition is None:
                continue  # undecodable; raw bytes stay readable and decode() says why
            try:
                typestore.register(get_types_from_msg(definition, msgtype))
            except Exception as error:
                raise BagError(
                    f"bag {self.path}: topic {topic}: cannot parse the definition "
                    f"of {msgtype}: {one_line(error)}"
                ) from error
        return typestore

    @property
    def duration_s(self) -> float:
        """Time between the first and the last message's log time, s."""
        return (self.end_ns - self.start_ns) * 1e-9

    def _topic_listing(self) -> str:
        if not self.stored_topics:
            return "it has no topics"
        return "it has " + ", ".join(
            f"{name} ({info.msgtype}, {info.count})"
            for name, info in sorted(self.stored_topics.items())
        )

    def _resolve_topics(self, topics: Iterable[str]) -> list[str]:
        resolved, missing = [], []
        for name in topics:
            found = find_topic(self.topics, name)
            if found is None:
                missing.append(name)
            else:
                resolved.append(found)
        if missing:
            damage = "" if self.recovery is None else f" ({self.recovery.describe(self.path)})"
            where = ""
            if self.view is not None and (self.view.namespace or self.view.remaps):
                looked_for = ", ".join(self.view.stored_name(name) for name in missing)
                where = f" (looked for {looked_for} in namespace {self.view.label})"
            raise BagError(
                f"bag {self.path} lacks topic(s) {', '.join(missing)}{where}; "
                f"{self._topic_listing()}{damage}"
            )
        return resolved

    def require(self, *topics: str) -> None:
        """Raise BagError naming every missing topic and listing the bag's topics."""
        self._resolve_topics(topics)

    def messages(self, topics: Iterable[str] | None = None) -> Iterator[BagMessage]:
        """Messages of ``topics`` (all when None) in log-time order across topics.

        Once the iteration has completed, the per-topic counts are checked against the bag's
        listing, so a bag whose data were cut short raises BagError instead of passing for a
        short bag.
        """
        wanted = set(self.topics if topics is None else self._resolve_topics(topics))
        return self._iterate(wanted)

    def message_batches(self, topics: Iterable[str] | None = None) -> Iterator[list[BagMessage]]:
        """:meth:`messages` handed over a list at a time (the messages of one chunk of the
        bag's file, or up to BATCH_MESSAGES of a bag read through rosbags): the same messages
        in the same order, checked against the listing in the same way; for decoding a topic's
        messages together (:func:`~buoy_common.bag_io.columns.batch_columns`)."""
        wanted = set(self.topics if topics is None else self._resolve_topics(topics))
        return self._iterate_batches(wanted)

    def _iterate(self, wanted: set[str]) -> Iterator[BagMessage]:
        if not wanted:
            return
        seen: Counter[str] = Counter()
        try:
            for message in self._read(wanted):
                seen[message.topic] += 1
                yield message
        except Exception as error:
            raise BagError(f"bag {self.path}: corrupt message data: {one_line(error)}") from error
        self._check_counts(wanted, seen)

    def _iterate_batches(self, wanted: set[str]) -> Iterator[list[BagMessage]]:
        if not wanted:
            return
        seen: Counter[str] = Counter()
        try:
            for batch in self._read_batches(wanted):
                seen.update([message.topic for message in batch])
                yield batch
        except Exception as error:
            raise BagError(f"bag {self.path}: corrupt message data: {one_line(error)}") from error
        self._check_counts(wanted, seen)

    def _check_counts(self, wanted: set[str], seen: Counter[str]) -> None:
        """BagError when the messages read of a topic are not as many as the bag lists."""
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

    def _read(self, wanted: set[str]) -> Iterator[BagMessage]:
        view_of = {self._stored_of[name]: name for name in wanted}
        if self._recovered is not None:
            return (
                message._replace(topic=view_of[message.topic])
                for message in self._recovered.messages(set(view_of))
            )
        if self._indexed is not None:
            return self._indexed.messages(view_of)
        connections = [c for c in self._reader.connections if c.topic in view_of]
        return (
            BagMessage(view_of[connection.topic], connection.msgtype, log_time_ns, raw)
            for connection, log_time_ns, raw in self._reader.messages(connections=connections)
        )

    def _read_batches(self, wanted: set[str]) -> Iterator[list[BagMessage]]:
        if self._indexed is not None:
            view_of = {self._stored_of[name]: name for name in wanted}
            return self._indexed.batches(view_of)
        return _in_lists(self._read(wanted), BATCH_MESSAGES)

    def decode(self, message: BagMessage):
        """The rosbags message object of ``message`` (fields named as in ROS, arrays as numpy)."""
        try:
            return self._typestore.deserialize_cdr(message.raw, message.msgtype)
        except Exception as error:
            raise BagError(
                f"bag {self.path}: cannot decode {message.msgtype} on {message.topic} at log time "
                f"{message.log_time_ns} ns: {one_line(error)}"
            ) from error

    def close(self) -> None:
        reader, self._reader = self._reader, None
        if reader is not None and reader.is_open:
            reader.close()

    def __enter__(self) -> BagReader:
        return self

    def __exit__(self, *exc_info) -> None:
        self.close()
