"""``fuse_bag`` on the committed bags: the command line, its errors, and the accuracy of the
fusion against the truth each bag carries.

Accuracy is judged on ``process_bag``'s output, whose ``nav/*`` are ``fuse_bag``'s (same core;
``test_process_bag`` holds them byte-equal), so every bag is fused once per session, with the
parameter files of the buoy that recorded it (the shipped geometry, or ``off_axis``'s own, also
fused from the heading alone). The filter must be consistent (its errors the size its
covariance claims) and never worse than what the simulated sensors allow (limits of
:mod:`error_budget`, from the data sheets the simulator drew the errors from).
"""

from __future__ import annotations

import gc
import math
import subprocess
import sys
from pathlib import Path
from typing import NamedTuple

import numpy as np
import pytest
from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory
from scipy.stats import chi2

from against_truth import (
    NavigationErrors,
    Truth,
    assert_navigation_within_limits,
    topic_columns,
)
from buoy_common.bag_io import BagReader, BagWriter
from buoy_nav.config import fusion_config_from_files
from buoy_processing.bag_fusion import fuse_bag
from buoy_processing.offline_fusion import OfflineFusion
from processed_bags import BAGS_DIR, BUOY_PARAMETERS, CASES, processed_bag
from ros_messages import raw_stamp_ns

FUSE_BAG = Path(sys.executable).parent / "fuse_bag"
CLI_BAG = "sea_state"
NAV_TOPICS = ("/nav/odometry", "/nav/imu", "/nav/velocity", "/nav/fix")
SENSOR_TOPICS = ("/imu/data_raw", "/gnss/fix", "/gnss/vel", "/gnss/heading")
NANOSECONDS_PER_SECOND = 1_000_000_000

SETTLING_S = 60.0  # accuracy is judged from the first solution + this
# Statistics at the GNSS rate: consecutive 100 Hz errors add no independent information.
EVALUATION_PERIOD_NS = 100_000_000
ATTITUDE_VARIANCE_INDICES = (21, 28, 35)  # E, N, U rotation-vector error in the pose covariance
VELOCITY_VARIANCE_INDICES = (0, 7, 14)  # E, N, U in the ENU twist covariance
AXES = ("E", "N", "U")
# Per bag and axis the error may be one slowly varying draw over the whole window (bias driven),
# so its mean NEES is bounded only by the chi-square quantile of ONE degree of freedom; pooled
# over all bags and axes (independent seeds), the mean has at least that many degrees.
CONFIDENCE = 0.999
MAX_SIGMAS = 4.0
MIN_FRACTION_WITHIN = 0.999


class Accuracy(NamedTuple):
    """Errors estimate − truth at the evaluation samples and the filter's variances."""

    errors: NavigationErrors
    attitude_variance_rad2: np.ndarray  # (N, 3) E, N, U
    velocity_variance_m2s2: np.ndarray  # (N, 3)


def accuracy_of(bag: Path) -> Accuracy:
    """The first solution of every 100 ms from SETTLING_S after the first one, against the
    truth interpolated to its stamp."""
    truth = Truth(bag)
    with BagReader(bag) as reader:
        odometry = topic_columns(reader, "nav/odometry", "nav_msgs/msg/Odometry")
        velocity = topic_columns(
            reader, "nav/velocity", "geometry_msgs/msg/TwistWithCovarianceStamped"
        )
    stamps = odometry.stamp_ns
    assert np.array_equal(velocity.stamp_ns, stamps), "nav/velocity is not one per odometry"
    from_ns = stamps[0] + int(SETTLING_S * NANOSECONDS_PER_SECOND)
    bins = stamps // EVALUATION_PERIOD_NS
    first_of_bin = np.concatenate(([True], bins[1:] != bins[:-1]))
    chosen = np.flatnonzero(first_of_bin & (stamps >= from_ns) & truth.covers(stamps))
    assert chosen.size >= 0.95 * (stamps[-1] - from_ns) / EVALUATION_PERIOD_NS > 100
    pose_covariance = odometry["pose_covariance"].reshape(-1, 36)[chosen]
    twist_covariance = velocity["covariance"].reshape(-1, 36)[chosen]
    return Accuracy(
        errors=truth.navigation_errors(
            stamps[chosen], odometry["orientation"][chosen], velocity["linear"][chosen]
        ),
        attitude_variance_rad2=pose_covariance[:, ATTITUDE_VARIANCE_INDICES],
        velocity_variance_m2s2=twist_covariance[:, VELOCITY_VARIANCE_INDICES],
    )


