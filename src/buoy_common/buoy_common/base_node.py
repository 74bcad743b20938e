"""ROS plumbing shared by every node of the suite.

Start-up and shutdown (clean exits on SIGINT/SIGTERM, a one-line message and exit code 2 for a
configuration error), typed parameters declared from the cores' configuration dataclasses,
rate-limited and counted rejection of bad input, and the ``diagnostics`` publisher.
"""

from __future__ import annotations

import importlib
import signal
import sys
import threading
import time
import typing
from collections import Counter
from collections.abc import Callable, Mapping

import rclpy
import rclpy.signals
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from rcl_interfaces.msg import ParameterDescriptor
from rclpy.duration import Duration
from rclpy.executors import ExternalShutdownException
from rclpy.experimental import EventsExecutor
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from rclpy.signals import SignalHandlerOptions

from buoy_common.cli import asks_for_help, node_help, write_help
from buoy_common.contract import BODY_FRAME, TF_STATIC_TOPIC
from buoy_common.heap import freeze_existing_objects
from buoy_common.parameters import (
    ParameterError,
    build_config,
    check_parameter_names,
    coerce_parameter,
    command_line_parameters,
    config_parameters,
    load_parameter_sections,
    to_ros_value,
)
from buoy_common.transform_messages import FrameTransform, tf_cdr

# Reliable with a deep queue: a recorder or a slow subscriber must not lose sensor samples.
DATA_QOS = QoSProfile(
    depth=1000,
    history=HistoryPolicy.KEEP_LAST,
    reliability=ReliabilityPolicy.RELIABLE,
    durability=DurabilityPolicy.VOLATILE,
)

# tf2_ros's static broadcaster profile: a subscriber that comes later still receives the one
# message, as tf2 listeners expect of ``tf_static``.
TF_STATIC_QOS = QoSProfile(
    depth=1,
    history=HistoryPolicy.KEEP_LAST,
    reliability=ReliabilityPolicy.RELIABLE,
    durability=DurabilityPolicy.TRANSIENT_LOCAL,
)

REJECTION_LOG_PERIOD_S = 5.0
# Longest wait of the spin loop for an event before it checks whether to stop (s).
SPIN_TIMEOUT_S = 0.1
# Bound on the wait, at shutdown, for subscribers to acknowledge the last published messages.
FLUSH_ACK_TIMEOUT_S = 2.0


STOP_SIGNALS = (signal.SIGINT, signal.SIGTERM)


class StartupError(Exception):
    """A node cannot start: bad parameter, missing file. The message names the culprit."""


class SuiteNode(Node):
    """A Node that can ask to stop (end of a simulation, end of a bag) and counts rejections."""

    def __init__(self, node_name: str, **kwargs):
        super().__init__(node_name, **kwargs)
        self.finished = False
        self.exit_code = 0
        self.rejections: Counter[str] = Counter()
        # Monotonic time (s) at which the spin loop calls run_deferred_work; None: nothing due.
        self.deferred_work_due_s: float | None = None
        self.static_transforms_publisher = None

    def run_deferred_work(self) -> None:
        """Work a callback put off (see :func:`run_node`); clears ``deferred_work_due_s``."""
        self.deferred_work_due_s = None

    def finish(self, exit_code: int = 0) -> None:
        """Leave the spin loop after the current callback."""
        self.finished = True
        self.exit_code = exit_code

    def reject(self, input_name: str, reason: str) -> None:
        """Count a rejected input sample and warn, rate-limited, with the running count."""
        key = f"{input_name}: {reason}"
        self.rejections[key] += 1
        self.get_logger().warning(
            f"rejected {key} (total {self.rejections[key]})",
            throttle_duration_sec=REJECTION_LOG_PERIOD_S,
        )

    def broadcast_static_transforms(
        self, tf_message_class: type | None, transforms: list[FrameTransform]
    ) -> None:
        """Publish ``transforms`` (the sensor frames in ``base_link``) once on ``tf_static``
        and keep the publisher, which hands them to every later subscriber; where tf2_msgs is
        not installed (``tf_message_class`` None) the log says they are not broadcast."""
        frames = f"{BODY_FRAME} -> {', '.join(t.child_frame for t in transforms)}"
        if tf_message_class is None:
            self.get_logger().info(
                f"tf2_msgs is not installed: {frames} is not broadcast on {TF_STATIC_TOPIC}"
            )
            return
        self.static_transforms_publisher = self.create_publisher(
            tf_message_class, TF_STATIC_TOPIC, TF_STATIC_QOS
        )
        sec, nanosec = self.get_clock().now().seconds_nanoseconds()
        self.static_transforms_publisher.publish(tf_cdr(sec, nanosec, transforms))
        self.get_logger().info(f"broadcasting {frames} on {TF_STATIC_TOPIC}")

    # -- parameters -------------------------------------------------------------------------

    def declare_value(self, name: str, default, description: str = ""):
        """Declare a parameter whose value is checked against the type of ``default``.

        Integers are accepted where a double is expected (YAML ``100`` for ``100.0``); anything
        else of the wrong type, or a vector of the wrong length, raises StartupError naming it.
        """
        descriptor = ParameterDescriptor(description=description, dynamic_typing=True)
        value = self.declare_parameter(name, to_ros_value(default), descriptor).value
        try:
            return coerce_parameter(name, value, default)
        except ParameterError as error:
            raise StartupError(str(error)) from error

    def declare_string_list(self, name: str, description: str = "") -> list[str]:
        """Declare a string-array parameter (default empty)."""
        descriptor = ParameterDescriptor(description=description)
        try:
            self.declare_parameter(name, Parameter.Type.STRING_ARRAY, descriptor)
            value = self.get_parameter(name).value
        except rclpy.exceptions.ParameterUninitializedException:
            return []
        except rclpy.exceptions.InvalidParameterTypeException as error:
            raise StartupError(f"parameter '{name}' must be a list of strings") from error
        return list(value)

    def declare_config(
        self,
        config_type: type,
        prefix: str = "",
        renamed: Mapping[str, str] | None = None,
        skip: tuple[str, ...] = (),
        **fixed,
    ):
        """Declare one parameter per field of a configuration dataclass and build it.

        The parameter of field ``f`` is ``prefix + f`` unless ``renamed`` maps it elsewhere (the
        shared extrinsics such as ``gnss.primary_antenna``). Fields in ``skip`` keep their default;
        ``fixed`` gives values that are not parameters.
        """
        values = {
            parameter: self.declare_value(parameter, default)
            for _, parameter, default in config_parameters(
                config_type, prefix, renamed, set(skip) | set(fixed)
            )
        }
        try:
            return build_config(config_type, values, prefix, renamed, skip, **fixed)
        except ParameterError as error:
            raise StartupError(str(error)) from error

    def refuse_unknown_parameters(self, ros_arguments: list[str]) -> None:
        """Raise StartupError for a parameter given to this node that it has not declared.

        Called once every parameter is declared. ``-p`` values and the node's own sections of
        the parameter files must all be known; ``/**`` sections may hold other nodes'
        parameters (see :func:`buoy_common.parameters.check_parameter_names`).
        """
        params_files, command_line = command_line_parameters(ros_arguments)
        try:
            wildcard, own = load_parameter_sections(params_files, self.get_name())
            declared = self.list_parameters([], 0).names
            check_parameter_names(declared, shared=wildcard, own=[*own, *command_line])
        except ParameterError as error:
            raise StartupError(str(error)) from error


