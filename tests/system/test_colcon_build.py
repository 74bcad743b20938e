"""The workspace builds with colcon like any ament_python workspace, what it installs runs, and
``colcon test`` finds and runs the packages' unit tests."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[2]
BIN = Path(sys.executable).parent
PACKAGES = ("buoy_common", "sensor_sim", "buoy_nav", "wind_comp", "buoy_processing")


def colcon(
    base: Path, verb: str, *arguments: str, ament_prefix_path: bool = True
) -> subprocess.CompletedProcess:
    """``colcon VERB`` on the workspace, with build, install and log bases under ``base``;
    ``AMENT_PREFIX_PATH`` left out of its environment unless ``ament_prefix_path``."""
    environment = dict(os.environ)
    if not ament_prefix_path:
        environment.pop("AMENT_PREFIX_PATH", None)
    return subprocess.run(
        [
            str(BIN / "colcon"),
            "--log-base",
            str(base / "log"),
            verb,
            "--base-paths",
            str(REPO / "ros2_ws" / "src"),
            "--build-base",
            str(base / "build"),
            "--install-base",
            str(base / "install"),
            *arguments,
        ],
        capture_output=True,
        text=True,
        timeout=600,
        cwd=base,
        env=environment,
    )


@pytest.fixture(scope="module")
def workspace(tmp_path_factory):
    """The base of a colcon build of the workspace (build/, install/, log/), built as
    `make colcon` builds it: without a single warning."""
    base = tmp_path_factory.mktemp("colcon")
    # The venv is no colcon install space: colcon would warn that it lacks local_setup files.
    result = colcon(base, "build", "--symlink-install", ament_prefix_path=False)
    output = result.stdout + result.stderr
    assert result.returncode == 0, output[-6000:]
    assert "WARNING" not in output and "Warning" not in output, output[-6000:]
    return base


@pytest.fixture(scope="module")
def install_base(workspace):
    return workspace / "install"


def test_colcon_installs_packages_with_ament_index_and_config(install_base):
    for package in PACKAGES:
        assert (install_base / "share/ament_index/resource_index/packages" / package).exists() or (
            install_base / package / "share/ament_index/resource_index/packages" / package
        ).exists()
        assert (install_base / package / "share" / package / "package.xml").exists()
    assert (install_base / "buoy_common/share/buoy_common/config/buoy.yaml").exists()
    assert (install_base / "sensor_sim/share/sensor_sim/config/sim.yaml").exists()
    # What `ros2 launch` and Foxglove look for.
    assert (install_base / "wind_comp/share/wind_comp/launch/processing.launch.py").exists()
    assert (install_base / "sensor_sim/share/sensor_sim/launch/demo.launch.py").exists()
    assert (install_base / "buoy_common/share/buoy_common/config/foxglove_layout.json").exists()


def test_installed_executable_runs_where_ros2_run_looks(install_base, tmp_path):
    # `ros2 run sensor_sim simulate_bag` executes install/sensor_sim/lib/sensor_sim/simulate_bag
    executable = install_base / "sensor_sim/lib/sensor_sim/simulate_bag"
    assert executable.exists()
    result = subprocess.run(
        [sys.executable, str(executable), "static", str(tmp_path / "bag"), "--set", "duration_s=2"],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert result.returncode == 0, result.stderr
    assert (tmp_path / "bag" / "metadata.yaml").exists()
    for node in (
        "imu_sim_node",
        "gnss_sim_node",
        "anemometer_sim_node",
        "truth_node",
        "sim_clock_node",
        "bag_recorder",
        "bag_player",
    ):
        assert (install_base / "sensor_sim/lib/sensor_sim" / node).exists(), node


def test_the_offline_commands_are_the_applications(install_base):
    # `ros2 run buoy_processing process_bag`: the offline commands belong to the application.
    for command in (
        "fuse_bag",
        "process_bag",
        "process_archive",
        "wind_report",
        "calibrate_mounting",
    ):
        assert (install_base / "buoy_processing/lib/buoy_processing" / command).exists(), command
        for package in ("buoy_nav", "wind_comp"):
            assert not (install_base / package / "lib" / package / command).exists(), command


@pytest.mark.long
def test_colcon_test_runs_the_unit_tests_of_a_package(workspace, tmp_path):
    # One package, the smallest: `make test` runs every package's unit tests through pytest
    # already (testpaths); this shows that colcon finds them too, as a ROS user runs them.
    result = colcon(
        workspace, "test", "--packages-select", "buoy_common", "--return-code-on-test-failure"
    )
    assert result.returncode == 0, result.stdout[-3000:] + result.stderr[-3000:]
    report = subprocess.run(
        [str(BIN / "colcon"), "test-result", "--test-result-base", str(workspace / "build")],
        capture_output=True,
        text=True,
        timeout=60,
    )
    unit_tests = REPO / "src" / "buoy_common" / "test"
    collected = subprocess.run(
        [
            sys.executable,
            "-m",
            "pytest",
            "--collect-only",
            "-q",
            "-p",
            "no:cacheprovider",
            unit_tests,
        ],
        capture_output=True,
        text=True,
        timeout=120,
        cwd=REPO,
    )
    n_tests = sum("::" in line for line in collected.stdout.splitlines())
    assert n_tests > 0, collected.stdout
    assert f"{n_tests} tests, 0 errors, 0 failures" in report.stdout, report.stdout

    # And a failing test fails the command (plain `colcon test` would return 0).
    failing = tmp_path / "test_failing.py"
    failing.write_text("def test_fails():\n    assert False\n")
    result = colcon(
        workspace,
        "test",
        "--packages-select",
        "buoy_common",
        "--return-code-on-test-failure",
        "--pytest-args",
        str(failing),
    )
    assert result.returncode != 0, result.stdout[-3000:]
