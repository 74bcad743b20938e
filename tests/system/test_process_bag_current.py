"""``process_bag`` on simulated bags with a DVL: one ``current/velocity`` per ``dvl/velocity``
sample, an error that is the navigation's and nothing more, products that match their CSV, and a
bag without an anemometer processed for its current alone.

The simulator (sensor_sim) is the independent witness: its truth gives the water's velocity at
the DVL, the navigation's true attitude, rate and velocity."""

from __future__ import annotations

import csv
import math
from pathlib import Path

import bag_faults
import numpy as np
import pytest
import xarray as xr
from scipy.spatial.transform import Rotation

from buoy_common.bag_io import BagReader
from buoy_nav.config import fusion_config_from_files
from buoy_processing.bag_processing import (
    CURRENT_PRODUCTS_CSV_SUFFIX,
    process_bag,
    product_field_of_csv_column,
    products_csv_path,
)
from buoy_processing.process_bag import main as process_bag_main
from buoy_processing.wind_report import main as wind_report_main
from ros_messages import stamp_ns
from sensor_sim import simulate_bag
from sensor_sim.geodesy import earth_rate_enu_rad_s
from wind_comp.compensation_messages import CURRENT_STATS_FIELDS, stats_values
from wind_comp.config import compensator_config_from_files, current_config_from_files

REPO = Path(__file__).resolve().parents[2]
PARAMETER_FILES = [
    REPO / "src" / "buoy_common" / "config" / "buoy.yaml",
    REPO / "src" / "wind_comp" / "config" / "current.yaml",
]
DVL_POSITION_M = np.array([0.0, 0.0, -2.0])  # buoy.yaml's dvl.position
ERROR_FREE_DVL = (
    "sensors.dvl.scale_factor_error_percent=0",
    "sensors.dvl.bias_mps=[0, 0, 0]",
    "sensors.dvl.noise_mps=0",
)


def simulate(folder: Path, scenario: str, *overrides: str) -> Path:
    bag = folder / f"{scenario}_sensors"
    arguments = [item for override in overrides for item in ("--set", override)]
    simulate_bag.simulate(
        simulate_bag.parse_arguments(
            [scenario, str(bag), *arguments, "--params-file", str(PARAMETER_FILES[0])]
        )
    )
    return bag


def processed(folder: Path, bag: Path):
    out = folder / f"{bag.name}_processed"
    summary = process_bag(
        bag,
        out,
        fusion_config_from_files(PARAMETER_FILES),
        compensator_config_from_files(PARAMETER_FILES),
        current_config=current_config_from_files(PARAMETER_FILES),
    )
    return out, summary


@pytest.fixture(scope="module")
def open_ocean(tmp_path_factory):
    """open_ocean for 200 s, its DVL without errors but losing 2 % of its pings."""
    folder = tmp_path_factory.mktemp("open_ocean_current")
    bag = simulate(folder, "open_ocean", "duration_s=200", *ERROR_FREE_DVL)
    return (bag, *processed(folder, bag))


@pytest.fixture(scope="module")
def ship(tmp_path_factory):
    """Paper 003's ship for 200 s: a DVL, no anemometer."""
    folder = tmp_path_factory.mktemp("ship_current")
    bag = simulate(folder, "ship_current", "duration_s=200")
    return (bag, *processed(folder, bag))


def messages(bag: Path, topic: str) -> list:
    with BagReader(bag) as reader:
        return [reader.decode(record) for record in reader.messages([topic])]


def vectors(items) -> np.ndarray:
    return np.array([[m.vector.x, m.vector.y, m.vector.z] for m in items])


def test_one_current_per_dvl_sample_nan_where_the_ping_was_lost(open_ocean):
    sensors, out, summary = open_ocean
    pings = messages(sensors, "dvl/velocity")
    currents = messages(out, "current/velocity")
    assert [stamp_ns(m) for m in currents] == [stamp_ns(m) for m in pings]
    assert {m.header.frame_id for m in currents} == {"map"}
    lost = np.array([math.isnan(m.twist.twist.linear.x) for m in pings])
    assert 0 < np.count_nonzero(lost) < 0.1 * len(pings)
    assert np.all(np.isnan(vectors(currents)[lost]))
    counts = summary.current.status_counts
    assert counts["invalid_dvl"] == np.count_nonzero(lost)
    assert summary.current.rejected_messages == {"non_finite": np.count_nonzero(lost)}
    # Before the navigation's first solution (about 10 s) there is none to use.
    assert counts["valid"] + counts["invalid_dvl"] + counts["no_navigation"] == len(pings)
    assert summary.wind is not None  # open_ocean carries an anemometer too


