"""The reference: Edson et al.'s direct covariance flux processing, as OOI publishes it.

OOI's reference processing of the FDCHP flux buoy record (Edson et al. 1998, "Direct covariance
flux estimates from mobile platforms at sea", JTECH 15; the OOI data product specification
1341-00280) is ``ion_functions/data/fdc_functions.py`` of ``oceanobservatories/ion-functions``
(Apache-2.0). This harness does not copy it: it loads the module from a checkout given by
``--ion-functions DIR`` or the ``ION_FUNCTIONS_DIR`` environment variable, e.g.

    git clone https://github.com/oceanobservatories/ion-functions out/ion-functions

and runs it on a record. The module was written for Python 2 and the scipy of 2014: two names it
uses have since left scipy (``scipy.sin``/``scipy.cos``, numpy's functions re-exported, and
``scipy.integrate.cumtrapz``, renamed ``cumulative_trapezoid``); the harness hands the module
those same functions under the old names, nothing else. :func:`check_published_fluxes` holds the
result to the fluxes ion-functions' own test publishes for the record before anything is
compared with it.

    python -m tools.edson_fdchp RECORD [--column-map YAML] [--ion-functions DIR] [--save-wind NPY]
"""

from __future__ import annotations

import argparse
import importlib.util
import os
import sys
import types
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import scipy.integrate

from buoy_common.records.column_map import load_column_map
from buoy_common.records.decoding import read_table

MODULE_PATH = Path("ion_functions/data/fdc_functions.py")
LATITUDE_DEG = 38.5
"""The latitude ion-functions' test gives the record (its gravity)."""
EDGE_S = 30.0
"""Edson trims 30 s at each end of the processed record before the fluxes."""
RATE_HZ = 10.0
PUBLISHED_FLUXES = (-0.350371566926, 0.115496951668, -0.008274161328)
"""u'w' (m²/s²), v'w' (m²/s²), w'Ts' (K m/s) of the test record: ion-functions' test, which
holds its Python port to Edson's MATLAB at 1e-4 (relative for the momentum fluxes, absolute for
the buoyancy flux)."""
PUBLISHED_TOLERANCE = (1e-4 * 0.350371566926, 1e-4 * 0.115496951668, 1e-4)
"""Absolute: ion-functions' test holds u'w' and v'w' at a relative 1e-4, w'Ts' at 1e-4."""


RECORD_MAPS = Path(__file__).resolve().parent.parent / "src/buoy_common/config/records"
TEXT_MAP = RECORD_MAPS / "ooi_fdchp.yaml"
L0_FIELDS = (
    *(f"anemometer.{axis}" for axis in "uvw"),
    "anemometer.speed_of_sound",
    *(f"imu.angular_rate.{axis}" for axis in "xyz"),
    *(f"imu.specific_force.{axis}" for axis in "xyz"),
    *(f"ahrs.{angle}" for angle in ("roll", "pitch", "heading")),
)
"""The column map's fields in the order of Edson's 13 L0 columns."""
TEST_RECORD = "fdchp_test_dp.dat"
"""The record whose fluxes ion-functions' test publishes: the harness is checked on it."""


class ReferenceUnavailableError(RuntimeError):
    """No checkout of ion-functions was given or found."""


def ion_functions_dir(given: str | None = None) -> Path:
    """The ion-functions checkout: ``given``, else ``$ION_FUNCTIONS_DIR``, else
    ``out/ion-functions`` of this repository; ReferenceUnavailableError if none holds the module."""
    repository = Path(__file__).resolve().parent.parent
    candidates = [given, os.environ.get("ION_FUNCTIONS_DIR"), repository / "out/ion-functions"]
    for candidate in candidates:
        if candidate and (Path(candidate) / MODULE_PATH).is_file():
            return Path(candidate)
    raise ReferenceUnavailableError(
        "Edson's processing needs a checkout of oceanobservatories/ion-functions: "
        "git clone https://github.com/oceanobservatories/ion-functions out/ion-functions "
        "(or set ION_FUNCTIONS_DIR)"
    )


def load_reference(directory: Path) -> types.ModuleType:
    """``fdc_functions`` from the checkout, with the two scipy names of 2014 it calls."""
    spec = importlib.util.spec_from_file_location("fdc_functions", directory / MODULE_PATH)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    module.sp = types.SimpleNamespace(sin=np.sin, cos=np.cos)
    module.integrate = types.SimpleNamespace(cumtrapz=scipy.integrate.cumulative_trapezoid)
    return module