class FlushingNode(SuiteNode):
    """A node that holds output back (waiting for later input) and publishes it when it stops.

    SIGINT and SIGTERM only end the spin loop (:func:`take_stop_signals`): the context stays
    valid, :meth:`flush_held_back` can still publish, and the node waits (at most
    ``FLUSH_ACK_TIMEOUT_S``) for the subscribers to acknowledge what it published.
    """

    def flush_held_back(self) -> list:
        """Publish what is held back; return the publishers to wait for."""
        raise NotImplementedError

    def destroy_node(self) -> None:
        if self.context.ok():
            try:
                publishers = self.flush_held_back()
                deadline_s = time.monotonic() + FLUSH_ACK_TIMEOUT_S
                for publisher in publishers:
                    remaining_s = max(0.0, deadline_s - time.monotonic())
                    publisher.wait_for_all_acked(Duration(seconds=remaining_s))
            except Exception as error:  # a failing flush must not hide the node's exit
                self.get_logger().error(f"could not publish the held-back output: {error}")
        super().destroy_node()


def take_stop_signals(on_stop: Callable[[], None]) -> None:
    """Make SIGINT and SIGTERM, however often and however close together they come, call
    ``on_stop`` instead of rclpy's handling.

    rclpy turns SIGINT into a KeyboardInterrupt raised wherever the program happens to be: in a
    callback run by the C++ executor that aborts the process, elsewhere it leaves a traceback.
    ``on_stop`` only records the request and is called once, at the first signal; the program's loop
    ends at its next turn, and :func:`ignore_stop_signals` is called on the way out.
    """
    rclpy.signals.uninstall_signal_handlers()
    stop_requested = False

    def request_stop(*_) -> None:
        # A second signal can arrive while the first one's ``on_stop`` holds a lock of rclpy's
        # (try_shutdown does): calling it again there would wait for that lock forever.
        nonlocal stop_requested
        if not stop_requested:
            stop_requested = True
            on_stop()

    for signal_number in STOP_SIGNALS:
        signal.signal(signal_number, request_stop)


def ignore_stop_signals() -> None:
    """Ignore SIGINT and SIGTERM from here on: the process is ending. The interpreter resets a
    handler written in Python to the default action while it exits, so a signal in its last
    milliseconds would otherwise kill the process; an ignored one stays ignored."""
    for signal_number in STOP_SIGNALS:
        signal.signal(signal_number, signal.SIG_IGN)


def message_class(msgtype: str):
    """The rclpy message class of a type string such as 'sensor_msgs/msg/Imu'."""
    package, kind, name = msgtype.split("/")
    return getattr(importlib.import_module(f"{package}.{kind}"), name)


# -- diagnostics ---------------------------------------------------------------------------------