def test_the_current_error_is_the_navigations_and_nothing_more(open_ocean):
    """With an error-free DVL, current − water velocity = the navigation's velocity error plus
    what its attitude and rate errors make of the DVL's reading and lever arm: at most
    |δθ| (|v_dvl| + |ω × l|) + |δω| |l| to first order. The simulator's truth gives all of it
    at the DVL's stamps (on the navigation's and the truth's sample grids)."""
    sensors, out, _ = open_ocean
    currents = {stamp_ns(m): m.vector for m in messages(out, "current/velocity")}
    water = {stamp_ns(m): m.vector for m in messages(out, "truth/water_velocity")}
    nav = {stamp_ns(m): m for m in messages(out, "nav/odometry")}
    truth = {stamp_ns(m): m for m in messages(out, "truth/odometry")}
    pings = {stamp_ns(m): m.twist.twist.linear for m in messages(sensors, "dvl/velocity")}
    latitude = math.radians(20.0)  # open_ocean's site; the drift changes it by 1e-5 rad
    earth_rate = earth_rate_enu_rad_s(latitude)
    checked = 0
    for stamp, current in currents.items():
        if math.isnan(current.x) or stamp not in nav or stamp not in truth:
            continue
        estimated = Rotation.from_quat(_quaternion(nav[stamp]))
        true = Rotation.from_quat(_quaternion(truth[stamp]))
        velocity_error = estimated.apply(_vector(nav[stamp].twist.twist.linear)) - true.apply(
            _vector(truth[stamp].twist.twist.linear)
        )
        level_rate = _vector(nav[stamp].twist.twist.angular) - estimated.inv().apply(earth_rate)
        rate_error = np.linalg.norm(level_rate - _vector(truth[stamp].twist.twist.angular))
        attitude_error = (true * estimated.inv()).magnitude()
        lever_velocity = np.linalg.norm(
            np.cross(_vector(truth[stamp].twist.twist.angular), DVL_POSITION_M)
        )
        bound = attitude_error * (np.linalg.norm(_vector(pings[stamp])) + lever_velocity)
        bound += rate_error * np.linalg.norm(DVL_POSITION_M)
        residual = _vector(current) - _vector(water[stamp]) - velocity_error
        assert np.linalg.norm(residual) <= 1.5 * bound + 1e-6, (stamp, residual, bound)
        checked += 1
    assert checked > 150


def test_current_products_are_in_the_bag_and_the_csv(open_ocean):
    _, out, summary = open_ocean
    csv_path = products_csv_path(out, CURRENT_PRODUCTS_CSV_SUFFIX)
    assert summary.current.csv_path == csv_path
    with open(csv_path, newline="") as stream:
        rows = list(csv.DictReader(stream))
    # The simulated ship's GNSS heading: the direction column names true north.
    assert "direction_true_north_deg" in rows[0]
    rows = [{product_field_of_csv_column(k): v for k, v in row.items()} for row in rows]
    stats = [stats_values(m) for m in messages(out, "current/stats_1min")]
    means = vectors(messages(out, "current/mean_1min"))
    one_minute = [row for row in rows if float(row["window_s"]) == 60.0]
    assert len(one_minute) == len(stats) == len(means) == 4  # 0-60, ..., 180-200 s
    for row, values, mean in zip(one_minute, stats, means, strict=True):
        assert list(values) == list(CURRENT_STATS_FIELDS)
        for name in ("speed_mps", "direction_deg", "n_valid", "n_invalid"):
            assert float(row[name]) == pytest.approx(values[name], abs=1e-6)
        np.testing.assert_allclose(
            [float(row[f"mean_{axis}_enu_mps"]) for axis in "uvw"], mean, atol=1e-6
        )
        # Oceanographic: the direction the mean flows toward.
        toward = math.degrees(math.atan2(mean[0], mean[1])) % 360.0
        assert values["direction_deg"] == pytest.approx(toward, abs=1e-9)


def test_a_bag_without_an_anemometer_gives_its_current_alone(ship):
    sensors, out, summary = ship
    with BagReader(sensors) as reader:
        assert "anemometer/wind" not in {name.lstrip("/") for name in reader.topics}
    with BagReader(out) as reader:
        topics = {name.lstrip("/") for name in reader.topics}
    assert "current/velocity" in topics and "wind/true" not in topics
    assert summary.wind is None
    assert not products_csv_path(out).exists()  # no wind products
    current = vectors(messages(out, "current/velocity"))
    valid = ~np.isnan(current).any(axis=1)
    mean = current[valid].mean(axis=0)
    # 2 m/s toward 60°; the DVL's default errors are 0.2 % of 4.4 m/s and 0.2 cm/s.
    assert math.hypot(mean[0], mean[1]) == pytest.approx(2.0, abs=0.015)
    assert math.degrees(math.atan2(mean[0], mean[1])) == pytest.approx(60.0, abs=0.5)


