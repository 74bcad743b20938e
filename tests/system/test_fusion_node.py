"""fusion_node as a real process over DDS, fed the sensor messages of a committed bag.

The test process publishes ``imu/data_raw``, ``gnss/fix``, ``gnss/vel`` and ``gnss/heading`` in
bag order, paced at a multiple of real time, and listens to the four ``nav/*`` topics and
``diagnostics``. The reference is a FusionEngine fed the same messages offline through the same
conversion (:func:`buoy_nav.fusion_messages.feed_message`): the engine's results depend on header
stamps only, so the live node must publish exactly the offline solutions; and these must be as
close to the simulator's truth as the sensors allow, or a fault common to both would pass. The
bags are ``sea_state`` (shipped geometry) and ``off_axis`` (its own buoy, stamps apart); the
sensor sets beyond RTK are fed straight from the simulator: a moored buoy with a magnetometer and
a motion pack and no GNSS, and a single GNSS antenna with a magnetometer through an outage.
"""

from __future__ import annotations

import array
import copy
import functools
import importlib
import math
import os
import signal
import sys
import threading
import time
import types

import numpy as np
import pytest
import rclpy
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
from geometry_msgs.msg import TwistWithCovarianceStamped
from nav_msgs.msg import Odometry
from rclpy.context import Context
from rclpy.executors import SingleThreadedExecutor
from rclpy.serialization import deserialize_message
from sensor_msgs.msg import Imu, NavSatFix
from test_nav_sensor_sets import HARD_IRON_UT, MAGNETOMETER, SOFT_IRON, euler_errors_deg

from against_truth import Truth, assert_navigation_within_limits, odometry_errors
from buoy_common.bag_io import BagReader
from buoy_common.base_node import DATA_QOS
from buoy_common.contract import (
    GNSS_FIX_TOPIC,
    GNSS_HEADING_TOPIC,
    GNSS_VELOCITY_TOPIC,
    IMU_RAW_TOPIC,
    NAV_MSGTYPES,
    NAV_ODOMETRY_TOPIC,
    Reason,
)
from buoy_common.parameters import build_config, load_parameter_files
from buoy_nav import fusion_node
from buoy_nav.aiding import GnssFixSource, GnssHeadingSource, GnssVelocitySource
from buoy_nav.config import (
    FUSION_FIELDS_NOT_PARAMETERS,
    FUSION_NODE_NAME,
    FUSION_PARAMETER_PREFIX,
    FusionConfig,
)
from buoy_nav.engine import IMU, FusionEngine
from buoy_nav.fusion_messages import (
    FUSION_INPUT_MSGTYPES,
    NavMessageClasses,
    StampBook,
    feed_message,
    solution_messages,
)
from buoy_nav.fusion_node import INPUT_CLASSES, OUTPUT_CLASSES
from processed_bags import CASES
from ros_messages import reports_publishers_on, stamp_ns, to_rclpy, wait_for
from sensor_sim.scenario import load_scenario
from sensor_sim.streams import STREAMS, merged_messages
from sensor_sim.truth import TruthModel

pytestmark = pytest.mark.ros

NODE = FUSION_NODE_NAME
# The message-object form of the solutions: an independent path to the CDR the node publishes.
NAV_CLASSES = NavMessageClasses(Odometry, Imu, TwistWithCovarianceStamped, NavSatFix)
LIVE_EQUALS_OFFLINE_S = 40.0  # the alignment takes the first 10 s
MALFORMED_RUN_S = 16.0
MALFORMED_AFTER_S = 12.0  # aligned by then
FLUSH_RUN_S = 12.0
PLAY_RATE = 4.0
# From the node's first solution on, the replay is held back by the node's output (Listener.play
# given the solution stamps) and cannot outrun it: asked for more than the node sustains, it goes
# at the node's own pace. Not before (nothing holds it back while the node aligns), nor in the
# run that judges the node's timing figures, which were measured at PLAY_RATE.
HELD_PLAY_RATE = 8.0
# The replay's hold on the node's output (Listener.play): checked every half second of stamps,
# the solutions a second behind must have arrived, waiting for them at most CATCH_UP_TIMEOUT_S.
CHECK_NS = 500_000_000
CATCH_UP_NS = 1_000_000_000
CATCH_UP_TIMEOUT_S = 30.0
# From SIGINT to the node's exit (NodeProcesses.interrupt's bound).
STOP_TIMEOUT_S = 15.0
# The solutions are judged against the truth from this long after the first one in the long
# run (the first seconds after the alignment carry its errors), from the first in the short.
SETTLING_S = 20.0
# Equality of live and offline values: relative, and absolute for values near zero.
RELATIVE_TOLERANCE = 1e-9
ABSOLUTE_TOLERANCE = 1e-12


