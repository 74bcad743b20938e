"""import_records: stamps written as a calendar date and time of day (a logger's year, month,
day, hour, minute, second and millisecond columns), held to Python's own calendar; a part that
is no date is a one-line error; OOI's FDCHP binary records read as the test record's map reads
its text."""

from __future__ import annotations

import dataclasses
import datetime as dt
from pathlib import Path

import numpy as np
import pytest
import yaml

from buoy_common.import_records import main
from buoy_common.records.column_map import MapError, load_column_map
from buoy_common.records.decoding import decode, read_table

REPO = Path(__file__).resolve().parents[3]
RECORD_MAPS = REPO / "src/buoy_common/config/records"
CALENDAR = {part: part for part in ("year", "month", "day", "hour", "minute", "second")}
LAYOUT = [
    ["year", ">u2"],
    *([part, "u1"] for part in ("month", "day", "hour", "minute", "second")),
    ["millisecond", ">u2"],
    *([axis, ">i2"] for axis in "uvw"),
]
TIMES = [
    dt.datetime(2014, 12, 18, 18, 0, 0, 23000, tzinfo=dt.UTC),
    dt.datetime(2014, 12, 31, 23, 59, 59, 999000, tzinfo=dt.UTC),
    dt.datetime(2016, 2, 29, 0, 0, 0, 0, tzinfo=dt.UTC),
]


def binary_record(tmp_path, times, column_map_changes=None):
    records = np.zeros(len(times), dtype=np.dtype([(name, kind) for name, kind in LAYOUT]))
    for i, time in enumerate(times):
        for part in ("year", "month", "day", "hour", "minute", "second"):
            records[part][i] = getattr(time, part)
        records["millisecond"][i] = time.microsecond // 1000
    records["u"], records["v"], records["w"] = 250, -100, 5
    path = tmp_path / "record.bin"
    records.tofile(path)
    column_map = {
        "format": "binary",
        "record_layout": LAYOUT,
        "time": {"calendar": CALENDAR | {"millisecond": "millisecond"}},
        "anemometer": {axis: {"column": axis, "unit": "cm/s"} for axis in "uvw"},
        **(column_map_changes or {}),
    }
    map_path = tmp_path / "map.yaml"
    map_path.write_text(yaml.safe_dump(column_map))
    return path, map_path


def stamps_ns(path, map_path) -> np.ndarray:
    loaded = load_column_map(map_path)
    return decode(read_table(path, loaded), loaded).time_ns


def unix_ns(time: dt.datetime) -> int:
    return (time - dt.datetime(1970, 1, 1, tzinfo=dt.UTC)) // dt.timedelta(microseconds=1) * 1000


def test_calendar_parts_give_the_stamps_pythons_calendar_gives(tmp_path):
    expected = [unix_ns(time) for time in TIMES]
    np.testing.assert_array_equal(stamps_ns(*binary_record(tmp_path, TIMES)), expected)


def test_a_fractional_second_column_carries_the_sub_second_part(tmp_path):
    record = tmp_path / "record.csv"
    record.write_text("2024,5,1,12,30,7.25,100,0,0\n2024,5,1,12,30,7.35,100,0,0\n")
    map_path = tmp_path / "map.yaml"
    columns = dict(zip(CALENDAR, range(1, 7), strict=True))
    map_path.write_text(
        yaml.safe_dump(
            {
                "format": "delimited",
                "delimiter": ",",
                "time": {"calendar": columns},
                "anemometer": {
                    axis: {"column": 7 + i, "unit": "m/s"} for i, axis in enumerate("uvw")
                },
            }
        )
    )
    start = unix_ns(dt.datetime(2024, 5, 1, 12, 30, 7, 250000, tzinfo=dt.UTC))
    np.testing.assert_array_equal(stamps_ns(record, map_path), [start, start + 100_000_000])


@pytest.mark.parametrize(
    ("bad_time", "named"),
    [
        ((2015, 4, 31, 0, 0, 0), "month 4, day 31"),
        ((2015, 2, 29, 0, 0, 0), "month 2, day 29"),
        ((2015, 1, 1, 24, 0, 0), "hour 24"),
    ],
)
def test_a_part_that_is_no_date_is_a_one_line_error_naming_the_sample(
    tmp_path, capsys, bad_time, named
):
    path, map_path = binary_record(tmp_path, TIMES)
    records = np.fromfile(path, dtype=np.dtype([(name, kind) for name, kind in LAYOUT]))
    for part, value in zip(CALENDAR, bad_time, strict=True):
        records[part][1] = value
    records.tofile(path)
    with pytest.raises(SystemExit) as stopped:
        main([str(path), str(map_path), str(tmp_path / "bag")])
    assert stopped.value.code == 2
    error = capsys.readouterr().err
    assert "1 samples have no valid calendar time, the first sample 2" in error
    assert named in error and error.count("\n") == 1
    assert not (tmp_path / "bag").exists()


def test_a_record_that_dates_its_samples_refuses_another_start(tmp_path, capsys):
    path, map_path = binary_record(tmp_path, TIMES)
    with pytest.raises(SystemExit):
        main([str(path), str(map_path), str(tmp_path / "bag"), "--start", "2020-01-01T00:00:00Z"])
    assert "its start is its own" in capsys.readouterr().err


@pytest.mark.parametrize(
    ("calendar", "message"),
    [
        ({k: v for k, v in CALENDAR.items() if k != "day"}, "give the column of day"),
        (CALENDAR | {"fortnight": "u"}, "unknown parts fortnight"),
    ],
)
def test_a_calendar_without_a_part_or_with_an_unknown_one_is_refused(tmp_path, calendar, message):
    _, map_path = binary_record(tmp_path, TIMES, {"time": {"calendar": calendar}})
    with pytest.raises(MapError, match=message):
        load_column_map(map_path)


def test_the_fdchp_binary_map_reads_what_the_text_map_reads():
    """The FDCHP's own binary records and OOI's text test record hold the same fields: the
    two maps give them the same units, codes, ranges, axes and conventions."""
    maps = ("ooi_fdchp.yaml", "ooi_fdchp_raw.yaml")
    text, binary = (load_column_map(RECORD_MAPS / name) for name in maps)
    layout = binary.record_layout.names

    def without_columns(fields):
        return [
            dataclasses.replace(f, column=None) for f in fields if not f.name.startswith("time")
        ]

    assert without_columns(text.fields()) == without_columns(binary.fields())
    for field in binary.fields():
        assert field.column in layout
    same = ("wind_axes", "imu_axes", "ahrs_convention", "ahrs_yaw_reference", "ahrs_sigma_rad")
    for name in (*same, "gravity_tolerance_mps2", "max_gyro_bias_rad_s"):
        assert getattr(text, name) == getattr(binary, name), name
    assert binary.record_layout.itemsize == 55
