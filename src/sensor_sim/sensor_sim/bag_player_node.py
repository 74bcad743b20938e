"""bag_player: replay a rosbag2 bag's messages on their topics at their recorded pace.

    bag_player INPUT_BAG [--rate R] [--clock] [--topics T ...] [--wait-for-subscribers N]
               [--start-delay-s S] [--ros-args ...]

Each message's serialised bytes are published (reliable, deep queue) when its log time comes,
scaled by 1/R (R > 1 plays faster). The schedule is absolute, measured from one monotonic start
time, so a late message never delays the ones after it. Recorded topic names are published
relative to the node namespace: ``/imu/data_raw`` plays on ``imu/data_raw``, i.e. unchanged at
the root and inside the namespace under ``-r __ns:=/buoy1``.

``--clock`` publishes /clock (rosgraph_msgs/Clock) from the bag's log time every 10 ms of bag
time, each tick before the messages it precedes, so nodes with ``use_sim_time`` run on the
bag's clock; the bag's own /clock messages, if any, are then not replayed.

Parameters: ``wait_for_subscribers_timeout_s`` (default 30.0) bounds the wait of
``--wait-for-subscribers``; ``drain_timeout_s`` (default 5.0) bounds the wait, after the last
message, for reliable subscribers to acknowledge everything.

Exit codes: 0 at the end of the bag or on SIGINT or SIGTERM (however often repeated); 2 for a
missing or corrupt bag, an unknown topic, an unknown parameter or a bad argument (one line on
stderr); 1 when the subscribers do not appear in time; 3 at the end of a bag that was cut short
(a recorder killed or out of power), played up to its last complete chunk (a warning on stderr
says how much was read).
"""

from __future__ import annotations

import argparse
import sys
import time

import rclpy
from rclpy.duration import Duration
from rclpy.executors import ExternalShutdownException
from rclpy.qos import QoSProfile, ReliabilityPolicy
from rosgraph_msgs.msg import Clock

from buoy_common.bag_io import RECOVERED_BAG_EXIT_CODE, BagError, BagReader
from buoy_common.base_node import (
    DATA_QOS,
    StartupError,
    SuiteNode,
    ignore_stop_signals,
    message_class,
    take_stop_signals,
)
from buoy_common.cli import BAD_INPUT, RECOVERED_BAG, ROS_ARGUMENTS_NOTE, ExitCode, command_parser
from buoy_common.contract import CLOCK_TOPIC
from sensor_sim.bag_recorder_node import split_ros_arguments

PROGRAM = "bag_player"
CLOCK_PERIOD_NS = 10_000_000
PROGRESS_PERIOD_S = 3.0
WAIT_REPORT_PERIOD_S = 5.0
# Longest single sleep, so that a shutdown requested meanwhile is noticed promptly.
MAX_SLEEP_S = 0.1
CLOCK_QOS = QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE)


EXIT_CODES = (
    ExitCode(0, "the end of the bag reached, or stopped by SIGINT or SIGTERM"),
    ExitCode(1, "the subscribers did not appear in time"),
    BAD_INPUT,
    RECOVERED_BAG,
)


class PlaybackError(Exception):
    """Playback cannot proceed (subscribers never appeared); exit code 1."""


def sleep_until(due_s: float) -> bool:
    """Sleep until monotonic time ``due_s``; False if shutdown was requested meanwhile."""
    while True:
        remaining_s = due_s - time.monotonic()
        if remaining_s <= 0:
            return True
        if not rclpy.ok():
            return False
        time.sleep(min(remaining_s, MAX_SLEEP_S))


