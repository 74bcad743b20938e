"""run_scenario never leaves its nodes behind: they run in sessions of their own, so a terminal's
Ctrl-C does not reach them, and run_scenario must stop them however it ends itself; here, when
the reader of its output goes away (``run_scenario ... | head -1``)."""

from __future__ import annotations

import subprocess
import sys
import time
from pathlib import Path

import pytest

from buoy_common.bag_io import BagReader
from buoy_common.contract import WIND_RAW_TOPIC
from ros_messages import stamp_ns, wait_for
from sensor_sim.run_scenario import sensor_node_names
from sensor_sim.scenario import load_scenario

REPO = Path(__file__).resolve().parents[2]
BIN = Path(sys.executable).parent
BUOY_PARAMETERS = str(REPO / "src" / "buoy_common" / "config" / "buoy.yaml")
# run_scenario writes a progress line every 10 s, and a line when the fusion has aligned: the
# first one after the reader has gone fails.
EXIT_TIMEOUT_S = 60.0
# At four times real time the fusion aligns (after 10 s of the scenario) a few seconds after
# the nodes are up, so that its line comes before the first progress line.
ALIGNMENT_SOONER_RATE_FACTOR = 4.0
# Imports and DDS discovery of the simulation's nodes on a busy machine.
NODES_UP_TIMEOUT_S = 30.0
# Simulated seconds per wall-clock second of the awaited listener's run: its samples' stamps
# come from the simulation clock, whatever its pace.
AWAITED_RATE_FACTOR = 4.0

pytestmark = pytest.mark.ros


def node_pids(parent_pid: int) -> set[int]:
    """The pids of the processes ``parent_pid`` started."""
    found = subprocess.run(["pgrep", "-P", str(parent_pid)], capture_output=True, text=True)
    return {int(pid) for pid in found.stdout.split()}


def running(pid: int) -> bool:
    try:
        state = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0]
    except OSError:
        return False
    return state != "Z"


def node_log(log_dir: Path, name: str) -> str:
    """What node ``name`` of a run_scenario has logged so far to ``log_dir``."""
    try:
        return (log_dir / f"{name}.log").read_text(errors="replace")
    except OSError:
        return ""


def test_nodes_stop_when_the_reader_of_the_output_goes_away(nodes, tmp_path):
    scenario = subprocess.Popen(
        [
            str(BIN / "run_scenario"),
            "static",
            "--set",
            "duration_s=600",
            "--fusion",
            "--params-file",
            BUOY_PARAMETERS,
            "--rate-factor",
            f"{ALIGNMENT_SOONER_RATE_FACTOR:g}",
            "--log-dir",
            str(tmp_path),
        ],
        env=nodes.env,
        stdout=subprocess.PIPE,
        stderr=subprocess.DEVNULL,
        text=True,
    )
    try:
        first_line = scenario.stdout.readline()
        assert first_line.startswith("run_scenario: 'static'"), first_line
        started = node_pids(scenario.pid)
        assert len(started) >= 4, started  # the clock, the sensors, the fusion
        scenario.stdout.close()
        scenario.wait(timeout=EXIT_TIMEOUT_S)
    finally:
        if scenario.poll() is None:
            scenario.kill()
    deadline = time.monotonic() + 30.0
    while any(running(pid) for pid in started) and time.monotonic() < deadline:
        time.sleep(0.2)
    left = [pid for pid in started if running(pid)]
    for pid in left:
        subprocess.run(["kill", "-9", str(pid)], check=False)
    assert not left, f"run_scenario exited with {scenario.returncode} and left {left} running"


def test_the_simulation_waits_for_an_awaited_listener_and_it_misses_no_sample(nodes, tmp_path):
    """A listener that subscribes seconds after run_scenario starts still receives the first
    anemometer sample and every one after it: the sensors hold the clock until its subscription
    has reached them. (Without the wait, a listener started once the simulation's nodes are up
    misses the first seconds.)"""
    duration_s, rate_hz = 4.0, 20.0
    log_dir = tmp_path / "logs"
    simulation_nodes = [*sensor_node_names(load_scenario("static")), "sim_clock_node"]
    scenario = subprocess.Popen(
        [
            str(BIN / "run_scenario"),
            "static",
            "--set",
            f"duration_s={duration_s:g}",
            "--params-file",
            BUOY_PARAMETERS,
            "--wait-for-subscription",
            f"late_listener:{WIND_RAW_TOPIC}",
            "--rate-factor",
            f"{AWAITED_RATE_FACTOR:g}",
            "--log-dir",
            str(log_dir),
        ],
        env=nodes.env,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
    )
    try:
        # Every node of the simulation has started (each logs its scenario): the clock would
        # run now but for the awaited listener, which only then starts, seconds late.
        assert wait_for(
            lambda: all(
                "scenario 'static'" in node_log(log_dir, name) for name in simulation_nodes
            ),
            NODES_UP_TIMEOUT_S,
        ), {name: node_log(log_dir, name) for name in simulation_nodes}
        bag = tmp_path / "late"
        nodes.start(
            "bag_recorder",
            str(bag),
            "--topics",
            WIND_RAW_TOPIC,
            "--ros-args",
            "-r",
            "__node:=late_listener",
        )
        assert scenario.wait(timeout=EXIT_TIMEOUT_S) == 0
    finally:
        if scenario.poll() is None:
            scenario.kill()
    nodes.stop_all()
    with BagReader(bag) as reader:
        stamps = [stamp_ns(reader.decode(m)) for m in reader.messages([WIND_RAW_TOPIC])]
    start_ns = load_scenario("static").start_time_ns
    assert stamps[0] == start_ns
    assert len(stamps) == round(duration_s * rate_hz) + 1


def test_a_wait_that_cannot_be_met_is_refused_before_anything_starts(nodes):
    for entry, complaint in (
        ("late_listener", "expected NODE:TOPIC"),
        ("late_listener:wind/true", "the simulation does not publish wind/true"),
    ):
        result = nodes.run("run_scenario", "static", "--wait-for-subscription", entry)
        assert result.returncode == 2
        assert complaint in result.stderr
