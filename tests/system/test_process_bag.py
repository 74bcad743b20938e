"""``process_bag`` on the committed bags: one corrected wind per anemometer sample, as accurate
as the simulated anemometer and the navigation allow, products that match their CSV, and the
same navigation as ``fuse_bag``."""

from __future__ import annotations

import csv
import math
from pathlib import Path

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from buoy_common.bag_io import BagReader
from buoy_common.contract import (
    window_label,
)
from buoy_nav.bag_fusion import fuse_bag
from buoy_nav.config import fusion_config_from_files
from ros_messages import raw_stamp_ns
from sensor_sim.sensor_errors import AnemometerErrorConfig
from wind_comp.bag_processing import process_bag, products_csv_path
from wind_comp.compensation_messages import (
    STATS_FIELDS,
    stats_values,
)
from wind_comp.config import compensator_config_from_files

REPO = Path(__file__).resolve().parents[2]
BAGS_DIR = REPO / "bags"
BAGS = ("static", "tilt_table", "wind_tunnel_10", "vertical_wind_5", "sea_state", "open_ocean")
BUOY_PARAMETERS = REPO / "src" / "buoy_common" / "config" / "buoy.yaml"
COMPENSATOR = compensator_config_from_files([BUOY_PARAMETERS])
NAV_TOPICS = ("/nav/odometry", "/nav/imu", "/nav/velocity", "/nav/fix")
NANOSECONDS_PER_SECOND = 1_000_000_000
# Navigation errors are sampled at the GNSS rate: consecutive 100 Hz errors add nothing.
EVALUATION_PERIOD_MS = 100
ANEMOMETER_NOISE_MPS = AnemometerErrorConfig().noise_mps  # per axis, what recorded the bags
STAMP_MATCH_NS = 1000
# The RMS of N ≥ 1000 samples of white noise is within 1.2 sigma with certainty (its relative
# spread is 1/sqrt(2N) ≈ 2 %).
NOISE_RMS_FACTOR = 1.2
# CSV values carry 6 decimals; epoch stamps in float64 add 2.4e-7 s.
CSV_TOLERANCE = 1e-6


def processed_bag(tmp_path_factory, name: str) -> Path:
    """``process_bag``'s output of committed bag ``name``, made once per test session."""
    out = tmp_path_factory.getbasetemp() / "processed_bags" / name
    if not (out / "metadata.yaml").is_file():
        out.parent.mkdir(exist_ok=True)
        process_bag(
            BAGS_DIR / name,
            out,
            fusion_config_from_files([BUOY_PARAMETERS]),
            COMPENSATOR,
            overwrite=True,
        )
    return out


def vector(v) -> list[float]:
    return [v.x, v.y, v.z]


def quaternion(message) -> list[float]:
    q = message.pose.pose.orientation
    return [q.x, q.y, q.z, q.w]


class WindRun:
    """The wind and navigation of one processed bag, as arrays."""

    def __init__(self, bag: Path):
        with BagReader(bag) as reader:
            self.topics = dict(reader.topics)
            self.anemometer_ns, self.anemometer_mps = self._vectors(reader, "anemometer/wind")
            self.true_wind_ns, self.true_wind_enu_mps = self._vectors(reader, "wind/true")
            self.truth_ns, self.truth_enu_mps = self._vectors(reader, "truth/wind")
            self.true_wind_frames = {
                reader.decode(r).header.frame_id for r in reader.messages(["wind/true"])
            }
            self.first_nav_ns = raw_stamp_ns(next(iter(reader.messages(["nav/odometry"]))).raw)
            nav = self._on_grid(reader, "nav/odometry")
            truth = self._on_grid(reader, "truth/odometry")
            self.means = self._decoded(reader, "/wind/mean_")
            self.stats = {
                topic: [stats_values(message) for message in messages]
                for topic, messages in self._decoded(reader, "/wind/stats_").items()
            }
        grid = sorted(set(nav) & set(truth))
        estimated = Rotation.from_quat([quaternion(nav[t]) for t in grid])
        true = Rotation.from_quat([quaternion(truth[t]) for t in grid])
        self.attitude_error_rad = (true * estimated.inv()).as_rotvec()
        self.velocity_error_mps = estimated.apply(
            [vector(nav[t].twist.twist.linear) for t in grid]
        ) - true.apply([vector(truth[t].twist.twist.linear) for t in grid])
        self.rate_error_rad_s = np.array(
            [vector(nav[t].twist.twist.angular) for t in grid]
        ) - np.array([vector(truth[t].twist.twist.angular) for t in grid])

    @staticmethod
    def _vectors(reader: BagReader, topic: str) -> tuple[np.ndarray, np.ndarray]:
        messages = [reader.decode(r) for r in reader.messages([topic])]
        stamps = np.array(
            [m.header.stamp.sec * NANOSECONDS_PER_SECOND + m.header.stamp.nanosec for m in messages]
        )
        return stamps, np.array([vector(m.vector) for m in messages])

    def _on_grid(self, reader: BagReader, topic: str) -> dict[int, object]:
        samples = {}
        for record in reader.messages([topic]):
            stamp = raw_stamp_ns(record.raw)
            grid_ms = round(stamp / 1e6)
            if stamp >= self.first_nav_ns and grid_ms % EVALUATION_PERIOD_MS == 0:
                samples[grid_ms] = reader.decode(record)
        return samples

    @staticmethod
    def _decoded(reader: BagReader, prefix: str) -> dict[str, list]:
        return {
            topic: [reader.decode(r) for r in reader.messages([topic])]
            for topic in sorted(reader.topics)
            if topic.startswith(prefix)
        }


