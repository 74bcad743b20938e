"""A bag replayed over DDS to ``fusion_node`` and a correction node (``compensation_node`` or
``current_node``), their outputs recorded.

The one live replay of the system tests (the live-equals-offline tests, the live half of the
fault matrix and the real record's): ``bag_player`` plays the sensor topics at :data:`RATE`
times their pace (or at the rate asked), ``bag_recorder`` records ``nav/odometry`` and the
correction's output (``wind/true`` or ``current/velocity``), and the nodes are interrupted once
the recorder has what ``process_bag`` wrote for the same bag. The nodes decide on header stamps
only, so message timing over DDS must not matter, given a latency budget the replay stays
within; the correction node publishes the samples that still wait for navigation when it is
interrupted, as ``process_bag`` does at the end of its data.
"""

from __future__ import annotations

import contextlib
import os
import signal
import subprocess
import threading
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import rclpy
from diagnostic_msgs.msg import DiagnosticArray
from rclpy.context import Context
from rclpy.executors import SingleThreadedExecutor

from against_truth import (
    Truth,
    assert_navigation_within_limits,
    assert_wind_within_budget,
    odometry_errors,
)
from buoy_common.bag_io import BagReader
from buoy_nav.config import fusion_config_from_files
from buoy_processing.bag_processing import process_bag
from processed_bags import CASES
from ros_messages import stamp_ns, wait_for
from wind_comp.config import compensator_config_from_files, current_config_from_files

# Twice the pace: the Python nodes, the player and the recorder then need about a core; at 4x
# a busy 2-core machine starves them long enough for the 1000-deep reliable queues to overflow.
RATE = 2.0
# compensation_node and current_node give up on a sample whose navigation is this late (in
# stamps and in wall time): a live-only latency budget that process_bag does not have. Their
# defaults (1 s, 5 s) are exceeded by a fusion_node starved of CPU for that long; the tests are
# about equal numbers, so the budget is longer than any replay.
LATENCY_BUDGET_S = 120.0
STARTUP_TIMEOUT_S = 30.0
# After the player has finished: the nodes' queues drain in well under this.
DRAIN_TIMEOUT_S = 30.0
FLUSH_TIMEOUT_S = 10.0
# From SIGINT to a node's exit (NodeProcesses.interrupt's bound).
STOP_TIMEOUT_S = 15.0
NAVIGATION_TOPICS = ("/imu/data_raw", "/gnss/fix", "/gnss/vel", "/gnss/heading", "/gnss/baseline")
"""The inputs of ``fusion_node``."""
# The navigation is judged against the truth from this long after its first solution: the
# first seconds after the alignment carry its errors, which the limits are not about.
SETTLING_S = 20.0


def flux_window_parameters(folder: Path, window_s: float) -> Path:
    """A parameter file in ``folder`` that sets the flux window to ``window_s`` seconds."""
    path = folder / "flux_window.yaml"
    path.write_text(
        f"/**:\n  ros__parameters:\n    compensation:\n      flux_window_s: {window_s}\n"
    )
    return path


def process_offline(played: Path, offline: Path, parameter_files, current: bool = False):
    """``process_bag`` of ``played`` into ``offline`` with the parameters the live nodes get
    (the current too, when ``current``); returns its summary."""
    return process_bag(
        played,
        offline,
        fusion_config_from_files(parameter_files),
        compensator_config_from_files(parameter_files),
        current_config=current_config_from_files(parameter_files) if current else None,
    )


@dataclass(frozen=True)
class Correction:
    """One of the corrections a replay runs: its node, input, output, latency budget and the
    key of its diagnostics that counts the input samples it has taken."""

    node: str
    input_topic: str
    output_topic: str
    timeout_parameter: str
    samples_in_key: str

    @property
    def sensor_topics(self) -> tuple[str, ...]:
        """What a replay plays: the navigation's inputs and the correction's."""
        return (*NAVIGATION_TOPICS, f"/{self.input_topic}")


WIND = Correction(
    "compensation_node",
    "anemometer/wind",
    "wind/true",
    "compensation.nav_timeout_s",
    "wind_samples_in",
)
CURRENT = Correction(
    "current_node",
    "dvl/velocity",
    "current/velocity",
    "current.nav_timeout_s",
    "dvl_samples_in",
)
SENSOR_TOPICS = WIND.sensor_topics
"""The inputs of ``fusion_node`` and ``compensation_node``."""


