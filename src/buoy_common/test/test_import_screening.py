"""import_records on the OOI FDCHP record with the shipped map: fill words, invalid codes and
implausible values become invalid samples and are counted per field; a record whose sonic
delivered no wind is refused unless asked; the start comes from the command line or the map,
and says which; the record's facts are in the bag for any MCAP reader."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
import yaml
from mcap.reader import make_reader

from buoy_common.bag_io import BagReader
from buoy_common.contract import SONIC_TEMPERATURE_TOPIC, WIND_RAW_TOPIC
from buoy_common.import_records import WIND_ALL_INVALID_EXIT_CODE, main
from buoy_common.record_facts import RECORD_METADATA_NAME, read_imported_record

REPO = Path(__file__).resolve().parents[3]
RECORD = REPO / "tests/data/ooi_fdchp/fdchp_test_dp.dat"
OOI_MAP = REPO / "src/buoy_common/config/records/ooi_fdchp.yaml"
ROWS = 200
SONIC_WORDS = (0, 1, 2, 3)  # u, v, w, speed of sound: the sonic's 16-bit words
SONIC_FIELDS = ("anemometer.u", "anemometer.v", "anemometer.w", "anemometer.speed_of_sound")
FILL = "32767"


def first_rows(rows: int = ROWS) -> list[list[str]]:
    return [line.split(",") for line in RECORD.read_text().splitlines()[:rows]]


def write_rows(path: Path, rows: list[list[str]]) -> Path:
    path.write_text("".join(",".join(row) + "\n" for row in rows))
    return path


def imported(tmp_path: Path, rows, *options, name="bag") -> tuple[int, Path]:
    record = write_rows(tmp_path / f"{name}.dat", rows)
    out = tmp_path / name
    with pytest.raises(SystemExit) as ended:
        main([str(record), str(OOI_MAP), str(out), *options])
        raise SystemExit(0)
    return ended.value.code, out


def vectors(bag: Path, topic: str) -> np.ndarray:
    with BagReader(bag) as reader:
        return np.array(
            [(lambda v: (v.x, v.y, v.z))(reader.decode(m).vector) for m in reader.messages([topic])]
        )


def temperatures(bag: Path) -> np.ndarray:
    with BagReader(bag) as reader:
        messages = reader.messages([SONIC_TEMPERATURE_TOPIC])
        return np.array([reader.decode(m).temperature for m in messages])


def independent_metadata(bag: Path) -> dict[str, str]:
    """The bag's record facts as the ``mcap`` library alone reads them."""
    (mcap_file,) = bag.glob("*.mcap")
    with mcap_file.open("rb") as stream:
        (record,) = [m for m in make_reader(stream).iter_metadata() if m.name == "buoy_record"]
    return dict(record.metadata)


def test_fill_words_become_invalid_samples_and_are_counted(tmp_path, capsys):
    clean_code, clean = imported(tmp_path, first_rows(), name="clean")
    rows = first_rows()
    filled = list(range(50, 60))
    for i in filled:
        for word in SONIC_WORDS:
            rows[i][word] = FILL
    code, bag = imported(tmp_path, rows, name="filled")
    assert clean_code == code == 0
    wind, clean_wind = vectors(bag, WIND_RAW_TOPIC), vectors(clean, WIND_RAW_TOPIC)
    invalid = ~np.isfinite(wind).all(axis=1)
    assert np.flatnonzero(invalid).tolist() == filled
    # Neither a 327.67 m/s wind nor the −6.7 °C the fill word reads as a speed of sound.
    assert np.isnan(temperatures(bag)[filled]).all()
    np.testing.assert_array_equal(wind[~invalid], clean_wind[~invalid])
    metadata = independent_metadata(bag)
    for field in SONIC_FIELDS:
        counts = json.loads(metadata[f"samples.{field}"])
        assert counts == {"read": ROWS, "filled": 10, "invalid": 0, "out_of_range": 0}
    assert json.loads(metadata["samples.imu.angular_rate.x"])["filled"] == 0
    table = capsys.readouterr().out
    assert any(line.split()[:3] == ["anemometer.u", str(ROWS), "10"] for line in table.splitlines())


def test_out_of_range_and_unreadable_values_are_counted_apart(tmp_path):
    rows = first_rows()
    rows[5][2] = "2500"  # w of 25 m/s: beyond the map's ±20 m/s
    rows[6][2] = "nan"  # the logger wrote no number
    rows[7][2] = FILL
    code, bag = imported(tmp_path, rows)
    assert code == 0
    counts = read_imported_record(bag).field_counts["anemometer.w"]
    assert (counts.filled, counts.invalid, counts.out_of_range, counts.valid) == (1, 1, 1, ROWS - 3)
    wind = vectors(bag, WIND_RAW_TOPIC)
    assert np.flatnonzero(~np.isfinite(wind).all(axis=1)).tolist() == [5, 6, 7]
    assert read_imported_record(bag).temperatures_without_wind == 3


def failed_sonic_rows() -> list[list[str]]:
    rows = first_rows()
    for row in rows:
        for word in SONIC_WORDS:
            row[word] = FILL
    return rows


