"""``fuse_bag``: the fusion of ``fusion_node`` run over a recorded bag, as fast as it goes.

    fuse_bag IN_BAG OUT_BAG [--params-file buoy.yaml] [--params-file fusion.yaml] [--overwrite]

Reads the sensor topics ``imu/data_raw``, ``gnss/fix``, ``gnss/heading`` (required),
``gnss/vel`` and ``gnss/baseline`` (used when present) in log-time order, feeds them through the
same conversion and engine as the live node, and writes ``nav/odometry``, ``nav/imu``,
``nav/velocity`` and ``nav/fix`` to a new bag, each with the log time of the IMU message that
produced it. Truth topics (``truth/*``) are copied unchanged, so the output carries its own
answer. Parameters come from the same YAML files the node takes (sections ``/**`` and
``fusion_node``).

OUT_BAG is written under a temporary name beside it and appears only when complete; it may not
be, contain or lie inside IN_BAG. Exit codes: 0 done; 2 bad arguments, parameters or bags
(one line on stderr); 3 done, but IN_BAG was cut short (a recorder killed or out of power) and
was processed up to its last complete chunk (a warning says how much was read).
"""

from __future__ import annotations

import argparse
import math
import sys
import time
from collections import Counter
from collections.abc import Iterable

from tqdm import tqdm

from buoy_common.bag_io import (
    RECOVERED_BAG_EXIT_CODE,
    BackgroundBagWriter,
    BagError,
    BagMessage,
    BagReader,
    BagWriter,
)
from buoy_common.contract import (
    GNSS_BASELINE_TOPIC,
    GNSS_FIX_TOPIC,
    GNSS_HEADING_TOPIC,
    GNSS_VELOCITY_TOPIC,
    IMU_RAW_TOPIC,
    NAV_MSGTYPES,
    TRUTH_PREFIX,
    bag_topic,
)
from buoy_common.parameters import ParameterError, build_config, load_parameter_files
from buoy_common.safe_output import OutputError, check_outputs_apart_from_inputs
from buoy_nav.config import (
    FUSION_FIELDS_NOT_PARAMETERS,
    FUSION_NODE_NAME,
    FUSION_PARAMETER_PREFIX,
    FusionConfig,
)
from buoy_nav.engine import FusionEngine, NavSolution
from buoy_nav.fusion_messages import (
    FUSION_INPUT_MSGTYPES,
    NavValues,
    StampBook,
    feed_imu_cdr,
    feed_message,
    nav_values,
    solution_cdr,
)

REQUIRED_TOPICS = (IMU_RAW_TOPIC, GNSS_FIX_TOPIC, GNSS_HEADING_TOPIC)
OPTIONAL_TOPICS = (GNSS_VELOCITY_TOPIC, GNSS_BASELINE_TOPIC)
PROGRESS_EVERY_MESSAGES = 2000


def fusion_config_from_files(paths: Iterable[str]) -> FusionConfig:
    """The :class:`FusionConfig` ``fusion_node`` would build from these parameter files."""
    values = load_parameter_files(paths, FUSION_NODE_NAME)
    return build_config(
        FusionConfig,
        values,
        FUSION_PARAMETER_PREFIX,
        skip=FUSION_FIELDS_NOT_PARAMETERS,
    )


def relative_topic(name: str) -> str:
    """A bag topic name without its leading slash (topic names of the contract are relative)."""
    return name.lstrip("/")


# Relative nav topic → (name stored in the bag, message type).
NAV_BAG_TOPICS = {topic: (bag_topic(topic), msgtype) for topic, msgtype in NAV_MSGTYPES.items()}


def sensor_topics_of(
    reader: BagReader, config: FusionConfig, extra_required: Iterable[str] = ()
) -> dict[str, str]:
    """Relative → stored name of the fusion's input topics in ``reader``'s bag (``gnss/baseline``
    only when ``config`` fuses it).

    Raises BagError naming what is missing or of the wrong type.
    """
    reader.require(*REQUIRED_TOPICS, *extra_required)
    stored = {relative_topic(name): name for name in reader.topics}
    found = {}
    for topic in (*REQUIRED_TOPICS, *OPTIONAL_TOPICS):
        if topic not in stored or (topic == GNSS_BASELINE_TOPIC and not config.use_gnss_baseline):
            continue
        msgtype = reader.topics[stored[topic]].msgtype
        if msgtype != FUSION_INPUT_MSGTYPES[topic]:
            raise BagError(
                f"bag {reader.path}: topic {stored[topic]} holds {msgtype}, "
                f"expected {FUSION_INPUT_MSGTYPES[topic]}"
            )
        found[topic] = stored[topic]
    return found


def truth_topics_of(reader: BagReader) -> list[str]:
    """Stored names of the truth topics in ``reader``'s bag."""
    return sorted(n for n in reader.topics if relative_topic(n).startswith(TRUTH_PREFIX))