def set_stamp_ns(message, time_ns: int) -> None:
    message.header.stamp.sec, message.header.stamp.nanosec = divmod(time_ns, 1_000_000_000)


@functools.cache
def sensor_stream_of(name: str) -> list:
    """(topic, rclpy message) of bag ``name``'s first LIVE_EQUALS_OFFLINE_S of sensor data, in
    bag order."""
    stream = []
    with BagReader(CASES[name].bag_path) as reader:
        present = {name.lstrip("/") for name in reader.topics}
        first_ns = None
        for record in reader.messages([t for t in FUSION_INPUT_MSGTYPES if t in present]):
            first_ns = record.log_time_ns if first_ns is None else first_ns
            if record.log_time_ns - first_ns > LIVE_EQUALS_OFFLINE_S * 1e9:
                break
            topic = record.topic.lstrip("/")
            stream.append((topic, to_rclpy(reader.decode(record), INPUT_CLASSES[topic]())))
    return stream


@functools.cache
def truth_of(name: str) -> Truth:
    return Truth(CASES[name].bag_path)


def parameter_arguments(name: str) -> list[str]:
    """``--params-file`` arguments of the buoy that recorded bag ``name``."""
    return [a for path in CASES[name].buoy_parameter_files for a in ("--params-file", str(path))]


def node_config(name: str = "sea_state", **overrides) -> FusionConfig:
    """The configuration the node builds from the parameter files of the buoy that recorded
    bag ``name`` and ``overrides`` (parameter name → value, as ``-p`` gives them)."""
    return config_from_files(CASES[name].buoy_parameter_files, **overrides)


def config_from_files(files, **overrides) -> FusionConfig:
    """The configuration the node builds from the parameter ``files`` and ``overrides``."""
    parameters = load_parameter_files(files, NODE) | overrides
    return build_config(
        FusionConfig,
        parameters,
        FUSION_PARAMETER_PREFIX,
        skip=FUSION_FIELDS_NOT_PARAMETERS,
    )


def nav_messages(solutions, outputs: dict[str, list], stamps: StampBook) -> None:
    for solution in solutions:
        for nav_topic, nav_message in solution_messages(solution, NAV_CLASSES, stamps).items():
            outputs[nav_topic].append(nav_message)


def offline_run(
    stream, name: str = "sea_state", **overrides
) -> tuple[dict[str, list], FusionEngine, StampBook]:
    """The nav messages of a fresh engine configured for bag ``name``'s buoy and fed ``stream``
    in order, by topic, the engine and the book of IMU stamps its solutions are stamped from."""
    engine = FusionEngine(node_config(name, **overrides))
    outputs = {topic: [] for topic in NAV_MSGTYPES}
    stamps = StampBook()
    for topic, message in stream:
        nav_messages(feed_message(engine, topic, message, stamps)[0], outputs, stamps)
    return outputs, engine, stamps


def assert_near_the_truth(offline: dict[str, list], name: str, settling_s: float) -> None:
    """The offline solutions' attitude and velocity within the limits of the sensors."""
    errors = odometry_errors(truth_of(name), offline[NAV_ODOMETRY_TOPIC], settling_s)
    print(assert_navigation_within_limits(errors, CASES[name].navigation_limits(), name))


