"""Live latency and CPU of the nodes: the last part of `make bench`, also runnable alone.

Runs ``run_scenario sea_state --fusion --compensation`` in a ROS domain of its own and, in this
process, an rclpy node listening to ``imu/data_raw``, ``nav/imu``, ``anemometer/wind`` and
``wind/true``. Latency of a stage is the receive time of its output minus the receive time of
the input with the same header stamp (receive times from the middleware's reception stamp when
it gives one), over all pairs and "in service" (without the first second of output, when a
just-aligned filter releases its held-back solutions at once); the same difference of the
publishers' source stamps is given beside it. The simulated sensors and clock run at niceness
``SIMULATOR_NICENESS``, the nodes under test at the default. The CPU shares of ``fusion_node``
and ``compensation_node`` come from /proc/<pid>/stat (utime + stime) while their input streams
flow.

With ``--passthrough`` the two nodes are replaced by ``tools/passthrough_node.py``, stand-ins
that compute nothing: the same run then measures the floor that the middleware, the Python
executor and this machine set on the same path.

    python -m tools.bench_live [--duration-s 40] [--passthrough]
"""

from __future__ import annotations

import argparse
import json
import math
import os
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

import numpy as np

from buoy_common import cdr
from tools.ros_domains import claim_domain, isolated_environment, release_domain

REPO = Path(__file__).resolve().parents[1]
BIN = Path(sys.executable).parent
PARAMS_FILE = REPO / "src/buoy_common/config/buoy.yaml"
NODES_UNDER_TEST = ("fusion_node", "compensation_node")
LATENCY_TARGET_P99_MS = 5.0
CPU_SAMPLE_PERIOD_S = 0.25
FIND_PID_TIMEOUT_S = 30.0
# The nodes whose CPU is measured: (the output that shows it works, the input that drives it).
CPU_MEASURED = {
    "fusion_node": ("nav/imu", "imu/data_raw"),
    "compensation_node": ("wind/true", "anemometer/wind"),
}
# The simulated sensors and clock stand in for hardware and its drivers; on this machine they are
# five Python processes sharing two cores with the nodes under test, so they run at a lower
# priority, as a buoy computer would run its processing nodes above housekeeping.
SIMULATOR_PROCESSES = (
    "truth_node",
    "imu_sim_node",
    "gnss_sim_node",
    "anemometer_sim_node",
    "sim_clock_node",
)
SIMULATOR_NICENESS = 10
RUN_MARGIN_S = 90.0
IN_SERVICE_AFTER_S = 1.0
# CDR of a message that starts with a std_msgs/Header, after the 4-byte encapsulation header.


def isolate_ros_domain() -> int:
    """A domain of the live benchmark's range (tools/ros_domains.py) no other run holds,
    discovery on loopback only; set for this process and its children (rclpy reads the
    environment at init)."""
    domain = claim_domain("bench_live")
    isolated_environment(domain, os.environ)
    os.environ.setdefault("AMENT_PREFIX_PATH", str(BIN.parent))
    os.environ["PYTHONUNBUFFERED"] = "1"
    return domain


class Listener:
    """Receive times (ns) per topic and header stamp, in an rclpy context of its own."""

    def __init__(self):
        import rclpy
        from geometry_msgs.msg import Vector3Stamped
        from rclpy.context import Context
        from rclpy.executors import SingleThreadedExecutor
        from sensor_msgs.msg import Imu

        from buoy_common.base_node import DATA_QOS

        self._rclpy = rclpy
        self.context = Context()
        rclpy.init(context=self.context)
        self.node = rclpy.create_node("bench_latency", context=self.context)
        # topic → header stamp (sec, nanosec) → (receive time, source time), ns
        self.received: dict[str, dict[tuple[int, int], tuple[int, int]]] = {}
        self.first_callback_ns: dict[str, int] = {}
        self.last_callback_ns: dict[str, int] = {}
        self.valid_true_wind: set[tuple[int, int]] = set()
        self.middleware_stamps = 0
        self.callback_stamps = 0
        types = {
            "imu/data_raw": Imu,
            "nav/imu": Imu,
            "anemometer/wind": Vector3Stamped,
            "wind/true": Vector3Stamped,
        }
        # Raw: the stamps are read from the CDR bytes, so this process's own load (which
        # delays nothing it measures, but competes for the cores) stays small.
        for topic, message_type in types.items():
            self.received[topic] = {}
            self.node.create_subscription(
                message_type, topic, self._callback_for(topic), DATA_QOS, raw=True
            )
        self.executor = SingleThreadedExecutor(context=self.context)
        self.executor.add_node(self.node)
        self.thread = threading.Thread(target=self.executor.spin, daemon=True)
        self.thread.start()

    def _callback_for(self, topic: str):
        table = self.received[topic]

        def on_message(message, info) -> None:
            now_ns = time.time_ns()
            # The middleware's reception stamp (system clock) excludes the time the sample
            # waited in this process's executor; the callback time is the fallback. The source
            # stamp is when the publishing process wrote the sample.
            received_ns = info.get("received_timestamp", 0)
            if received_ns > 0:
                self.middleware_stamps += 1
            else:
                received_ns = now_ns
                self.callback_stamps += 1
            key = cdr.read_stamp(message)
            table.setdefault(key, (received_ns, info.get("source_timestamp", 0)))
            if topic == "wind/true" and math.isfinite(cdr.read_vector3_stamped(message)[3][0]):
                self.valid_true_wind.add(key)
            self.first_callback_ns.setdefault(topic, time.monotonic_ns())
            self.last_callback_ns[topic] = time.monotonic_ns()

        return on_message

    def close(self) -> None:
        self.executor.shutdown()
        self.node.destroy_node()
        self._rclpy.try_shutdown(context=self.context)
        self.thread.join(timeout=5.0)


