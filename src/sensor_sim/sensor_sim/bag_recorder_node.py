"""bag_recorder: record topics of a running system into a rosbag2 bag (version 9, MCAP).

    bag_recorder OUTPUT_BAG [--topics T ...] [--all] [--duration-s S] [--ros-args ...]

Messages are taken serialised (no decoding) and written with the node clock's time as log time,
so with ``use_sim_time`` the bag shares the replayed or simulated clock. Topics that appear after
start-up are picked up (the graph is polled every 0.5 s); a topic is subscribed once it has a
publisher, best-effort if any of its publishers is best-effort, reliable otherwise. Topic names
are stored fully qualified (``/imu/data_raw``, or ``/buoy1/imu/data_raw`` under a namespace).

SIGINT, SIGTERM or the end of ``--duration-s`` (node-clock seconds) closes the bag properly and
logs per-topic counts; exit code 0. An existing OUTPUT_BAG is never overwritten (exit code 2).

The bag is written in place by a thread of its own, so that compressing and flushing never delay
the reception (and with it the log times) of the messages; every second (wall time) the open
chunk is closed and what was recorded is flushed to the disk. A recorder that is killed
(SIGKILL, power lost) leaves a bag without metadata.yaml and without its MCAP index; the suite's
tools read it up to the last flush and warn that it was cut short.
"""

from __future__ import annotations

import argparse
import functools
import sys
import time
from collections import Counter

from rclpy.clock import Clock, ClockType
from rclpy.qos import QoSProfile, ReliabilityPolicy

from buoy_common.bag_io import BagError, jazzy_typestore
from buoy_common.bag_io.recording import RecordingBagWriter
from buoy_common.base_node import (
    DATA_QOS,
    DiagnosticsPublisher,
    StartupError,
    SuiteNode,
    message_class,
    run_node,
)
from buoy_common.cli import BAD_INPUT, ROS_ARGUMENTS_NOTE, ExitCode, command_parser
from buoy_common.contract import (
    CLOCK_TOPIC,
    CURRENT_TOPIC,
    DEFAULT_PRODUCT_WINDOWS_S,
    NAV_MSGTYPES,
    SENSOR_MSGTYPES,
    TRUTH_MSGTYPES,
    WIND_TRUE_TOPIC,
    current_mean_topic,
    current_stats_topic,
    wind_mean_topic,
    wind_stats_topic,
)

# The contract's sensor, truth, navigation, wind and current topics; relative, so a namespace
# applies.
DEFAULT_TOPICS = (
    *SENSOR_MSGTYPES,
    *TRUTH_MSGTYPES,
    *NAV_MSGTYPES,
    WIND_TRUE_TOPIC,
    *(wind_mean_topic(window_s) for window_s in DEFAULT_PRODUCT_WINDOWS_S),
    *(wind_stats_topic(window_s) for window_s in DEFAULT_PRODUCT_WINDOWS_S),
    CURRENT_TOPIC,
    *(current_mean_topic(window_s) for window_s in DEFAULT_PRODUCT_WINDOWS_S),
    *(current_stats_topic(window_s) for window_s in DEFAULT_PRODUCT_WINDOWS_S),
)
# ROS infrastructure that --all leaves out; /clock is recorded only when listed in --topics.
EXCLUDED_FROM_ALL = frozenset({"/rosout", "/parameter_events", CLOCK_TOPIC})
DISCOVERY_PERIOD_S = 0.5
# Wall-clock period of closing the open chunk and flushing the bag to the disk: what a killed
# recorder can lose at most.
FLUSH_PERIOD_S = 1.0

BEST_EFFORT_DATA_QOS = QoSProfile(
    depth=DATA_QOS.depth,
    history=DATA_QOS.history,
    reliability=ReliabilityPolicy.BEST_EFFORT,
    durability=DATA_QOS.durability,
)


EXIT_CODES = (
    ExitCode(0, "the bag closed properly after SIGINT, SIGTERM or the end of --duration-s"),
    ExitCode(1, "the bag could not be closed properly"),
    BAD_INPUT,
)