class Listener:
    """An in-process DDS participant in the test's isolated domain: publishes the sensor topics,
    records the nav topics and the diagnostics."""

    def __init__(self, env: dict[str, str]):
        for name in ("ROS_DOMAIN_ID", "ROS_AUTOMATIC_DISCOVERY_RANGE"):
            os.environ[name] = env[name]
        self.context = Context()
        rclpy.init(context=self.context)
        self.node = rclpy.create_node("fusion_test", context=self.context)
        # The node sends five nav messages per IMU sample, 2000 a second at PLAY_RATE: they are
        # kept serialised and decoded afterwards, so that this listener keeps up on a busy
        # machine (the publisher's history is 1000 messages deep; a reader further behind loses).
        self.received_raw: dict[str, list[bytes]] = {topic: [] for topic in NAV_MSGTYPES}
        for topic, message_class in OUTPUT_CLASSES.items():
            self.node.create_subscription(
                message_class, topic, self.received_raw[topic].append, DATA_QOS, raw=True
            )
        self.diagnostics: list[DiagnosticStatus] = []
        self.node.create_subscription(
            DiagnosticArray,
            "diagnostics",
            lambda array: self.diagnostics.extend(s for s in array.status if s.hardware_id == NODE),
            10,
        )
        self.publishers = {
            topic: self.node.create_publisher(message_class, topic, DATA_QOS)
            for topic, message_class in INPUT_CLASSES.items()
        }
        self.executor = SingleThreadedExecutor(context=self.context)
        self.executor.add_node(self.node)
        self.thread = threading.Thread(target=self.executor.spin, daemon=True)
        self.thread.start()

    def wait_for_node(self, timeout_s: float = 20.0) -> bool:
        """Until the node's subscriptions and publishers are matched with ours, on both sides."""
        return wait_for(
            lambda: (
                self.node_sees_publishers()
                and all(self.publishers[t].get_subscription_count() > 0 for t in self.node_inputs())
                and all(self.node.count_publishers(topic) > 0 for topic in NAV_MSGTYPES)
            ),
            timeout_s,
        )

    def node_inputs(self) -> list[str]:
        """The input topics the node subscribes to, as its latest diagnostics list them (a
        source the configuration disables, such as a third antenna, has no subscription)."""
        if not self.diagnostics:
            return []
        keys = {item.key for item in self.diagnostics[-1].values}
        return [topic for topic in INPUT_CLASSES if f"publishers[/{topic}]" in keys]

    def node_sees_publishers(self) -> bool:
        """The node's latest diagnostics report a matched publisher on every input it takes."""
        inputs = self.node_inputs()
        return bool(inputs) and reports_publishers_on(self.diagnostics[-1], inputs)

    def play(
        self,
        paced_stream,
        solution_stamps_ns=None,
        rate: float = PLAY_RATE,
        held_rate: float | None = None,
    ) -> None:
        """Publish (pace stamp ns, topic, message) rows at ``rate`` times real time.

        With ``solution_stamps_ns`` (the stamps of the solutions the node is to publish, from
        the offline run), the pace is also held back by the node's output: every CHECK_NS of
        stamps, the solutions stamped more than CATCH_UP_NS before the stamp reached must have
        arrived here (the node publishes up to ``max_measurement_delay_s`` behind its newest IMU
        sample). On a loaded machine the replay then slows down instead of the node or this
        listener falling further behind than their 1000-message queues hold; what is compared
        is unchanged, since the node runs on stamps alone. Held back so, the pace can rise to
        ``held_rate`` (if given) from the first solution due on.
        """
        start_wall_s, first_ns = time.monotonic(), paced_stream[0][0]
        next_check_ns = first_ns + CHECK_NS
        pace_rate = rate
        for pace_ns, topic, message in paced_stream:
            if solution_stamps_ns is not None and pace_ns >= next_check_ns:
                due = int(np.searchsorted(solution_stamps_ns, pace_ns - CATCH_UP_NS, "right"))
                wait_for(lambda due=due: received_count(self) >= due, CATCH_UP_TIMEOUT_S)
                if due and held_rate is not None:
                    pace_rate = held_rate
                start_wall_s = time.monotonic() - (pace_ns - first_ns) * 1e-9 / pace_rate
                next_check_ns = pace_ns + CHECK_NS
            delay_s = (pace_ns - first_ns) * 1e-9 / pace_rate - (time.monotonic() - start_wall_s)
            if delay_s > 0:
                time.sleep(delay_s)
            self.publishers[topic].publish(message)

    def latest_diagnostics_where(self, condition, timeout_s: float) -> dict[str, str] | None:
        """Values of the first diagnostics status, from now on, satisfying ``condition``."""
        start = len(self.diagnostics)
        found = []

        def arrived() -> bool:
            for status in self.diagnostics[start:]:
                values = {kv.key: kv.value for kv in status.values}
                if condition(values):
                    found.append(values)
                    return True
            return False

        wait_for(arrived, timeout_s)
        return found[0] if found else None

    def received(self) -> dict[str, list[bytes]]:
        """The nav messages received so far, as received (CDR), by topic."""
        return {topic: list(messages) for topic, messages in self.received_raw.items()}

    def close(self):
        self.executor.shutdown()
        self.node.destroy_node()
        rclpy.try_shutdown(context=self.context)
        self.thread.join(timeout=5.0)


def flatten(message, strings: list[str], numbers: list[float]) -> None:
    """Every string and every number of ``message``, depth first, in field order."""
    for name in message.get_fields_and_field_types():
        value = getattr(message, name)
        if hasattr(value, "get_fields_and_field_types"):
            flatten(value, strings, numbers)
        elif isinstance(value, str):
            strings.append(value)
        elif isinstance(value, (np.ndarray, array.array, list, tuple)):
            numbers.extend(float(x) for x in value)
        else:
            numbers.append(float(value))


