"""Soak: hours of simulated sea through the live nodes, at an accelerated pace.

Runs ``run_scenario SCENARIO --fusion --compensation`` for ``--hours`` of simulated time at
``--rate-factor`` times real time, in a ROS domain of its own, on one of these sensor sets
(``--scenario``):

- ``moored_outages`` (default): ``set_e_imperfect`` moored, as the day of
  ``tools/bench_uncertainty_day.py``: one GNSS antenna at 1 Hz, silent for 60 s every
  10 simulated minutes (the first at 4 min), a lagging motion pack that gives the heading and an
  uncalibrated magnetometer that the fusion suspends; ``fusion.moored`` set;
- ``sea_state``: a drifting buoy with the dual-antenna RTK GNSS, no outage.

Meanwhile, in this process, it

- samples the resident memory (VmRSS) of ``fusion_node`` and ``compensation_node`` every
  ``--rss-period-s`` wall-clock seconds, each sample tagged with the simulated time reached;
  memory is flat when the RSS at the end is within 10 % of the RSS at the end of the first
  simulated hour (of the first half, for a run shorter than two hours);
- follows every ``anemometer/wind`` sample to its ``wind/true`` and its
  ``wind/true_with_covariance`` (same header stamp; one of each per sample, interfaces.md):
  the delay input → ``wind/true`` per simulated hour (percentiles; the samples still open are
  the only state it keeps, so its own memory stays flat), the samples in, out and valid (a
  finite wind), and per topic the samples missing or received twice. Nothing is lost when no
  sample misses an output or its input and none comes twice. Samples stamped before the first
  complete one are counted apart: DDS delivers a message only to subscriptions already matched,
  so the simulation waits for this listener's and the compensation node's subscriptions to
  reach the anemometer before it starts (``run_scenario --wait-for-subscription``); what is
  counted apart is what still slips through;
- reads the fusion node's log at the end: its alignment, and every source suspended or resumed.

Prints a table and writes the figures as JSON (``--json``); Ctrl-C stops the run and still
reports what was measured up to then (marked ``interrupted``). ``make bench`` runs two
simulated hours, an hour of wall time (``tools/bench.py --only soak``); ``make test-long`` a
few seconds of it (tests/system/test_soak.py).

    python -m tools.soak [--hours 2] [--rate-factor 2] [--scenario moored_outages|sea_state]
                         [--json out/bench/soak.json]
"""

from __future__ import annotations

import argparse
import collections
import json
import math
import os
import re
import signal
import subprocess
import sys
import tempfile
import threading
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from buoy_common import cdr
from buoy_common.contract import WIND_RAW_TOPIC, WIND_TRUE_TOPIC, WIND_TRUE_WITH_COVARIANCE_TOPIC
from sensor_sim.run_scenario import sensor_node_names
from sensor_sim.scenario import load_scenario
from tools.bench_plan import PROCESSING_PARAMS
from tools.bench_uncertainty import MOORED, Case, write_parameters
from tools.bench_uncertainty_day import SCENARIO_OVERRIDES as MOORED_DAY_OVERRIDES
from tools.ros_domains import claim_domain, isolated_environment, release_domain

BIN = Path(sys.executable).parent
NODES = ("fusion_node", "compensation_node")
LISTENER_NODE = "soak_listener"
TOPICS = (WIND_RAW_TOPIC, WIND_TRUE_TOPIC, WIND_TRUE_WITH_COVARIANCE_TOPIC)
OUTPUT_TOPICS = TOPICS[1:]
FIND_PID_TIMEOUT_S = 60.0
RUN_MARGIN_S = 120.0
SECONDS_PER_HOUR = 3600.0
PERCENTILES = (50.0, 99.0, 100.0)
FLAT_MEMORY_SHARE = 0.10
"""Memory is flat when the RSS at the end is within this share of its value after hour 1."""
TRANSITION = re.compile(r"stamp ([-\d.]+) s: (\S+) (suspended|resumed):")
REJECTION = re.compile(r"rejected (\S+): (\S+) \(total (\d+)\)")
ALIGNMENT_MARK = "aligned at stamp"
DOMAIN_TRIES = 5
DISCOVERY_S = 2.0
"""How long the listener waits to see whether its new domain holds other nodes."""


