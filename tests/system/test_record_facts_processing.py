"""process_bag takes an imported record's facts as defaults under the parameter files: the
yaw reference stated in the column map gives the same output as the same yaw reference given as
a parameter, a parameter file overrides the map, and the run's OutputFacts say what the output
is referenced to and which record it came from. A misspelt parameter group is refused all the
same."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
import yaml

from buoy_common.bag_io import BagReader
from buoy_common.contract import NAV_ODOMETRY_TOPIC, WIND_TRUE_TOPIC
from buoy_common.import_records import import_records
from buoy_common.record_facts import read_imported_record
from buoy_processing.bag_facts import fusion_config_for_bag
from buoy_processing.bag_processing import process_bag
from buoy_processing.process_bag import main as process_bag_main
from wind_comp.config import compensator_config_from_files

REPO = Path(__file__).resolve().parents[2]
RECORD = REPO / "tests/data/ooi_fdchp/fdchp_test_dp.dat"
RECORDS = REPO / "src/buoy_common/config/records"
ROWS = 1200  # two minutes at 10 Hz
DECLINATION_DEG = 10.0
"""Not the OOI parameters' 0: with 0 a magnetic and a true yaw reference give the same wind."""


def parameters(folder: Path, name: str, ahrs: dict | None = None) -> Path:
    """OOI's FDCHP parameters without a yaw reference (or with ``ahrs``), a declination of
    :data:`DECLINATION_DEG`, the wind's σ limits lifted."""
    document = yaml.safe_load((RECORDS / "ooi_fdchp_params.yaml").read_text())
    shared = document["/**"]["ros__parameters"]
    shared.pop("ahrs")
    if ahrs is not None:
        shared["ahrs"] = ahrs
    shared["magnetic"]["declination_deg"] = DECLINATION_DEG
    # Without GNSS the compass heading leaves most of the record's wind above the shipped σ
    # limits (README); lifted, so that the two references can be compared sample by sample.
    shared["compensation"].update(
        max_attitude_sigma_deg=40.0,
        max_wind_sigma_horizontal_mps=20.0,
        max_wind_sigma_vertical_mps=20.0,
    )
    path = folder / f"{name}.yaml"
    path.write_text(yaml.safe_dump(document))
    return path


def imported(folder: Path, yaw_reference: str | None) -> Path:
    """The record's first two minutes imported with the shipped map, whose yaw reference is
    ``yaw_reference`` (None: not stated, the map's default)."""
    document = yaml.safe_load((RECORDS / "ooi_fdchp.yaml").read_text())
    if yaw_reference is None:
        document["ahrs"].pop("yaw_reference")
    else:
        document["ahrs"]["yaw_reference"] = yaw_reference
    column_map = folder / f"map_{yaw_reference}.yaml"
    column_map.write_text(yaml.safe_dump(document))
    record = folder / "fdchp_2min.dat"
    record.write_text("".join(RECORD.read_text().splitlines(keepends=True)[:ROWS]))
    bag = folder / f"imported_{yaw_reference}"
    import_records(record, column_map, bag)
    return bag


def processed(in_bag: Path, out_bag: Path, *parameter_files: Path) -> Path:
    arguments = [str(in_bag), str(out_bag)]
    for path in parameter_files:
        arguments += ["--params-file", str(path)]
    with pytest.raises(SystemExit) as ended:
        process_bag_main(arguments)
        raise SystemExit(0)
    assert ended.value.code == 0
    return out_bag


def raw_messages(bag: Path, topic: str) -> list[tuple[int, bytes]]:
    with BagReader(bag) as reader:
        return [(m.log_time_ns, bytes(m.raw)) for m in reader.messages([topic])]


def winds(bag: Path) -> np.ndarray:
    with BagReader(bag) as reader:
        return np.array(
            [
                (lambda v: (v.x, v.y, v.z))(reader.decode(m).vector)
                for m in reader.messages([WIND_TRUE_TOPIC])
            ]
        )


@pytest.fixture(scope="module")
def runs(tmp_path_factory):
    folder = tmp_path_factory.mktemp("record_facts")
    magnetic_bag, unstated_bag = imported(folder, "magnetic_north"), imported(folder, None)
    plain = parameters(folder, "plain")
    magnetic = parameters(folder, "magnetic", {"yaw_reference": "magnetic_north"})
    true = parameters(folder, "true", {"yaw_reference": "true_north"})
    return {
        "map": processed(magnetic_bag, folder / "from_map", plain),
        "parameter": processed(unstated_bag, folder / "from_parameter", magnetic),
        "overridden": processed(magnetic_bag, folder / "overridden", true),
    }


