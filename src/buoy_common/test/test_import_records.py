"""import_records: units, axes, Euler conventions, time and invalid codes into the contract; a
map that does not fit its file is a one-line error; implausible physics is a loud warning."""

from __future__ import annotations

import math

import numpy as np
import pytest
import yaml
from scipy.spatial.transform import Rotation

from buoy_common.bag_io import BagReader
from buoy_common.import_records import main
from buoy_common.records.column_map import STANDARD_GRAVITY_MPS2, MapError, load_column_map
from buoy_common.records.decoding import decode, plausibility_warnings, read_table

# A pack in forward-right-down axes, g and deg/s; a sonic in forward-left-up, cm/s; the
# pack's attitude in degrees, aerospace convention (NED, heading clockwise from north).
MAP = {
    "format": "delimited",
    "delimiter": ",",
    "columns": 14,
    "time": {"column": 1, "unit": "ms", "epoch": "2024-05-01T00:00:00Z"},
    "anemometer": {
        "axes": "FLU",
        "u": {"column": 2, "unit": "cm/s", "invalid": [-99999]},
        "v": {"column": 3, "unit": "cm/s", "invalid": [-99999]},
        "w": {"column": 4, "unit": "cm/s", "invalid": [-99999]},
        "temperature": {"column": 5, "unit": "K"},
    },
    "imu": {
        "axes": "FRD",
        "angular_rate": {"columns": [6, 7, 8], "unit": "deg/s"},
        "specific_force": {"columns": [9, 10, 11], "unit": "g"},
    },
    "ahrs": {
        "convention": "ned_zyx",
        "yaw_reference": "magnetic_north",
        "roll": {"column": 12, "unit": "deg"},
        "pitch": {"column": 13, "unit": "deg"},
        "heading": {"column": 14, "unit": "deg"},
    },
}
EPOCH_NS = 1714521600 * 10**9


def row(t_ms, wind_cm_s=(500, -200, 30), kelvin=290.0, rate=(0.1, 0.2, 0.3), force=(0, 0, -1),
        rph=(0.0, 0.0, 0.0)):  # fmt: skip
    return ",".join(str(v) for v in (t_ms, *wind_cm_s, kelvin, *rate, *force, *rph))


def write(tmp_path, rows, column_map=MAP):
    record = tmp_path / "record.csv"
    record.write_text("\n".join(rows) + "\n")
    map_path = tmp_path / "map.yaml"
    map_path.write_text(yaml.safe_dump(column_map))
    return record, map_path


def decoded(tmp_path, rows, column_map=MAP):
    record, map_path = write(tmp_path, rows, column_map)
    loaded = load_column_map(map_path)
    return decode(read_table(record, loaded), loaded), loaded


def test_units_and_axes_become_the_contracts(tmp_path):
    samples, _ = decoded(tmp_path, [row(0), row(100)])
    np.testing.assert_array_equal(samples.time_ns, [EPOCH_NS, EPOCH_NS + 100_000_000])
    np.testing.assert_allclose(samples.wind_mps[0], [5.0, -2.0, 0.3])
    np.testing.assert_allclose(samples.sonic_temperature_degc, [290.0 - 273.15] * 2)
    # forward-right-down → forward-left-up: y and z change sign; a level pack reads +g up
    np.testing.assert_allclose(samples.specific_force_mps2[0], [0.0, 0.0, STANDARD_GRAVITY_MPS2])
    np.testing.assert_allclose(
        samples.angular_rate_rad_s[0], np.radians([0.1, -0.2, -0.3]), rtol=1e-12
    )


@pytest.mark.parametrize(
    ("heading_deg", "forward_enu"),
    [(0.0, (0.0, 1.0, 0.0)), (90.0, (1.0, 0.0, 0.0)), (180.0, (0.0, -1.0, 0.0))],
)
def test_a_heading_clockwise_from_north_points_the_body_forward_axis(
    tmp_path, heading_deg, forward_enu
):
    samples, _ = decoded(tmp_path, [row(0, rph=(0.0, 0.0, heading_deg))])
    attitude = Rotation.from_quat(samples.orientation_xyzw[0])
    np.testing.assert_allclose(attitude.apply([1.0, 0.0, 0.0]), forward_enu, atol=1e-12)
    np.testing.assert_allclose(attitude.apply([0.0, 0.0, 1.0]), [0.0, 0.0, 1.0], atol=1e-12)


def test_roll_and_pitch_follow_the_aerospace_signs(tmp_path):
    # Aerospace roll positive = right side down; pitch positive = nose up.
    samples, _ = decoded(tmp_path, [row(0, rph=(10.0, 0.0, 0.0)), row(100, rph=(0.0, 10.0, 0.0))])
    rolled, pitched = Rotation.from_quat(samples.orientation_xyzw)
    left_enu = rolled.apply([0.0, 1.0, 0.0])  # heading north: left is west
    assert left_enu[2] > 0.17 and left_enu[0] < -0.98  # the left side rises
    nose_enu = pitched.apply([1.0, 0.0, 0.0])
    assert math.isclose(nose_enu[2], math.sin(math.radians(10.0)), rel_tol=1e-12)
    # the attitude and the specific force agree: a rolled pack feels gravity on its left axis
    gravity_body = rolled.inv().apply([0.0, 0.0, STANDARD_GRAVITY_MPS2])
    assert gravity_body[1] > 0  # +y (left) is up-tilted, so f_y > 0 in REP-145 terms