@dataclass(frozen=True)
class Setup:
    """A sensor set to soak on: the scenario case, and a silent GNSS outage of
    ``gnss_outage_s`` every ``gnss_outage_every_s`` from ``gnss_first_outage_s`` on (none
    when ``gnss_outage_every_s`` is None)."""

    case: Case
    gnss_outage_every_s: float | None = None
    gnss_first_outage_s: float = 240.0
    gnss_outage_s: float = 60.0

    def overrides(self, duration_s: float) -> list[str]:
        """The scenario overrides for a run of ``duration_s`` simulated seconds."""
        overrides = [*self.case.overrides, f"duration_s={duration_s:g}"]
        if self.gnss_outage_every_s is not None:
            starts = np.arange(
                self.gnss_first_outage_s, duration_s - self.gnss_outage_s, self.gnss_outage_every_s
            )
            outages = [[float(start), float(start + self.gnss_outage_s)] for start in starts]
            overrides.append(f"sensors.gnss.silent_outages_s={outages}")
        return overrides


SETUPS = {
    "moored_outages": Setup(
        Case(
            "set_e_imperfect",
            "(e) moored: one antenna at 1 Hz silent 60 s every 10 min, a lagging motion pack "
            "giving the heading, the uncalibrated magnetometer suspended",
            MOORED_DAY_OVERRIDES,
            (MOORED,),
        ),
        gnss_outage_every_s=600.0,
    ),
    "sea_state": Setup(Case("sea_state", "(a) dual-antenna RTK, drifting, no outage")),
}
DEFAULT_SETUP = "moored_outages"


def isolate_ros_domain() -> int:
    """A domain of the soak's range (tools/ros_domains.py: apart from every other run of the
    suite, whose samples would mix into the soak's counts) that no other run holds, discovery
    on loopback only, for this process and its children."""
    domain = claim_domain("soak")
    isolated_environment(domain, os.environ)
    os.environ.setdefault("AMENT_PREFIX_PATH", str(BIN.parent))
    os.environ["PYTHONUNBUFFERED"] = "1"
    return domain


