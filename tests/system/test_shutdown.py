"""Every executable stops cleanly on SIGINT and SIGTERM, however close together they come.

A wrapper (a launch system, a shell script, a terminal) often forwards a signal it received
itself: the program then gets two in quick succession. Each executable is started on real work,
sent two signals 50 ms apart, and must exit with its documented code, without a traceback or an
abort.
"""

from __future__ import annotations

import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

import pytest

from buoy_common.cli import INTERRUPTED_EXIT_CODE
from ros_messages import wait_for

pytestmark = [pytest.mark.slow, pytest.mark.long]

REPO = Path(__file__).resolve().parents[2]
BIN = Path(sys.executable).parent
BUOY_PARAMETERS = str(REPO / "src" / "buoy_common" / "config" / "buoy.yaml")
SEA_STATE = str(REPO / "bags" / "sea_state")
PARAMETERS = ("--ros-args", "--params-file", BUOY_PARAMETERS)
# A program takes its signals over once its modules are imported, which on a loaded machine
# takes seconds: each is signalled once it has written its first line, then after this settling.
AT_WORK_S = 2.0
STARTUP_TIMEOUT_S = 40.0
SILENT_AT_START = ("wind_echo", "simulate_bag")
SECOND_SIGNAL_AFTER_S = 0.05
CALIBRATION_AT_WORK_S = 0.5
"""How long after its first line ``calibrate_mounting`` is signalled, at work on the bag."""
NODES_STOP_CODE = 0


def free_port() -> int:
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        return probe.getsockname()[1]


def commands(folder: Path) -> dict[str, tuple[tuple[str, ...], int]]:
    """Each executable's command line on real work, with the exit code an interruption gives.
    ``calibrate_imu`` and ``calibrate_magnetometer`` are not among them: no committed bag holds
    a calibration run to keep them at work (they refuse any other at once); they stop through
    the same :func:`buoy_common.cli.interruptible` as the other offline commands.
    ``calibrate_mounting`` has a test of its own: its imports (the report's plotting stack) are
    the slowest, and started beside all the others it is not at work in time."""
    return {
        "fusion_node": (PARAMETERS, NODES_STOP_CODE),
        "compensation_node": (PARAMETERS, NODES_STOP_CODE),
        "current_node": (PARAMETERS, NODES_STOP_CODE),
        "imu_sim_node": (PARAMETERS, NODES_STOP_CODE),
        "gnss_sim_node": (PARAMETERS, NODES_STOP_CODE),
        "anemometer_sim_node": (PARAMETERS, NODES_STOP_CODE),
        "dvl_sim_node": (PARAMETERS, NODES_STOP_CODE),
        "truth_node": (PARAMETERS, NODES_STOP_CODE),
        "sim_clock_node": (PARAMETERS, NODES_STOP_CODE),
        "wind_echo": ((), NODES_STOP_CODE),
        "foxglove_bridge": (("--ros-args", "-p", f"port:={free_port()}"), NODES_STOP_CODE),
        "bag_recorder": ((str(folder / "recorded"), "--topics", "imu/data_raw"), 0),
        "bag_player": ((SEA_STATE,), 0),
        "run_scenario": (
            ("static", "--set", "duration_s=600", "--params-file", BUOY_PARAMETERS),
            INTERRUPTED_EXIT_CODE,
        ),
        "process_bag": ((SEA_STATE, str(folder / "processed")), INTERRUPTED_EXIT_CODE),
        "fuse_bag": ((SEA_STATE, str(folder / "fused")), INTERRUPTED_EXIT_CODE),
        "simulate_bag": (
            ("sea_state", str(folder / "simulated"), "--set", "duration_s=3600"),
            INTERRUPTED_EXIT_CODE,
        ),
    }


@pytest.mark.ros
@pytest.mark.parametrize(
    "signals",
    [(signal.SIGINT, signal.SIGINT), (signal.SIGTERM, signal.SIGINT)],
    ids=["SIGINT-SIGINT", "SIGTERM-SIGINT"],
)
def test_two_signals_in_quick_succession(signals, nodes, tmp_path):
    expected = commands(tmp_path)
    processes = {name: nodes.start(name, *arguments) for name, (arguments, _) in expected.items()}
    wait_for(
        lambda: all(
            nodes.log_of(process) or process.poll() is not None
            for name, process in processes.items()
            if name not in SILENT_AT_START
        ),
        STARTUP_TIMEOUT_S,
    )
    time.sleep(AT_WORK_S)
    finished_early = {name: p.returncode for name, p in processes.items() if p.poll() is not None}
    for process in processes.values():
        if process.poll() is None:
            process.send_signal(signals[0])
    time.sleep(SECOND_SIGNAL_AFTER_S)
    for process in processes.values():
        if process.poll() is None:
            process.send_signal(signals[1])
    failures = []
    for name, process in processes.items():
        try:
            code = process.wait(timeout=30.0)
        except Exception:
            process.kill()
            code = process.wait()
            failures.append(f"{name}: did not stop within 30 s")
        log = nodes.log_of(process)
        if name in finished_early:
            failures.append(f"{name}: exited {finished_early[name]} before the signals:\n{log}")
            continue
        if code != expected[name][1]:
            failures.append(f"{name}: exit code {code}, expected {expected[name][1]}:\n{log}")
        for sign in ("Traceback", "error_already_set", "terminate called", "Aborted"):
            if sign in log:
                failures.append(f"{name}: '{sign}' in its output:\n{log}")
    assert not failures, "\n\n".join(failures)
    assert not (tmp_path / "processed").exists(), "an interrupted process_bag left its output"
    assert not (tmp_path / "fused").exists(), "an interrupted fuse_bag left its output"


def test_calibrate_mounting_stops_on_two_signals(tmp_path):
    mounting = tmp_path / "mounting.yaml"
    command = (BIN / "calibrate_mounting", SEA_STATE, mounting, "--params-file", BUOY_PARAMETERS)
    process = subprocess.Popen(
        [str(part) for part in command],
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
    )
    try:
        # Its first line, the extrinsics, comes once its modules are imported and it is at work;
        # the fusion of the bag then takes it about two seconds on a quiet machine, longer on a
        # loaded one, so it is signalled well within that.
        first_line = process.stdout.readline()
        assert first_line.startswith("extrinsics:"), first_line
        time.sleep(CALIBRATION_AT_WORK_S)
        process.send_signal(signal.SIGTERM)
        time.sleep(SECOND_SIGNAL_AFTER_S)
        process.send_signal(signal.SIGINT)
        output = first_line + process.communicate(timeout=60.0)[0]
    finally:
        if process.poll() is None:
            process.kill()
            process.wait()
    assert process.returncode == INTERRUPTED_EXIT_CODE, output
    assert "Traceback" not in output, output
    assert not mounting.exists()
