"""``process_bag`` on the committed bags: one corrected wind per anemometer sample, as accurate
as the simulated anemometer and the navigation allow (a budget from the sensors' data sheets),
products that match their CSV, and the same navigation as ``fuse_bag``."""

from __future__ import annotations

import csv
import datetime
import math
from pathlib import Path

import numpy as np
import pytest
import xarray as xr
from scipy.spatial.transform import Rotation

from against_truth import Truth, assert_wind_within_budget
from buoy_common.bag_io import BagReader, BagWriter
from buoy_common.contract import (
    window_label,
)
from buoy_nav.config import fusion_config_from_files
from buoy_processing import bag_processing
from buoy_processing.bag_fusion import fuse_bag
from buoy_processing.bag_processing import (
    ISO_TIME_COLUMNS,
    product_field_of_csv_column,
    products_csv_path,
)
from buoy_processing.netcdf_variables import product_time_name, product_variable_name
from buoy_processing.process_bag import main as process_bag_main
from error_budget import ANEMOMETER
from processed_bags import BAGS_DIR, BUOY_PARAMETERS, CASES, processed_bag, processed_netcdf
from ros_messages import raw_stamp_ns
from wind_comp.compensation_messages import (
    STATS_FIELDS,
    stats_values,
)
from wind_comp.compensator import SampleStatus
from wind_comp.config import compensator_config_from_files
from wind_comp.pipeline import CompensationPipeline

COMPENSATOR = compensator_config_from_files([BUOY_PARAMETERS])
NAV_TOPICS = ("/nav/odometry", "/nav/imu", "/nav/velocity", "/nav/fix")
NANOSECONDS_PER_SECOND = 1_000_000_000
SETTLING_S = 2.0
"""How long after its first solution the navigation may still be too uncertain for the wind."""
# CSV values carry 6 decimals; epoch stamps in float64 add 2.4e-7 s.
CSV_TOLERANCE = 1e-6


def vector(v) -> list[float]:
    return [v.x, v.y, v.z]


class WindRun:
    """The wind of one processed bag, as arrays."""

    def __init__(self, bag: Path):
        with BagReader(bag) as reader:
            self.topics = dict(reader.topics)
            self.anemometer_ns, self.anemometer_mps = self._vectors(reader, "anemometer/wind")
            self.true_wind_ns, self.true_wind_enu_mps = self._vectors(reader, "wind/true")
            self.true_wind_frames = {
                reader.decode(r).header.frame_id for r in reader.messages(["wind/true"])
            }
            self.first_nav_ns = raw_stamp_ns(next(iter(reader.messages(["nav/odometry"]))).raw)
            self.means = self._decoded(reader, "/wind/mean_")
            self.stats = {
                topic: [stats_values(message) for message in messages]
                for topic, messages in self._decoded(reader, "/wind/stats_").items()
            }
        self.truth = Truth(bag)

    @staticmethod
    def _vectors(reader: BagReader, topic: str) -> tuple[np.ndarray, np.ndarray]:
        messages = [reader.decode(r) for r in reader.messages([topic])]
        stamps = np.array(
            [m.header.stamp.sec * NANOSECONDS_PER_SECOND + m.header.stamp.nanosec for m in messages]
        )
        return stamps, np.array([vector(m.vector) for m in messages])

    @staticmethod
    def _decoded(reader: BagReader, prefix: str) -> dict[str, list]:
        return {
            topic: [reader.decode(r) for r in reader.messages([topic])]
            for topic in sorted(reader.topics)
            if topic.startswith(prefix)
        }


@pytest.fixture(scope="module")
def runs(tmp_path_factory) -> dict[str, WindRun]:
    return {name: WindRun(processed_bag(tmp_path_factory, name)) for name in CASES}


@pytest.mark.parametrize("name", CASES)
def test_one_true_wind_per_anemometer_sample_with_its_stamp(runs, name):
    run = runs[name]
    assert run.topics["/wind/true"].count == run.topics["/anemometer/wind"].count
    np.testing.assert_array_equal(run.true_wind_ns, run.anemometer_ns)
    assert run.true_wind_frames == {"map"}