def test_invalid_codes_make_the_whole_sample_nan(tmp_path):
    samples, _ = decoded(tmp_path, [row(0), row(100, wind_cm_s=(500, -99999, 30)), row(200)])
    assert np.isnan(samples.wind_mps[1]).all()
    assert np.isfinite(samples.wind_mps[[0, 2]]).all()


def test_binary_records_with_a_given_layout(tmp_path):
    layout = [["t", "<f8"], ["u", "<i2"], ["v", "<i2"], ["w", "<i2"]]
    records = np.zeros(3, dtype=np.dtype([(a, b) for a, b in layout]))
    records["t"] = [0.0, 0.05, 0.1]
    records["u"], records["v"], records["w"] = 250, -100, 5
    path = tmp_path / "record.bin"
    records.tofile(path)
    column_map = {
        "format": "binary",
        "record_layout": layout,
        "time": {"column": "t", "unit": "s", "epoch": "2024-05-01T00:00:00Z"},
        "anemometer": {f: {"column": f, "unit": "cm/s"} for f in "uvw"},
    }
    map_path = tmp_path / "map.yaml"
    map_path.write_text(yaml.safe_dump(column_map))
    loaded = load_column_map(map_path)
    samples = decode(read_table(path, loaded), loaded)
    np.testing.assert_allclose(samples.wind_mps, [[2.5, -1.0, 0.05]] * 3)
    np.testing.assert_array_equal(samples.time_ns - EPOCH_NS, [0, 50_000_000, 100_000_000])
    path.write_bytes(path.read_bytes()[:-1])
    with pytest.raises(MapError, match="not a whole number"):
        read_table(path, loaded)


def test_the_bag_holds_one_message_per_sample_and_topic(tmp_path, capsys):
    record, map_path = write(tmp_path, [row(t) for t in range(0, 1000, 100)])
    main([str(record), str(map_path), str(tmp_path / "bag")])
    with BagReader(tmp_path / "bag") as reader:
        counts = {topic: info.count for topic, info in reader.topics.items()}
        first = {}
        for message in reader.messages():
            first.setdefault(message.topic, reader.decode(message))
    assert counts == {
        "/anemometer/wind": 10,
        "/anemometer/temperature": 10,
        "/imu/data_raw": 10,
        "/imu/data": 10,
    }
    assert first["/imu/data_raw"].orientation_covariance[0] == -1.0
    assert first["/imu/data"].orientation_covariance[0] > 0.0
    assert first["/anemometer/temperature"].header.frame_id == "anemometer_link"
    assert "wrote" in capsys.readouterr().out


def bad_map(**changes):
    column_map = yaml.safe_load(yaml.safe_dump(MAP))
    for dotted, value in changes.items():
        *parents, key = dotted.split("__")
        target = column_map
        for parent in parents:
            target = target[parent]
        target[key] = value
    return column_map


@pytest.mark.parametrize(
    ("rows", "column_map", "message"),
    [
        ([row(0), row(100) + ",7"], MAP, "line 2: 15 columns, the map says 14"),
        ([], MAP, "no data rows (empty file)"),
        (
            [",".join(row(0).split(",")[:12])] * 2,
            bad_map(columns=None),
            "ahrs.pitch: the map reads column 13, the file has only 12 columns",
        ),
        (
            [row(0)],
            bad_map(imu__specific_force__unit="gee"),
            "unit 'gee' is not a unit of acceleration",
        ),
        ([row(0)], bad_map(anemometer__u__unit="m/s/s"), "anemometer.u: unit 'm/s/s'"),
        ([row(0)], bad_map(imu__axes="FLD"), "left-handed"),
        ([row(0).replace("500", "5OO", 1)], MAP, "line 1 column 2: not a number: '5OO'"),
    ],
)
def test_a_map_that_does_not_fit_is_a_one_line_error(tmp_path, capsys, rows, column_map, message):
    if column_map.get("columns", 0) is None:
        column_map.pop("columns")
    record, map_path = write(tmp_path, rows, column_map)
    with pytest.raises(SystemExit) as stopped:
        main([str(record), str(map_path), str(tmp_path / "bag")])
    assert stopped.value.code == 2
    error = capsys.readouterr().err
    assert message in error and error.count("\n") == 1
    assert not (tmp_path / "bag").exists()


def test_implausible_gravity_and_gyro_bias_are_loud_warnings(tmp_path):
    # the accelerometer really reads m/s² while the map says g: gravity comes out 9.8 g
    samples, loaded = decoded(tmp_path, [row(t, force=(0, 0, -9.8)) for t in (0, 100)])
    (warning,) = plausibility_warnings(samples, loaded)
    assert "not near gravity" in warning
    # axes given as forward-left-up for a forward-right-down pack: gravity points down
    samples, loaded = decoded(tmp_path, [row(0)], bad_map(imu__axes="FLU"))
    assert any("not up" in w for w in plausibility_warnings(samples, loaded))
    # a rate logged in rad/s under a deg/s map is small; the other way round is a bias of 57°/s
    rad_as_deg = bad_map(imu__angular_rate__unit="rad/s")
    samples, loaded = decoded(tmp_path, [row(0), row(100)], rad_as_deg)
    assert any("gyro bias" in w for w in plausibility_warnings(samples, loaded))
    samples, loaded = decoded(tmp_path, [row(0), row(100)])
    assert plausibility_warnings(samples, loaded) == []
