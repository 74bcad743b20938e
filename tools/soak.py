"""Soak: hours of simulated sea through the live nodes, at an accelerated pace.

Runs ``run_scenario sea_state --fusion --compensation`` for ``--hours`` of simulated time at
``--rate-factor`` times real time, in a ROS domain of its own, and meanwhile, in this process:

- samples the resident memory (VmRSS) of ``fusion_node`` and ``compensation_node`` every
  ``--rss-period-s`` wall-clock seconds;
- pairs every ``anemometer/wind`` sample with its ``wind/true`` (same header stamp) and records
  the delay between their receptions, per simulated hour (percentiles; the pairs still open are
  the only state it keeps, so its own memory stays flat);
- counts samples in and out: every ``anemometer/wind`` sample must come out on ``wind/true``.
  Samples stamped before the first pair this process saw are counted apart. DDS delivers a
  message only to subscriptions already matched, so the simulation waits for this listener's
  and the compensation node's subscriptions to reach the anemometer before it starts
  (``run_scenario --wait-for-subscription``); what is counted apart is what still slips through.

Prints a table and writes the figures as JSON (``--json``); Ctrl-C stops the run and still
reports what was measured up to then (marked ``interrupted``). ``make bench`` runs the full day
(``tools/bench.py --only soak``); ``make test-long`` a few minutes of it
(tests/system/test_soak.py).

    python -m tools.soak [--hours 24] [--rate-factor 2] [--json out/bench/soak.json]
"""

from __future__ import annotations

import argparse
import json
import math
import os
import random
import signal
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

import numpy as np

from buoy_common import cdr
from buoy_common.contract import WIND_RAW_TOPIC, WIND_TRUE_TOPIC

REPO = Path(__file__).resolve().parents[1]
BIN = Path(sys.executable).parent
PARAMS_FILE = REPO / "src/buoy_common/config/buoy.yaml"
NODES = ("fusion_node", "compensation_node")
LISTENER_NODE = "soak_listener"
FIND_PID_TIMEOUT_S = 60.0
RUN_MARGIN_S = 120.0
SECONDS_PER_HOUR = 3600.0
PERCENTILES = (50.0, 99.0, 100.0)


def isolate_ros_domain() -> int:
    """A random domain in 100-200, discovery on loopback only, for this process and children."""
    domain = random.randint(100, 200)
    os.environ["ROS_DOMAIN_ID"] = str(domain)
    os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
    os.environ.pop("ROS_LOCALHOST_ONLY", None)
    os.environ.setdefault("AMENT_PREFIX_PATH", str(BIN.parent))
    os.environ["PYTHONUNBUFFERED"] = "1"
    return domain