class BagPlayer:
    """Publishers for the played topics and the paced publishing loop."""

    def __init__(
        self,
        node: SuiteNode,
        reader: BagReader,
        topics: list[str],
        rate: float,
        publish_clock: bool,
    ):
        self._node = node
        self._reader = reader
        self._topics = [t for t in topics if not (publish_clock and t == CLOCK_TOPIC)]
        self._rate = rate
        self._publishers = {}
        for topic in self._topics:
            msgtype = reader.topics[topic].msgtype
            try:
                msg_class = message_class(msgtype)
            except (ImportError, AttributeError, ValueError) as error:
                raise StartupError(
                    f"bag {reader.path}: topic {topic}: message type {msgtype} is not installed"
                ) from error
            self._publishers[topic] = node.create_publisher(
                msg_class, topic if topic == CLOCK_TOPIC else topic.lstrip("/"), DATA_QOS
            )
        self._clock_publisher = (
            node.create_publisher(Clock, CLOCK_TOPIC, CLOCK_QOS) if publish_clock else None
        )
        self._clock_message = Clock()
        self.published = 0
        # Largest delay of a publication behind its schedule, wall-clock s.
        self.max_lag_s = 0.0

    def wait_for_subscribers(self, minimum: int, timeout_s: float) -> bool:
        """Block until every played topic, and /clock when it is published, has ``minimum``
        subscribers.

        Returns False when shutdown was requested meanwhile; PlaybackError on timeout.
        """
        waited_for = dict(self._publishers)
        if self._clock_publisher is not None:
            # A node on the bag's clock that gets a message before its first /clock stamps
            # that message with a time of its own.
            waited_for[CLOCK_TOPIC] = self._clock_publisher
        logger = self._node.get_logger()
        deadline = time.monotonic() + timeout_s
        next_report = time.monotonic()
        while rclpy.ok():
            lacking = {
                topic: publisher.get_subscription_count()
                for topic, publisher in waited_for.items()
                if publisher.get_subscription_count() < minimum
            }
            if not lacking:
                return True
            now = time.monotonic()
            detail = ", ".join(f"{waited_for[t].topic_name} (has {n})" for t, n in lacking.items())
            if now >= deadline:
                raise PlaybackError(
                    f"gave up after {timeout_s:g} s waiting for {minimum} subscriber(s) on: "
                    f"{detail}"
                )
            if now >= next_report:
                logger.info(f"waiting for {minimum} subscriber(s) on: {detail}")
                next_report = now + WAIT_REPORT_PERIOD_S
            time.sleep(0.02)
        return False

    def play(self) -> bool:
        """Publish the bag at its pace; False when shutdown interrupted it."""
        logger = self._node.get_logger()
        first_ns = None
        wall_start_s = 0.0
        speedup = self._rate
        duration_ns = max(self._reader.end_ns - self._reader.start_ns, 1)
        next_tick_ns = 0
        next_progress_s = 0.0
        publishers = self._publishers
        log_time_ns = 0
        for message in self._reader.messages(self._topics):
            log_time_ns = message.log_time_ns
            if first_ns is None:
                first_ns = next_tick_ns = log_time_ns
                wall_start_s = time.monotonic()
                next_progress_s = wall_start_s + PROGRESS_PERIOD_S
            if self._clock_publisher is not None:
                while next_tick_ns <= log_time_ns:
                    if not sleep_until(wall_start_s + (next_tick_ns - first_ns) * 1e-9 / speedup):
                        return False
                    self._publish_clock(next_tick_ns)
                    next_tick_ns += CLOCK_PERIOD_NS
            due_s = wall_start_s + (log_time_ns - first_ns) * 1e-9 / speedup
            if not sleep_until(due_s):
                return False
            publishers[message.topic].publish(message.raw)
            self.published += 1
            now_s = time.monotonic()
            if now_s - due_s > self.max_lag_s:
                self.max_lag_s = now_s - due_s
            if now_s >= next_progress_s:
                next_progress_s = now_s + PROGRESS_PERIOD_S
                percent = 100.0 * (log_time_ns - self._reader.start_ns) / duration_ns
                logger.info(
                    f"{percent:.0f}% played ({self.published} messages, "
                    f"bag time {(log_time_ns - first_ns) * 1e-9:.1f} s)"
                )
        if self._clock_publisher is not None and first_ns is not None:
            self._publish_clock(log_time_ns)
        return True

    def _publish_clock(self, time_ns: int) -> None:
        self._clock_message.clock.sec, self._clock_message.clock.nanosec = divmod(
            time_ns, 1_000_000_000
        )
        self._clock_publisher.publish(self._clock_message)

    def drain(self, timeout_s: float) -> bool:
        """Wait until reliable subscribers acknowledged every message; False on timeout."""
        deadline = time.monotonic() + timeout_s
        publishers = list(self._publishers.values())
        if self._clock_publisher is not None:
            publishers.append(self._clock_publisher)
        for publisher in publishers:
            remaining_s = max(deadline - time.monotonic(), 0.0)
            if not publisher.wait_for_all_acked(Duration(nanoseconds=int(remaining_s * 1e9))):
                return False
        return True