@pytest.fixture(scope="module")
def runs(tmp_path_factory) -> dict[str, WindRun]:
    return {name: WindRun(processed_bag(tmp_path_factory, name)) for name in BAGS}


@pytest.mark.parametrize("name", BAGS)
def test_one_true_wind_per_anemometer_sample_with_its_stamp(runs, name):
    run = runs[name]
    assert run.topics["/wind/true"].count == run.topics["/anemometer/wind"].count
    np.testing.assert_array_equal(run.true_wind_ns, run.anemometer_ns)
    assert run.true_wind_frames == {"map"}


@pytest.mark.parametrize("name", BAGS)
def test_wind_is_nan_only_before_the_first_navigation_solution(runs, name):
    run = runs[name]
    invalid = np.isnan(run.true_wind_enu_mps)
    assert np.array_equal(invalid.any(axis=1), invalid.all(axis=1)), "NaN vectors, not parts"
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


@pytest.mark.parametrize("name", BAGS)
def test_corrected_wind_matches_the_truth_within_the_error_budget(runs, name):
    """Corrected − true wind = anemometer noise − φ×W_rel − δv − R(δω×B), so by Minkowski its
    RMS per axis is at most the sum of the terms' RMS: noise from the simulator's anemometer
    model, the rest from the actual navigation errors against the truth the bag carries. The
    truth is taken at the anemometer stamps where it has a sample (every other one): between its
    50 Hz samples the turbulence is not linear, and interpolating it would add an error of its
    own of the size of the anemometer noise."""
    run = runs[name]
    valid = ~np.isnan(run.true_wind_enu_mps).any(axis=1)
    after = np.clip(np.searchsorted(run.truth_ns, run.true_wind_ns), 1, run.truth_ns.size - 1)
    nearest_gap_ns = np.minimum(
        np.abs(run.truth_ns[after] - run.true_wind_ns),
        np.abs(run.truth_ns[after - 1] - run.true_wind_ns),
    )
    on_truth_sample = nearest_gap_ns < STAMP_MATCH_NS
    compared = valid & on_truth_sample
    assert np.count_nonzero(compared) >= 0.4 * np.count_nonzero(valid)
    truth_at_samples = np.column_stack(
        [np.interp(run.true_wind_ns, run.truth_ns, run.truth_enu_mps[:, k]) for k in range(3)]
    )
    error = run.true_wind_enu_mps[compared] - truth_at_samples[compared]
    rms_error = np.sqrt(np.mean(error**2, axis=0))

    def rms_norm(values):
        return float(np.sqrt(np.mean(np.sum(values**2, axis=1))))

    relative_air_speed = float(np.max(np.linalg.norm(run.anemometer_mps, axis=1)))
    lever_arm_m = float(np.linalg.norm(COMPENSATOR.anemometer_position_body_m))
    budget = {
        "anemometer noise": NOISE_RMS_FACTOR * ANEMOMETER_NOISE_MPS,
        "attitude x wind": rms_norm(run.attitude_error_rad) * relative_air_speed,
        "velocity": rms_norm(run.velocity_error_mps),
        "rate x lever arm": rms_norm(run.rate_error_rad_s) * lever_arm_m,
    }
    tolerance = sum(budget.values())
    figures = (
        f"{name}: RMS error E, N, U {np.round(rms_error, 4)} m/s over {error.shape[0]} samples; "
        f"tolerance {tolerance:.4f} = " + ", ".join(f"{k} {v:.4f}" for k, v in budget.items())
    )
    assert np.all(rms_error <= tolerance), figures
    # the correction does something: the anemometer's own noise is the floor
    assert np.all(rms_error >= (1 - 0.1) * ANEMOMETER_NOISE_MPS), figures


def read_products_csv(path: Path) -> list[dict[str, float]]:
    with open(path, newline="") as stream:
        return [{key: float(value) for key, value in row.items()} for row in csv.DictReader(stream)]


@pytest.mark.parametrize("name", BAGS)
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


def test_navigation_is_fuse_bags_byte_for_byte(tmp_path_factory, tmp_path):
    processed = processed_bag(tmp_path_factory, "sea_state")
    fused = tmp_path / "fused"
    fuse_bag(BAGS_DIR / "sea_state", fused, fusion_config_from_files([BUOY_PARAMETERS]))
    with BagReader(processed) as ours, BagReader(fused) as theirs:
        for topic in NAV_TOPICS:
            assert ours.topics[topic] == theirs.topics[topic]
            for a, b in zip(ours.messages([topic]), theirs.messages([topic]), strict=True):
                assert (a.log_time_ns, a.raw) == (b.log_time_ns, b.raw), topic