class CpuSampler:
    """utime + stime of a process (clock ticks), sampled with monotonic times in a thread."""

    def __init__(self, pid: int):
        self.pid = pid
        self.samples: list[tuple[int, int]] = []
        self._stop = threading.Event()
        self.thread = threading.Thread(target=self._run, daemon=True)
        self.thread.start()

    def _ticks(self) -> int | None:
        try:
            text = Path(f"/proc/{self.pid}/stat").read_text()
        except OSError:
            return None
        # Fields after the command name (which may contain spaces) start at field 3 (state);
        # utime and stime are fields 14 and 15.
        fields = text[text.rindex(")") + 2 :].split()
        return int(fields[11]) + int(fields[12])

    def _run(self) -> None:
        while not self._stop.is_set():
            ticks = self._ticks()
            if ticks is None:
                return
            self.samples.append((time.monotonic_ns(), ticks))
            self._stop.wait(CPU_SAMPLE_PERIOD_S)

    def stop(self) -> None:
        self._stop.set()
        self.thread.join(timeout=2.0)

    def share_between(self, start_ns: int, end_ns: int) -> tuple[float, float] | None:
        """(CPU share of one core, window s) between the samples inside [start, end]."""
        inside = [s for s in self.samples if start_ns <= s[0] <= end_ns]
        if len(inside) < 2:
            return None
        (t0, c0), (t1, c1) = inside[0], inside[-1]
        window_s = (t1 - t0) * 1e-9
        return (c1 - c0) / os.sysconf("SC_CLK_TCK") / window_s, window_s


def child_pid(parent_pid: int, pattern: str, timeout_s: float) -> int | None:
    """The pid of ``parent_pid``'s child whose command line matches ``pattern`` (pgrep -f)."""
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        found = subprocess.run(
            ["pgrep", "-f", "-P", str(parent_pid), pattern], capture_output=True, text=True
        ).stdout.split()
        if found:
            return int(found[0])
        time.sleep(0.1)
    return None


def lower_priority(parent_pid: int, names) -> dict[str, int | None]:
    """Set the niceness of ``parent_pid``'s children of these names to SIMULATOR_NICENESS;
    returns the niceness each got (None: not found)."""
    niceness = {}
    for name in names:
        pid = child_pid(parent_pid, name, FIND_PID_TIMEOUT_S)
        if pid is not None:
            os.setpriority(os.PRIO_PROCESS, pid, SIMULATOR_NICENESS)
        niceness[name] = None if pid is None else os.getpriority(os.PRIO_PROCESS, pid)
    return niceness


def latency_stats(inputs: dict, outputs: dict) -> dict:
    """Output minus input time of the samples with the same header stamp, ms: by receive
    times in this process and, for comparison, by the publishers' source stamps."""
    matched = [stamp for stamp in outputs if stamp in inputs]
    if not matched:
        return {"pairs": 0, "unmatched": len(outputs)}
    received_ms = np.array([outputs[s][0] - inputs[s][0] for s in matched]) * 1e-6
    source_ms = np.array([outputs[s][1] - inputs[s][1] for s in matched]) * 1e-6
    p99 = float(np.percentile(received_ms, 99))
    return {
        "pairs": len(matched),
        "unmatched": len(outputs) - len(matched),
        "median_ms": float(np.median(received_ms)),
        "p99_ms": p99,
        "max_ms": float(received_ms.max()),
        "min_ms": float(received_ms.min()),
        "p99_pass": bool(p99 <= LATENCY_TARGET_P99_MS),
        "source_stamp_median_ms": float(np.median(source_ms)),
        "source_stamp_p99_ms": float(np.percentile(source_ms, 99)),
        "source_stamp_max_ms": float(source_ms.max()),
    }