def parse_arguments(arguments: list[str]) -> argparse.Namespace:
    parser = command_parser(PROGRAM, __doc__, EXIT_CODES, ROS_ARGUMENTS_NOTE)
    parser.add_argument("input_bag", help="bag directory to play")
    parser.add_argument(
        "--rate", type=float, default=1.0, metavar="R", help="speed factor, > 1 plays faster"
    )
    parser.add_argument(
        "--clock", action="store_true", help="publish /clock from the bag's log time"
    )
    parser.add_argument(
        "--topics", nargs="+", metavar="T", help="play only these topics (default: all)"
    )
    parser.add_argument(
        "--wait-for-subscribers",
        type=int,
        default=0,
        metavar="N",
        help="before playing, wait until every played topic (and /clock with --clock) has N "
        "subscribers",
    )
    parser.add_argument(
        "--start-delay-s",
        type=float,
        default=0.0,
        metavar="S",
        help="pause S seconds (wall time) before the first message",
    )
    options = parser.parse_args(arguments)
    if not options.rate > 0:
        parser.error("--rate must be positive")
    if options.wait_for_subscribers < 0:
        parser.error("--wait-for-subscribers must not be negative")
    if not options.start_delay_s >= 0:
        parser.error("--start-delay-s must not be negative")
    return options


def _resolve_topics(reader: BagReader, requested: list[str] | None) -> list[str]:
    """The bag's names of the topics to play; BagError naming any the bag lacks."""
    if requested is None:
        return sorted(reader.topics)
    reader.require(*requested)
    stored = set(reader.topics)
    return sorted({name if name in stored else "/" + name.lstrip("/") for name in requested})


def run(options: argparse.Namespace, ros_arguments: list[str]) -> int:
    try:
        reader = BagReader(options.input_bag)
    except BagError as error:
        print(f"{PROGRAM}: {error}", file=sys.stderr)
        return 2
    with reader:
        if reader.recovery is not None:
            print(f"{PROGRAM}: warning: {reader.recovery.describe(reader.path)}", file=sys.stderr)
        try:
            topics = _resolve_topics(reader, options.topics)
        except BagError as error:
            print(f"{PROGRAM}: {error}", file=sys.stderr)
            return 2
        try:
            rclpy.init(args=ros_arguments)
        except Exception as error:
            print(f"{PROGRAM}: cannot start: {error}", file=sys.stderr)
            return 2
        node = player = None
        try:
            node = SuiteNode(PROGRAM)
            # A stop request shuts the context down: every wait and the playing loop notice it.
            take_stop_signals(rclpy.try_shutdown)
            wait_timeout_s = node.declare_value(
                "wait_for_subscribers_timeout_s", 30.0, "longest wait for subscribers, s"
            )
            drain_timeout_s = node.declare_value(
                "drain_timeout_s", 5.0, "longest wait for acknowledgements at the end, s"
            )
            node.refuse_unknown_parameters(ros_arguments)
            player = BagPlayer(node, reader, topics, options.rate, options.clock)
            logger = node.get_logger()
            if options.wait_for_subscribers and not player.wait_for_subscribers(
                options.wait_for_subscribers, wait_timeout_s
            ):
                return _stopped(player)
            if not sleep_until(time.monotonic() + options.start_delay_s):
                return _stopped(player)
            logger.info(
                f"playing {reader.path}: {len(topics)} topics, {reader.duration_s:.1f} s "
                f"at rate {options.rate:g}"
            )
            started_s = time.monotonic()
            if not player.play():
                return _stopped(player)
            played_s = time.monotonic() - started_s
            if not player.drain(drain_timeout_s):
                logger.warning(f"not every message was acknowledged within {drain_timeout_s:g} s")
            logger.info(
                f"finished: {player.published} messages in {played_s:.2f} s "
                f"(at most {player.max_lag_s * 1e3:.1f} ms behind schedule), "
                f"acknowledged after {time.monotonic() - started_s:.2f} s"
            )
            if reader.recovery is not None and reader.recovery.truncated:
                return RECOVERED_BAG_EXIT_CODE
            return 0
        except (StartupError, BagError, rclpy.exceptions.ParameterException) as error:
            print(f"{PROGRAM}: {error}", file=sys.stderr)
            return 2
        except PlaybackError as error:
            print(f"{PROGRAM}: {error}", file=sys.stderr)
            return 1
        except (KeyboardInterrupt, ExternalShutdownException):
            return _stopped(player)
        except Exception:
            # SIGINT/SIGTERM invalidate the context, so a publish under way raises RCLError.
            if not rclpy.ok():
                return _stopped(player)
            raise
        finally:
            if node is not None:
                node.destroy_node()
            rclpy.try_shutdown()
            ignore_stop_signals()


def _stopped(player: BagPlayer | None) -> int:
    """Report an interrupted replay (rclpy's logger is unusable after shutdown); exit code 0."""
    published = 0 if player is None else player.published
    print(f"{PROGRAM}: stopped after {published} messages", file=sys.stderr)
    return 0


def main() -> None:
    arguments, ros_arguments = split_ros_arguments(sys.argv)
    sys.exit(run(parse_arguments(arguments), ros_arguments))