def assert_same_messages(live_raw: dict[str, list[bytes]], offline: dict[str, list]) -> float:
    """Same count, stamps, strings and (to RELATIVE_TOLERANCE) numbers on every nav topic, the
    live messages as received (CDR); returns the largest relative difference seen.

    A topic whose live messages equal the offline ones field for field (the same arithmetic on
    the same numbers gives that; a NaN anywhere does not) holds all of these without the
    number-by-number comparison, which takes a second for the thousands of messages of a run."""
    largest = 0.0
    for topic in NAV_MSGTYPES:
        assert len(live_raw[topic]) == len(offline[topic]), topic
        live = [deserialize_message(raw, OUTPUT_CLASSES[topic]) for raw in live_raw[topic]]
        if live == offline[topic]:
            continue
        assert [stamp_ns(m) for m in live] == [stamp_ns(m) for m in offline[topic]], topic
        live_strings, live_numbers, offline_strings, offline_numbers = [], [], [], []
        for message in live:
            flatten(message, live_strings, live_numbers)
        for message in offline[topic]:
            flatten(message, offline_strings, offline_numbers)
        assert live_strings == offline_strings, topic
        live_values, offline_values = np.array(live_numbers), np.array(offline_numbers)
        np.testing.assert_allclose(
            live_values,
            offline_values,
            rtol=RELATIVE_TOLERANCE,
            atol=ABSOLUTE_TOLERANCE,
            equal_nan=True,
            err_msg=topic,
        )
        finite = np.isfinite(offline_values)
        difference = np.abs(live_values[finite] - offline_values[finite])
        scale = np.maximum(np.abs(offline_values[finite]), ABSOLUTE_TOLERANCE)
        largest = max(largest, float(np.max(difference / scale, initial=0.0)))
    return largest


def test_tf_is_broadcast_exactly_when_tf2_msgs_is_importable(monkeypatch):
    """The guarded import: absent here (PyPI wheels), present on a full install (a stand-in)."""
    monkeypatch.setitem(sys.modules, "tf2_msgs", None)
    monkeypatch.setitem(sys.modules, "tf2_msgs.msg", None)
    assert importlib.reload(fusion_node).TFMessage is None
    stand_in = types.ModuleType("tf2_msgs.msg")
    stand_in.TFMessage = type("TFMessage", (), {})
    monkeypatch.setitem(sys.modules, "tf2_msgs", types.ModuleType("tf2_msgs"))
    monkeypatch.setitem(sys.modules, "tf2_msgs.msg", stand_in)
    try:
        assert importlib.reload(fusion_node).TFMessage is stand_in.TFMessage
    finally:
        monkeypatch.undo()
        importlib.reload(fusion_node)


def solution_stamps_ns(outputs: dict[str, list]) -> np.ndarray:
    """Stamps (ns) of the odometry solutions of an offline run, in order."""
    return np.array([stamp_ns(m) for m in outputs[NAV_ODOMETRY_TOPIC]], dtype=np.int64)


def received_count(listener: Listener) -> int:
    return min(len(messages) for messages in listener.received_raw.values())


