"""The OOI FDCHP records the repository carries, each with the column map that imports it and
Edson's corrected wind of it (``tests/data/ooi_fdchp/README.md``), and the bound that wind puts
on the platform's motion."""

from __future__ import annotations

from pathlib import Path
from typing import NamedTuple

import numpy as np

from buoy_common.records.column_map import load_column_map
from buoy_common.records.decoding import read_table

REPO = Path(__file__).resolve().parent.parent
DATA = REPO / "tests/data/ooi_fdchp"
MAPS = REPO / "src/buoy_common/config/records"
EDGE_ROWS = 300
"""Edson keeps rows 300 to 11 700 (30 s trimmed at each end of the first 12 000)."""
ENU_FROM_NWU = np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])


class OoiRecord(NamedTuple):
    record: Path
    column_map: Path
    edson_wind_nwu: Path
    """Edson's corrected wind of rows 300..11 699 (North, West, Up; m/s; float64), written by
    ``python -m tools.edson_fdchp RECORD --column-map MAP --save-wind NPY``."""


OOI_RECORDS = {
    "test_record": OoiRecord(
        DATA / "fdchp_test_dp.dat", MAPS / "ooi_fdchp.yaml", DATA / "edson_corrected_wind_nwu.npy"
    ),
    "2014-12-18T18": OoiRecord(
        DATA / "fdchp_20141218_180000.dat",
        MAPS / "ooi_fdchp_raw.yaml",
        DATA / "edson_corrected_wind_nwu_20141218_180000.npy",
    ),
}
"""OOI's text test record, and the instrument's own binary records of 18 December 2014 from
18:00."""


def horizontal_speed_mps(vectors: np.ndarray) -> np.ndarray:
    return np.hypot(vectors[:, 0], vectors[:, 1])


def edsons_largest_speed_change_mps(record: OoiRecord) -> float:
    """The largest change of horizontal speed (m/s) Edson's correction makes over the samples
    he keeps: what his processing says the platform's horizontal motion plausibly is."""
    edson = np.load(record.edson_wind_nwu) @ ENU_FROM_NWU.T
    table = read_table(record.record, load_column_map(record.column_map))
    kept = slice(EDGE_ROWS, EDGE_ROWS + len(edson))
    measured_cm_s = np.column_stack([table[f"anemometer.{axis}"][kept] for axis in "uvw"])
    measured = measured_cm_s * 0.01
    return float(np.max(np.abs(horizontal_speed_mps(edson) - horizontal_speed_mps(measured))))


def first_rows(record: OoiRecord, rows: int | None, directory: Path) -> Path:
    """The record cut to its first ``rows`` rows (text lines, or fixed-size binary records),
    written into ``directory``; the record itself for None."""
    if rows is None:
        return record.record
    cut = directory / record.record.name
    layout = load_column_map(record.column_map).record_layout
    if layout is None:
        lines = record.record.read_text().splitlines(keepends=True)
        cut.write_text("".join(lines[:rows]))
    else:
        cut.write_bytes(record.record.read_bytes()[: rows * layout.itemsize])
    return cut