def in_service(outputs: dict) -> dict:
    """The outputs received from IN_SERVICE_AFTER_S after the first one on: without the burst
    of solutions a filter releases at once when it has just aligned."""
    if not outputs:
        return outputs
    start_ns = min(received for received, _ in outputs.values()) + IN_SERVICE_AFTER_S * 1e9
    return {stamp: times for stamp, times in outputs.items() if times[0] >= start_ns}


def passthrough_path(shim_dir: Path) -> str:
    """A PATH on which ``fusion_node`` and ``compensation_node`` are the pass-through stand-ins
    (run_scenario takes the suite's executables from PATH first)."""
    for name in NODES_UNDER_TEST:
        shim = shim_dir / name
        shim.write_text(
            f'#!/bin/sh\nPYTHONPATH="{REPO}${{PYTHONPATH:+:$PYTHONPATH}}" '
            f'exec "{sys.executable}" -m tools.passthrough_node {name} "$@"\n'
        )
        shim.chmod(0o755)
    return f"{shim_dir}{os.pathsep}{os.environ.get('PATH', '')}"


def run_live(duration_s: float, log_dir: Path, passthrough: bool = False) -> dict:
    """Run the live scenario and measure; returns figures (or ``error`` with what failed).
    ``passthrough``: with the stand-ins of tools/passthrough_node.py in place of the nodes."""
    domain = isolate_ros_domain()
    try:
        with tempfile.TemporaryDirectory(prefix="bench_live_") as shim_dir:
            environment = dict(os.environ)
            if passthrough:
                environment["PATH"] = passthrough_path(Path(shim_dir))
            return _run_live(duration_s, log_dir, environment, domain, passthrough)
    finally:
        release_domain(domain)


def _run_live(
    duration_s: float, log_dir: Path, environment: dict, domain: int, passthrough: bool
) -> dict:
    # Latency is only as good as the machine is idle: other work on it shows up here, the
    # flushing of bags written just before too.
    os.sync()
    load_before = os.getloadavg()[0]
    log_dir.mkdir(parents=True, exist_ok=True)
    command = scenario_command(duration_s, log_dir)
    result = {
        "passthrough": passthrough,
        "duration_s": duration_s,
        "ros_domain_id": domain,
        "command": command[1:],
        "load_average_1min_before": load_before,
        "cpus": os.cpu_count(),
    }
    print(f"bench: live: {' '.join(command[1:])} (domain {domain})", file=sys.stderr, flush=True)
    listener = Listener()
    run, samplers = run_scenario_sampled(command, environment, duration_s, listener)
    result.update(run)
    if run["run_scenario_exit_code"] != 0:
        result["error"] = (
            f"run_scenario exited with {run['run_scenario_exit_code']}: "
            + " | ".join(run["run_scenario_output"][-5:])
        )
    received = listener.received
    result["received"] = {topic: len(stamps) for topic, stamps in received.items()}
    result["receive_time_source"] = (
        "middleware reception stamps"
        if listener.callback_stamps == 0
        else f"callback times for {listener.callback_stamps} messages, "
        f"middleware stamps for {listener.middleware_stamps}"
    )
    result["in_service_after_s"] = IN_SERVICE_AFTER_S
    result["latency"] = stage_latencies(received, listener.valid_true_wind)
    for node, (output, data) in CPU_MEASURED.items():
        result[f"{node.removesuffix('_node')}_cpu"] = node_cpu(
            node, samplers.get(node), listener, output, data, received
        )
    return result


def scenario_command(duration_s: float, log_dir: Path) -> list[str]:
    """run_scenario of sea_state for ``duration_s`` (s) with both nodes under test."""
    return [
        str(BIN / "run_scenario"),
        "sea_state",
        "--set",
        f"duration_s={duration_s:g}",
        # The wind's latency on the buoy it was first measured on: without the DVL, whose node
        # would be one more process taking /clock at 200 Hz beside the two under test.
        "--set",
        "sensors.dvl=null",
        "--fusion",
        "--compensation",
        "--params-file",
        str(PARAMS_FILE),
        "--log-dir",
        str(log_dir),
    ]


