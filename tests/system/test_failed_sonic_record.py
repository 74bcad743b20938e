"""A record whose sonic failed (every wind word the fill code), imported on request and processed
without any parameter file: what every output says about the run (the processed bag's
``buoy_outputs``, the NetCDF attributes, the products CSV's header, the printed summary, the
report) is true of what the bags hold. Beside it the same rows with the sonic intact, so that
the statements are seen to follow the data rather than be fixed, and a run that aligned at a
known site, whose true north names the World Magnetic Model's declination at that site.

Without parameters the motion pack's record has neither GNSS, nor a site, nor the mooring
constraint: the fusion cannot align, so no heading exists and no declination was applied."""

from __future__ import annotations

import contextlib
import io
import json
from pathlib import Path

import numpy as np
import pytest
import xarray as xr
import yaml
from mcap.reader import make_reader

from buoy_common.bag_io import BagReader
from buoy_common.contract import (
    NAV_ODOMETRY_TOPIC,
    SONIC_TEMPERATURE_TOPIC,
    WIND_RAW_TOPIC,
    WIND_TRUE_TOPIC,
)
from buoy_common.import_records import main as import_records_main
from buoy_processing.bag_processing import products_csv_path
from buoy_processing.output_facts import OUTPUTS_METADATA_NAME
from buoy_processing.process_bag import main as process_bag_main
from buoy_processing.wind_report import main as wind_report_main

REPO = Path(__file__).resolve().parents[2]
RECORD = REPO / "tests/data/ooi_fdchp/fdchp_test_dp.dat"
OOI_MAP = REPO / "src/buoy_common/config/records/ooi_fdchp.yaml"
OOI_PARAMS = REPO / "src/buoy_common/config/records/ooi_fdchp_params.yaml"
ROWS = 600  # one minute at 10 Hz
SONIC_COLUMNS = (0, 1, 2, 3)  # u, v, w, speed of sound (the sonic temperature): 16-bit words
FILL = "32767"


def record_rows(sonic_failed: bool) -> str:
    rows = [line.split(",") for line in RECORD.read_text().splitlines()[:ROWS]]
    if sonic_failed:
        for row in rows:
            for column in SONIC_COLUMNS:
                row[column] = FILL
    return "".join(",".join(row) + "\n" for row in rows)


def exit_code(main, arguments: list[str]) -> int:
    with pytest.raises(SystemExit) as ended:
        main(arguments)
        raise SystemExit(0)
    return ended.value.code


def finite_rows(bag: Path, topic: str) -> tuple[int, int]:
    """(messages, messages whose values are all finite) of a Vector3Stamped or Temperature
    topic."""
    total = finite = 0
    with BagReader(bag) as reader:
        for message in reader.messages([topic]):
            decoded = reader.decode(message)
            if hasattr(decoded, "vector"):
                values = (decoded.vector.x, decoded.vector.y, decoded.vector.z)
            else:
                values = (decoded.temperature,)
            total += 1
            finite += bool(np.isfinite(values).all())
    return total, finite


def message_count(bag: Path, topic: str) -> int:
    """Messages of relative ``topic`` in ``bag``; 0 when it lacks the topic."""
    with BagReader(bag) as reader:
        return sum(info.count for name, info in reader.topics.items() if name.lstrip("/") == topic)


def outputs_metadata(bag: Path) -> dict[str, str]:
    """The processed bag's ``buoy_outputs`` record, as the ``mcap`` library alone reads it."""
    (mcap_file,) = bag.glob("*.mcap")
    with mcap_file.open("rb") as stream:
        records = [
            m for m in make_reader(stream).iter_metadata() if m.name == OUTPUTS_METADATA_NAME
        ]
    (record,) = records
    return dict(record.metadata)


@pytest.fixture(scope="module", params=["sonic_failed", "sonic_intact"])
def run(request, tmp_path_factory):
    """The record's first minute imported (with --allow-invalid-wind) and processed without
    parameters, with NetCDF, then reported; what each step wrote and what process_bag printed."""
    folder = tmp_path_factory.mktemp(request.param)
    record = folder / "record.dat"
    record.write_text(record_rows(request.param == "sonic_failed"))
    imported, processed, netcdf = folder / "imported", folder / "processed", folder / "out.nc"
    printed = io.StringIO()
    with contextlib.redirect_stdout(io.StringIO()):
        arguments = [str(record), str(OOI_MAP), str(imported), "--allow-invalid-wind"]
        assert exit_code(import_records_main, arguments) == 0
        with contextlib.redirect_stdout(printed):
            arguments = [str(imported), str(processed), "--netcdf", str(netcdf)]
            code = exit_code(process_bag_main, arguments)
        assert exit_code(wind_report_main, [str(processed)]) == 0
    return {
        "imported": imported,
        "processed": processed,
        "netcdf": netcdf,
        "printed": printed.getvalue(),
        "process_bag_code": code,
        "report": processed.with_name(processed.name + "_report"),
    }


def what_the_bags_hold(run) -> dict:
    """The facts the outputs may state, read from the input and output bags."""
    wind_total, wind_valid = finite_rows(run["imported"], WIND_RAW_TOPIC)
    temperature_total, temperature_valid = finite_rows(run["imported"], SONIC_TEMPERATURE_TOPIC)
    _, corrected_valid = finite_rows(run["processed"], WIND_TRUE_TOPIC)
    return {
        "wind_samples": wind_total,
        "wind_valid": wind_valid,
        "temperature_valid": temperature_valid,
        "corrected_valid": corrected_valid,
        "navigation_solutions": message_count(run["processed"], NAV_ODOMETRY_TOPIC),
        "temperature_total": temperature_total,
    }