class OfflineFusion:
    """Feeds sensor messages to a :class:`FusionEngine` and writes its ``nav/*`` to a bag."""

    def __init__(self, config: FusionConfig, writer: BagWriter | BackgroundBagWriter):
        self.engine = FusionEngine(config)
        self.stamps = StampBook()
        self.writer = writer
        self.rejections: Counter[str] = Counter()
        self.first_solution_s: float | None = None
        self.last_log_time_ns = 0

    def add(self, topic: str, message, log_time_ns: int) -> list[NavValues]:
        """One decoded sensor message of relative ``topic``; returns the values of the new
        solutions' ``nav/*`` messages, which are written with log time ``log_time_ns``."""
        return self._take(
            topic, feed_message(self.engine, topic, message, self.stamps), log_time_ns
        )

    def add_message(self, reader: BagReader, topic: str, message: BagMessage) -> list[NavValues]:
        """:meth:`add` of a bag message of relative ``topic``, IMU samples read from CDR."""
        fed = (
            feed_imu_cdr(self.engine, message.raw, self.stamps) if topic == IMU_RAW_TOPIC else None
        )
        if fed is None:
            return self.add(topic, reader.decode(message), message.log_time_ns)
        return self._take(topic, fed, message.log_time_ns)

    def _take(self, topic: str, fed, log_time_ns: int) -> list[NavValues]:
        solutions, rejection = fed
        if rejection is not None:
            self.rejections[f"{topic}: {rejection}"] += 1
        self.last_log_time_ns = log_time_ns
        return self._write(solutions, log_time_ns)

    def finish(self) -> list[NavValues]:
        """End of the data: the solutions still held back by the engine (written too)."""
        return self._write(self.engine.flush(), self.last_log_time_ns)

    def _write(self, solutions: list[NavSolution], log_time_ns: int) -> list[NavValues]:
        written = []
        for solution in solutions:
            if self.first_solution_s is None:
                self.first_solution_s = solution.t_s
            values = nav_values(solution, self.stamps)
            for topic, raw in solution_cdr(values).items():
                stored_topic, msgtype = NAV_BAG_TOPICS[topic]
                self.writer.write_raw(stored_topic, msgtype, log_time_ns, raw)
            written.append(values)
        return written

    def summary(self) -> list[str]:
        """Human-readable lines: alignment, measurement use and rejections."""
        health = self.engine.health()
        lines = []
        if self.first_solution_s is None:
            lines.append(f"never aligned (alignment state: {health.alignment_state.name})")
        else:
            lines.append(f"first navigation solution at stamp {self.first_solution_s:.3f} s")
        for kind, counters in health.counters.items():
            rejected = ", ".join(f"{r} {n}" for r, n in sorted(counters.rejected.items()))
            lines.append(
                f"{kind:14s} accepted {counters.accepted:7d}  "
                f"alignment {counters.used_for_alignment:4d}  "
                f"superseded {counters.superseded:6d}  resets {counters.resets:3d}  "
                f"mean NIS {counters.mean_nis:6.2f}  rejected: {rejected or 'none'}"
            )
        for key, count in sorted(self.rejections.items()):
            lines.append(f"rejected message {key}: {count}")
        return lines


def fuse_bag(in_bag: str, out_bag: str, config: FusionConfig, overwrite: bool = False):
    """Run the fusion over ``in_bag`` into ``out_bag``; returns (OfflineFusion, counts, wall s,
    bag duration s, the input's :class:`~buoy_common.bag_io.Recovery` or None).

    OutputError, before anything is read or written, if ``out_bag`` is, contains or lies inside
    ``in_bag``.
    """
    started = time.monotonic()
    check_outputs_apart_from_inputs([in_bag], [out_bag])
    with BagReader(in_bag) as reader:
        sensors = sensor_topics_of(reader, config)
        truth = truth_topics_of(reader)
        relative_of = {stored: relative for relative, stored in sensors.items()}
        with (
            tqdm(
                total=math.ceil(reader.duration_s),
                desc=f"fuse_bag {in_bag}",
                unit="bag s",
                disable=None,
            ) as progress,
            BackgroundBagWriter(out_bag, overwrite=overwrite) as writer,
        ):
            fusion = OfflineFusion(config, writer)
            for index, message in enumerate(reader.messages([*sensors.values(), *truth])):
                topic = relative_of.get(message.topic)
                if topic is None:
                    writer.write_raw(
                        message.topic, message.msgtype, message.log_time_ns, message.raw
                    )
                else:
                    fusion.add_message(reader, topic, message)
                if index % PROGRESS_EVERY_MESSAGES == 0:
                    progress.update(
                        int((message.log_time_ns - reader.start_ns) * 1e-9) - progress.n
                    )
            fusion.finish()
            progress.update(progress.total - progress.n)
        counts = writer.counts
    return fusion, counts, time.monotonic() - started, reader.duration_s, reader.recovery


def parse_arguments(argv):
    parser = argparse.ArgumentParser(prog="fuse_bag", description=__doc__.split("\n")[0])
    parser.add_argument(
        "in_bag", help="bag with imu/data_raw, gnss/fix, gnss/heading[, gnss/vel, gnss/baseline]"
    )
    parser.add_argument("out_bag", help="bag directory to create with the nav/* topics")
    parser.add_argument(
        "--params-file",
        action="append",
        default=[],
        help="ROS parameter YAML as given to fusion_node (repeatable; later files win)",
    )
    parser.add_argument("--overwrite", action="store_true", help="replace an existing OUT_BAG")
    return parser.parse_args(argv)


def main(argv=None) -> None:
    arguments = parse_arguments(sys.argv[1:] if argv is None else argv)
    try:
        config = fusion_config_from_files(arguments.params_file)
        fusion, counts, wall_s, duration_s, recovery = fuse_bag(
            arguments.in_bag, arguments.out_bag, config, arguments.overwrite
        )
    except (ParameterError, BagError, OutputError) as error:
        print(f"fuse_bag: {error}", file=sys.stderr)
        sys.exit(2)
    for line in fusion.summary():
        print(line)
    for topic, count in sorted(counts.items()):
        print(f"{topic:20s} {count:8d}")
    print(
        f"wrote {arguments.out_bag}: {duration_s:.1f} s of data in {wall_s:.1f} s "
        f"({duration_s / max(wall_s, 1e-9):.0f}x real time)"
    )
    if recovery is not None:
        print(f"fuse_bag: warning: {recovery.describe(arguments.in_bag)}", file=sys.stderr)
        if recovery.truncated:
            sys.exit(RECOVERED_BAG_EXIT_CODE)