@pytest.fixture(scope="module")
def accuracy(tmp_path_factory) -> dict[str, Accuracy]:
    return {name: accuracy_of(processed_bag(tmp_path_factory, name)) for name in CASES}


def consistency_figures(error: np.ndarray, variance: np.ndarray) -> str:
    nees = np.mean(error**2 / variance, axis=0)
    rms = np.sqrt(np.mean(error**2, axis=0))
    sigma = np.sqrt(np.mean(variance, axis=0))
    return ", ".join(
        f"{axis}: mean NEES {n:.2f}, RMS error {r:.3g}, mean sigma {s:.3g}"
        for axis, n, r, s in zip(AXES, nees, rms, sigma, strict=True)
    )


def assert_consistent(error: np.ndarray, variance: np.ndarray, what: str) -> None:
    figures = consistency_figures(error, variance)
    assert np.all(variance > 0), what
    nees = np.mean(error**2 / variance, axis=0)
    bound = chi2.ppf(CONFIDENCE, 1)
    assert np.all(nees < bound), f"{what}: mean NEES above {bound:.1f}: {figures}"
    within = np.mean(np.abs(error) < MAX_SIGMAS * np.sqrt(variance), axis=0)
    assert np.all(within >= MIN_FRACTION_WITHIN), (
        f"{what}: fraction within {MAX_SIGMAS:g} sigma {within}: {figures}"
    )


# -- accuracy ----------------------------------------------------------------------------------


@pytest.mark.parametrize("name", CASES)
def test_attitude_error_is_what_the_covariance_says(accuracy, name):
    result = accuracy[name]
    assert_consistent(
        result.errors.attitude_enu_rad, result.attitude_variance_rad2, f"{name} attitude (rad)"
    )


@pytest.mark.parametrize("name", CASES)
def test_velocity_error_is_what_the_covariance_says(accuracy, name):
    result = accuracy[name]
    assert_consistent(
        result.errors.velocity_enu_mps, result.velocity_variance_m2s2, f"{name} velocity (m/s)"
    )


@pytest.mark.parametrize(
    "error_of, variance_field",
    [
        (lambda errors: errors.attitude_enu_rad, "attitude_variance_rad2"),
        (lambda errors: errors.velocity_enu_mps, "velocity_variance_m2s2"),
    ],
    ids=["attitude", "velocity"],
)
def test_pooled_nees_is_within_chi_square_bounds(accuracy, error_of, variance_field):
    nees = {
        name: np.mean(error_of(r.errors) ** 2 / getattr(r, variance_field), axis=0)
        for name, r in accuracy.items()
    }
    per_bag_axis = np.concatenate(list(nees.values()))
    degrees = per_bag_axis.size
    low = chi2.ppf(1 - CONFIDENCE, degrees) / degrees
    high = chi2.ppf(CONFIDENCE, degrees) / degrees
    figures = {name: np.round(value, 2) for name, value in nees.items()}
    assert low < per_bag_axis.mean() < high, (
        f"{variance_field}: mean NEES {per_bag_axis.mean():.2f} outside [{low:.2f}, {high:.2f}]; "
        f"per bag (E, N, U): {figures}"
    )


@pytest.mark.parametrize("name", CASES)
def test_attitude_and_velocity_stay_within_what_the_sensors_allow(accuracy, name):
    print(
        assert_navigation_within_limits(
            accuracy[name].errors, CASES[name].navigation_limits(), name
        )
    )


# -- the command line --------------------------------------------------------------------------


def run_fuse_bag(*arguments, timeout_s: float = 120.0) -> subprocess.CompletedProcess:
    return subprocess.run(
        [str(FUSE_BAG), *map(str, arguments)],
        capture_output=True,
        text=True,
        timeout=timeout_s,
    )


@pytest.fixture(scope="module")
def cli_run(tmp_path_factory):
    out = tmp_path_factory.mktemp("fuse_bag") / CLI_BAG
    completed = run_fuse_bag(BAGS_DIR / CLI_BAG, out, "--params-file", BUOY_PARAMETERS)
    return completed, out


def stamps_of(reader: BagReader, topic: str) -> list[int]:
    return [raw_stamp_ns(record.raw) for record in reader.messages([topic])]


