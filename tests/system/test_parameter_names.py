"""A misspelt parameter is an error naming it and the closest known name, live and offline;
the shared parameter files given to every node are accepted by every node."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

from ros_messages import wait_for

REPO = Path(__file__).resolve().parents[2]
BIN = Path(sys.executable).parent
SHARED_FILES = [
    REPO / "src" / "buoy_common" / "config" / "buoy.yaml",
    REPO / "src" / "sensor_sim" / "config" / "sim.yaml",
    REPO / "src" / "buoy_nav" / "config" / "fusion.yaml",
    REPO / "src" / "wind_comp" / "config" / "compensation.yaml",
    REPO / "src" / "wind_comp" / "config" / "current.yaml",
]
MISSPELT = {
    "anemometer.postion": "anemometer.position",
    "gnss.secondary_antena": "gnss.secondary_antenna",
    "fusion.gyro_noise_deg_sqrt_hr": "fusion.gyro_noise_deg_sqrt_h",
    "dvl.postion": "dvl.position",
}
STARTUP_TIMEOUT_S = 30.0


def misspelt_file(folder: Path, name: str) -> Path:
    group, key = name.split(".")
    path = folder / f"{name}.yaml"
    value = "0.2" if group == "fusion" else "[0.75, 0.0, 1.0]"
    path.write_text(f"/**:\n  ros__parameters:\n    {group}:\n      {key}: {value}\n")
    return path


@pytest.mark.parametrize("name", sorted(MISSPELT))
def test_offline_refuses_a_misspelt_parameter_naming_the_closest(name, tmp_path):
    params = ["--params-file", *map(str, SHARED_FILES[:1])]
    result = subprocess.run(
        [
            str(BIN / "process_bag"),
            str(REPO / "bags" / "static"),
            str(tmp_path / "out"),
            *params,
            "--params-file",
            str(misspelt_file(tmp_path, name)),
        ],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert result.returncode == 2, result.stdout + result.stderr
    assert f"unknown parameter '{name}' (did you mean '{MISSPELT[name]}'?)" in result.stderr
    assert len(result.stderr.strip().splitlines()) == 1, result.stderr
    assert not (tmp_path / "out").exists()


@pytest.mark.ros
@pytest.mark.parametrize(
    ("node", "name"),
    [
        ("fusion_node", "gnss.secondary_antena"),
        ("fusion_node", "fusion.gyro_noise_deg_sqrt_hr"),
        ("compensation_node", "anemometer.postion"),
        ("current_node", "dvl.postion"),
        ("anemometer_sim_node", "anemometer.postion"),
    ],
)
def test_node_refuses_a_misspelt_parameter_naming_the_closest(node, name, nodes, tmp_path):
    result = nodes.run(
        node,
        "--ros-args",
        "--params-file",
        str(SHARED_FILES[0]),
        "--params-file",
        str(misspelt_file(tmp_path, name)),
        timeout_s=STARTUP_TIMEOUT_S,
    )
    assert result.returncode == 2, result.stdout + result.stderr
    assert f"unknown parameter '{name}' (did you mean '{MISSPELT[name]}'?)" in result.stderr
    assert "Traceback" not in result.stderr


@pytest.mark.ros
def test_node_refuses_an_unknown_command_line_parameter(nodes):
    result = nodes.run(
        "compensation_node", "--ros-args", "-p", "compensation.max_nav_gap:=0.2", timeout_s=30.0
    )
    assert result.returncode == 2, result.stderr
    assert "did you mean 'compensation.max_nav_gap_s'?" in result.stderr


@pytest.mark.ros
def test_every_node_accepts_the_shared_files(nodes):
    arguments = ["--ros-args"]
    for path in SHARED_FILES:
        arguments += ["--params-file", str(path)]
    started = {
        node: nodes.start(node, *arguments)
        for node in (
            "fusion_node",
            "compensation_node",
            "current_node",
            "imu_sim_node",
            "gnss_sim_node",
            "anemometer_sim_node",
            "dvl_sim_node",
            "truth_node",
        )
    }
    # Each logs the extrinsics it uses once it runs.
    markers = {
        "fusion_node": "antennas [-0.75, 0.0, 1.0] m (primary)",
        "compensation_node": "anemometer/wind with nav/odometry into wind/true: sensor at "
        "[0.0, 0.0, 3.0] m",
        "current_node": "dvl/velocity with nav/odometry into current/velocity: sensor at "
        "[0.0, 0.0, -2.0] m",
    }
    for node, process in started.items():
        marker = markers.get(node)
        if marker is not None:
            assert wait_for(
                lambda marker=marker, process=process: marker in nodes.log_of(process),
                STARTUP_TIMEOUT_S,
            ), nodes.log_of(process)
    for node, process in started.items():
        assert process.poll() is None, f"{node} stopped:\n{nodes.log_of(process)}"
