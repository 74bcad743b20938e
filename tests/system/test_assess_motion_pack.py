"""``assess_motion_pack`` on OOI's FDCHP record (imported with the shipped map, as
``test_real_record`` does): the pack's gyro wander and the sea's heave, as measured on it by hand
(docs/real-records.md), and the command's refusals."""

from __future__ import annotations

import contextlib
import io
import re

import pytest
import yaml
from test_real_record import COLUMN_MAP, RECORD

from buoy_common.import_records import import_records
from buoy_nav.assess_motion_pack import main

SHORT_ROWS = 1200
"""Two minutes: too short for the wander below 0.01 Hz."""


def run(argv) -> tuple[int, str, str]:
    stdout, stderr = io.StringIO(), io.StringIO()
    with (
        contextlib.redirect_stdout(stdout),
        contextlib.redirect_stderr(stderr),
        pytest.raises(SystemExit) as exited,
    ):
        main(argv)
        raise SystemExit(0)
    return exited.value.code, stdout.getvalue(), stderr.getvalue()


@pytest.fixture(scope="module")
def imported_record(tmp_path_factory):
    directory = tmp_path_factory.mktemp("fdchp")
    with contextlib.redirect_stdout(io.StringIO()):
        import_records(RECORD, COLUMN_MAP, directory / "fdchp")
    return directory / "fdchp"


def test_the_records_gyro_wander_and_heave(imported_record, tmp_path):
    output = tmp_path / "pack.yaml"
    code, stdout, _ = run([str(imported_record), str(output)])
    assert code == 0, stdout
    parameters = yaml.safe_load(output.read_text())["/**"]["ros__parameters"]
    # By hand, from the rates of the pack's roll and pitch: 166 °/h below 0.01 Hz on both axes.
    # The command differences body rates instead; at the record's tilts (a few degrees) the two
    # differ by the tilt times the yaw rate, a few per cent: a tenth allowed.
    x, y = re.search(r"below 0\.01 Hz, 1 sigma: x (\d+), y (\d+)", stdout).groups()
    assert all(abs(float(axis) / 166.0 - 1.0) < 0.1 for axis in (x, y))
    # A Gauss-Markov model with that much below 0.01 Hz has at least as much in all.
    assert parameters["fusion.gyro_bias_instability_deg_h"] >= 166.0 * 0.9
    # The heave from the levelled vertical force: between the record's 0.1–2 Hz figure by hand
    # (0.10 m) and its figure from the magnitude of the force (0.23 m), which the waves' beat
    # inflates at the band's low end.
    assert 0.10 <= parameters["fusion.moored_position_sigma_horizontal_m"] < 0.23


def test_an_existing_output_needs_overwrite(imported_record, tmp_path):
    output = tmp_path / "pack.yaml"
    output.write_text("kept\n")
    code, _, stderr = run([str(imported_record), str(output)])
    assert code == 2 and "--overwrite" in stderr
    assert output.read_text() == "kept\n"
    code, _, _ = run([str(imported_record), str(output), "--overwrite"])
    assert code == 0 and "fusion.gyro_bias_instability_deg_h" in output.read_text()


def test_too_short_a_record_is_refused(tmp_path):
    shortened = tmp_path / "fdchp_2min.dat"
    shortened.write_text("".join(RECORD.read_text().splitlines(keepends=True)[:SHORT_ROWS]))
    with contextlib.redirect_stdout(io.StringIO()):
        import_records(shortened, COLUMN_MAP, tmp_path / "short")
    code, _, stderr = run([str(tmp_path / "short")])
    assert code == 2 and "at least 300 s" in stderr