@dataclass
class ReferenceRun:
    """Edson's outputs for one record: the fluxes and the corrected wind (North, West, Up;
    m/s) of the samples he keeps, ``kept`` (row indices of the record)."""

    fluxes: tuple[float, float, float]
    wind_nwu_mps: np.ndarray
    kept: slice


def run_reference(record: np.ndarray, module: types.ModuleType) -> ReferenceRun:
    """Edson's ``fdc_flux_and_wind`` on the (N, 13) L0 record, with the timestamps and the
    latitude that ion-functions' test gives it."""
    count = record.shape[0]
    timestamps = 400000.0 + np.arange(1.0, count + 1) / RATE_HZ
    columns = [np.array(record[:, i], dtype=float) for i in range(13)]
    u, v, w, sound, rate_x, rate_y, rate_z, acc_x, acc_y, acc_z, _, _, heading = columns
    latitude = np.full(count, LATITUDE_DEG)
    fluxes, winds = module.fdc_flux_and_wind(
        timestamps, u, v, w, sound, heading, rate_x, rate_y, rate_z, acc_x, acc_y, acc_z, latitude
    )
    edge = int(EDGE_S * RATE_HZ)
    packet = 12000  # his processing takes the first 12 000 rows of a 20-min record
    wind = np.column_stack([np.asarray(winds[axis][0]) for axis in range(3)])
    return ReferenceRun(
        fluxes=tuple(float(np.ravel(f)[0]) for f in fluxes),
        wind_nwu_mps=wind,
        kept=slice(edge, packet - edge),
    )


def check_published_fluxes(run: ReferenceRun) -> None:
    """RuntimeError unless the harness reproduces the fluxes ion-functions publishes."""
    for name, got, published, tolerance in zip(
        ("u'w'", "v'w'", "w'Ts'"), run.fluxes, PUBLISHED_FLUXES, PUBLISHED_TOLERANCE, strict=True
    ):
        if abs(got - published) > tolerance:
            raise RuntimeError(
                f"Edson's processing gives {name} = {got:.9f}, ion-functions publishes "
                f"{published:.9f}: the harness does not reproduce the reference"
            )


def load_record(path: str | Path, column_map: str | Path = TEXT_MAP) -> np.ndarray:
    """The (N, 13) L0 record in Edson's order and the logger's own units, read by the column
    map the suite imports it with (OOI's text test record, or the instrument's binary records
    with ``ooi_fdchp_raw.yaml``)."""
    loaded = load_column_map(column_map)
    table = read_table(path, loaded)
    return np.column_stack([table[name] for name in L0_FIELDS])


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(prog="edson_fdchp", description=__doc__.split("\n")[0])
    parser.add_argument("record", help="the FDCHP L0 record (fdchp_test_dp.dat)")
    parser.add_argument(
        "--column-map",
        default=str(TEXT_MAP),
        help="the record's column map (default: the text test record's, ooi_fdchp.yaml)",
    )
    parser.add_argument("--ion-functions", help="checkout of oceanobservatories/ion-functions")
    parser.add_argument(
        "--save-wind",
        metavar="NPY",
        help="also write his corrected wind of the kept samples (North, West, Up; m/s, float64)",
    )
    arguments = parser.parse_args(argv)
    try:
        module = load_reference(ion_functions_dir(arguments.ion_functions))
    except ReferenceUnavailableError as error:
        print(f"edson_fdchp: {error}", file=sys.stderr)
        sys.exit(2)
    run = run_reference(load_record(arguments.record, arguments.column_map), module)
    published = Path(arguments.record).name == TEST_RECORD
    if published:
        check_published_fluxes(run)
    if arguments.save_wind:
        np.save(arguments.save_wind, run.wind_nwu_mps)
    for name, value, reference in zip(
        ("u'w'", "v'w'", "w'Ts'"), run.fluxes, PUBLISHED_FLUXES, strict=True
    ):
        said = f"   published {reference: .12f}" if published else ""
        print(f"{name:6s} {value: .12f}{said}")
    if not published:
        print(f"(no fluxes are published for this record; the harness is checked on {TEST_RECORD})")


if __name__ == "__main__":
    main()
