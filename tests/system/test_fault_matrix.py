"""The fault matrix, offline and live: see :mod:`fault_matrix` for the rows and what each demands.

Each group of faults is written into one bag. ``process_bag`` runs over it (offline), and the
same bag is replayed by ``bag_player`` to ``fusion_node`` and ``compensation_node`` whose
outputs ``bag_recorder`` records (live, :mod:`live_replay`). Both must do what every row
demands; live must equal offline sample for sample.
"""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import bag_faults as faults
import fault_matrix as matrix
import numpy as np
import pytest
from live_replay import differences_from_offline, replay

from buoy_common.bag_io import RECOVERED_BAG_EXIT_CODE, BagReader
from buoy_processing.process_bag import MOSTLY_INVALID_EXIT_CODE

BIN = Path(sys.executable).parent
GROUP_PARAMETERS = [pytest.param(group, id=group.name.replace(" ", "_")) for group in matrix.GROUPS]


@pytest.fixture(scope="module")
def faulted_bags(tmp_path_factory):
    """Each group's bag, its records, process_bag's output and outcome (computed once)."""
    made = {}

    def make(group: matrix.FaultGroup):
        if group.name not in made:
            folder = tmp_path_factory.mktemp(group.name.replace(" ", "_"))
            records = matrix.faulted_records(group)
            bag, offline = folder / "faulted", folder / "offline"
            faults.write_records(records, bag)
            made[group.name] = (bag, records, offline, matrix.run_offline(bag, offline))
        return made[group.name]

    return make


@pytest.mark.slow
@pytest.mark.parametrize("group", GROUP_PARAMETERS)
def test_offline_does_what_each_row_demands(group, faulted_bags):
    bag, records, offline, outcome = faulted_bags(group)
    failures = matrix.offline_failures(group, bag, records, offline, outcome)
    assert not failures, "\n".join(failures)


@pytest.mark.ros
@pytest.mark.long
@pytest.mark.parametrize("group", GROUP_PARAMETERS)
def test_live_equals_offline(group, faulted_bags, nodes, tmp_path):
    bag, records, offline, _ = faulted_bags(group)
    recorded = tmp_path / "live"
    figures = replay(
        nodes, bag, [matrix.BUOY_PARAMETERS], offline, recorded, topics=matrix.SENSOR_TOPICS
    )
    failures = differences_from_offline(recorded, offline)
    matrix.check_outputs(records, matrix.bag_outcome(recorded), f"{group.name} live", failures)
    assert not failures, "\n".join(failures) + f"\n{figures}"


# -- file faults -----------------------------------------------------------------------------------

FILE_FAULT_SECONDS = 25.0


@pytest.fixture(scope="module")
def short_bag(tmp_path_factory):
    """The first seconds of the source bag, sensors and true wind."""
    bag = tmp_path_factory.mktemp("file_faults") / "short"
    records = faults.read_records(
        matrix.SOURCE_BAG, (*matrix.SENSOR_TOPICS, matrix.TRUTH_WIND_TOPIC), FILE_FAULT_SECONDS
    )
    faults.write_records(records, bag)
    return bag


def process_bag_cli(*arguments):
    """``process_bag`` as a user runs it (it takes no part in DDS)."""
    return subprocess.run(
        [str(BIN / "process_bag"), *map(str, arguments)],
        capture_output=True,
        text=True,
        timeout=300,
    )


def one_output_per_input(bag, out) -> None:
    with BagReader(bag) as reader:
        inputs_ns = [
            faults.stamp_to_ns(reader.decode(m).header.stamp)
            for m in reader.messages(["/anemometer/wind"])
        ]
    outcome = matrix.bag_outcome(out)
    assert outcome.wind_ns.tolist() == inputs_ns


@pytest.mark.slow
def test_truncated_bag_is_processed_up_to_its_cut(short_bag, tmp_path):
    cut = faults.copy_bag(short_bag, tmp_path / "cut")
    faults.truncate_file(cut, 0.6)
    result = process_bag_cli(cut, tmp_path / "out")
    assert result.returncode == RECOVERED_BAG_EXIT_CODE, result.stderr
    assert "Traceback" not in result.stderr
    one_output_per_input(cut, tmp_path / "out")


@pytest.mark.slow
def test_bag_without_metadata_is_processed(short_bag, tmp_path):
    bare = faults.copy_bag(short_bag, tmp_path / "bare")
    faults.remove_metadata(bare)
    result = process_bag_cli(bare, tmp_path / "out")
    assert result.returncode in (0, RECOVERED_BAG_EXIT_CODE), result.stderr
    one_output_per_input(bare, tmp_path / "out")


def test_empty_bag_is_one_line_error(tmp_path):
    empty = tmp_path / "empty"
    faults.write_records([], empty)
    result = process_bag_cli(empty, tmp_path / "out")
    assert result.returncode == 2
    assert len(result.stderr.strip().splitlines()) == 1, result.stderr
    assert not (tmp_path / "out").exists()


@pytest.mark.slow
def test_wrong_anemometer_frame_is_an_error_naming_both_frames(short_bag, tmp_path):
    records = faults.read_records(short_bag, matrix.SENSOR_TOPICS, FILE_FAULT_SECONDS)
    sonic = tmp_path / "sonic"
    faults.write_records(faults.set_frame("/anemometer/wind", "sonic")(records), sonic)

    refused = process_bag_cli(sonic, tmp_path / "refused")
    assert refused.returncode == MOSTLY_INVALID_EXIT_CODE, refused.stderr
    assert "'sonic'" in refused.stderr and "'anemometer_link'" in refused.stderr
    assert "compensation.anemometer_frame_id" in refused.stderr
    assert np.isnan(matrix.bag_outcome(tmp_path / "refused").wind).all()

    driver_frame = tmp_path / "driver_frame.yaml"
    driver_frame.write_text(
        "/**:\n  ros__parameters:\n    compensation: {anemometer_frame_id: sonic}\n"
    )
    accepted = process_bag_cli(sonic, tmp_path / "accepted", "--params-file", driver_frame)
    assert accepted.returncode == 0, accepted.stderr
    reference = tmp_path / "reference"
    assert process_bag_cli(short_bag, reference).returncode == 0
    np.testing.assert_array_equal(
        matrix.bag_outcome(tmp_path / "accepted").wind, matrix.bag_outcome(reference).wind
    )
