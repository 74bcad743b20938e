"""The structure the design rests on, checked on the source tree.

The simulator is the independent witness of the estimator, so it never imports it; rclpy lives
in node modules only, so every algorithm runs offline unchanged; the packages stand in layers,
each importing only those below it, the offline application on top, so the live nodes carry
none of its weight; every package declares the packages it imports; and a shared parameter is
refused or accepted alike everywhere.
"""

import ast
import json
import subprocess
import sys
import xml.etree.ElementTree as ET
from pathlib import Path

import pytest

from buoy_nav.config import ConfigError, FusionConfig
from sensor_sim.streams import Extrinsics

REPO = Path(__file__).resolve().parents[2]
PACKAGES = ("buoy_common", "sensor_sim", "buoy_nav", "wind_comp", "buoy_processing")
# A package imports only packages of a lower layer: the simulator and the estimator stand side
# by side on the contract, blind to each other; the wind correction uses the estimator's
# rotations; the offline application uses them all and nothing uses it.
LAYERS = {"buoy_common": 0, "sensor_sim": 1, "buoy_nav": 1, "wind_comp": 2, "buoy_processing": 3}
# What the offline application needs and a live node must not pay for at start-up.
APPLICATION_ONLY_MODULES = (
    "dask",
    "distributed",
    "pyarrow",
    "xarray",
    "netCDF4",
    "matplotlib",
    "tqdm",
)
STANDARD_LIBRARY = set(sys.stdlib_module_names)
# Python distributions named differently from their package.xml keys.
ROSDEP_KEYS = {
    "numpy": "python3-numpy",
    "numba": "python3-numba",
    "llvmlite": "python3-llvmlite",
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
    "netCDF4": "python3-netcdf4",
    "dask": "python3-dask",
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


def test_the_simulator_never_imports_the_estimator_the_wind_core_or_the_application():
    forbidden = {"buoy_nav", "wind_comp", "buoy_processing"}
    offenders = {
        str(path.relative_to(REPO)): sorted(_imported_top_levels(path) & forbidden)
        for path in _modules("sensor_sim")
    }
    assert {k: v for k, v in offenders.items() if v} == {}


def test_no_package_imports_a_package_of_its_layer_or_above():
    offenders = {
        str(path.relative_to(REPO)): sorted(
            name
            for name in _imported_top_levels(path) & set(PACKAGES) - {package}
            if LAYERS[name] >= LAYERS[package]
        )
        for package in PACKAGES
        for path in _modules(package)
    }
    assert {k: v for k, v in offenders.items() if v} == {}


def test_the_layers_are_the_packages():
    assert set(LAYERS) == set(PACKAGES)
    manifests = (REPO / "src").glob("*/package.xml")
    assert sorted(path.parent.name for path in manifests) == sorted(PACKAGES)


def loaded_by_importing(modules: list[str], watched: list[str]) -> list[str]:
    """Which of the ``watched`` modules a fresh interpreter has loaded once it imported
    ``modules``."""
    probe = (
        "import importlib, json, sys\n"
        f"for name in {modules!r}:\n"
        "    importlib.import_module(name)\n"
        f"print(json.dumps(sorted(m for m in {watched!r} if m in sys.modules)))\n"
    )
    completed = subprocess.run(
        [sys.executable, "-c", probe], capture_output=True, text=True, timeout=120
    )
    assert completed.returncode == 0, completed.stderr[-3000:]
    return json.loads(completed.stdout)


def test_the_wind_correction_runs_live_without_the_applications_dependencies():
    # compensation_node on a buoy's computer needs numpy and scipy, not the NetCDF, Parquet,
    # Dask and plotting stack of the offline application.
    live_modules = sorted(
        f"wind_comp.{path.stem}" for path in _modules("wind_comp") if path.stem != "__init__"
    )
    assert "wind_comp.compensation_node" in live_modules
    assert loaded_by_importing(live_modules, list(APPLICATION_ONLY_MODULES)) == []


def test_processing_records_does_not_load_the_reports_plotting():
    # matplotlib takes some 0.6 s to import: a run that writes bags, tables and NetCDF files
    # must not pay for the figures only wind_report draws.
    modules = [
        "buoy_processing.process_bag",
        "buoy_processing.process_archive",
        "buoy_processing.fuse_bag",
        "buoy_processing.netcdf_output",
    ]
    assert loaded_by_importing(modules, ["matplotlib"]) == []


def test_the_wind_correction_declares_none_of_the_applications_dependencies():
    manifest = ET.parse(REPO / "src" / "wind_comp" / "package.xml").getroot()
    declared = {element.text for element in manifest if element.tag.endswith("depend")}
    heavy = {ROSDEP_KEYS[name] for name in APPLICATION_ONLY_MODULES}
    assert declared & heavy == set()


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
