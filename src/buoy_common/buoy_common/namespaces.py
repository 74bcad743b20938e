"""Namespaces and remappings of recorded topics, for the offline tools.

A buoy started with ``--ros-args -r __ns:=/buoy1`` publishes ``/buoy1/imu/data_raw``; a bag
recorded from a fleet holds one such set of topics per buoy. The offline tools read a bag
through a :class:`TopicView`: the topics of one namespace, seen under the contract's names
(``/imu/data_raw``), with single topics remapped as ``ros2 run ... -r from:=to`` would
(``imu/data_raw:=xsens/imu`` reads ``/buoy1/xsens/imu`` as the IMU of namespace ``/buoy1``).
What a tool writes for that buoy goes back into the namespace (``/buoy1/nav/odometry``), as the
nodes started in it would publish it.

:func:`add_namespace_arguments` and :func:`views_from_arguments` give every tool the same
``--namespace`` and ``--remap`` options and the same choice: the namespace named, else the one
namespace that holds the tool's anchor topic, else each of several, one output apiece.
"""

from __future__ import annotations

import argparse
from collections.abc import Iterable
from dataclasses import dataclass, field
from pathlib import Path

from buoy_common.bag_io import BagReader
from buoy_common.bag_io.stretch import Stretch

REMAP_SEPARATOR = ":="


class NamespaceError(ValueError):
    """A namespace or remapping that is malformed or names nothing in the bag."""


def normalised_namespace(namespace: str) -> str:
    """``buoy1``, ``/buoy1/`` → ``/buoy1``; the root namespace is ``""``."""
    parts = [part for part in namespace.strip().split("/") if part]
    for part in parts:
        if not part.replace("_", "a").isalnum() or part[0].isdigit():
            raise NamespaceError(
                f"namespace {namespace!r}: {part!r} is not a valid ROS name token "
                "(letters, digits and underscores, not starting with a digit)"
            )
    return "".join("/" + part for part in parts)


def resolved_name(name: str, namespace: str) -> str:
    """A topic name as ROS resolves it in ``namespace``: absolute names stay, relative ones are
    put under the namespace (``imu/data_raw`` in ``/buoy1`` → ``/buoy1/imu/data_raw``)."""
    name = name.strip()
    if not name or name.endswith("/") or "//" in name or "~" in name:
        raise NamespaceError(f"topic name {name!r} is not a valid ROS topic name")
    return name if name.startswith("/") else f"{namespace}/{name}"


def parse_remap(rule: str) -> tuple[str, str]:
    """``from:=to`` → (from, to), as given (resolution happens per namespace)."""
    source, separator, target = rule.partition(REMAP_SEPARATOR)
    if not separator or not source.strip() or not target.strip():
        raise NamespaceError(f"remapping {rule!r} is not of the form FROM{REMAP_SEPARATOR}TO")
    return source.strip(), target.strip()


@dataclass(frozen=True)
class TopicView:
    """One namespace of a bag, seen under the contract's (root) topic names.

    ``remaps`` are (from, to) as the user wrote them; relative names are resolved in
    ``namespace``, ``from`` names what the tool looks for, ``to`` what the bag stores.
    """

    namespace: str = ""
    remaps: tuple[tuple[str, str], ...] = ()
    _stored_of: dict[str, str] = field(init=False, repr=False, compare=False)
    _view_of: dict[str, str] = field(init=False, repr=False, compare=False)

    def __post_init__(self):
        namespace = normalised_namespace(self.namespace)
        object.__setattr__(self, "namespace", namespace)
        stored_of = {}
        for source, target in self.remaps:
            wanted = resolved_name(source, namespace)
            if not wanted.startswith(namespace + "/"):
                raise NamespaceError(
                    f"remapping {source}{REMAP_SEPARATOR}{target}: {wanted} lies outside the "
                    f"namespace {namespace or '/'}"
                )
            stored_of["/" + wanted.removeprefix(namespace + "/")] = resolved_name(target, namespace)
        object.__setattr__(self, "_stored_of", stored_of)
        object.__setattr__(self, "_view_of", {stored: view for view, stored in stored_of.items()})

    @property
    def label(self) -> str:
        """The namespace as a reader sees it: ``/buoy1``, or ``/`` for the root."""
        return self.namespace or "/"

    def stored_name(self, topic: str) -> str:
        """Where the bag keeps contract topic ``topic`` (with or without its leading slash)."""
        view_name = "/" + topic.lstrip("/")
        return self._stored_of.get(view_name, self.namespace + view_name)

    def output_name(self, topic: str) -> str:
        """Where an output topic of this buoy goes: into the namespace, never remapped."""
        return self.namespace + "/" + topic.lstrip("/")

    def view_name(self, stored: str) -> str | None:
        """The contract name under which stored topic ``stored`` is seen; None when it lies
        outside the namespace or its contract name was remapped away to another topic."""
        stored = "/" + stored.lstrip("/")
        if stored in self._view_of:
            return self._view_of[stored]
        if self.namespace and not stored.startswith(self.namespace + "/"):
            return None
        view = stored[len(self.namespace) :]
        return None if view in self._stored_of else view

    def visible(self, stored_topics: Iterable[str]) -> dict[str, str]:
        """Contract name → stored name of every stored topic this view sees."""
        found = {}
        for stored in stored_topics:
            view = self.view_name(stored)
            if view is not None:
                found[view] = stored
        return found