LEVELS = {"ok": DiagnosticStatus.OK, "warn": DiagnosticStatus.WARN, "error": DiagnosticStatus.ERROR}


class DiagnosticsPublisher:
    """Publishes the node's health on ``diagnostics`` once per period.

    ``report()`` returns (level, message, values) with level one of 'ok', 'warn', 'error' and
    values a flat mapping; the number of matched publishers of each subscription
    (``publishers[/topic]``) and the node's rejection counts are appended automatically.
    """

    def __init__(
        self,
        node: SuiteNode,
        report: Callable[[], tuple[str, str, Mapping[str, typing.Any]]],
        period_s: float = 1.0,
    ):
        self._node = node
        self._report = report
        self._publisher = node.create_publisher(DiagnosticArray, "diagnostics", 10)
        self._timer = node.create_timer(period_s, self.publish)

    def publish(self) -> None:
        level, message, values = self._report()
        status = DiagnosticStatus()
        status.level = LEVELS[level]
        status.name = f"{self._node.get_namespace().rstrip('/')}/{self._node.get_name()}"
        status.message = message
        status.hardware_id = self._node.get_name()
        items = dict(values)
        # Matched publishers per input: zero names a sensor that is missing or not yet
        # discovered, whose samples, once matched, may arrive as a burst.
        for subscription in self._node.subscriptions:
            items[f"publishers[{subscription.topic_name}]"] = subscription.get_publisher_count()
        items["rejected_total"] = sum(self._node.rejections.values())
        for key, count in sorted(self._node.rejections.items()):
            items[f"rejected[{key}]"] = count
        status.values = [KeyValue(key=str(k), value=_format_value(v)) for k, v in items.items()]
        array = DiagnosticArray()
        array.header.stamp = self._node.get_clock().now().to_msg()
        array.status = [status]
        self._publisher.publish(array)


def _format_value(value) -> str:
    if isinstance(value, float):
        return f"{value:.6g}"
    return str(value)


# -- running ----------------------------------------------------------------------------------


def run_node(node_factory: Callable[[], SuiteNode], args: list[str] | None = None) -> int:
    """Initialise rclpy, build the node, spin until SIGINT/SIGTERM or ``node.finish()``.

    Returns the process exit code: 0 for a clean stop, 2 for a configuration error (reported as
    one line on stderr, without a traceback).
    """
    program = sys.argv[0].rsplit("/", 1)[-1]
    args = sys.argv if args is None else args
    # Taken before anything else, so that a signal during start-up is a stop request too.
    stop_requested = threading.Event()
    take_stop_signals(stop_requested.set)
    try:
        rclpy.init(args=args, signal_handler_options=SignalHandlerOptions.NO)
    except Exception as error:  # rclpy raises RCLError for a missing --params-file
        print(f"{program}: cannot start: {error}", file=sys.stderr)
        return 2
    node = None
    try:
        # The events executor dispatches each message as the middleware reports it, in arrival
        # order, without rebuilding a wait set per message: half the CPU per message of the
        # wait-set executors. It installs rclpy's SIGINT/SIGTERM handling when built, which is
        # taken back at once.
        executor = EventsExecutor()
        take_stop_signals(stop_requested.set)
        node = node_factory()
        node.refuse_unknown_parameters(args)
        executor.add_node(node)
        # What the start-up built lives as long as the node: a full collection walking it would
        # stall a callback for tens of milliseconds.
        freeze_existing_objects()
        while rclpy.ok() and not node.finished and not stop_requested.is_set():
            due_s = node.deferred_work_due_s
            if due_s is None:
                executor.spin_once(timeout_sec=SPIN_TIMEOUT_S)
                continue
            wait_s = due_s - time.monotonic()
            if wait_s > 0.0:
                executor.spin_once(timeout_sec=min(wait_s, SPIN_TIMEOUT_S))
            due_s = node.deferred_work_due_s  # a callback may have run it meanwhile
            if due_s is not None and time.monotonic() >= due_s:
                node.run_deferred_work()
        return node.exit_code
    except StartupError as error:
        print(f"{program}: {error}", file=sys.stderr)
        return 2
    except (KeyboardInterrupt, ExternalShutdownException):
        return 0
    except (rclpy.exceptions.ParameterException, ParameterError) as error:
        print(f"{program}: {error}", file=sys.stderr)
        return 2
    except Exception:
        # SIGTERM can invalidate the context under a running callback: that is a normal stop.
        if not rclpy.ok():
            return 0
        raise
    finally:
        if node is not None:
            node.destroy_node()
        rclpy.try_shutdown()
        ignore_stop_signals()


def main_for(node_factory: Callable[[], SuiteNode], docstring: str) -> Callable[[], None]:
    """A console-script entry point that runs ``node_factory`` and exits with its code, or,
    asked for ``--help``, prints what the node does (from its module's ``docstring``) and its
    exit codes."""

    def main() -> None:
        if asks_for_help(sys.argv):
            write_help(node_help(sys.argv[0].rsplit("/", 1)[-1], docstring) + "\n")
            sys.exit(0)
        sys.exit(run_node(node_factory))

    return main