class DiagnosticsWatcher:
    """The latest ``diagnostics`` values of each node, to know when the nodes are done (an
    in-process participant in the test's isolated domain; it takes none of the 100 Hz data)."""

    def __init__(self, env: dict[str, str]):
        self._saved = {
            name: os.environ.get(name)
            for name in ("ROS_DOMAIN_ID", "ROS_AUTOMATIC_DISCOVERY_RANGE")
        }
        for name in self._saved:
            os.environ[name] = env[name]
        self.context = Context()
        rclpy.init(context=self.context)
        self.node = rclpy.create_node("live_replay_test", context=self.context)
        self.latest: dict[str, dict[str, str]] = {}
        self.node.create_subscription(DiagnosticArray, "diagnostics", self._on_diagnostics, 50)
        self.executor = SingleThreadedExecutor(context=self.context)
        self.executor.add_node(self.node)
        self.thread = threading.Thread(target=self.executor.spin, daemon=True)
        self.thread.start()

    def _on_diagnostics(self, message: DiagnosticArray) -> None:
        for status in message.status:
            self.latest[status.name.lstrip("/")] = {kv.key: kv.value for kv in status.values}

    def value(self, node: str, key: str) -> int:
        return int(self.latest.get(node, {}).get(key, 0))

    def close(self) -> None:
        self.executor.shutdown()
        self.node.destroy_node()
        rclpy.try_shutdown(context=self.context)
        self.thread.join(timeout=5.0)
        for name, value in self._saved.items():
            if value is None:
                os.environ.pop(name, None)
            else:
                os.environ[name] = value


def vector_arrays(bag: Path, topic: str) -> tuple[np.ndarray, np.ndarray]:
    """Stamps (ns) and vectors of a Vector3Stamped topic."""
    with BagReader(bag) as reader:
        messages = [reader.decode(r) for r in reader.messages([topic])]
    return (
        np.array([stamp_ns(m) for m in messages]),
        np.array([[m.vector.x, m.vector.y, m.vector.z] for m in messages]),
    )


def odometry_arrays(bag: Path) -> tuple[np.ndarray, np.ndarray]:
    """Stamps and every number of nav/odometry: position, orientation, pose covariance, twist
    and its covariance."""
    with BagReader(bag) as reader:
        messages = [reader.decode(r) for r in reader.messages(["nav/odometry"])]
    rows = []
    for m in messages:
        p, q = m.pose.pose.position, m.pose.pose.orientation
        v, w = m.twist.twist.linear, m.twist.twist.angular
        rows.append(
            [
                *(p.x, p.y, p.z, q.x, q.y, q.z, q.w),
                *m.pose.covariance,
                *(v.x, v.y, v.z, w.x, w.y, w.z),
                *m.twist.covariance,
            ]
        )
    return np.array([stamp_ns(m) for m in messages]), np.array(rows)


def stop_together(nodes, processes) -> None:
    """SIGINT to each of ``processes`` at once, as Ctrl-C would; each must exit with 0."""
    for process in processes:
        process.send_signal(signal.SIGINT)
    for process in processes:
        try:
            code = process.wait(timeout=STOP_TIMEOUT_S)
        except subprocess.TimeoutExpired:
            process.kill()
            process.wait()
            raise
        assert code == 0, nodes.log_of(process)


def replay(
    nodes,
    played: Path,
    parameter_files,
    offline: Path,
    recorded: Path,
    topics: tuple[str, ...] = (),
    correction: Correction = WIND,
    also_recorded: tuple[str, ...] = (),
    rate: float = RATE,
) -> str:
    """Replay ``played`` (its ``topics``, default all) to ``fusion_node`` and the
    ``correction``'s node started with ``parameter_files``, record their outputs to
    ``recorded``, and return a line of figures for the assertion messages. ``offline`` is
    ``process_bag``'s output for the same bag: the replay waits until the recorder holds as
    many messages. ``also_recorded``: further output topics to record; ``rate``: the pace, in
    times the bag's (a bag of fewer messages a second than the simulated ones can go faster).
    """
    with started_pipeline(nodes, parameter_files, recorded, correction, also_recorded) as pipeline:
        return pipeline.replay(played, offline, topics, rate)