# off_axis (every lever arm, mounting angle and stamp offset unlike the shipped buoy's) is the
# stricter case; the shipped geometry's sea_state is a long run.
@pytest.mark.parametrize("name", [pytest.param("sea_state", marks=pytest.mark.long), "off_axis"])
def test_live_solutions_equal_offline_fusion(nodes, name):
    listener = Listener(nodes.env)
    try:
        # The node starts (seconds of imports and discovery) while the reference is computed.
        process = nodes.start(NODE, "--ros-args", *parameter_arguments(name))
        sensor_stream = sensor_stream_of(name)
        offline, engine, _ = offline_run(sensor_stream, name)
        n_solutions = len(offline[NAV_ODOMETRY_TOPIC])
        assert n_solutions > 0.6 * sum(topic == IMU_RAW_TOPIC for topic, _ in sensor_stream)
        assert_near_the_truth(offline, name, SETTLING_S)

        assert listener.wait_for_node(), nodes.log_of(process)
        listener.play(
            [(stamp_ns(m), topic, m) for topic, m in sensor_stream],
            solution_stamps_ns(offline),
        )
        wait_for(lambda: received_count(listener) >= n_solutions, 20.0)
        n_imu = sum(topic == IMU_RAW_TOPIC for topic, _ in sensor_stream)
        final = listener.latest_diagnostics_where(
            lambda values: values.get(f"messages_in[{IMU_RAW_TOPIC}]") == str(n_imu), 5.0
        )
        live = listener.received()
        statuses = list(listener.diagnostics)
        # SIGINT, as Ctrl-C would: the node stops while its messages are compared.
        process.send_signal(signal.SIGINT)
        largest_relative_difference = assert_same_messages(live, offline)
        assert process.wait(timeout=STOP_TIMEOUT_S) == 0, nodes.log_of(process)
    finally:
        listener.close()

    # The log says what the node fuses, when it aligned, and whether it broadcasts tf.
    log = nodes.log_of(process)
    assert f"fusing {IMU_RAW_TOPIC}, " in log
    first = offline[NAV_ODOMETRY_TOPIC][0].header.stamp
    assert f"aligned at stamp {first.sec + first.nanosec * 1e-9:.3f} s: roll " in log
    tf_line = "broadcasting map -> base_link on tf"
    assert (tf_line in log) == (fusion_node.TFMessage is not None), log
    assert (tf_line not in log) == ("tf2_msgs is not installed: map -> base_link" in log)
    static_line = "base_link -> imu_link, gnss_primary, gnss_secondary"
    assert (f"broadcasting {static_line} on tf_static" in log) == (tf_line in log), log
    assert (f"{static_line} is not broadcast on tf_static" in log) == (tf_line not in log), log

    print(f"{n_solutions} solutions, largest relative difference {largest_relative_difference:g}")

    assert final is not None, nodes.log_of(process)
    health = engine.health()
    assert final["aligned"] == "True"
    assert final["solutions_published"] == str(n_solutions)
    for kind, counters in health.counters.items():
        assert final[f"{kind}.accepted"] == str(counters.accepted), kind
        if kind != IMU:
            assert final[f"{kind}.used_for_alignment"] == str(counters.used_for_alignment), kind
    assert final["rejected_total"] == "0"
    # The filter's uncertainty and bias estimates, in the documented units, are those of the
    # offline engine fed the same messages.
    covariance, state = engine.covariance, engine.nav_state
    for k, axis in enumerate(("east", "north", "up")):
        assert float(final[f"attitude_sigma_deg[{axis}]"]) == pytest.approx(
            math.degrees(math.sqrt(covariance[k, k])), rel=1e-5
        )
        assert float(final[f"velocity_sigma_mps[{axis}]"]) == pytest.approx(
            math.sqrt(covariance[3 + k, 3 + k]), rel=1e-5
        )
    for k, axis in enumerate("xyz"):
        assert float(final[f"gyro_bias_deg_s[{axis}]"]) == pytest.approx(
            math.degrees(state.gyro_bias_rad_s[k]), rel=1e-5
        )
        assert float(final[f"accel_bias_mg[{axis}]"]) == pytest.approx(
            state.accel_bias_mps2[k] / 9.80665e-3, rel=1e-5
        )
    # Wall-clock times per diagnostics period: the IMU callback up to its publishing
    # ("latency") and the filtering after it.
    maxima = {"latency": [], "filtering": []}
    for status in statuses:
        values = {kv.key: kv.value for kv in status.values}
        if values["aligned"] != "True":
            assert status.level == DiagnosticStatus.WARN
        for name, period_maxima in maxima.items():
            mean_s, max_s = float(values[f"{name}_mean_s"]), float(values[f"{name}_max_s"])
            # A period without IMU callbacks (after the stream ended) has no times: NaN.
            if math.isfinite(mean_s):
                assert 0.0 < mean_s <= max_s
                period_maxima.append(max_s)
    assert all(maxima.values()), f"a time no diagnostics period reported: {maxima}"
    overdue = int(final["filtering_overdue"])
    print(
        f"IMU callback up to publishing: largest of the run {max(maxima['latency'])} s; "
        f"filtering after it: largest {max(maxima['filtering'])} s, overdue {overdue} times"
    )
    # The spin loop runs the filtering between IMU samples. Played at PLAY_RATE times real time
    # by a Python loop, some samples come in bursts and find it still undone, but were the spin
    # loop not to run it, every sample would.
    assert overdue < 0.5 * n_imu, f"{overdue} of {n_imu} IMU samples found the filtering undone"
    assert any(status.level == DiagnosticStatus.OK for status in statuses)


