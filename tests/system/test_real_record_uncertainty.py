"""The real records' valid corrected wind against the motion Edson's processing finds in them.

Two records of OOI's FDCHP flux buoy (sonic and motion pack at 10 Hz, no GNSS): the text test
record of OOI's reference processing, and the instrument's own binary records of 18 December
2014 from 18:00 (``tests/data/ooi_fdchp/README.md``), each imported with its shipped column map
and processed with the shipped parameters and validity limits. The Miller correction changes
the horizontal speed of a sample by about the platform's horizontal velocity (the rotation into
ENU keeps the speed but for the tilt). Edson's published processing of the same record bounds
what that velocity plausibly is: the largest change of horizontal speed his correction makes
over the record. A valid sample of ours may change the speed by no more than that plus three of
its own horizontal standard deviations.
"""

from __future__ import annotations

import contextlib
import io

import numpy as np
import pytest
from test_real_record import PARAMS

from buoy_common.bag_io import BagReader
from buoy_common.contract import WIND_RAW_TOPIC, WIND_TRUE_WITH_COVARIANCE_TOPIC
from buoy_common.import_records import import_records
from buoy_nav.config import fusion_config_from_files
from buoy_processing.bag_processing import process_bag
from buoy_processing.report.data import stamped_vectors
from tools.ooi_records import (
    OOI_RECORDS,
    edsons_largest_speed_change_mps,
    first_rows,
    horizontal_speed_mps,
)
from wind_comp.config import compensator_config_from_files

TEST_RECORD_ROWS = 6000
"""The test record's first 10 minutes: enough to judge, in test time. The binary record of
2014-12-18 is judged whole."""


@pytest.fixture(scope="module", params=sorted(OOI_RECORDS))
def processed(request, tmp_path_factory):
    """The record, measured wind (sonic axes), corrected wind (ENU) and its horizontal 1σ (the
    larger of the east and north standard deviations) of every processed row."""
    real = OOI_RECORDS[request.param]
    rows = TEST_RECORD_ROWS if request.param == "test_record" else None
    directory = tmp_path_factory.mktemp("fdchp_uncertainty")
    imported, output = directory / "fdchp", directory / "fdchp_processed"
    with contextlib.redirect_stdout(io.StringIO()):
        import_records(first_rows(real, rows, directory), real.column_map, imported)
        process_bag(
            imported,
            output,
            fusion_config_from_files([str(PARAMS)]),
            compensator_config_from_files([str(PARAMS)]),
        )
    with BagReader(output) as reader:
        measured = stamped_vectors(reader, WIND_RAW_TOPIC).vectors
        corrected, sigma = [], []
        for message in reader.messages([WIND_TRUE_WITH_COVARIANCE_TOPIC]):
            twist = reader.decode(message).twist
            corrected.append((twist.twist.linear.x, twist.twist.linear.y, twist.twist.linear.z))
            sigma.append(np.sqrt(max(twist.covariance[0], twist.covariance[7])))
    return real, measured, np.array(corrected), np.array(sigma)


def test_no_valid_sample_changes_the_speed_beyond_the_plausible_platform_motion(processed):
    real, measured, corrected, sigma = processed
    valid = np.isfinite(corrected).all(axis=1)
    assert valid.sum() > 0.3 * len(valid), "too few valid samples to judge"
    change = np.abs(horizontal_speed_mps(corrected) - horizontal_speed_mps(measured))[valid]
    plausible = edsons_largest_speed_change_mps(real) + 3.0 * sigma[valid]
    beyond = change > plausible
    assert not beyond.any(), (
        f"{beyond.sum()} of {valid.sum()} valid samples change the horizontal speed by more "
        f"than Edson's largest change plus 3σ (worst {np.max(change - plausible):.2f} m/s over)"
    )
