"""``calibrate_mounting`` on the simulator: a sonic mounted a few degrees off in roll, pitch and
yaw, processed with the nominal (zero) mounting, is found to within 0.2° of how it was mounted;
the parameter file it writes, given to ``process_bag``, removes the mean vertical wind the
misalignment made. In the committed turbulent ``sea_state`` recording, three minutes cannot
determine the angles, and the command says so without writing anything.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import yaml

from buoy_common.bag_io import BagReader
from buoy_common.contract import WIND_TRUE_TOPIC
from buoy_nav.config import fusion_config_from_files
from buoy_processing import calibrate_mounting
from buoy_processing.bag_processing import process_bag
from buoy_processing.report.data import stamped_vectors
from sensor_sim import simulate_bag
from wind_comp.config import compensator_config_from_files

REPO = Path(__file__).resolve().parents[2]
BUOY_PARAMETERS = REPO / "src" / "buoy_common" / "config" / "buoy.yaml"
MOUNTED_RPY_DEG = (1.5, -2.0, 3.0)
TOLERANCE_DEG = 0.2
# The sea_state motion (roll 10°, pitch 5°, yaw 5°, the mooring turning ±40°) in a steady wind:
# the motion observes every angle; turbulence, which only adds noise, is left out so that three
# minutes suffice.
SCENARIO_SETTINGS = ("duration_s=180", "wind.turbulence_intensity=0.0")


def run(module, argv: list[str]) -> int:
    try:
        module.main(argv)
    except SystemExit as exit_:
        return int(exit_.code or 0)
    return 0


@pytest.fixture(scope="module")
def misaligned_bag(tmp_path_factory) -> Path:
    folder = tmp_path_factory.mktemp("misaligned")
    mounting = folder / "mounted.yaml"
    mounting.write_text(
        yaml.safe_dump(
            {"/**": {"ros__parameters": {"anemometer": {"rpy_deg": list(MOUNTED_RPY_DEG)}}}}
        )
    )
    bag = folder / "sea_state_misaligned"
    settings = [argument for setting in SCENARIO_SETTINGS for argument in ("--set", setting)]
    argv = ["sea_state", str(bag), *settings, "--params-file", str(BUOY_PARAMETERS)]
    assert run(simulate_bag, [*argv, "--params-file", str(mounting)]) == 0
    return bag


def mean_vertical_wind_mps(bag: Path, parameter_files: list[Path], out: Path) -> float:
    process_bag(
        bag,
        out,
        fusion_config_from_files(parameter_files),
        compensator_config_from_files(parameter_files),
    )
    with BagReader(out) as reader:
        corrected = stamped_vectors(reader, WIND_TRUE_TOPIC).vectors
    return float(np.nanmean(corrected[:, 2]))


def test_the_mounting_angles_are_recovered(misaligned_bag, tmp_path, capsys):
    out_yaml = tmp_path / "mounting.yaml"
    argv = [str(misaligned_bag), str(out_yaml), "--params-file", str(BUOY_PARAMETERS)]
    assert run(calibrate_mounting, argv) == 0
    printed = capsys.readouterr().out
    found = yaml.safe_load(out_yaml.read_text())["/**"]["ros__parameters"]["anemometer"]["rpy_deg"]
    errors = np.subtract(found, MOUNTED_RPY_DEG)
    assert np.all(np.abs(errors) < TOLERANCE_DEG), errors

    # 2° of tilt in an 8 m/s wind is about 0.28 m/s of vertical wind; processed with the
    # mounting found, what is left is less than 0.2° would make.
    assert "mean vertical wind -0.3" in printed
    after = mean_vertical_wind_mps(misaligned_bag, [BUOY_PARAMETERS, out_yaml], tmp_path / "after")
    assert abs(after) < 8.0 * np.radians(TOLERANCE_DEG)


def test_turbulent_minutes_are_refused_with_the_reason(tmp_path, capsys):
    out_yaml = tmp_path / "mounting.yaml"
    argv = [str(REPO / "bags" / "sea_state"), str(out_yaml), "--params-file", str(BUOY_PARAMETERS)]
    assert run(calibrate_mounting, argv) == 2
    error = capsys.readouterr().err
    assert "do not determine the mounting" in error and "yaw ±" in error
    assert not out_yaml.exists()


def test_a_parameter_file_given_is_never_the_output(misaligned_bag, tmp_path, capsys):
    given = tmp_path / "buoy.yaml"
    given.write_text(BUOY_PARAMETERS.read_text())
    argv = [str(misaligned_bag), str(given), "--params-file", str(given), "--overwrite"]
    assert run(calibrate_mounting, argv) == 2
    assert given.read_text() == BUOY_PARAMETERS.read_text()