def split_ros_arguments(argv: list[str]) -> tuple[list[str], list[str]]:
    """(program arguments, arguments for rclpy.init): everything from ``--ros-args`` goes to ROS."""
    if "--ros-args" in argv:
        index = argv.index("--ros-args")
        return argv[1:index], [argv[0], *argv[index:]]
    return argv[1:], [argv[0]]


class BagRecorder(SuiteNode):
    """Subscribes raw to the wanted topics and appends every message to one bag."""

    def __init__(
        self,
        output_bag: str,
        topics: list[str],
        record_all: bool,
        duration_s: float | None,
    ):
        super().__init__("bag_recorder")
        self._requested = {self.resolve_topic_name(name) for name in topics}
        self._record_all = record_all
        self._duration_ns = None if duration_s is None else int(duration_s * 1e9)
        self._first_clock_ns: int | None = None
        self._recorded: dict[str, object] = {}
        self._unrecordable: set[str] = set()
        # Messages that arrive under use_sim_time before the first /clock wait for a real time.
        self._awaiting_clock: list[tuple[str, str, bytes]] = []
        self._rate_counts: Counter[str] = Counter()
        self._rate_since_s = time.monotonic()
        self.close_failed = False
        try:
            self._writer = RecordingBagWriter(output_bag, FLUSH_PERIOD_S)
        except BagError as error:
            raise StartupError(str(error)) from error
        self._diagnostics = DiagnosticsPublisher(self, self._report)
        # Discovery runs on the steady clock: under use_sim_time it must not wait for /clock.
        steady = Clock(clock_type=ClockType.STEADY_TIME)
        self._discovery_timer = self.create_timer(DISCOVERY_PERIOD_S, self._discover, clock=steady)
        wanted = "every topic" if record_all else ", ".join(sorted(self._requested))
        self.get_logger().info(f"recording {wanted} into {output_bag}")
        self._discover()

    def _wanted(self, topic: str) -> bool:
        if topic in self._requested:
            return True
        return self._record_all and topic not in EXCLUDED_FROM_ALL

    def _discover(self) -> None:
        self._check_duration()
        for topic, types in self.get_topic_names_and_types():
            if topic in self._recorded or topic in self._unrecordable:
                continue
            if not self._wanted(topic):
                continue
            publishers = self.get_publishers_info_by_topic(topic)
            if not publishers:
                continue
            self._subscribe(topic, types, publishers)

    def _subscribe(self, topic: str, types: list[str], publishers) -> None:
        msgtype = types[0]
        if len(types) > 1:
            self.get_logger().warning(
                f"topic {topic} is published with several types {types}; recording {msgtype}"
            )
        if msgtype not in jazzy_typestore().fielddefs:
            self._refuse(topic, f"type {msgtype} is not a ROS 2 Jazzy message type")
            return
        try:
            msg_class = message_class(msgtype)
        except (ImportError, AttributeError, ValueError):
            self._refuse(topic, f"message type {msgtype} is not installed")
            return
        best_effort = any(
            info.qos_profile.reliability == ReliabilityPolicy.BEST_EFFORT for info in publishers
        )
        self._recorded[topic] = self.create_subscription(
            msg_class,
            topic,
            functools.partial(self._on_message, topic, msgtype),
            BEST_EFFORT_DATA_QOS if best_effort else DATA_QOS,
            raw=True,
        )
        self.get_logger().info(f"recording {topic} ({msgtype})")

    def _refuse(self, topic: str, reason: str) -> None:
        self._unrecordable.add(topic)
        self.get_logger().warning(f"cannot record {topic}: {reason}")

    def _on_message(self, topic: str, msgtype: str, raw: bytes) -> None:
        now_ns = self.get_clock().now().nanoseconds
        if now_ns <= 0:
            self._awaiting_clock.append((topic, msgtype, raw))
            return
        if self._awaiting_clock:
            self._write_awaiting(now_ns)
        self._writer.write_raw(topic, msgtype, now_ns, raw)
        self._rate_counts[topic] += 1

    def _write_awaiting(self, log_time_ns: int) -> None:
        for topic, msgtype, raw in self._awaiting_clock:
            self._writer.write_raw(topic, msgtype, log_time_ns, raw)
            self._rate_counts[topic] += 1
        self._awaiting_clock.clear()

    def _check_duration(self) -> None:
        if self._duration_ns is None:
            return
        now_ns = self.get_clock().now().nanoseconds
        if now_ns <= 0:
            return
        if self._first_clock_ns is None:
            self._first_clock_ns = now_ns
        elif now_ns - self._first_clock_ns >= self._duration_ns:
            self.get_logger().info(f"recorded for {self._duration_ns * 1e-9:g} s")
            self.finish(0)

    def _report(self):
        now_s = time.monotonic()
        elapsed_s = max(now_s - self._rate_since_s, 1e-9)
        counts = self._writer.counts
        values: dict[str, object] = {"bag": str(self._writer.path), "topics": len(counts)}
        values["messages"] = sum(counts.values())
        values["backlog"] = self._writer.backlog
        for topic in sorted(self._recorded):
            values[f"count[{topic}]"] = counts.get(topic, 0)
            values[f"rate_hz[{topic}]"] = self._rate_counts[topic] / elapsed_s
        self._rate_counts.clear()
        self._rate_since_s = now_s
        level = "ok" if self._recorded else "warn"
        message = f"recording {len(self._recorded)} topics"
        if self._unrecordable:
            level = "warn"
            message += f"; cannot record {', '.join(sorted(self._unrecordable))}"
        if self._writer.failure is not None:
            level = "error"
            message += f"; {self._writer.failure}"
        elif self._writer.flush_failure is not None:
            level = "error"
            message += f"; cannot flush the bag to the disk: {self._writer.flush_failure}"
        return level, message, values

    def close_bag(self) -> None:
        """Finish the bag and log what it holds; a failure is reported, never raised."""
        if self._writer.closed:
            return
        if self._awaiting_clock:
            self._log(
                f"{len(self._awaiting_clock)} messages arrived before any /clock; "
                "recorded at log time 0"
            )
            self._write_awaiting(0)
        try:
            self._writer.close()
        except BagError as error:
            self.close_failed = True
            print(f"bag_recorder: {error}", file=sys.stderr)
            return
        counts = self._writer.counts
        summary = ", ".join(f"{topic} {count}" for topic, count in sorted(counts.items()))
        self._log(
            f"closed bag {self._writer.path}: {sum(counts.values())} messages"
            + (f" ({summary})" if summary else "")
        )

    def _log(self, text: str) -> None:
        """Log; after shutdown began (SIGINT) /rosout is gone, so write to stderr instead."""
        if self.context.ok():
            self.get_logger().info(text)
        else:
            print(f"[bag_recorder] {text}", file=sys.stderr)

    def destroy_node(self) -> None:
        self.close_bag()
        super().destroy_node()