@contextlib.contextmanager
def started_pipeline(
    nodes,
    parameter_files,
    recorded: Path,
    correction: Correction = WIND,
    also_recorded: tuple[str, ...] = (),
):
    """``fusion_node`` and the ``correction``'s node started with ``parameter_files``, and
    ``bag_recorder`` recording their outputs (and ``also_recorded``) to ``recorded``: a
    :class:`LivePipeline` whose :meth:`~LivePipeline.replay` plays a bag through them. A test
    starts them before it writes the bag and runs ``process_bag``, which they start up during."""
    pipeline = LivePipeline(nodes, parameter_files, recorded, correction, also_recorded)
    try:
        yield pipeline
    finally:
        pipeline.watcher.close()


class LivePipeline:
    """The nodes of :func:`started_pipeline` and the watcher of their diagnostics."""

    def __init__(self, nodes, parameter_files, recorded: Path, correction, also_recorded):
        self.nodes = nodes
        self.correction = correction
        self.recorded_topics = ("nav/odometry", correction.output_topic, *also_recorded)
        parameters = (
            "--ros-args",
            *(a for path in parameter_files for a in ("--params-file", str(path))),
        )
        self.watcher = DiagnosticsWatcher(nodes.env)
        self.fusion = nodes.start("fusion_node", *parameters)
        self.correction_node = nodes.start(
            correction.node,
            *parameters,
            "-p",
            f"{correction.timeout_parameter}:={LATENCY_BUDGET_S}",
        )
        self.recorder = nodes.start(
            "bag_recorder", str(recorded), "--topics", *self.recorded_topics
        )

    def _recorded_count(self, topic: str) -> int:
        return self.watcher.value("bag_recorder", f"count[/{topic}]")

    def replay(
        self, played: Path, offline: Path, topics: tuple[str, ...] = (), rate: float = RATE
    ) -> str:
        """Play ``played`` through the nodes and stop them once the recorder holds what
        ``process_bag`` wrote to ``offline``: :func:`replay`."""
        nodes, correction = self.nodes, self.correction
        fusion, compensation, recorder = self.fusion, self.correction_node, self.recorder
        offline_nav_ns, _ = odometry_arrays(offline)
        offline_out_ns, _ = vector_arrays(offline, correction.output_topic)
        with BagReader(played) as reader:
            n_inputs = next(
                info.count
                for name, info in reader.topics.items()
                if name.lstrip("/") == correction.input_topic
            )
            duration_s = reader.duration_s
        # samples after the last navigation wait for it until the node is interrupted
        n_held_back = int(np.count_nonzero(offline_out_ns > offline_nav_ns[-1]))
        assert wait_for(
            lambda: all(
                f"recording /{topic} (" in nodes.log_of(recorder) for topic in self.recorded_topics
            ),
            STARTUP_TIMEOUT_S,
        ), nodes.log_of(recorder) + nodes.log_of(fusion) + nodes.log_of(compensation)

        started = time.monotonic()
        player = nodes.run(
            "bag_player",
            str(played),
            "--rate",
            str(rate),
            *(("--topics", *topics) if topics else ()),
            "--wait-for-subscribers",
            "1",
            timeout_s=STARTUP_TIMEOUT_S + duration_s / rate * 3,
        )
        played_wall_s = time.monotonic() - started
        assert player.returncode == 0, player.stderr

        # Drained: the recorder holds what process_bag wrote but the samples that wait for
        # navigation, and the correction node has taken every sample (those too).
        drained = wait_for(
            lambda: (
                self._recorded_count("nav/odometry") >= offline_nav_ns.size
                and self._recorded_count(correction.output_topic) >= n_inputs - n_held_back
                and self.watcher.value(correction.node, correction.samples_in_key) >= n_inputs
            ),
            DRAIN_TIMEOUT_S,
        )
        compensation_before_interrupt = dict(self.watcher.latest.get(correction.node, {}))
        if drained:
            # The recorder holds every solution process_bag made, so fusion_node has none left
            # to publish at SIGINT, and the correction node has taken every sample: both stop
            # together.
            stop_together(nodes, (fusion, compensation))
        else:
            # Upstream first: the correction node takes what fusion_node publishes at SIGINT.
            stop_together(nodes, (fusion,))
            stop_together(nodes, (compensation,))
        wait_for(lambda: self._recorded_count(correction.output_topic) >= n_inputs, FLUSH_TIMEOUT_S)
        assert nodes.interrupt(recorder) == 0, nodes.log_of(recorder)
        live_invalid_reasons = {
            key: value
            for key, value in compensation_before_interrupt.items()
            if key.startswith("invalid[") and value != "0"
        }
        return (
            f"played {duration_s:.0f} s at {rate:g}x in {played_wall_s:.1f} s (drained: "
            f"{drained}); {correction.node} before SIGINT: nav samples in "
            f"{compensation_before_interrupt.get('nav_samples_in')}, {live_invalid_reasons}; "
            f"offline: {offline_nav_ns.size} nav/odometry, {n_inputs} {correction.output_topic} "
            f"of which {n_held_back} wait for navigation"
        )


