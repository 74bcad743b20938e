"""What reading and writing bags share: the bag layout, the records handed around, the errors."""

from __future__ import annotations

import functools
from collections.abc import Iterable
from typing import NamedTuple, Protocol

from rosbags.typesys import Stores, get_typestore

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


@functools.cache
def jazzy_typestore():
    """The rosbags typestore of ROS 2 Jazzy's message types (shared, do not register into it)."""
    return get_typestore(Stores.ROS2_JAZZY)


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