def test_cli_writes_one_nav_set_per_imu_sample_after_alignment(cli_run):
    completed, out = cli_run
    assert completed.returncode == 0, completed.stderr
    assert "Traceback" not in completed.stderr
    with BagReader(BAGS_DIR / CLI_BAG) as source:
        imu_stamps = stamps_of(source, "imu/data_raw")
        truth_topics = {n: i for n, i in source.topics.items() if n.startswith("/truth/")}
        truth_raw = {n: [r.raw for r in source.messages([n])] for n in truth_topics}
    with BagReader(out) as fused:
        assert set(fused.topics) == set(NAV_TOPICS) | {"/tf", "/tf_static"} | set(truth_topics)
        assert fused.topics["/tf"].msgtype == "tf2_msgs/msg/TFMessage"
        assert fused.topics["/tf"].count == fused.topics["/nav/odometry"].count
        assert fused.topics["/nav/odometry"].msgtype == "nav_msgs/msg/Odometry"
        nav_stamps = {topic: stamps_of(fused, topic) for topic in NAV_TOPICS}
        for topic, info in truth_topics.items():
            assert fused.topics[topic] == info
            assert [r.raw for r in fused.messages([topic])] == truth_raw[topic], topic
    first = nav_stamps["/nav/odometry"][0]
    after_alignment = [t for t in imu_stamps if t >= first]
    assert len(after_alignment) > 0.9 * len(imu_stamps)
    for topic, stamps in nav_stamps.items():
        assert stamps == after_alignment, topic
    assert f"wrote {out}" in completed.stdout


def test_cli_output_is_read_by_the_independent_mcap_readers(cli_run):
    completed, out = cli_run
    assert completed.returncode == 0, completed.stderr
    (mcap_file,) = out.glob("*.mcap")
    counts: dict[str, int] = {}
    first_of_topic = {}
    with open(mcap_file, "rb") as stream:
        reader = make_reader(stream)
        assert reader.get_header().profile == "ros2"
        # Every message is read; the first of each topic is decoded (mcap_ros2 decodes in pure
        # Python, and every message's bytes are held to rosbags' elsewhere).
        for schema, channel, message in reader.iter_messages(log_time_order=False):
            assert schema.encoding == "ros2msg"
            counts[channel.topic] = counts.get(channel.topic, 0) + 1
            earliest = first_of_topic.get(channel.topic)
            if earliest is None or message.log_time < earliest[2].log_time:
                first_of_topic[channel.topic] = (schema, channel, message)
    decoders = DecoderFactory()
    first = {
        topic: decoders.decoder_for(channel.message_encoding, schema)(message.data)
        for topic, (schema, channel, message) in first_of_topic.items()
    }
    with BagReader(out) as ours:
        assert counts == {topic: info.count for topic, info in ours.topics.items()}
    odometry = first["/nav/odometry"]
    assert (odometry.header.frame_id, odometry.child_frame_id) == ("map", "base_link")
    q = odometry.pose.pose.orientation
    assert math.isclose(math.hypot(q.x, q.y, q.z, q.w), 1.0, abs_tol=1e-9)
    assert first["/nav/velocity"].header.frame_id == "map"
    fix = first["/nav/fix"]
    # sea_state starts at 35 N 120 E and drifts a few metres
    assert math.isclose(fix.latitude, 35.0, abs_tol=1e-3)
    assert math.isclose(fix.longitude, 120.0, abs_tol=1e-3)


@pytest.fixture(scope="module")
def short_bags(tmp_path_factory):
    """The first 12 s of the static bag (alignment takes 10 s), with and without a heading
    reference (gnss/heading and gnss/baseline)."""
    directory = tmp_path_factory.mktemp("short_bags")
    bags = {"complete": directory / "complete", "no_heading": directory / "no_heading"}
    with BagReader(BAGS_DIR / "static") as reader:
        end_ns = reader.start_ns + 12 * NANOSECONDS_PER_SECOND
        records = [r for r in reader.messages(SENSOR_TOPICS) if r.log_time_ns <= end_ns]
    for name, path in bags.items():
        with BagWriter(path) as writer:
            for record in records:
                if name == "no_heading" and record.topic in ("/gnss/heading", "/gnss/baseline"):
                    continue
                writer.write_raw(record.topic, record.msgtype, record.log_time_ns, record.raw)
    return bags


def assert_one_line_error(completed: subprocess.CompletedProcess, *expected: str) -> None:
    message = completed.stderr.strip()
    assert completed.returncode == 2, (completed.returncode, completed.stderr)
    assert "Traceback" not in completed.stderr, completed.stderr
    assert "\n" not in message, f"not one line: {message!r}"
    assert message.startswith("fuse_bag: "), message
    for text in expected:
        assert text in message, message


def write_parameters(path: Path, text: str) -> Path:
    path.write_text(text)
    return path


def test_missing_input_bag(tmp_path):
    missing = tmp_path / "no_such_bag"
    completed = run_fuse_bag(missing, tmp_path / "out")
    assert_one_line_error(completed, str(missing), "does not exist")
    assert not (tmp_path / "out").exists()


