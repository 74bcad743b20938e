"""What reading and writing bags share: the bag layout, the records handed around, the errors."""

from __future__ import annotations

import functools
from collections.abc import Iterable
from pathlib import Path
from typing import NamedTuple, Protocol

BAG_VERSION = 9
METADATA_FILE = "metadata.yaml"
MCAP_SUFFIX = ".mcap"
ROS_DISTRO = "jazzy"
# The last eight bytes of every finished MCAP file (and its first eight).
MCAP_MAGIC = b"\x89MCAP0\r\n"
# Exit code of the offline tools when their input bag was damaged (cut short, or left unfinished
# by a writer that was killed) and only its readable part was processed. 2 stays the code of a
# usage or configuration error.
RECOVERED_BAG_EXIT_CODE = 3


class BagError(Exception):
    """A bag cannot be read or written; the message names the bag path and the problem."""


class TopicInfo(NamedTuple):
    """One topic of a bag: its message type ('pkg/msg/Type') and message count."""

    msgtype: str
    count: int


class TopicSelection(Protocol):
    """What a reader needs of a namespace view (:class:`~buoy_common.namespaces.TopicView`):
    the bag does not depend on how names are resolved, only on the mapping it yields."""

    namespace: str
    remaps: tuple[tuple[str, str], ...]

    @property
    def label(self) -> str: ...

    def stored_name(self, topic: str) -> str: ...

    def visible(self, stored_topics: Iterable[str]) -> dict[str, str]: ...


class BagMessage(NamedTuple):
    """One recorded message: topic name, type, log time (ns since the epoch) and CDR bytes."""

    topic: str
    msgtype: str
    log_time_ns: int
    raw: bytes


class Recovery(NamedTuple):
    """How a damaged bag was read.

    ``problem`` says what was wrong. ``truncated`` is True when the MCAP file ends before its
    index (the recorder lost power or was killed, or the file was cut): the messages after the
    last complete chunk are lost and ``messages`` counts the ones read. ``listed_messages`` is
    what metadata.yaml promised, None without one.
    """

    problem: str
    truncated: bool
    messages: int
    listed_messages: int | None

    def describe(self, path) -> str:
        """One line for the user: what was wrong with bag ``path`` and how much was read."""
        if not self.truncated:
            return f"bag {path}: {self.problem}; read all {self.messages} messages it holds"
        listed = "" if self.listed_messages is None else f" of the {self.listed_messages} listed"
        return (
            f"bag {path}: {self.problem}; recovered {self.messages} messages{listed}, "
            "up to its last complete chunk"
        )


class TypeDescription(NamedTuple):
    """What a bag records of a message type besides its name."""

    definition: str
    """The ``ros2msg`` definition with those of the types it uses, as the MCAP schema."""
    hash: str
    """The type's RIHS01 hash, as metadata.yaml lists it."""


@functools.cache
def jazzy_typestore():
    """The rosbags typestore of ROS 2 Jazzy's message types (shared, do not register into it)."""
    # Imported on first use: the writing process of the offline tools, which is handed the
    # descriptions of its types (type_description), starts without rosbags.
    from rosbags.typesys import Stores, get_typestore

    return get_typestore(Stores.ROS2_JAZZY)


def require_known_type(typestore, path: Path, topic: str, msgtype: str) -> None:
    """BagError naming the bag and topic unless ``msgtype`` is one of the typestore's."""
    if msgtype not in typestore.fielddefs:
        raise BagError(
            f"bag {path}: topic {topic}: unknown message type {msgtype!r} "
            "(not a ROS 2 Jazzy type; expected 'package/msg/Type')"
        )


def type_description(path: Path, topic: str, msgtype: str) -> TypeDescription:
    """The description of Jazzy type ``msgtype``; BagError naming bag ``path`` and ``topic``
    for a type that is not one."""
    typestore = jazzy_typestore()
    require_known_type(typestore, path, topic, msgtype)
    definition, _ = typestore.generate_msgdef(msgtype, ros_version=2)
    return TypeDescription(definition, typestore.hash_rihs01(msgtype))


def one_line(error: BaseException) -> str:
    """An error's text on one line (YAML parser messages span several)."""
    return " ".join(str(error).split())


def find_topic(available: Iterable[str], name: str) -> str | None:
    """The stored topic name for ``name``, which may omit the leading slash of a root topic."""
    available = set(available)
    for candidate in (name, "/" + name.lstrip("/")):
        if candidate in available:
            return candidate
    return None