def parse_arguments(arguments: list[str]) -> argparse.Namespace:
    parser = command_parser("bag_recorder", __doc__, EXIT_CODES, ROS_ARGUMENTS_NOTE)
    parser.add_argument("output_bag", help="bag directory to create (must not exist)")
    parser.add_argument(
        "--topics",
        nargs="+",
        metavar="T",
        help="topics to record (relative names follow the node namespace); "
        "default: the suite's sensor, truth, nav and wind topics",
    )
    parser.add_argument(
        "--all",
        action="store_true",
        dest="record_all",
        help="record every topic except /rosout, /parameter_events and /clock "
        "(list /clock in --topics to record it too)",
    )
    parser.add_argument(
        "--duration-s",
        type=float,
        metavar="S",
        help="stop after S seconds of node-clock time (simulation time under use_sim_time)",
    )
    options = parser.parse_args(arguments)
    if options.duration_s is not None and not options.duration_s > 0:
        parser.error("--duration-s must be positive")
    if options.topics is None:
        options.topics = [] if options.record_all else list(DEFAULT_TOPICS)
    return options


def main() -> None:
    arguments, ros_arguments = split_ros_arguments(sys.argv)
    options = parse_arguments(arguments)
    recorders: list[BagRecorder] = []

    def make_recorder() -> BagRecorder:
        recorder = BagRecorder(
            options.output_bag, options.topics, options.record_all, options.duration_s
        )
        recorders.append(recorder)
        return recorder

    exit_code = run_node(make_recorder, ros_arguments)
    if any(recorder.close_failed for recorder in recorders):
        exit_code = 1
    sys.exit(exit_code)