def test_a_bag_with_nothing_to_correct_is_refused_with_one_line(tmp_path, capsys):
    bag = simulate(tmp_path, "static", "duration_s=5", "sensors.anemometer=null")
    with pytest.raises(SystemExit) as exit_info:
        process_bag_main([str(bag), str(tmp_path / "out")])
    assert exit_info.value.code == 2
    error = capsys.readouterr().err
    assert error.startswith("process_bag: ") and error.count("\n") == 1
    assert "anemometer/wind" in error and "dvl/velocity" in error
    assert not (tmp_path / "out").exists()


def _quaternion(odometry) -> list[float]:
    q = odometry.pose.pose.orientation
    return [q.x, q.y, q.z, q.w]


def _vector(v) -> np.ndarray:
    return np.array([v.x, v.y, v.z])


def test_wind_report_draws_the_current_of_a_bag_without_wind(ship, tmp_path, capsys):
    _, out, _ = ship
    assert wind_report_main([str(out), "--out", str(tmp_path / "report")]) == 0
    written = {Path(line).name for line in capsys.readouterr().out.split()}
    assert written == {
        "current_time_series.png",
        "current_averaging.png",
        "current_products.md",
        "summary.md",
    }
    table = (tmp_path / "report" / "current_products.md").read_text()
    ten_minutes = [line for line in table.splitlines() if line.startswith("| 600 s means")]
    assert len(ten_minutes) == 1


def test_wind_report_draws_wind_and_current_of_a_buoy(open_ocean, tmp_path, capsys):
    # The first 30 s of the record hold a corrected wind (from about 13 s on) and a current:
    # which figures are drawn does not depend on the length.
    sensors, _, _ = open_ocean
    first_seconds = tmp_path / "open_ocean_first_30s"
    bag_faults.write_records(bag_faults.read_records(sensors, None, seconds=30.0), first_seconds)
    out, _ = processed(tmp_path, first_seconds)
    assert wind_report_main([str(out), "--out", str(tmp_path / "report")]) == 0
    written = {Path(line).name for line in capsys.readouterr().out.split()}
    assert {"wind_time_series.png", "wind_products.md", "current_time_series.png"} <= written


def test_wind_report_names_both_reports_when_a_bag_has_neither(ship, tmp_path, capsys):
    sensors, _, _ = ship  # the ship's sensor bag: a DVL, but no current/velocity yet
    with pytest.raises(SystemExit) as exit_info:
        wind_report_main([str(sensors), "--out", str(tmp_path / "report")])
    assert exit_info.value.code == 2
    error = capsys.readouterr().err
    assert error.count("\n") == 1 and "wind/true" in error and "current/velocity" in error


def test_without_a_bag_the_wind_and_the_current_are_the_same(open_ocean, tmp_path):
    """Both corrections of one buoy take the navigation in bulk when no bag is written: their
    CSVs and the NetCDF file are the bag's run's, byte for byte and value for value."""
    bag, _, _ = open_ocean
    runs = {}
    for write_bag in (True, False):
        out = tmp_path / f"write_bag_{write_bag}"
        process_bag(
            bag,
            out,
            fusion_config_from_files(PARAMETER_FILES),
            compensator_config_from_files(PARAMETER_FILES),
            current_config=current_config_from_files(PARAMETER_FILES),
            netcdf_path=out.with_suffix(".nc"),
            write_bag=write_bag,
        )
        runs[write_bag] = out
    csvs = sorted(path.name for path in tmp_path.glob(f"{runs[True].name}*.csv"))
    assert any("current" in name for name in csvs) and any("wind" in name for name in csvs)
    for name in csvs:
        theirs = tmp_path / name
        ours = tmp_path / name.replace(runs[True].name, runs[False].name, 1)
        assert ours.read_text() == theirs.read_text(), name
    with (
        xr.open_dataset(runs[True].with_suffix(".nc"), decode_times=False) as theirs,
        xr.open_dataset(runs[False].with_suffix(".nc"), decode_times=False) as ours,
    ):
        assert sorted(ours.variables) == sorted(theirs.variables)
        assert ours.sizes["nav_time"] > 0
        for variable in theirs.variables:
            np.testing.assert_array_equal(ours[variable], theirs[variable], err_msg=variable)