def malformed_messages(
    imu: Imu, fix: NavSatFix, velocity: TwistWithCovarianceStamped, heading: Imu
) -> list[tuple]:
    """(topic, message, expected engine kind, expected reason) of bad messages derived from good
    ones: the IMU ones follow ``imu`` on its topic (so that its stamp is the newest), the others
    carry stamps between the good measurements'."""
    bad = []

    def variant(message, topic, kind, reason, time_ns=None):
        copied = copy.deepcopy(message)
        if time_ns is not None:
            set_stamp_ns(copied, time_ns)
        bad.append((topic, copied, kind, reason))
        return copied

    imu_ns, step_ns = stamp_ns(imu), 1_000_000
    variant(
        imu, IMU_RAW_TOPIC, IMU, Reason.NON_FINITE, imu_ns + step_ns
    ).angular_velocity.y = math.nan
    variant(
        imu, IMU_RAW_TOPIC, IMU, Reason.NON_FINITE, imu_ns + 2 * step_ns
    ).linear_acceleration.z = math.inf
    variant(
        imu, IMU_RAW_TOPIC, IMU, Reason.OUT_OF_RANGE, imu_ns + 3 * step_ns
    ).linear_acceleration.x = 1.0e4
    # Plausible values, so that they would visibly change the state were they used.
    backwards = variant(
        imu,
        IMU_RAW_TOPIC,
        IMU,
        Reason.STAMP_NOT_INCREASING,
        imu_ns - 500 * step_ns,
    )
    backwards.angular_velocity.z += 0.5
    duplicate = variant(imu, IMU_RAW_TOPIC, IMU, Reason.DUPLICATE_STAMP)
    duplicate.angular_velocity.z += 0.5
    duplicate.linear_acceleration.x += 2.0

    between_ns = stamp_ns(heading) + 50 * step_ns
    zero = variant(
        heading, GNSS_HEADING_TOPIC, GnssHeadingSource.kind, Reason.ZERO_QUATERNION, between_ns
    )
    zero.orientation.x = zero.orientation.y = zero.orientation.z = zero.orientation.w = 0.0
    negative = variant(
        heading,
        GNSS_HEADING_TOPIC,
        GnssHeadingSource.kind,
        Reason.NON_POSITIVE_VARIANCE,
        between_ns,
    )
    negative.orientation.z, negative.orientation.w = math.sin(0.5), math.cos(0.5)
    negative.orientation_covariance[8] = -1.0e-4
    variant(
        fix, GNSS_FIX_TOPIC, GnssFixSource.kind, Reason.NON_FINITE, between_ns
    ).latitude = math.nan
    variant(
        velocity,
        GNSS_VELOCITY_TOPIC,
        GnssVelocitySource.kind,
        Reason.NON_FINITE,
        between_ns,
    ).twist.twist.linear.x = math.inf
    no_fix = variant(fix, GNSS_FIX_TOPIC, GnssFixSource.kind, Reason.NO_FIX, between_ns)
    no_fix.status.status = -1
    no_fix.latitude += 1.0e-3
    return bad


def with_malformed_messages(good: list) -> tuple[list, list]:
    """(pace stamp ns, topic, message) rows of the ``good`` (topic, message) in order, with the
    :func:`malformed_messages` right after the first IMU sample from MALFORMED_AFTER_S on, at its
    pace; and those bad ones."""
    first_ns = stamp_ns(good[0][1])
    after_ns = first_ns + round(MALFORMED_AFTER_S * 1e9)
    imu_index = next(
        i for i, (topic, m) in enumerate(good) if topic == IMU_RAW_TOPIC and stamp_ns(m) >= after_ns
    )
    imu_ns = stamp_ns(good[imu_index][1])
    latest = {}
    for topic, m in good:
        if topic != IMU_RAW_TOPIC and stamp_ns(m) > imu_ns and topic not in latest:
            latest[topic] = m
    bad = malformed_messages(
        good[imu_index][1],
        latest[GNSS_FIX_TOPIC],
        latest[GNSS_VELOCITY_TOPIC],
        latest[GNSS_HEADING_TOPIC],
    )
    paced = []
    for index, (topic, m) in enumerate(good):
        paced.append((stamp_ns(m), topic, m))
        if index == imu_index:
            paced.extend((stamp_ns(m), bad_topic, message) for bad_topic, message, _, _ in bad)
    return paced, bad


def test_malformed_input_is_counted_and_never_reaches_the_state(nodes):
    listener = Listener(nodes.env)
    try:
        # The node starts (seconds of imports and discovery) while the reference is computed.
        process = nodes.start(NODE, "--ros-args", *parameter_arguments("sea_state"))
        sensor_stream = sensor_stream_of("sea_state")
        first_ns = stamp_ns(sensor_stream[0][1])
        good = [
            (topic, m)
            for topic, m in sensor_stream
            if stamp_ns(m) - first_ns <= MALFORMED_RUN_S * 1e9
        ]
        paced, bad = with_malformed_messages(good)
        reference, engine, _ = offline_run(good)
        assert_near_the_truth(reference, "sea_state", 0.0)
        n_solutions = len(reference[NAV_ODOMETRY_TOPIC])
        last_bad_ns = max(stamp_ns(message) for _, message, _, _ in bad)
        assert sum(stamp_ns(m) > last_bad_ns for m in reference[NAV_ODOMETRY_TOPIC]) > 100

        assert listener.wait_for_node(), nodes.log_of(process)
        listener.play(paced, solution_stamps_ns(reference), held_rate=HELD_PLAY_RATE)
        wait_for(lambda: received_count(listener) >= n_solutions, 20.0)
        n_imu = sum(topic == IMU_RAW_TOPIC for _, topic, _ in paced)
        final = listener.latest_diagnostics_where(
            lambda values: values.get(f"messages_in[{IMU_RAW_TOPIC}]") == str(n_imu), 5.0
        )
        live = listener.received()
        assert process.poll() is None, nodes.log_of(process)
        # SIGINT, as Ctrl-C would: the node stops while its messages are compared.
        process.send_signal(signal.SIGINT)
        assert_same_messages(live, reference)
        assert process.wait(timeout=STOP_TIMEOUT_S) == 0, nodes.log_of(process)
    finally:
        listener.close()

    assert final is not None, nodes.log_of(process)
    expected_node = {}
    expected_engine = {}
    for topic, _, kind, reason in bad:
        key = f"rejected[{topic}: {reason}]"
        expected_node[key] = expected_node.get(key, 0) + 1
        key = f"{kind}.rejected[{reason}]"
        expected_engine[key] = expected_engine.get(key, 0) + 1
    node_rejections = {k: int(v) for k, v in final.items() if k.startswith("rejected[")}
    assert node_rejections == expected_node
    assert final["rejected_total"] == str(len(bad))
    engine_rejections = {k: int(v) for k, v in final.items() if ".rejected[" in k}
    assert engine_rejections == expected_engine
    for kind, counters in engine.health().counters.items():
        assert final[f"{kind}.accepted"] == str(counters.accepted), kind
    assert final["solutions_published"] == str(n_solutions)