def run_scenario_sampled(
    command: list[str], environment: dict, duration_s: float, listener: Listener
) -> tuple[dict, dict[str, CpuSampler]]:
    """Run ``command`` (a run of ``duration_s``, s) to its end with the simulator at low
    priority and the CPU of the nodes under test sampled, then close ``listener``; returns the
    run's niceness, exit code and last lines of output, and the samplers by node."""
    run = {}
    samplers: dict[str, CpuSampler] = {}
    try:
        scenario = subprocess.Popen(
            command, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, env=environment
        )
        for node in CPU_MEASURED:
            pid = child_pid(scenario.pid, node, FIND_PID_TIMEOUT_S)
            if pid is not None:
                samplers[node] = CpuSampler(pid)
        run["simulator_niceness"] = lower_priority(scenario.pid, SIMULATOR_PROCESSES)
        try:
            output, _ = scenario.communicate(timeout=duration_s + RUN_MARGIN_S)
        except subprocess.TimeoutExpired:
            scenario.terminate()
            output, _ = scenario.communicate(timeout=30)
        run["run_scenario_exit_code"] = scenario.returncode
        run["run_scenario_output"] = output.strip().splitlines()[-20:]
        time.sleep(0.5)
    finally:
        for sampler in samplers.values():
            sampler.stop()
        listener.close()
    return run, samplers


def stage_latencies(received: dict, valid_true_wind: set) -> dict:
    """Latency figures of each stage (:func:`latency_stats`) from the receive times per topic
    and header stamp; ``valid_true_wind``: the stamps of the corrected (not NaN) true wind."""
    nav = received["nav/imu"]
    # Before the first navigation solution the wind samples can only be given up as NaN after
    # the node's navigation timeout; the corrected ones show the latency in service.
    corrected = {s: t for s, t in received["wind/true"].items() if s in valid_true_wind}
    latency = {
        "imu/data_raw → nav/imu, all": latency_stats(received["imu/data_raw"], nav),
        "imu/data_raw → nav/imu, in service": latency_stats(
            received["imu/data_raw"], in_service(nav)
        ),
        "anemometer/wind → wind/true, all": latency_stats(
            received["anemometer/wind"], received["wind/true"]
        ),
        "anemometer/wind → wind/true, corrected in service": latency_stats(
            received["anemometer/wind"], in_service(corrected)
        ),
    }
    # The corrected wind's latency in two parts: the wait for the IMU sample of the same
    # instant (which the simulated sensors publish independently) and the pipeline after it.
    corrected_in_service = in_service(corrected)
    imu = received["imu/data_raw"]
    latency["corrected wind, part 1: anemometer/wind → imu/data_raw, same stamp"] = latency_stats(
        received["anemometer/wind"], {s: imu[s] for s in corrected_in_service if s in imu}
    )
    latency["corrected wind, part 2: imu/data_raw → wind/true"] = latency_stats(
        imu, corrected_in_service
    )
    return latency


def node_cpu(
    node: str,
    sampler: CpuSampler | None,
    listener: Listener,
    output_topic: str,
    input_topic: str,
    received: dict,
) -> dict:
    """CPU share of ``node`` while it works: from its first ``output_topic`` message to the
    last ``input_topic`` message, with the rate of that input."""
    if sampler is None:
        return {"share_of_one_core": None, "note": f"{node} pid not found"}
    start_ns = listener.first_callback_ns.get(output_topic)
    end_ns = listener.last_callback_ns.get(input_topic)
    if start_ns is None or end_ns is None:
        return {"share_of_one_core": None, "note": f"no {output_topic} or {input_topic} received"}
    share = sampler.share_between(start_ns, end_ns)
    if share is None:
        return {"share_of_one_core": None, "note": "too few CPU samples in the window"}
    stamps = sorted(received[input_topic])
    span_s = (stamps[-1][0] - stamps[0][0]) + (stamps[-1][1] - stamps[0][1]) * 1e-9
    return {
        "pid": sampler.pid,
        "share_of_one_core": share[0],
        "window_s": share[1],
        "input_topic": input_topic,
        "input_rate_hz": (len(stamps) - 1) / span_s if span_s > 0 else float("nan"),
    }


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(prog="bench_live", description=__doc__.split("\n")[0])
    parser.add_argument("--duration-s", type=float, default=40.0, help="scenario length, s")
    parser.add_argument(
        "--passthrough",
        action="store_true",
        help="replace both nodes by the stand-ins of tools/passthrough_node.py (the floor)",
    )
    arguments = parser.parse_args(argv)
    result = run_live(
        arguments.duration_s, REPO / "out" / "bench" / "live_logs", arguments.passthrough
    )
    print(json.dumps(result, indent=2))


if __name__ == "__main__":
    main()