def test_a_record_without_one_valid_wind_sample_is_refused(tmp_path, capsys):
    code, bag = imported(tmp_path, failed_sonic_rows())
    assert code == WIND_ALL_INVALID_EXIT_CODE
    error = capsys.readouterr().err
    assert len(error.strip().splitlines()) == 1
    assert "every one of the 200 wind samples is invalid" in error
    assert "--allow-invalid-wind" in error
    assert not bag.exists()


def test_on_request_it_is_imported_with_every_wind_invalid_and_no_temperature(tmp_path):
    code, bag = imported(tmp_path, failed_sonic_rows(), "--allow-invalid-wind")
    assert code == 0
    wind, temperature = vectors(bag, WIND_RAW_TOPIC), temperatures(bag)
    assert wind.shape == (ROWS, 3) and np.isnan(wind).all()
    assert temperature.shape == (ROWS,) and np.isnan(temperature).all()
    facts = read_imported_record(bag)
    assert facts.field_counts["anemometer.speed_of_sound"].filled == ROWS
    # the motion pack's samples are data all the same
    assert facts.field_counts["imu.angular_rate.x"].valid == ROWS


def first_stamp_ns(bag: Path) -> int:
    with BagReader(bag) as reader:
        return next(iter(reader.messages([WIND_RAW_TOPIC]))).log_time_ns


def test_the_start_on_the_command_line_overrides_the_maps_and_says_so(tmp_path, capsys):
    code, bag = imported(tmp_path, first_rows(), "--start", "2014-12-18T06:30:00Z", name="given")
    assert code == 0
    assert "start 2014-12-18T06:30:00.000Z (from the command line)" in capsys.readouterr().out
    start_ns = 1418884200 * 10**9  # 2014-12-18T06:30:00Z
    assert first_stamp_ns(bag) == start_ns
    assert independent_metadata(bag)["start_source"] == "command line"
    assert int(independent_metadata(bag)["start_ns"]) == start_ns

    code, bag = imported(tmp_path, first_rows(), name="mapped")
    assert "(from the column map ooi_fdchp.yaml)" in capsys.readouterr().out
    assert independent_metadata(bag)["start_source"] == "column map"
    assert first_stamp_ns(bag) == 1388534400 * 10**9  # the map's 2014-01-01T00:00:00Z


def test_without_a_start_from_either_it_is_a_one_line_error(tmp_path, capsys):
    document = yaml.safe_load(OOI_MAP.read_text())
    del document["time"]["start"]
    column_map = tmp_path / "no_start.yaml"
    column_map.write_text(yaml.safe_dump(document))
    record = write_rows(tmp_path / "record.dat", first_rows())
    with pytest.raises(SystemExit) as ended:
        main([str(record), str(column_map), str(tmp_path / "bag")])
    assert ended.value.code == 2
    error = capsys.readouterr().err.strip()
    assert len(error.splitlines()) == 1 and "--start" in error
    assert not (tmp_path / "bag").exists()


def test_the_maps_facts_are_in_the_bag_for_any_mcap_reader(tmp_path):
    code, bag = imported(tmp_path, first_rows(), "--site", "44.64,-124.30")
    assert code == 0
    metadata = independent_metadata(bag)
    assert metadata["yaw_reference"] == "magnetic_north"  # the map's ahrs.yaw_reference
    assert metadata["sensors"] == "sonic, sonic_temperature, imu, ahrs"
    assert "gnss" in metadata["sensors_absent"]
    assert (metadata["site_latitude_deg"], metadata["site_longitude_deg"]) == ("44.64", "-124.3")
    assert metadata["site_source"] == "command line"
    assert metadata["column_map"] == "ooi_fdchp.yaml"
    facts = read_imported_record(bag)
    assert facts.parameter_defaults() == {
        "ahrs.yaw_reference": "magnetic_north",
        "site.latitude_deg": 44.64,
        "site.longitude_deg": -124.3,
    }
    assert RECORD_METADATA_NAME == "buoy_record"


def test_without_a_site_the_site_is_unknown(tmp_path):
    _, bag = imported(tmp_path, first_rows())
    assert independent_metadata(bag)["site_source"] == "unknown"
    assert "site_latitude_deg" not in independent_metadata(bag)
    assert "site.latitude_deg" not in read_imported_record(bag).parameter_defaults()


@pytest.mark.parametrize(
    "options",
    [["--site", "95,10"], ["--site", "44.6"], ["--start", "yesterday"]],
    ids=["latitude", "one-number", "start"],
)
def test_a_bad_site_or_start_is_refused(tmp_path, capsys, options):
    code, bag = imported(tmp_path, first_rows(), *options)
    assert code == 2
    assert options[0] in capsys.readouterr().err
    assert not bag.exists()


def test_a_misspelt_key_of_a_field_is_refused(tmp_path, capsys):
    document = yaml.safe_load(OOI_MAP.read_text())
    document["anemometer"]["u"]["fil"] = document["anemometer"]["u"].pop("fill")
    column_map = tmp_path / "misspelt.yaml"
    column_map.write_text(yaml.safe_dump(document))
    record = write_rows(tmp_path / "record.dat", first_rows())
    with pytest.raises(SystemExit) as ended:
        main([str(record), str(column_map), str(tmp_path / "bag")])
    assert ended.value.code == 2
    assert "anemometer.u: unknown keys fil" in capsys.readouterr().err