class WindPairs:
    """``anemometer/wind`` → ``wind/true`` reception delays by simulated hour, and the counts."""

    def __init__(self):
        import rclpy
        from geometry_msgs.msg import Vector3Stamped
        from rclpy.context import Context
        from rclpy.executors import SingleThreadedExecutor

        from buoy_common.base_node import DATA_QOS

        self._rclpy = rclpy
        self.context = Context()
        rclpy.init(context=self.context)
        self.node = rclpy.create_node(LISTENER_NODE, context=self.context)
        self._lock = threading.Lock()
        self._open: dict[tuple[int, int], int] = {}  # stamp → reception time, ns
        self.first_stamp_s: float | None = None
        self.delays_by_hour_s: dict[int, list[float]] = {}
        self.wind_in = 0
        self.wind_out = 0
        self.wind_out_valid = 0
        self.first_paired_stamp: tuple[int, int] | None = None
        # Outputs whose input this listener has not seen (yet): stamp → reception time, ns.
        self._early_out: dict[tuple[int, int], int] = {}
        self.node.create_subscription(
            Vector3Stamped, WIND_RAW_TOPIC, self._on_wind, DATA_QOS, raw=True
        )
        self.node.create_subscription(
            Vector3Stamped, WIND_TRUE_TOPIC, self._on_true_wind, DATA_QOS, raw=True
        )
        self.executor = SingleThreadedExecutor(context=self.context)
        self.executor.add_node(self.node)
        self.thread = threading.Thread(target=self.executor.spin, daemon=True)
        self.thread.start()

    @staticmethod
    def _received_ns(info) -> int:
        received_ns = info.get("received_timestamp", 0)
        return received_ns if received_ns > 0 else time.time_ns()

    def _on_wind(self, message, info) -> None:
        received_ns = self._received_ns(info)
        stamp = cdr.read_stamp(message)
        with self._lock:
            self.wind_in += 1
            # The two topics reach this listener by separate paths, and its callbacks may take
            # an output before its input.
            output_received_ns = self._early_out.pop(stamp, None)
            if output_received_ns is None:
                self._open[stamp] = received_ns
            else:
                self._pair(stamp, received_ns, output_received_ns)

    def _on_true_wind(self, message, info) -> None:
        received_ns = self._received_ns(info)
        stamp = cdr.read_stamp(message)
        valid = math.isfinite(cdr.read_vector3_stamped(message)[3][0])
        with self._lock:
            self.wind_out += 1
            self.wind_out_valid += valid
            sent_ns = self._open.pop(stamp, None)
            if sent_ns is None:
                self._early_out[stamp] = received_ns
            else:
                self._pair(stamp, sent_ns, received_ns)

    def _pair(self, stamp, input_received_ns: int, output_received_ns: int) -> None:
        if self.first_paired_stamp is None:
            self.first_paired_stamp = stamp
        stamp_s = stamp[0] + stamp[1] * 1e-9
        if self.first_stamp_s is None:
            self.first_stamp_s = stamp_s
        hour = int((stamp_s - self.first_stamp_s) // SECONDS_PER_HOUR)
        delay_s = (output_received_ns - input_received_ns) * 1e-9
        self.delays_by_hour_s.setdefault(hour, []).append(delay_s)

    def open_pairs(self) -> tuple[int, int]:
        """Inputs still without output: (stamped before the first pair, after it)."""
        with self._lock:
            return self._split_at_first_pair(self._open)

    def unpaired_outputs(self) -> tuple[int, int]:
        """Outputs whose input this listener never saw: (stamped before the first pair, after
        it). By stamp, not by arrival: an output published late (invalid at its latency budget)
        may arrive after the first pair, its input before this listener was matched."""
        with self._lock:
            return self._split_at_first_pair(self._early_out)

    def _split_at_first_pair(self, stamps) -> tuple[int, int]:
        first = self.first_paired_stamp
        if first is None:
            return len(stamps), 0
        before = sum(stamp < first for stamp in stamps)
        return before, len(stamps) - before

    def close(self) -> None:
        self.executor.shutdown()
        self.node.destroy_node()
        self._rclpy.try_shutdown(context=self.context)
        self.thread.join(timeout=5.0)


def child_pids(parent_pid: int, names, timeout_s: float) -> dict[str, int]:
    """The pids of ``parent_pid``'s children running these executables."""
    deadline = time.monotonic() + timeout_s
    found: dict[str, int] = {}
    while len(found) < len(names) and time.monotonic() < deadline:
        for name in names:
            if name in found:
                continue
            pids = subprocess.run(
                ["pgrep", "-f", "-P", str(parent_pid), name], capture_output=True, text=True
            ).stdout.split()
            if pids:
                found[name] = int(pids[0])
        time.sleep(0.2)
    return found


def rss_mib(pid: int) -> float | None:
    """Resident memory of a process, MiB (None once it is gone)."""
    try:
        for line in Path(f"/proc/{pid}/status").read_text().splitlines():
            if line.startswith("VmRSS:"):
                return int(line.split()[1]) / 1024.0
    except OSError:
        return None
    return None


def soak(hours: float, rate_factor: float, rss_period_s: float, log_dir: Path) -> dict:
    """Run the soak; returns its figures (``error`` says what failed, if anything did)."""
    domain = isolate_ros_domain()
    duration_s = hours * SECONDS_PER_HOUR
    command = [
        str(BIN / "run_scenario"),
        "sea_state",
        "--set",
        f"duration_s={duration_s:g}",
        "--rate-factor",
        f"{rate_factor:g}",
        "--fusion",
        "--compensation",
        "--params-file",
        str(PARAMS_FILE),
        # The simulation starts once this listener's subscription has reached the anemometer.
        "--wait-for-subscription",
        f"{LISTENER_NODE}:{WIND_RAW_TOPIC}",
        "--log-dir",
        str(log_dir),
    ]
    result: dict = {
        "simulated_hours": hours,
        "rate_factor": rate_factor,
        "ros_domain_id": domain,
        "command": command[1:],
    }
    print(f"soak: {' '.join(command[1:])} (domain {domain})", file=sys.stderr, flush=True)
    pairs = WindPairs()
    rss_samples: dict[str, list[tuple[float, float]]] = {name: [] for name in NODES}
    started_s = time.monotonic()
    try:
        scenario = subprocess.Popen(
            command, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True
        )
        pids = child_pids(scenario.pid, NODES, FIND_PID_TIMEOUT_S)
        deadline_s = started_s + duration_s / rate_factor + RUN_MARGIN_S
        try:
            while scenario.poll() is None and time.monotonic() < deadline_s:
                elapsed_s = time.monotonic() - started_s
                for name, pid in pids.items():
                    rss = rss_mib(pid)
                    if rss is not None:
                        rss_samples[name].append((elapsed_s, rss))
                time.sleep(rss_period_s)
        except KeyboardInterrupt:
            # Hours of figures are worth keeping: stop the run and report what was measured.
            print("soak: interrupted; stopping the run", file=sys.stderr, flush=True)
            result["interrupted"] = True
        if scenario.poll() is None:
            scenario.send_signal(signal.SIGINT)
        output, _ = scenario.communicate(timeout=60)
        result["run_scenario_exit_code"] = scenario.returncode
        result["run_scenario_output"] = output.strip().splitlines()[-10:]
        time.sleep(1.0)
    finally:
        pairs.close()
    result["wall_s"] = time.monotonic() - started_s
    if scenario.returncode != 0:
        result["error"] = f"run_scenario exited with {scenario.returncode}"
    open_before_first_pair, open_after_first_pair = pairs.open_pairs()
    out_before_first_pair, out_after_first_pair = pairs.unpaired_outputs()
    result["counts"] = {
        "anemometer/wind in": pairs.wind_in,
        "wind/true out": pairs.wind_out,
        "wind/true valid": pairs.wind_out_valid,
        "wind/true without its input": out_after_first_pair,
        "anemometer/wind without output": open_after_first_pair,
        "before the first pair: wind/true alone": out_before_first_pair,
        "before the first pair: anemometer/wind alone": open_before_first_pair,
    }
    result["latency_s_by_simulated_hour"] = {
        str(hour): {
            "n": len(delays),
            **{f"p{p:g}": float(np.percentile(delays, p)) for p in PERCENTILES},
        }
        for hour, delays in sorted(pairs.delays_by_hour_s.items())
    }
    result["rss_mib"] = {name: rss_summary(samples) for name, samples in rss_samples.items()}
    return result


def rss_summary(samples: list[tuple[float, float]]) -> dict:
    """Resident memory over the run: at the first and last quarter, the most, and the slope of
    a straight line through the second half (MiB per wall-clock hour)."""
    if len(samples) < 4:
        return {"samples": len(samples)}
    times_s = np.array([t for t, _ in samples])
    values = np.array([v for _, v in samples])
    quarter = len(samples) // 4
    second_half = slice(len(samples) // 2, None)
    slope = np.polyfit(times_s[second_half], values[second_half], 1)[0] if quarter else math.nan
    return {
        "samples": len(samples),
        "first_quarter_mean": float(values[:quarter].mean()),
        "last_quarter_mean": float(values[-quarter:].mean()),
        "max": float(values.max()),
        "second_half_slope_mib_per_h": float(slope * SECONDS_PER_HOUR),
        "over_time": [
            (round(t, 1), round(v, 2)) for t, v in samples[:: max(1, len(samples) // 24)]
        ],
    }


def print_table(result: dict) -> None:
    planned = f"{result['simulated_hours']:g} h simulated at {result['rate_factor']:g}x"
    if result.get("interrupted"):
        print(f"soak: {planned}, interrupted after {result['wall_s'] / 60:.1f} min")
    else:
        print(f"soak: {planned} in {result['wall_s'] / 60:.1f} min")
    for key, value in result["counts"].items():
        print(f"  {key:32s} {value:10d}")
    print("  latency anemometer/wind → wind/true per simulated hour, ms:")
    for hour, stats in result["latency_s_by_simulated_hour"].items():
        print(
            f"    hour {hour:>3s}: n {stats['n']:7d}  p50 {stats['p50'] * 1e3:7.1f}  "
            f"p99 {stats['p99'] * 1e3:7.1f}  max {stats['p100'] * 1e3:7.1f}"
        )
    for name, rss in result["rss_mib"].items():
        if "max" in rss:
            print(
                f"  RSS {name:18s} first quarter {rss['first_quarter_mean']:7.1f} MiB, "
                f"last quarter {rss['last_quarter_mean']:7.1f} MiB, max {rss['max']:7.1f} MiB, "
                f"second-half slope {rss['second_half_slope_mib_per_h']:+.2f} MiB/h"
            )
    if "error" in result:
        print(f"  error: {result['error']}")


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--hours", type=float, default=24.0, help="simulated hours (24)")
    parser.add_argument(
        "--rate-factor", type=float, default=2.0, help="simulated seconds per wall second (2)"
    )
    parser.add_argument("--rss-period-s", type=float, default=10.0, help="RSS sampling period")
    parser.add_argument("--json", type=Path, help="write the figures here")
    arguments = parser.parse_args(argv)
    with tempfile.TemporaryDirectory(prefix="soak_") as log_dir:
        result = soak(arguments.hours, arguments.rate_factor, arguments.rss_period_s, Path(log_dir))
    print_table(result)
    if arguments.json:
        arguments.json.parent.mkdir(parents=True, exist_ok=True)
        arguments.json.write_text(json.dumps(result, indent=1))
    return 1 if "error" in result else 0


if __name__ == "__main__":
    sys.exit(main())