def namespaces_holding(stored_topics: Iterable[str], topic: str) -> list[str]:
    """The namespaces (``""`` for the root) under which ``topic`` is stored, sorted."""
    suffix = "/" + topic.lstrip("/")
    return sorted(
        {
            stored[: -len(suffix)]
            for stored in ("/" + name.lstrip("/") for name in stored_topics)
            if stored.endswith(suffix)
        }
    )


def add_namespace_arguments(parser: argparse.ArgumentParser) -> None:
    """The ``--namespace`` and ``--remap`` options every offline tool takes."""
    parser.add_argument(
        "--namespace",
        default=None,
        help="process the topics under this namespace (e.g. /buoy1); by default the one "
        "namespace holding the input topics, or each of several, one output apiece",
    )
    parser.add_argument(
        "--remap",
        action="append",
        default=[],
        metavar="FROM:=TO",
        help="read topic FROM from the bag's topic TO, as ros2 run -r does; relative names lie "
        "in the namespace (repeatable; e.g. imu/data_raw:=xsens/imu)",
    )


def views_of_bag(
    arguments: argparse.Namespace, bag: str | Path, *anchor_topics: str
) -> list[TopicView]:
    """:func:`views_from_arguments` of the topics stored in ``bag`` (BagError if unreadable)."""
    with BagReader(bag) as reader:
        return views_from_arguments(arguments, reader.stored_topics, *anchor_topics)


def views_from_arguments(
    arguments: argparse.Namespace, stored_topics: Iterable[str], *anchor_topics: str
) -> list[TopicView]:
    """The views a tool processes: the ``--namespace`` given; else every namespace holding
    one of ``anchor_topics`` (after the remappings); the root namespace when none does, so the
    tool's own check names what is missing. Raises NamespaceError for a malformed option."""
    remaps = tuple(parse_remap(rule) for rule in arguments.remap)
    if arguments.namespace is not None:
        return [TopicView(arguments.namespace, remaps)]
    stored_topics = list(stored_topics)
    candidates = set()
    for anchor_topic in anchor_topics:
        candidates |= set(namespaces_holding(stored_topics, anchor_topic))
        for source, target in remaps:
            if source.lstrip("/") == anchor_topic.lstrip("/"):
                # The anchor itself is remapped: its namespaces are those of its new name.
                candidates |= (
                    {""}
                    if target.startswith("/")
                    else set(namespaces_holding(stored_topics, target))
                )
    views = [TopicView(namespace, remaps) for namespace in sorted(candidates)]
    found = [
        view
        for view in views
        if any(view.stored_name(anchor) in stored_topics for anchor in anchor_topics)
    ]
    return found or [TopicView("", remaps)]


def output_for(out_path: str | Path, view: TopicView, several: bool) -> Path:
    """Where the output of ``view`` goes: ``out_path`` itself for a single buoy, else the
    namespace's path under it (``OUT/buoy1``, ``OUT/fleet/buoy2``)."""
    out_path = Path(out_path)
    if not several:
        return out_path
    if not view.namespace:
        return out_path / "root"
    return out_path.joinpath(*view.namespace.strip("/").split("/"))


class NamespacedWriter:
    """Writes a tool's outputs of one buoy into its namespace; otherwise a bag writer."""

    def __init__(self, writer, view: TopicView):
        self._writer = writer
        self._view = view
        # A tool writes a handful of topics at the IMU's rate: name each once.
        self._output_names: dict[str, str] = {}

    def output_name(self, topic: str) -> str:
        """Where ``topic`` of this buoy is written (:meth:`TopicView.output_name`)."""
        name = self._output_names.get(topic)
        if name is None:
            name = self._output_names[topic] = self._view.output_name(topic)
        return name

    def write_raw(self, topic: str, msgtype: str, log_time_ns: int, raw: bytes) -> None:
        self._writer.write_raw(self.output_name(topic), msgtype, log_time_ns, raw)

    def write_named_stretch(self, stretch: Stretch) -> None:
        """The messages of ``stretch`` (:mod:`buoy_common.bag_io.stretch`), in order, each
        topic already its :meth:`output_name`: a stretch named as it was gathered goes to the
        bag's writer as it is."""
        self._writer.write_stretch(stretch)

    def write(self, topic: str, msgtype: str, log_time_ns: int, message) -> None:
        self._writer.write(self.output_name(topic), msgtype, log_time_ns, message)

    @property
    def counts(self) -> dict[str, int]:
        return self._writer.counts
