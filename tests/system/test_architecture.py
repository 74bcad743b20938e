"""The structure the design rests on, checked on the source tree.

The simulator is the independent witness of the estimator, so it never imports it; rclpy lives
in node modules only, so every algorithm runs offline unchanged; every package declares the
packages it imports; and a shared parameter is refused or accepted alike everywhere.
"""

import ast
import sys
import xml.etree.ElementTree as ET
from pathlib import Path

import pytest

from buoy_nav.config import ConfigError, FusionConfig
from sensor_sim.streams import Extrinsics

REPO = Path(__file__).resolve().parents[2]
PACKAGES = ("buoy_common", "sensor_sim", "buoy_nav", "wind_comp")
STANDARD_LIBRARY = set(sys.stdlib_module_names)
# Python distributions named differently from their package.xml keys.
ROSDEP_KEYS = {
    "numpy": "python3-numpy",
    "numba": "python3-numba",
    "scipy": "python3-scipy",
    "yaml": "python3-yaml",
    "rosbags": "python3-rosbags",
    "zstandard": "python3-zstandard",
    "matplotlib": "python3-matplotlib",
    "mcap": "python3-mcap",
    "mcap_ros2": "python3-mcap-ros2-support",
    "tqdm": "python3-tqdm",
    "foxglove": "python3-foxglove-sdk-pip",
    "ppigrf": "python3-ppigrf-pip",
    "pygeomag": "python3-pygeomag-pip",
    "distributed": "python3-distributed-pip",
    "pyarrow": "python3-pyarrow-pip",
    "xarray": "python3-xarray",
}


def _modules(package: str):
    return sorted((REPO / "src" / package / package).rglob("*.py"))


def _imported_top_levels(path: Path) -> set[str]:
    names = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.Import):
            names |= {alias.name.split(".")[0] for alias in node.names}
        elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
            names.add(node.module.split(".")[0])
    return names


def test_the_simulator_never_imports_the_estimator_or_the_wind_core():
    offenders = {
        str(path.relative_to(REPO)): sorted(_imported_top_levels(path) & {"buoy_nav", "wind_comp"})
        for path in _modules("sensor_sim")
    }
    assert {k: v for k, v in offenders.items() if v} == {}


def test_rclpy_is_imported_by_node_modules_only():
    offenders = [
        str(path.relative_to(REPO))
        for package in PACKAGES
        for path in _modules(package)
        if "rclpy" in _imported_top_levels(path) and not path.name.endswith("_node.py")
    ]
    assert offenders == []


def test_buoy_common_depends_on_no_other_package_of_the_suite():
    offenders = {
        str(path.relative_to(REPO)): sorted(_imported_top_levels(path) & set(PACKAGES[1:]))
        for path in _modules("buoy_common")
    }
    assert {k: v for k, v in offenders.items() if v} == {}


@pytest.mark.parametrize("package", PACKAGES)
def test_package_xml_declares_what_the_package_imports(package):
    manifest = ET.parse(REPO / "src" / package / "package.xml").getroot()
    declared = {element.text for element in manifest if element.tag.endswith("depend")}
    imported = set().union(*(_imported_top_levels(path) for path in _modules(package)))
    missing = []
    for name in sorted(imported - STANDARD_LIBRARY - {package}):
        key = ROSDEP_KEYS.get(name, name)
        if key not in declared:
            missing.append(f"{name} ({key})")
    assert missing == []


def test_the_simulator_and_the_filter_share_one_antenna_rule():
    # A 0.07 m baseline once ran in the simulator and stopped the fusion node at start-up.
    close = {"primary_antenna_body_m": (0.0, 0.0, 1.0), "secondary_antenna_body_m": (0.07, 0, 1)}
    with pytest.raises(ValueError, match=r"gnss\.secondary_antenna"):
        Extrinsics(**close)
    with pytest.raises(ConfigError, match=r"gnss\.secondary_antenna"):
        FusionConfig(**close)
    vertical = {"primary_antenna_body_m": (0.0, 0.0, 1.0), "secondary_antenna_body_m": (0, 0, 1.5)}
    Extrinsics(**vertical)
    FusionConfig(**vertical)


@pytest.mark.parametrize("package", PACKAGES)
def test_every_executable_is_the_module_of_its_name(package):
    # A node module carries the suffix the rclpy rule asks for; a command's module holds its
    # command line, named as the command is.
    setup = (REPO / "src" / package / "setup.py").read_text()
    scripts = dict(
        (name.strip(), target.strip())
        for name, target in (
            line.strip().strip('",').split("=") for line in setup.splitlines() if ":main" in line
        )
    )
    mismatched = {
        name: target
        for name, target in scripts.items()
        if target.split(":")[0] not in (f"{package}.{name}", f"{package}.{name}_node")
    }
    assert mismatched == {}


def test_a_parallel_run_keeps_a_module_on_one_worker(request):
    """`make test` relies on pytest-xdist's groups: the live tests one after another on one
    worker, a module's fixtures made once. A pytest that drops the groups silently would let
    live nodes starve each other and every fixture be made twice."""
    if not getattr(request.config.option, "loadgroup", False):
        pytest.skip("not a pytest-xdist run with --dist loadgroup")
    assert request.node.nodeid.endswith("@tests/system/test_architecture.py"), request.node.nodeid