@pytest.mark.parametrize("name", CASES)
def test_wind_is_nan_only_before_the_first_navigation_solution(runs, tmp_path_factory, name):
    """Or while the navigation's covariance, just after the alignment, still makes the wind's
    σ too large: those samples are refused for their uncertainty."""
    run = runs[name]
    invalid = np.isnan(run.true_wind_enu_mps)
    assert np.array_equal(invalid.any(axis=1), invalid.all(axis=1)), "NaN vectors, not parts"
    with xr.open_dataset(processed_netcdf(tmp_path_factory, name)) as dataset:
        status = dataset["wind_status"].values
    too_uncertain = status == SampleStatus.UNCERTAINTY_TOO_LARGE
    assert np.all(invalid[too_uncertain])
    settled = run.anemometer_ns < run.first_nav_ns + SETTLING_S * NANOSECONDS_PER_SECOND
    assert np.all(settled[too_uncertain]), f"{name}: refused for its σ after {SETTLING_S} s"
    invalid[too_uncertain] = False
    nan_stamps = run.true_wind_ns[invalid.any(axis=1)]
    before_navigation = run.anemometer_ns < run.first_nav_ns
    last_allowed_ns = run.first_nav_ns + COMPENSATOR.max_nav_gap_s * NANOSECONDS_PER_SECOND
    figures = (
        f"{name}: {nan_stamps.size} NaN of {run.true_wind_ns.size}, "
        f"{np.count_nonzero(before_navigation)} before the first solution; last NaN "
        f"{(nan_stamps.max() - run.first_nav_ns) * 1e-9 if nan_stamps.size else math.nan:+.3f} s "
        "from it"
    )
    assert np.all(nan_stamps < last_allowed_ns), figures
    assert np.all(invalid[before_navigation]), f"no navigation, no correction: {figures}"
    assert nan_stamps.size < 0.2 * run.true_wind_ns.size, figures


@pytest.mark.parametrize("name", CASES)
def test_corrected_wind_matches_the_truth_within_the_error_budget(runs, name):
    """Every valid corrected sample from the first solution on, where the truth has a sample
    of its stamp (every other one), against the budget of :mod:`error_budget`: anemometer
    noise, the attitude targets times the air speed, one GNSS velocity's noise and the gyro
    noise times the lever arm, none taken from this run's navigation."""
    run = runs[name]
    valid = np.count_nonzero(~np.isnan(run.true_wind_enu_mps).any(axis=1))
    errors = run.truth.wind_errors(run.true_wind_ns, run.true_wind_enu_mps)
    assert errors.shape[0] >= 0.4 * valid, "the truth shares every other anemometer stamp"
    figures = assert_wind_within_budget(
        errors, run.anemometer_mps, CASES[name].anemometer_position_body_m, name
    )
    # the correction does something: the anemometer's own noise is the floor
    rms = np.sqrt(np.mean(errors**2, axis=0))
    assert np.all(rms >= (1 - 0.1) * ANEMOMETER.noise_mps), figures
    print(figures)


def read_products_csv(path: Path) -> list[dict[str, float]]:
    """The rows of a products CSV as numbers, keyed by product field; the ISO 8601 bounds are
    checked against the numeric ones and left out. The simulated buoys carry GNSS headings, so
    every direction column names true north."""
    rows = []
    with open(path, newline="") as stream:
        for row in csv.DictReader(stream):
            directions = [key for key in row if "direction" in key]
            assert all(key.endswith("_true_north_deg") for key in directions), directions
            numbers = {
                product_field_of_csv_column(key): float(value)
                for key, value in row.items()
                if key not in ISO_TIME_COLUMNS
            }
            for iso_column, seconds_column in zip(
                ISO_TIME_COLUMNS, ("window_start_s", "window_end_s"), strict=True
            ):
                moment = datetime.datetime.fromisoformat(row[iso_column])
                assert moment.tzinfo == datetime.UTC, row[iso_column]
                assert abs(moment.timestamp() - numbers[seconds_column]) < 1e-3, row
            rows.append(numbers)
    return rows


@pytest.mark.parametrize("name", CASES)
def test_csv_rows_are_the_published_products(runs, tmp_path_factory, name):
    run = runs[name]
    rows = read_products_csv(products_csv_path(processed_bag(tmp_path_factory, name)))
    assert len(rows) == sum(len(s) for s in run.stats.values()) > 0
    seen = {topic: 0 for topic in run.stats}
    for row in rows:
        label = window_label(row["window_s"])
        stats_topic, mean_topic = f"/wind/stats_{label}", f"/wind/mean_{label}"
        index = seen[stats_topic]
        seen[stats_topic] += 1
        stats = run.stats[stats_topic][index]
        assert list(stats) == list(STATS_FIELDS)
        for field in STATS_FIELDS:
            if math.isnan(row[field]):
                assert math.isnan(stats[field]), (name, label, index, field)
            else:
                assert math.isclose(row[field], stats[field], abs_tol=CSV_TOLERANCE), (
                    name,
                    label,
                    index,
                    field,
                    row[field],
                    stats[field],
                )
        mean = run.means[mean_topic][index]
        np.testing.assert_allclose(
            vector(mean.vector),
            [row["mean_u_enu_mps"], row["mean_v_enu_mps"], row["mean_w_enu_mps"]],
            rtol=0,
            atol=CSV_TOLERANCE,
        )
        end_ns = mean.header.stamp.sec * NANOSECONDS_PER_SECOND + mean.header.stamp.nanosec
        assert abs(end_ns * 1e-9 - row["window_end_s"]) < CSV_TOLERANCE
    assert seen == {topic: len(messages) for topic, messages in run.stats.items()}


