"""The real record's valid corrected wind against the motion Edson's processing finds in it.

OOI's FDCHP test record (a moored flux buoy, sonic and motion pack at 10 Hz, no GNSS) is
processed as the README does, with the shipped column map and parameters and the shipped
validity limits. The Miller correction changes the horizontal speed of a sample by about the
platform's horizontal velocity (the rotation into ENU keeps the speed but for the tilt). Edson's
published processing of the same record bounds what that velocity plausibly is: the largest
change of horizontal speed his correction makes over the record. A valid sample of ours may
change the speed by no more than that plus three of its own horizontal standard deviations.
"""

from __future__ import annotations

import contextlib
import io

import numpy as np
import pytest
from test_real_record import (
    COLUMN_MAP,
    EDGE,
    PARAMS,
    PROCESSED_ROWS,
    RECORD,
    edson_corrected_wind_enu,
)

from buoy_common.bag_io import BagReader
from buoy_common.contract import WIND_RAW_TOPIC, WIND_TRUE_WITH_COVARIANCE_TOPIC
from buoy_common.import_records import import_records
from buoy_nav.config import fusion_config_from_files
from buoy_processing.bag_processing import process_bag
from buoy_processing.report.data import stamped_vectors
from wind_comp.config import compensator_config_from_files


def horizontal_speed_mps(vectors: np.ndarray) -> np.ndarray:
    return np.hypot(vectors[:, 0], vectors[:, 1])


@pytest.fixture(scope="module")
def processed(tmp_path_factory):
    """Measured wind (sonic axes), corrected wind (ENU) and its horizontal 1σ (the larger of
    the east and north standard deviations), rows 0 to PROCESSED_ROWS of the record."""
    directory = tmp_path_factory.mktemp("fdchp_uncertainty")
    shortened = directory / "fdchp_10min.dat"
    shortened.write_text("".join(RECORD.read_text().splitlines(keepends=True)[:PROCESSED_ROWS]))
    imported, output = directory / "fdchp", directory / "fdchp_processed"
    import_records(shortened, COLUMN_MAP, imported)
    parameter_files = [str(PARAMS)]
    with contextlib.redirect_stdout(io.StringIO()):
        process_bag(
            imported,
            output,
            fusion_config_from_files(parameter_files),
            compensator_config_from_files(parameter_files),
        )
    with BagReader(output) as reader:
        measured = stamped_vectors(reader, WIND_RAW_TOPIC).vectors
        corrected, sigma = [], []
        for message in reader.messages([WIND_TRUE_WITH_COVARIANCE_TOPIC]):
            twist = reader.decode(message).twist
            corrected.append((twist.twist.linear.x, twist.twist.linear.y, twist.twist.linear.z))
            sigma.append(np.sqrt(max(twist.covariance[0], twist.covariance[7])))
    return measured, np.array(corrected), np.array(sigma)


def edsons_largest_speed_change_mps() -> float:
    """The largest change of horizontal speed Edson's correction makes over the record."""
    edson = edson_corrected_wind_enu()
    rows = slice(EDGE, EDGE + len(edson))
    measured = np.loadtxt(RECORD, delimiter=",")[rows, 0:3] * 0.01  # cm/s
    return float(np.max(np.abs(horizontal_speed_mps(edson) - horizontal_speed_mps(measured))))


def test_no_valid_sample_changes_the_speed_beyond_the_plausible_platform_motion(processed):
    measured, corrected, sigma = processed
    valid = np.isfinite(corrected).all(axis=1)
    assert valid.sum() > 0.3 * len(valid), "too few valid samples to judge"
    change = np.abs(horizontal_speed_mps(corrected) - horizontal_speed_mps(measured))[valid]
    plausible = edsons_largest_speed_change_mps() + 3.0 * sigma[valid]
    beyond = change > plausible
    assert not beyond.any(), (
        f"{beyond.sum()} of {valid.sum()} valid samples change the horizontal speed by more "
        f"than Edson's largest change plus 3σ (worst {np.max(change - plausible):.2f} m/s over)"
    )