class WindTriples:
    """Every ``anemometer/wind`` sample and its two outputs, ``wind/true`` and
    ``wind/true_with_covariance`` (same header stamp): the reception delay input → ``wind/true``
    by simulated hour, the counts, and what is missing or duplicated."""

    def __init__(self):
        import rclpy
        from geometry_msgs.msg import TwistWithCovarianceStamped, Vector3Stamped
        from rclpy.context import Context
        from rclpy.executors import SingleThreadedExecutor

        from buoy_common.base_node import DATA_QOS

        self._rclpy = rclpy
        self.context = Context()
        rclpy.init(context=self.context)
        self.node = rclpy.create_node(LISTENER_NODE, context=self.context)
        self._lock = threading.Lock()
        # Stamps not yet seen on all three topics: stamp → reception time per topic, ns.
        self._open: dict[tuple[int, int], list[int | None]] = {}
        self.first_stamp_s: float | None = None
        self.latest_stamp_s: float | None = None
        self.delays_by_hour_s: dict[int, list[float]] = {}
        self.received = dict.fromkeys(TOPICS, 0)
        self.valid = dict.fromkeys(OUTPUT_TOPICS, 0)
        self.duplicates = dict.fromkeys(TOPICS, 0)
        self.first_complete_stamp: tuple[int, int] | None = None
        subscriptions = (
            (Vector3Stamped, WIND_RAW_TOPIC),
            (Vector3Stamped, WIND_TRUE_TOPIC),
            (TwistWithCovarianceStamped, WIND_TRUE_WITH_COVARIANCE_TOPIC),
        )
        for index, (message_type, topic) in enumerate(subscriptions):
            self.node.create_subscription(
                message_type,
                topic,
                lambda message, info, index=index: self._on_message(index, message, info),
                DATA_QOS,
                raw=True,
            )
        self.executor = SingleThreadedExecutor(context=self.context)
        self.executor.add_node(self.node)
        self.thread = threading.Thread(target=self.executor.spin, daemon=True)
        self.thread.start()

    @staticmethod
    def _received_ns(info) -> int:
        received_ns = info.get("received_timestamp", 0)
        return received_ns if received_ns > 0 else time.time_ns()

    def _on_message(self, index: int, message: bytes, info) -> None:
        """One message of topic ``TOPICS[index]``; the three topics reach this listener by
        separate paths, so an output may come before its input."""
        received_ns = self._received_ns(info)
        # Vector3Stamped's vector and TwistWithCovarianceStamped's twist.linear sit at the
        # same place after the header.
        decoded = cdr.read_vector3_stamped(message)
        if decoded is None:
            return
        stamp = decoded[0], decoded[1]
        topic = TOPICS[index]
        with self._lock:
            self.received[topic] += 1
            if topic in self.valid:
                self.valid[topic] += math.isfinite(decoded[3][0])
            seen = self._open.setdefault(stamp, [None] * len(TOPICS))
            if seen[index] is not None:
                self.duplicates[topic] += 1
                return
            seen[index] = received_ns
            if all(at is not None for at in seen):
                del self._open[stamp]
                self._complete(stamp, seen)

    def _complete(self, stamp: tuple[int, int], received_ns: list[int]) -> None:
        if self.first_complete_stamp is None:
            self.first_complete_stamp = stamp
        stamp_s = stamp[0] + stamp[1] * 1e-9
        if self.first_stamp_s is None:
            self.first_stamp_s = stamp_s
        self.latest_stamp_s = stamp_s
        hour = int((stamp_s - self.first_stamp_s) // SECONDS_PER_HOUR)
        delay_s = (received_ns[1] - received_ns[0]) * 1e-9
        self.delays_by_hour_s.setdefault(hour, []).append(delay_s)

    def simulated_s(self) -> float | None:
        """Simulated seconds from the first complete sample to the latest, None before it."""
        with self._lock:
            if self.first_stamp_s is None:
                return None
            return self.latest_stamp_s - self.first_stamp_s

    def missing(self) -> dict[str, dict[str, int]]:
        """Per topic, the stamps seen on another of the three topics but never on it: those
        stamped before the first complete sample, and those after it."""
        with self._lock:
            first = self.first_complete_stamp
            counts = {"before": dict.fromkeys(TOPICS, 0), "after": dict.fromkeys(TOPICS, 0)}
            for stamp, seen in self._open.items():
                side = "before" if first is None or stamp < first else "after"
                for topic, at in zip(TOPICS, seen, strict=True):
                    counts[side][topic] += at is None
            return counts

    def intruders(self, own_names: set[str]) -> list[str]:
        """Nodes in this domain that are not the soak's own: other names, and own names held
        by more than one node (another buoy's simulation)."""
        names = collections.Counter(self.node.get_node_names())
        return sorted(name for name, n in names.items() if name not in own_names or n > 1)

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


def scenario_command(setup: Setup, duration_s: float, rate_factor: float, log_dir: Path):
    """The ``run_scenario`` command of the soak, with the parameter file it writes into
    ``log_dir``: the buoy, the nodes' defaults and what this sensor set implies (its sensors'
    places, ``fusion.moored``)."""
    overrides = setup.overrides(duration_s)
    scenario = load_scenario(setup.case.scenario, overrides, None)
    command = [str(BIN / "run_scenario"), setup.case.scenario]
    for override in overrides:
        command += ["--set", override]
    command += ["--rate-factor", f"{rate_factor:g}", "--fusion", "--compensation"]
    for params_file in [*PROCESSING_PARAMS, write_parameters(log_dir, scenario, setup.case)]:
        command += ["--params-file", params_file]
    # The simulation starts once this listener's subscription has reached the anemometer.
    command += ["--wait-for-subscription", f"{LISTENER_NODE}:{WIND_RAW_TOPIC}"]
    command += ["--log-dir", str(log_dir)]
    return command


def listener_in_a_quiet_domain() -> tuple[WindTriples, int]:
    """The listener, in a domain where it saw no other node (after DOMAIN_TRIES, the last
    domain tried; the run then reports the intruders), and that domain, held until
    :func:`~tools.ros_domains.release_domain`. The domains found in use are held while the
    others are tried, then let go."""
    in_use: list[int] = []
    try:
        for _ in range(DOMAIN_TRIES):
            domain = isolate_ros_domain()
            triples = WindTriples()
            time.sleep(DISCOVERY_S)
            if not triples.intruders({LISTENER_NODE}):
                return triples, domain
            print(f"soak: ROS domain {domain} is in use; trying another", file=sys.stderr)
            triples.close()
            in_use.append(domain)
        in_use.remove(domain)
        return WindTriples(), domain
    finally:
        for other in in_use:
            release_domain(other)


def own_node_names(setup: Setup, duration_s: float) -> set[str]:
    """The nodes of the soak's own run: the scenario's sensors, clock, processing, listener."""
    scenario = load_scenario(setup.case.scenario, setup.overrides(duration_s), None)
    return {*sensor_node_names(scenario), "sim_clock_node", *NODES, LISTENER_NODE}


def sample_while_running(scenario, triples, own_names, deadline_and_period_s, result):
    """RSS samples (wall s, simulated s or None, MiB) of each node every period (s) until
    ``run_scenario`` ends or overruns the deadline (monotonic s); meanwhile, the nodes of
    another run that join the domain, with the wall second each was first seen, into
    ``result["intruders"]``. Ctrl-C stops sampling and marks the result."""
    deadline_s, rss_period_s = deadline_and_period_s
    result["intruders"] = {}
    started_s = time.monotonic()
    pids = child_pids(scenario.pid, NODES, FIND_PID_TIMEOUT_S)
    samples: dict[str, list[tuple[float, float | None, float]]] = {name: [] for name in NODES}
    try:
        while scenario.poll() is None and time.monotonic() < deadline_s:
            elapsed_s = time.monotonic() - started_s
            simulated_s = triples.simulated_s()
            for name, pid in pids.items():
                rss = rss_mib(pid)
                if rss is not None:
                    samples[name].append((elapsed_s, simulated_s, rss))
            for name in triples.intruders(own_names):
                result["intruders"].setdefault(name, elapsed_s)
            time.sleep(rss_period_s)
    except KeyboardInterrupt:
        # Hours of figures are worth keeping: stop the run and report what was measured.
        print("soak: interrupted; stopping the run", file=sys.stderr, flush=True)
        result["interrupted"] = True
    return samples


def soak(
    hours: float,
    rate_factor: float,
    rss_period_s: float,
    log_dir: Path,
    setup_name: str = DEFAULT_SETUP,
) -> dict:
    """Run the soak; returns its figures (``error`` says what failed, if anything did)."""
    triples, domain = listener_in_a_quiet_domain()
    duration_s = hours * SECONDS_PER_HOUR
    log_dir.mkdir(parents=True, exist_ok=True)
    command = scenario_command(SETUPS[setup_name], duration_s, rate_factor, log_dir)
    own_names = own_node_names(SETUPS[setup_name], duration_s)
    result: dict = {
        "simulated_hours": hours,
        "rate_factor": rate_factor,
        "setup": setup_name,
        "description": SETUPS[setup_name].case.description,
        "ros_domain_id": domain,
        "command": command[1:],
    }
    print(f"soak: {' '.join(command[1:])} (domain {domain})", file=sys.stderr, flush=True)
    started_s = time.monotonic()
    # To a file, not a pipe: hours of progress lines would fill a pipe nobody reads meanwhile.
    output_path = log_dir / "run_scenario.log"
    try:
        with output_path.open("w") as output:
            scenario = subprocess.Popen(command, stdout=output, stderr=subprocess.STDOUT)
            deadline_s = started_s + duration_s / rate_factor + RUN_MARGIN_S
            rss_samples = sample_while_running(
                scenario, triples, own_names, (deadline_s, rss_period_s), result
            )
            if scenario.poll() is None:
                scenario.send_signal(signal.SIGINT)
            scenario.wait(timeout=60)
        result["run_scenario_exit_code"] = scenario.returncode
        result["run_scenario_output"] = output_path.read_text().strip().splitlines()[-10:]
        time.sleep(1.0)
    finally:
        triples.close()
        release_domain(domain)
    result["wall_s"] = time.monotonic() - started_s
    if scenario.returncode != 0:
        result["error"] = f"run_scenario exited with {scenario.returncode}"
    elif result["intruders"]:
        first = ", ".join(f"{name} at {t:.0f} s" for name, t in result["intruders"].items())
        result["error"] = (
            f"nodes of another run joined ROS domain {domain} ({first}, wall clock): the "
            "counts, latencies and the fusion's state are not this run's alone"
        )
    result["counts"] = sample_counts(triples)
    result["latency_s_by_simulated_hour"] = {
        str(hour): {
            "n": len(delays),
            **{f"p{p:g}": float(np.percentile(delays, p)) for p in PERCENTILES},
        }
        for hour, delays in sorted(triples.delays_by_hour_s.items())
    }
    result["rss_mib"] = {name: rss_summary(samples) for name, samples in rss_samples.items()}
    result["first_sample_stamp_s"] = triples.first_stamp_s
    result["fusion"] = fusion_events(log_dir / "fusion_node.log")
    result["verdict"] = verdict(result)
    return result


def sample_counts(triples: WindTriples) -> dict[str, int]:
    """Samples received and valid per topic; per topic, those missing (stamped after the first
    complete sample, and before it, apart) and those received twice."""
    missing = triples.missing()
    counts = {f"{topic} in": triples.received[topic] for topic in TOPICS}
    counts |= {f"{topic} valid": triples.valid[topic] for topic in OUTPUT_TOPICS}
    counts |= {f"{topic} missing": missing["after"][topic] for topic in TOPICS}
    counts |= {f"{topic} twice": triples.duplicates[topic] for topic in TOPICS}
    counts |= {
        f"before the first complete sample: {topic} missing": missing["before"][topic]
        for topic in TOPICS
    }
    return counts


def fusion_events(log_path: Path) -> dict:
    """The fusion node's alignment line, every source suspended or resumed (stamp s, source,
    what), the sources suspended at the end, and its rejected inputs by topic and reason (the
    last running count its rate-limited log gave: at least that many)."""
    try:
        lines = log_path.read_text(errors="replace").splitlines()
    except OSError:
        return {"log": f"{log_path} not readable"}
    aligned = next(
        (line[line.index(ALIGNMENT_MARK) :] for line in lines if ALIGNMENT_MARK in line), None
    )
    transitions = [
        (float(match[1]), match[2], match[3])
        for match in (TRANSITION.search(line) for line in lines)
        if match is not None
    ]
    state: dict[str, str] = {}
    for _, source, change in transitions:
        state[source] = change
    rejections: dict[str, int] = {}
    for match in (REJECTION.search(line) for line in lines):
        if match is not None:
            rejections[f"{match[1]}: {match[2]}"] = int(match[3])
    return {
        "rejected_at_least": rejections,
        "aligned": aligned,
        "transitions": transitions,
        "suspended_at_end": sorted(
            source for source, change in state.items() if change == "suspended"
        ),
    }


def verdict(result: dict) -> dict[str, bool]:
    """Nothing lost (every sample out once on each output, every output from a sample seen,
    nothing twice) and memory flat (each node within FLAT_MEMORY_SHARE of hour 1 at the end)."""
    counts = result["counts"]
    received = all(counts[f"{topic} in"] > 0 for topic in TOPICS)
    lost = sum(counts[f"{topic} missing"] + counts[f"{topic} twice"] for topic in TOPICS)
    flat = [rss.get("flat") for rss in result["rss_mib"].values()]
    return {
        "nothing_lost": received and lost == 0,
        "memory_flat": bool(flat) and all(value is True for value in flat),
    }


def rss_summary(samples: list[tuple[float, float | None, float]]) -> dict:
    """Resident memory over the run: at the end of the first simulated hour (or halfway through
    a shorter run) and at the end, and whether the end is within FLAT_MEMORY_SHARE of the
    first; the first and last quarter, the most, and the slope of a straight line through the
    second half (MiB per wall-clock hour)."""
    if len(samples) < 4:
        return {"samples": len(samples)}
    times_s = np.array([t for t, _, _ in samples])
    values = np.array([v for _, _, v in samples])
    quarter = len(samples) // 4
    second_half = slice(len(samples) // 2, None)
    slope = np.polyfit(times_s[second_half], values[second_half], 1)[0]
    return {
        "samples": len(samples),
        **flatness(samples),
        "first_quarter_mean": float(values[:quarter].mean()),
        "last_quarter_mean": float(values[-quarter:].mean()),
        "max": float(values.max()),
        "second_half_slope_mib_per_h": float(slope * SECONDS_PER_HOUR),
        "over_time": [
            (round(t, 1), None if s is None else round(s, 1), round(v, 2))
            for t, s, v in samples[:: max(1, len(samples) // 24)]
        ],
    }


def flatness(samples: list[tuple[float, float | None, float]]) -> dict:
    """RSS (MiB) at the end of the first simulated hour, or halfway through a run shorter than
    two hours, and at the end; flat when the end is within FLAT_MEMORY_SHARE of the first."""
    simulated = [(s, v) for _, s, v in samples if s is not None]
    if len(simulated) < 2:
        return {}
    end_simulated_s, end_mib = simulated[-1]
    reference_s = min(SECONDS_PER_HOUR, end_simulated_s / 2.0)
    reference_mib = next(v for s, v in simulated if s >= reference_s)
    growth = (end_mib - reference_mib) / reference_mib
    return {
        "reference_simulated_s": reference_s,
        "reference_mib": reference_mib,
        "end_simulated_s": end_simulated_s,
        "end_mib": end_mib,
        "growth_share": growth,
        "flat": bool(abs(growth) <= FLAT_MEMORY_SHARE),
    }


def print_table(result: dict) -> None:
    planned = f"{result['simulated_hours']:g} h simulated at {result['rate_factor']:g}x"
    if result.get("interrupted"):
        print(f"soak: {planned}, interrupted after {result['wall_s'] / 60:.1f} min")
    else:
        print(f"soak: {planned} in {result['wall_s'] / 60:.1f} min")
    print(f"  {result['setup']}: {result['description']}")
    for key, value in result["counts"].items():
        print(f"  {key:68s} {value:8d}")
    print("  latency anemometer/wind → wind/true per simulated hour, ms:")
    for hour, stats in result["latency_s_by_simulated_hour"].items():
        print(
            f"    hour {hour:>3s}: n {stats['n']:7d}  p50 {stats['p50'] * 1e3:7.1f}  "
            f"p99 {stats['p99'] * 1e3:7.1f}  max {stats['p100'] * 1e3:7.1f}"
        )
    for name, rss in result["rss_mib"].items():
        print_rss(name, rss)
    print_fusion(result["fusion"], result["first_sample_stamp_s"] or 0.0)
    print(
        "  nothing lost: {nothing_lost}; memory flat (within 10 %): {memory_flat}".format(
            **result["verdict"]
        )
    )
    if "error" in result:
        print(f"  error: {result['error']}")


def print_rss(name: str, rss: dict) -> None:
    if "max" not in rss:
        return
    if "flat" in rss:
        print(
            f"  RSS {name:18s} {rss['reference_mib']:7.1f} MiB at simulated "
            f"{rss['reference_simulated_s'] / 60:.0f} min, {rss['end_mib']:7.1f} MiB at "
            f"{rss['end_simulated_s'] / 60:.0f} min ({rss['growth_share']:+.1%})"
        )
    print(
        f"  RSS {name:18s} first quarter {rss['first_quarter_mean']:7.1f} MiB, "
        f"last quarter {rss['last_quarter_mean']:7.1f} MiB, max {rss['max']:7.1f} MiB, "
        f"second-half slope {rss['second_half_slope_mib_per_h']:+.2f} MiB/h"
    )


def print_fusion(fusion: dict, first_sample_stamp_s: float) -> None:
    """The fusion's alignment and source transitions, these at simulated seconds from the
    first complete wind sample (stamped ``first_sample_stamp_s``, s since the epoch)."""
    print(f"  fusion: {fusion.get('aligned') or fusion.get('log') or 'not aligned'}")
    changes = [change for _, _, change in fusion.get("transitions", [])]
    suspended = ", ".join(fusion.get("suspended_at_end", [])) or "none"
    print(
        f"  fusion: {changes.count('suspended')} suspensions, {changes.count('resumed')} "
        f"resumptions; suspended at the end: {suspended}"
    )
    for stamp_s, source, change in fusion.get("transitions", [])[:10]:
        print(f"    at {stamp_s - first_sample_stamp_s:.1f} s: {source} {change}")
    for key, count in fusion.get("rejected_at_least", {}).items():
        print(f"  fusion rejected {key}: at least {count}")


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--hours", type=float, default=2.0, help="simulated hours (2)")
    parser.add_argument(
        "--rate-factor", type=float, default=2.0, help="simulated seconds per wall second (2)"
    )
    parser.add_argument(
        "--scenario",
        choices=sorted(SETUPS),
        default=DEFAULT_SETUP,
        help=f"the sensor set and scenario ({DEFAULT_SETUP})",
    )
    parser.add_argument("--rss-period-s", type=float, default=10.0, help="RSS sampling period")
    parser.add_argument("--json", type=Path, help="write the figures here")
    arguments = parser.parse_args(argv)
    with tempfile.TemporaryDirectory(prefix="soak_") as log_dir:
        result = soak(
            arguments.hours,
            arguments.rate_factor,
            arguments.rss_period_s,
            Path(log_dir),
            arguments.scenario,
        )
    print_table(result)
    if arguments.json:
        arguments.json.parent.mkdir(parents=True, exist_ok=True)
        arguments.json.write_text(json.dumps(result, indent=1))
    return 1 if "error" in result else 0


if __name__ == "__main__":
    sys.exit(main())
