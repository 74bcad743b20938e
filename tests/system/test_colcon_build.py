"""The workspace builds with colcon like any ament_python workspace, and what it installs runs."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[2]
BIN = Path(sys.executable).parent
PACKAGES = ("buoy_common", "sensor_sim", "buoy_nav", "wind_comp")


@pytest.fixture(scope="module")
def install_base(tmp_path_factory):
    base = tmp_path_factory.mktemp("colcon")
    result = subprocess.run(
        [
            str(BIN / "colcon"),
            "--log-base",
            str(base / "log"),
            "build",
            "--symlink-install",
            "--base-paths",
            str(REPO / "ros2_ws" / "src"),
            "--build-base",
            str(base / "build"),
            "--install-base",
            str(base / "install"),
        ],
        capture_output=True,
        text=True,
        timeout=600,
        cwd=base,
    )
    assert result.returncode == 0, result.stdout[-3000:] + result.stderr[-3000:]
    return base / "install"


def test_colcon_installs_packages_with_ament_index_and_config(install_base):
    for package in PACKAGES:
        assert (install_base / "share/ament_index/resource_index/packages" / package).exists() or (
            install_base / package / "share/ament_index/resource_index/packages" / package
        ).exists()
        assert (install_base / package / "share" / package / "package.xml").exists()
    assert (install_base / "buoy_common/share/buoy_common/config/buoy.yaml").exists()
    assert (install_base / "sensor_sim/share/sensor_sim/config/sim.yaml").exists()


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