def test_delayed_output_is_flushed_at_sigint(nodes):
    listener = Listener(nodes.env)
    try:
        # The node starts (seconds of imports and discovery) while the reference is computed.
        process = nodes.start(
            NODE,
            "--ros-args",
            *parameter_arguments("sea_state"),
            "-p",
            "fusion.realtime_output:=false",
        )
        sensor_stream = sensor_stream_of("sea_state")
        first_ns = stamp_ns(sensor_stream[0][1])
        stream = [
            (topic, m) for topic, m in sensor_stream if stamp_ns(m) - first_ns <= FLUSH_RUN_S * 1e9
        ]
        reference, engine, stamps = offline_run(stream, **{"fusion.realtime_output": False})
        n_before_end = len(reference[NAV_ODOMETRY_TOPIC])
        nav_messages(engine.flush(), reference, stamps)
        assert_near_the_truth(reference, "sea_state", 0.0)
        n_solutions = len(reference[NAV_ODOMETRY_TOPIC])
        # The last max_measurement_delay_s of IMU samples wait for measurements until the end.
        assert n_solutions - n_before_end > 10

        assert listener.wait_for_node(), nodes.log_of(process)
        listener.play([(stamp_ns(m), topic, m) for topic, m in stream])
        n_imu = sum(topic == IMU_RAW_TOPIC for topic, _ in stream)
        assert listener.latest_diagnostics_where(
            lambda values: values.get(f"messages_in[{IMU_RAW_TOPIC}]") == str(n_imu), 5.0
        ), nodes.log_of(process)
        wait_for(lambda: received_count(listener) >= n_before_end, 10.0)
        n_before_interrupt = received_count(listener)
        assert nodes.interrupt(process) == 0, nodes.log_of(process)
        wait_for(lambda: received_count(listener) >= n_solutions, 10.0)
        live = listener.received()
    finally:
        listener.close()

    assert n_before_interrupt == n_before_end
    assert_same_messages(live, reference)


@pytest.mark.parametrize(
    ("override", "parameter"),
    [
        ("gnss.secondary_antenna:=[-0.75,0.0,1.0]", "gnss.secondary_antenna"),
        ("fusion.gate_probability:=2.0", "fusion.gate_probability"),
        ("fusion.accel_noise_mps_sqrt_h:=-0.05", "fusion.accel_noise_mps_sqrt_h"),
    ],
)
def test_bad_parameter_stops_the_node_naming_it(nodes, override, parameter):
    result = nodes.run(
        NODE, "--ros-args", *parameter_arguments("sea_state"), "-p", override, timeout_s=30.0
    )
    assert result.returncode == 2, result.stdout + result.stderr
    assert parameter in result.stderr
    assert len(result.stderr.strip().splitlines()) == 1, result.stderr


# Sensor sets beyond RTK, simulated: (scenario, simulator overrides, fusion parameter lines).
CALIBRATED_MAGNETOMETER = (
    f"    fusion.magnetometer_hard_iron_t: {[h * 1e-6 for h in HARD_IRON_UT]}",
    "    fusion.magnetometer_soft_iron: "
    f"{np.linalg.inv(np.reshape(SOFT_IRON, (3, 3))).ravel().tolist()}",
)
LIVE_SENSOR_SETS = {
    "moored_magnetometer_and_motion_pack": (
        "moored_motion_pack",
        (),
        ("    fusion.moored: true", "    fusion.ahrs_lag_s: 0.2", *CALIBRATED_MAGNETOMETER),
        "d: motion pack + magnetometer",
    ),
    "single_antenna_magnetometer_outage": (
        "sea_state",
        (
            "sensors.gnss.receiver=single_antenna",
            *MAGNETOMETER,
            "sensors.gnss.fix_outages_s=[[25, 35]]",
        ),
        CALIBRATED_MAGNETOMETER,
        "b: single-antenna GNSS + magnetometer",
    ),
    # A steel hull beside the moored buoy from 25 s on, after the alignment (which takes the
    # levelling's 10 s and then 10 s of fields judged whole): the magnetometer keeps failing its
    # gate and is suspended; the heading is carried by the gyros.
    "moored_magnetometer_suspended": (
        "moored_motion_pack",
        ("sensors.magnetometer.disturbances_s=[[25, 40]]", "sensors.ahrs.fitted=false"),
        ("    fusion.moored: true", *CALIBRATED_MAGNETOMETER),
        "inertial only",
    ),
}