EQUAL_TO = 1e-9  # m/s, rad, m: the same arithmetic on the same numbers


def differences_from_offline(
    recorded: Path, offline: Path, correction: Correction = WIND
) -> list[str]:
    """How the live outputs differ from ``process_bag``'s: nothing when every output of the
    ``correction`` and every ``nav/odometry`` has the same stamp, the same NaNs and the same
    numbers."""
    topic = correction.output_topic
    offline_nav_ns, offline_nav = odometry_arrays(offline)
    offline_out_ns, offline_out = vector_arrays(offline, topic)
    live_nav_ns, live_nav = odometry_arrays(recorded)
    live_out_ns, live_out = vector_arrays(recorded, topic)
    if not np.array_equal(live_out_ns, offline_out_ns):
        return [f"{live_out_ns.size} {topic} live, {offline_out_ns.size} offline, or stamps differ"]
    differences = []
    live_invalid, offline_invalid = np.isnan(live_out), np.isnan(offline_out)
    differently_invalid = np.flatnonzero((live_invalid != offline_invalid).any(axis=1))
    if differently_invalid.size:
        first_s = [(offline_out_ns[i] - offline_nav_ns[0]) * 1e-9 for i in differently_invalid[:5]]
        differences.append(
            f"{differently_invalid.size} {topic} samples NaN in one run only, the first at "
            f"{np.round(first_s, 2).tolist()} s from the first solution"
        )
    else:
        valid = ~offline_invalid.any(axis=1)
        if valid.any():
            difference = float(np.max(np.abs(live_out[valid] - offline_out[valid])))
            if difference > EQUAL_TO:
                differences.append(f"max |live - offline| {topic} {difference:.3g} m/s")
    if not np.array_equal(live_nav_ns, offline_nav_ns):
        differences.append(
            f"{live_nav_ns.size} nav/odometry live, {offline_nav_ns.size} offline, or stamps differ"
        )
    else:
        nav_difference = float(np.max(np.abs(live_nav - offline_nav)))
        if not nav_difference <= EQUAL_TO:  # NaN included
            differences.append(f"max |live - offline| nav/odometry {nav_difference:.3g}")
    return differences


def assert_offline_run_is_near_the_truth(
    name: str, played: Path, offline: Path, label: str, until_ns: int | None = None
) -> None:
    """The offline wind of a replayed stretch of the committed bag ``name`` within the wind
    budget, its navigation within the limits (up to stamp ``until_ns``, if given)."""
    case = CASES[name]
    truth = Truth(case.bag_path)
    wind_ns, wind = vector_arrays(offline, "wind/true")
    _, measured = vector_arrays(played, "anemometer/wind")
    print(
        assert_wind_within_budget(
            truth.wind_errors(wind_ns, wind), measured, case.anemometer_position_body_m, label
        )
    )
    with BagReader(offline) as reader:
        odometry = [reader.decode(r) for r in reader.messages(["nav/odometry"])]
    if until_ns is not None:
        odometry = [m for m in odometry if stamp_ns(m) < until_ns]
    errors = odometry_errors(truth, odometry, SETTLING_S)
    print(assert_navigation_within_limits(errors, case.navigation_limits(), label))