def test_the_stored_facts_claim_no_heading_no_declination_and_no_unused_sensor(run):
    held = what_the_bags_hold(run)
    assert held["wind_samples"] == held["temperature_total"] == ROWS
    metadata = outputs_metadata(run["processed"])
    sensors = json.loads(metadata["sensors"])
    # No navigation solution: nothing may claim a heading, a north or a declination applied.
    assert held["navigation_solutions"] == 0
    assert metadata["north_token"] == "unknown_north"
    assert "never aligned" in metadata["north_basis"]
    assert "World Magnetic Model" not in metadata["north_basis"]
    assert json.loads(metadata["declination_deg"]) is None
    assert not any(word in " ".join(sensors) for word in ("IMU", "motion pack", "GNSS"))
    (sonic,) = [sensor for sensor in sensors if sensor.startswith("sonic anemometer")]
    assert ("no valid wind sample" in sonic) == (held["wind_valid"] == 0)
    with_temperature = held["wind_valid"] > 0 and held["temperature_valid"] > 0
    assert ("with temperature" in sonic) == with_temperature


def test_the_netcdf_attributes_say_the_same(run):
    held = what_the_bags_hold(run)
    metadata = outputs_metadata(run["processed"])
    sensor_text = ", ".join(json.loads(metadata["sensors"]))
    with xr.open_dataset(run["netcdf"]) as dataset:
        attributes = dict(dataset.attrs)
        variable_texts = [
            str(value) for name in dataset.variables for value in dataset[name].attrs.values()
        ]
    assert attributes["north_reference"] == metadata["north"]
    assert attributes["instrument"] == sensor_text
    assert f"sensors used: {sensor_text}." in attributes["summary"]
    assert "never aligned" in attributes["comment"]
    for text in [*attributes.values(), *variable_texts]:
        assert "World Magnetic Model" not in str(text)
        assert "true north" not in str(text)
    if held["corrected_valid"] == 0:
        assert f"none of the {held['wind_samples']} wind samples is valid" in attributes["summary"]
    assert "the navigation holds no solution" in attributes["summary"]


def test_the_products_csv_and_the_printed_summary_say_the_same(run):
    metadata = outputs_metadata(run["processed"])
    header = products_csv_path(run["processed"]).read_text().splitlines()[0].split(",")
    directions = [column for column in header if "direction" in column]
    assert directions and all(
        column.endswith(f"_{metadata['north_token']}_deg") for column in directions
    )
    outputs = [line for line in run["printed"].splitlines() if line.startswith("outputs: ")]
    sensor_text = ", ".join(json.loads(metadata["sensors"]))
    assert f"outputs: sensors used: {sensor_text}" in outputs
    assert any("never aligned" in line for line in outputs)
    assert not any("true north" in line or "magnetic north" in line for line in outputs)
    # every wind sample invalid: the run says so by its exit code (mostly invalid)
    assert run["process_bag_code"] == 4


def test_the_report_shows_no_invented_wind_and_no_empty_figure(run):
    held = what_the_bags_hold(run)
    report = run["report"]
    summary = (report / "summary.md").read_text()
    assert held["corrected_valid"] == 0
    assert "**No valid wind**" in summary
    why = "delivered no valid sample" if held["wind_valid"] == 0 else "none could be corrected"
    assert why in summary
    figures = {path.name for path in report.glob("*.png")}
    # the measured wind is the only series that may have values; fluxes of no valid sample none
    assert ("wind_time_series.png" in figures) == (held["wind_valid"] > 0)
    assert not figures & {"wind_fluxes.png", "wave_motion_left.png"}
    sensor_text = ", ".join(json.loads(outputs_metadata(run["processed"])["sensors"]))
    assert f"Sensors used: {sensor_text}." in summary
    assert "true north" not in summary


def test_a_run_that_aligned_at_a_known_site_names_the_models_declination_there(tmp_path):
    """The contrast: the intact rows at a site given on import, moored, the declination left
    to the World Magnetic Model: the heading was used, so the north is true and the outputs
    say where the model's declination was taken."""
    record = tmp_path / "record.dat"
    record.write_text(record_rows(sonic_failed=False))
    document = yaml.safe_load(OOI_PARAMS.read_text())
    shared = document["/**"]["ros__parameters"]
    del shared["magnetic"], shared["site"]  # the declination from the model, the site the record's
    parameters = tmp_path / "params.yaml"
    parameters.write_text(yaml.safe_dump(document))
    imported, processed = tmp_path / "imported", tmp_path / "processed"
    with contextlib.redirect_stdout(io.StringIO()):
        arguments = [str(record), str(OOI_MAP), str(imported), "--site", "44.64,-124.30"]
        assert exit_code(import_records_main, arguments) == 0
        arguments = [str(imported), str(processed), "--params-file", str(parameters)]
        assert exit_code(process_bag_main, arguments) in (0, 4)
    assert message_count(processed, NAV_ODOMETRY_TOPIC) > 0
    metadata = outputs_metadata(processed)
    assert metadata["north"] == "true north"
    assert (
        "World Magnetic Model at 44.64000, -124.30000 deg (the site given by the imported record)"
        in metadata["north_basis"]
    )
    sensors = json.loads(metadata["sensors"])
    assert sensors[0] == "IMU"
    assert "motion pack (its own attitude and heading)" in sensors
    assert "sonic anemometer with temperature" in sensors