@pytest.mark.parametrize("set_name", LIVE_SENSOR_SETS)
def test_live_sensor_sets_equal_offline_fusion(nodes, tmp_path, set_name):
    """Fed only what the set carries (no heading topic; a magnetometer, a motion pack), the
    node publishes exactly the offline solutions, names the set in its diagnostics and counts
    what it accepted and suspended as the engine does; the solutions hold the attitude within
    1° of the truth."""
    scenario_name, overrides, lines, final_set = LIVE_SENSOR_SETS[set_name]
    scenario = load_scenario(scenario_name, [*overrides, f"duration_s={LIVE_EQUALS_OFFLINE_S}"])
    parameters = tmp_path / "sensor_set.yaml"
    site = (
        f"    site.latitude_deg: {scenario.origin_latitude_deg}",
        f"    site.longitude_deg: {scenario.origin_longitude_deg}",
        "    ahrs.yaw_reference: magnetic_north",
    )
    parameters.write_text("/**:\n  ros__parameters:\n" + "\n".join([*site, *lines]) + "\n")
    files = [*CASES["sea_state"].buoy_parameter_files, parameters]

    listener = Listener(nodes.env)
    try:
        arguments = [a for path in files for a in ("--params-file", str(path))]
        # The node starts (seconds of imports and discovery) while the reference is computed.
        process = nodes.start(NODE, "--ros-args", *arguments)
        truth = TruthModel(scenario)
        streams = [STREAMS[kind].build(scenario, truth, {}) for kind in ("imu", "gnss")]
        stream = [
            (topic, message)
            for topic, _, message in merged_messages(streams, LIVE_EQUALS_OFFLINE_S)
            if topic in FUSION_INPUT_MSGTYPES
        ]
        engine = FusionEngine(config_from_files(files))
        offline = {topic: [] for topic in NAV_MSGTYPES}
        stamps = StampBook()
        solutions = []
        for topic, message in stream:
            new = feed_message(engine, topic, message, stamps)[0]
            solutions += new
            nav_messages(new, offline, stamps)
        times = np.array([s.t_s for s in solutions]) - scenario.start_time_ns * 1e-9
        errors = euler_errors_deg(solutions, truth, times)
        assert np.abs(errors[times >= 20.0]).max() < 1.0
        assert engine.health().sensor_set == final_set

        assert listener.wait_for_node(), nodes.log_of(process)
        assert {topic for topic, _ in stream} <= set(listener.node_inputs())
        listener.play(
            [(stamp_ns(m), topic, m) for topic, m in stream],
            solution_stamps_ns(offline),
            held_rate=HELD_PLAY_RATE,
        )
        n_solutions = len(offline[NAV_ODOMETRY_TOPIC])
        wait_for(lambda: received_count(listener) >= n_solutions, 20.0)
        n_imu = sum(topic == IMU_RAW_TOPIC for topic, _ in stream)
        final = listener.latest_diagnostics_where(
            lambda values: values.get(f"messages_in[{IMU_RAW_TOPIC}]") == str(n_imu), 5.0
        )
        live = listener.received()
        # SIGINT, as Ctrl-C would: the node stops while its messages are compared.
        process.send_signal(signal.SIGINT)
        assert_same_messages(live, offline)
        assert process.wait(timeout=STOP_TIMEOUT_S) == 0, nodes.log_of(process)
    finally:
        listener.close()
    assert final is not None, nodes.log_of(process)
    assert final["sensor_set"] == final_set
    for kind, counters in engine.health().counters.items():
        assert final[f"{kind}.accepted"] == str(counters.accepted), kind
    for kind, status in engine.health().source_health.items():
        assert final[f"{kind}.suspended"] == str(status.suspended), kind
        assert final[f"{kind}.suspensions"] == str(status.suspensions), kind
    if set_name == "moored_magnetometer_suspended":
        assert final["magnetometer.suspended"] == "True"
        assert "failed the gate" in final["magnetometer.suspension_reason"]