def test_bag_without_heading_names_the_missing_topics(short_bags, tmp_path):
    completed = run_fuse_bag(short_bags["no_heading"], tmp_path / "out")
    assert_one_line_error(completed, "gnss/heading", "gnss/baseline", "imu/mag", "imu/data")
    assert not (tmp_path / "out").exists()


def test_existing_output_is_kept_unless_overwrite_is_given(short_bags, tmp_path):
    out = tmp_path / "out"
    first = run_fuse_bag(short_bags["complete"], out)
    assert first.returncode == 0, first.stderr
    written = (out / "metadata.yaml").read_text()

    refused = run_fuse_bag(short_bags["complete"], out)
    assert_one_line_error(refused, str(out), "already exists")
    assert (out / "metadata.yaml").read_text() == written

    replaced = run_fuse_bag(short_bags["complete"], out, "--overwrite")
    assert replaced.returncode == 0, replaced.stderr
    with BagReader(out) as reader:
        assert reader.topics["/nav/odometry"].count > 100  # 2 s after alignment at 100 Hz


@pytest.mark.parametrize(
    "text, expected",
    [
        (
            "/**/fusion_node:\n  ros__parameters:\n    fusion: [gate_probability: 2.0\n",
            ("not valid YAML",),
        ),
        (
            "/**/fusion_node:\n  ros__parameters:\n    fusion:\n      gate_probability: 2.0\n",
            ("fusion.gate_probability", "(0, 1)"),
        ),
        (
            "/**:\n  ros__parameters:\n    gnss:\n      primary_antenna: [0.0, 1.0]\n",
            ("gnss.primary_antenna", "3"),
        ),
        (
            "/**/fusion_node:\n  ros__parameters:\n    fusion:\n      realtime_output: 1\n",
            ("fusion.realtime_output", "true or false"),
        ),
    ],
    ids=["malformed_yaml", "gate_probability_2", "antenna_of_two", "bool_as_number"],
)
def test_bad_parameters_stop_with_a_message_naming_them(short_bags, tmp_path, text, expected):
    parameters = write_parameters(tmp_path / "parameters.yaml", text)
    completed = run_fuse_bag(short_bags["complete"], tmp_path / "out", "--params-file", parameters)
    assert_one_line_error(completed, *expected)
    if "YAML" in expected[0]:
        assert str(parameters) in completed.stderr
    assert not (tmp_path / "out").exists()


def test_cli_smooth_writes_the_forward_odometry_beside_the_smoothed_nav(short_bags, tmp_path):
    """``--smooth`` on the first 12 s of the static bag: ``nav/*`` and
    ``nav/forward/odometry``, one of each per solution, and no temporary records left behind."""
    out = tmp_path / "smoothed"
    completed = run_fuse_bag(
        short_bags["complete"], out, "--params-file", BUOY_PARAMETERS, "--smooth"
    )
    assert completed.returncode == 0, completed.stderr
    with BagReader(out) as fused:
        forward = stamps_of(fused, "nav/forward/odometry")
        assert forward and all(stamps_of(fused, topic) == forward for topic in NAV_TOPICS)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["smoothed"]


@pytest.mark.parametrize("smooth", [False, True], ids=["forward", "smoothed"])
def test_the_pass_keeps_the_set_up_out_of_the_collector_and_hands_it_back(
    short_bags, tmp_path, monkeypatch, smooth
):
    """During the pass over the bag what the set-up built is frozen (left out of the cyclic
    collector's walks); after it nothing stays frozen, so a long-lived process (an archive's
    worker) still collects the garbage among it."""
    frozen_while_fusing = []
    calls = 0

    def watched(method):
        def counting(fusion, *arguments):
            nonlocal calls
            if calls % 50 == 0:  # counting the frozen objects walks them all
                frozen_while_fusing.append(gc.get_freeze_count())
            calls += 1
            return method(fusion, *arguments)

        return counting

    # The sensor messages reach the fusion one at a time or, read with their chunk, in runs.
    for name in ("add_message", "add_records"):
        monkeypatch.setattr(OfflineFusion, name, watched(getattr(OfflineFusion, name)))
    config = fusion_config_from_files([str(BUOY_PARAMETERS)])
    fuse_bag(short_bags["complete"], tmp_path / "out", config, smooth=smooth)
    engine_objects = 10_000  # an engine and its compiled kernels are far more
    assert frozen_while_fusing and min(frozen_while_fusing) > engine_objects
    assert gc.get_freeze_count() == 0