# About 20 s on two cores: three runs of process_bag over two minutes of the record.
@pytest.mark.long
def test_the_maps_yaw_reference_equals_the_same_given_as_a_parameter(runs):
    for topic in (WIND_TRUE_TOPIC, NAV_ODOMETRY_TOPIC):
        from_map, from_parameter = (
            raw_messages(runs["map"], topic),
            raw_messages(runs["parameter"], topic),
        )
        assert len(from_map) > 0.9 * ROWS
        assert from_map == from_parameter, topic


@pytest.mark.long
def test_a_parameter_file_overrides_the_maps_yaw_reference(runs):
    magnetic, true = winds(runs["map"]), winds(runs["overridden"])
    both = np.isfinite(magnetic).all(axis=1) & np.isfinite(true).all(axis=1)
    assert both.sum() > 0.5 * ROWS
    # The pack's heading read as magnetic is turned by the declination (east positive) to true:
    # the buoy, and the air it measures, point that much further clockwise, so the wind's ENU
    # angle (counter-clockwise from east) is the declination smaller than when read as true.
    mean_magnetic, mean_true = magnetic[both].mean(axis=0), true[both].mean(axis=0)
    turned_deg = math.degrees(
        math.atan2(mean_magnetic[1], mean_magnetic[0]) - math.atan2(mean_true[1], mean_true[0])
    )
    assert turned_deg == pytest.approx(-DECLINATION_DEG, abs=1.0)


def test_the_run_says_where_the_yaw_reference_came_from(tmp_path, capsys):
    bag = imported(tmp_path, "magnetic_north")
    plain = parameters(tmp_path, "plain")
    true = parameters(tmp_path, "true", {"yaw_reference": "true_north"})
    config, lines = fusion_config_for_bag(bag, [str(plain)])
    assert config.ahrs_yaw_reference == "magnetic_north"
    assert "ahrs.yaw_reference=magnetic_north from the record" in lines
    config, lines = fusion_config_for_bag(bag, [str(plain), str(true)])
    assert config.ahrs_yaw_reference == "true_north"
    assert (
        "ahrs.yaw_reference=true_north from the parameters, over the record's magnetic_north"
        in (lines)
    )
    # a bag that was not imported: the parameters alone, nothing said
    config, lines = fusion_config_for_bag(REPO / "bags" / "static", [str(true)])
    assert (config.ahrs_yaw_reference, lines) == ("true_north", [])


def test_the_runs_facts_say_what_the_output_is_referenced_to(tmp_path):
    bag = imported(tmp_path, "magnetic_north")
    files = [str(parameters(tmp_path, "plain"))]
    config, _ = fusion_config_for_bag(bag, files)
    with BagReader(bag) as reader:
        first_s, last_s = reader.start_ns / 1e9, reader.end_ns / 1e9
    summary = process_bag(bag, tmp_path / "out", config, compensator_config_from_files(files))
    facts = summary.facts
    assert facts.north == "true north"  # the magnetic pack turned by 10°
    assert facts.declination_deg == DECLINATION_DEG
    # the OOI parameters give a latitude for gravity, no position; the record knows none
    assert facts.record.site_deg is None
    assert facts.site_deg is None and facts.latitude_only_deg == 38.5
    assert "motion pack" in facts.sensor_text() and "GNSS" not in facts.sensor_text()
    assert not facts.position_known
    assert first_s <= facts.first_sample_s < facts.last_sample_s <= last_s
    assert facts.record.start_source == "column map"
    assert facts.record == read_imported_record(bag)


def test_a_misspelt_group_is_refused_with_the_record_facts(tmp_path, capsys):
    bag = imported(tmp_path, "magnetic_north")
    misspelt = tmp_path / "misspelt.yaml"
    misspelt.write_text("/**:\n  ros__parameters:\n    compenstion:\n      max_nav_gap_s: 0.2\n")
    with pytest.raises(SystemExit) as ended:
        process_bag_main([str(bag), str(tmp_path / "out"), "--params-file", str(misspelt)])
    assert ended.value.code == 2
    error = capsys.readouterr().err.strip()
    assert len(error.splitlines()) == 1
    assert "unknown parameter group 'compenstion'" in error and "'compensation'" in error
    assert not (tmp_path / "out").exists()
