"""The committed bags, the parameter files of the buoy that recorded each, and ``process_bag``'s
output of each, made once per test session.

Every bag but ``off_axis`` was recorded with the shipped geometry; ``off_axis`` with a buoy of
its own (``bags/off_axis.yaml``: antennas off the x axis at different heights, an anemometer off
the mast axis and turned about all three axes, sensor stamps that never line up).
``off_axis_heading_only`` is the same bag fused from the dual-antenna heading alone, the path
of a receiver that sends no baseline vector, where the heading depends on the tilt.
"""

from __future__ import annotations

import fcntl
import os
import shutil
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

from buoy_nav.config import fusion_config_from_files
from buoy_processing.bag_processing import process_bag
from error_budget import NavigationLimits, navigation_limits
from wind_comp.config import compensator_config_from_files

REPO = Path(__file__).resolve().parents[2]
BAGS_DIR = REPO / "bags"
BUOY_PARAMETERS = REPO / "src" / "buoy_common" / "config" / "buoy.yaml"
HEADING_ONLY = "/**:\n  ros__parameters:\n    fusion:\n      use_gnss_baseline: false\n"


@dataclass(frozen=True)
class Case:
    """A committed bag processed with the parameter files of the buoy that recorded it."""

    bag: str
    own_parameters: bool = False
    heading_only: bool = False

    @property
    def bag_path(self) -> Path:
        return BAGS_DIR / self.bag

    @property
    def buoy_parameter_files(self) -> list[Path]:
        """The parameter files that say where the sensors sit, in order."""
        own = [BAGS_DIR / f"{self.bag}.yaml"] if self.own_parameters else []
        return [BUOY_PARAMETERS, *own]

    def parameter_files(self, directory: Path) -> list[Path]:
        """Every parameter file of the processing, in order (a heading-only one is written
        into ``directory``)."""
        files = self.buoy_parameter_files
        if self.heading_only:
            heading_only = directory / "heading_only.yaml"
            heading_only.write_text(HEADING_ONLY)
            files.append(heading_only)
        return files

    @property
    def anemometer_position_body_m(self) -> tuple[float, ...]:
        return compensator_config_from_files(self.buoy_parameter_files).anemometer_position_body_m

    def navigation_limits(self) -> NavigationLimits:
        config = fusion_config_from_files(self.buoy_parameter_files)
        return navigation_limits(config.primary_antenna_body_m, config.secondary_antenna_body_m)


DEFAULT_GEOMETRY = (
    "static",
    "tilt_table",
    "wind_tunnel_10",
    "vertical_wind_5",
    "sea_state",
    "open_ocean",
)
CASES = {
    **{name: Case(name) for name in DEFAULT_GEOMETRY},
    "off_axis": Case("off_axis", own_parameters=True),
    "off_axis_heading_only": Case("off_axis", own_parameters=True, heading_only=True),
}


def made_once(tmp_path_factory, name: str, make: Callable[[Path], None]) -> Path:
    """The directory ``name`` that ``make(directory)`` fills, made once per test session even
    when pytest-xdist splits the session over workers: the first worker to ask makes it while
    holding a lock, the others wait for it and read it."""
    root = tmp_path_factory.getbasetemp()
    if os.environ.get("PYTEST_XDIST_WORKER"):
        root = root.parent  # the session's directory, above every worker's own
    out = root / "made_once" / name
    out.parent.mkdir(parents=True, exist_ok=True)
    done = out.parent / f"{name}.done"
    with open(out.parent / f"{name}.lock", "w") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)
        if not done.is_file():
            shutil.rmtree(out, ignore_errors=True)  # what a failed attempt left
            out.mkdir()
            make(out)
            done.touch()
    return out


def processed_bag(tmp_path_factory, name: str) -> Path:
    """``process_bag``'s output of case ``name``, made once per test session, with its NetCDF
    file beside it (:func:`processed_netcdf`)."""

    def make(directory: Path) -> None:
        case = CASES[name]
        files = case.parameter_files(directory)
        process_bag(
            case.bag_path,
            directory / "bag",
            fusion_config_from_files(files),
            compensator_config_from_files(files),
            overwrite=True,
            netcdf_path=directory / f"{name}.nc",
        )

    return made_once(tmp_path_factory, f"processed_{name}", make) / "bag"


def processed_netcdf(tmp_path_factory, name: str) -> Path:
    """The NetCDF file ``process_bag`` wrote beside :func:`processed_bag` of case ``name``."""
    return processed_bag(tmp_path_factory, name).with_name(f"{name}.nc")