def _netcdf_reference_s(units: str) -> float:
    """The epoch seconds of a CF time unit ``seconds since <ISO 8601 time>``."""
    prefix = "seconds since "
    assert units.startswith(prefix), units
    return datetime.datetime.fromisoformat(units.removeprefix(prefix)).timestamp()


@pytest.mark.parametrize("name", ["sea_state", "off_axis"])
def test_netcdf_holds_the_bag_outputs_value_for_value(runs, tmp_path_factory, name):
    run = runs[name]
    path = processed_netcdf(tmp_path_factory, name)
    with xr.open_dataset(path) as decoded:
        # CF decoding gives the sensors' stamps back to within a nanosecond (xarray truncates
        # the float seconds it decodes: 2.05 s comes back as 2.049999999 s)
        decoded_ns = decoded["time"].values.astype("datetime64[ns]").astype(np.int64)
        assert np.abs(decoded_ns - run.true_wind_ns).max() <= 1
    with xr.open_dataset(path, decode_times=False) as dataset:
        reference_s = _netcdf_reference_s(dataset["time"].attrs["units"])
        for axis, variable in enumerate(("eastward_wind", "northward_wind", "upward_air_velocity")):
            np.testing.assert_array_equal(dataset[variable].values, run.true_wind_enu_mps[:, axis])
        valid = np.isfinite(run.true_wind_enu_mps).all(axis=1)
        np.testing.assert_array_equal(dataset["wind_status"].values == 0, valid)
        for stats_topic, stats in run.stats.items():
            window_s = stats[0]["window_end_s"] - stats[0]["window_start_s"]
            bounds = dataset[f"{product_time_name('wind', window_s)}_bounds"].values
            np.testing.assert_allclose(
                bounds + reference_s,
                [[row["window_start_s"], row["window_end_s"]] for row in stats],
                rtol=0,
                atol=CSV_TOLERANCE,
            )
            for field in STATS_FIELDS:
                if field in ("window_start_s", "window_end_s"):
                    continue
                values = dataset[product_variable_name("wind", window_s, field)].values
                if field.endswith("sample_s"):
                    values = values + reference_s
                    np.testing.assert_allclose(
                        values, [row[field] for row in stats], rtol=0, atol=CSV_TOLERANCE
                    )
                else:
                    np.testing.assert_array_equal(
                        values, [row[field] for row in stats], err_msg=f"{stats_topic} {field}"
                    )
        with BagReader(processed_bag(tmp_path_factory, name)) as reader:
            fixes = [reader.decode(r) for r in reader.messages(["nav/fix"])]
            odometry = [reader.decode(r) for r in reader.messages(["nav/odometry"])]
        np.testing.assert_array_equal(dataset["latitude"].values, [m.latitude for m in fixes])
        np.testing.assert_array_equal(dataset["longitude"].values, [m.longitude for m in fixes])
        quaternions = [[q.x, q.y, q.z, q.w] for q in (m.pose.pose.orientation for m in odometry)]
        yaw_pitch_roll = Rotation.from_quat(quaternions).as_euler("ZYX", degrees=True)
        np.testing.assert_allclose(dataset["roll"].values, yaw_pitch_roll[:, 2], atol=1e-9)
        np.testing.assert_allclose(dataset["pitch"].values, yaw_pitch_roll[:, 1], atol=1e-9)
        heading_error = (dataset["heading"].values - (90.0 - yaw_pitch_roll[:, 0]) + 180) % 360
        np.testing.assert_allclose(heading_error - 180, 0.0, atol=1e-9)
        # The simulated buoy's GNSS heading and fixes: true north, a measured position, and
        # the file's span is that of its samples.
        assert dataset.attrs["north_reference"] == "true north"
        assert "GNSS" in dataset.attrs["instrument"]
        assert "comment" not in dataset["latitude"].attrs
        first_s = min(float(dataset[n].values.min()) for n in ("time", "nav_time"))
        last_s = max(float(dataset[n].values.max()) for n in ("time", "nav_time"))
        for attribute, seconds in (("time_coverage_start", first_s), ("time_coverage_end", last_s)):
            moment = datetime.datetime.fromisoformat(dataset.attrs[attribute])
            assert abs(moment.timestamp() - (reference_s + seconds)) < 1e-3, attribute


def test_navigation_is_fuse_bags_byte_for_byte(tmp_path_factory, tmp_path):
    processed = processed_bag(tmp_path_factory, "sea_state")
    fused = tmp_path / "fused"
    fuse_bag(BAGS_DIR / "sea_state", fused, fusion_config_from_files([BUOY_PARAMETERS]))
    with BagReader(processed) as ours, BagReader(fused) as theirs:
        for topic in NAV_TOPICS:
            assert ours.topics[topic] == theirs.topics[topic]
            for a, b in zip(ours.messages([topic]), theirs.messages([topic]), strict=True):
                assert (a.log_time_ns, a.raw) == (b.log_time_ns, b.raw), topic


def test_without_a_bag_the_csvs_and_the_netcdf_file_are_the_same(tmp_path_factory, tmp_path):
    name = "sea_state"
    with_bag = processed_bag(tmp_path_factory, name)
    out_bag = tmp_path / "bag"
    netcdf = tmp_path / f"{name}.nc"
    files = CASES[name].parameter_files(tmp_path)
    arguments = [str(CASES[name].bag_path), str(out_bag), "--netcdf", str(netcdf), "--no-bag"]
    process_bag_main([*arguments, *(f"--params-file={path}" for path in files)])
    assert not out_bag.exists()
    csvs = sorted(tmp_path.glob("*.csv"))
    assert csvs
    for path in csvs:
        assert path.read_text() == with_bag.with_name(path.name).read_text(), path.name
    with (
        xr.open_dataset(netcdf, decode_times=False) as ours,
        xr.open_dataset(processed_netcdf(tmp_path_factory, name), decode_times=False) as theirs,
    ):
        assert sorted(ours.variables) == sorted(theirs.variables)
        assert ours.sizes["nav_time"] > 0
        for variable in theirs.variables:
            np.testing.assert_array_equal(ours[variable], theirs[variable], err_msg=variable)


@pytest.mark.parametrize("write_bag", [True, False], ids=["bag", "no_bag"])
def test_a_silent_anemometer_does_not_pile_up_the_navigation(tmp_path, monkeypatch, write_bag):
    """Two minutes of ``sea_state`` whose anemometer falls silent for the second minute: the
    corrections hold no more solutions than their bound (here lowered to 1,000, ten seconds),
    and hand them over without changing a corrected sample or a product; with a bag, one by
    one as messages, without one, held back and handed over in bulk."""
    bag = tmp_path / "silent_minute"
    with BagReader(CASES["sea_state"].bag_path) as reader:
        silent_from_ns = reader.start_ns + 60 * NANOSECONDS_PER_SECOND
        with BagWriter(bag) as writer:
            for record in reader.messages(list(reader.topics)):
                if record.log_time_ns > silent_from_ns + 60 * NANOSECONDS_PER_SECOND:
                    break
                silent = record.log_time_ns > silent_from_ns
                if silent and record.topic.startswith("/anemometer/"):
                    continue
                writer.write_raw(record.topic, record.msgtype, record.log_time_ns, record.raw)
    files = [str(path) for path in CASES["sea_state"].parameter_files(tmp_path)]
    held = []
    add_odometry = CompensationPipeline.add_odometry
    add_navigation_columns = CompensationPipeline.add_navigation_columns

    def watched(pipeline, *arguments):
        held.append(pipeline.n_navigation_held)
        return add_odometry(pipeline, *arguments)

    def watched_in_bulk(pipeline, columns):
        held.append(pipeline.n_navigation_held + len(columns.stamps_s) - 1)
        return add_navigation_columns(pipeline, columns)

    monkeypatch.setattr(CompensationPipeline, "add_odometry", watched)
    monkeypatch.setattr(CompensationPipeline, "add_navigation_columns", watched_in_bulk)
    outputs, most_held = {}, {}
    for bound in (bag_processing.NAV_SOLUTIONS_HELD_AT_MOST, 1000):
        monkeypatch.setattr(bag_processing, "NAV_SOLUTIONS_HELD_AT_MOST", bound)
        held.clear()
        out = tmp_path / f"held_{bound}"
        bag_processing.process_bag(
            bag,
            out,
            fusion_config_from_files(files),
            compensator_config_from_files(files),
            netcdf_path=out.with_suffix(".nc"),
            say_statements=False,
            write_bag=write_bag,
            # The corrections in this process, where the watch and the bound are set (with the
            # bag written in the background they run in its writing process).
            write_in_background=False,
        )
        outputs[bound] = out
        most_held[bound] = max(held)
    default_held, bounded_held = most_held.values()
    assert bounded_held < 1000 < 60 * 100 <= default_held  # a silent minute at 100 Hz
    default, bounded = outputs.values()
    assert products_csv_path(bounded).read_text() == products_csv_path(default).read_text()
    with (
        xr.open_dataset(default.with_suffix(".nc"), decode_times=False) as theirs,
        xr.open_dataset(bounded.with_suffix(".nc"), decode_times=False) as ours,
    ):
        assert ours.sizes["time"] > 0
        for variable in theirs.variables:
            np.testing.assert_array_equal(ours[variable], theirs[variable], err_msg=variable)
