"""A second buoy's streams interleaved with the buoy's own on the same topics, judged against
the bag's own truth.

Another buoy's nodes on the same ROS domain publish on the fusion's and the compensation's
topics: from 45 s to 75 s of ``bags/sea_state`` the IMU (and in some cases the GNSS and
anemometer) messages of ``bags/open_ocean`` are interleaved by log time, stamped on their own
clock: 5 s behind the buoy's, 40 s ahead or 0.3 s ahead, delivered as they were stamped (as live
nodes deliver them). Each bag is processed by ``process_bag``. The second buoy's streams never
move anything's time: their samples are rejected (``out_of_sequence`` ahead of the latest
accepted stamp, ``stamp_not_increasing`` or, for a measurement behind those the fusion
processed, ``too_late`` behind it), no step of the IMU's clock is taken, each
GNSS topic and the anemometer count the second buoy's messages among their rejections; no valid
``wind/true_with_covariance`` sample is beyond 5σ of ``truth/wind``; and from ``RECOVERY_S``
after the second buoy stops, the wind is valid again. Replayed live, the nodes publish what
``process_bag`` writes.
"""

from __future__ import annotations

import functools
from pathlib import Path

import bag_faults
import numpy as np
import pytest
from live_replay import SENSOR_TOPICS, differences_from_offline, replay
from test_wind_uncertainty import normalised_errors, published

from against_truth import Truth
from buoy_common.contract import NANOSECONDS_PER_SECOND
from buoy_nav.config import fusion_config_from_files
from buoy_processing.bag_processing import process_bag
from wind_comp.config import compensator_config_from_files

REPO = Path(__file__).resolve().parents[2]
OWN_BAG = REPO / "bags" / "sea_state"
OTHER_BAG = REPO / "bags" / "open_ocean"
BUOY_PARAMETERS = REPO / "src" / "buoy_common" / "config" / "buoy.yaml"
KEPT_S = 140.0  # of log time
INTRUSION_S = (45.0, 75.0)  # of log time
RECOVERY_S = 30.0
IMU = ["/imu/data_raw"]
GNSS = ["/gnss/fix", "/gnss/vel", "/gnss/heading", "/gnss/baseline"]
ANEMOMETER = ["/anemometer/wind"]
GNSS_KINDS = {
    "/gnss/fix": "gnss_fix",
    "/gnss/vel": "gnss_velocity",
    "/gnss/heading": "gnss_heading",
    "/gnss/baseline": "gnss_baseline",
}
MIN_VALID_SHARE_AFTER = 0.99


@pytest.fixture(scope="module")
def own_records() -> list[bag_faults.Record]:
    """The first ``KEPT_S`` of the buoy's own bag, every topic: read once, each case copies
    what it changes."""
    return bag_faults.read_records(OWN_BAG, None, KEPT_S)


@pytest.fixture(scope="module")
def other_records() -> list[bag_faults.Record]:
    """The first ``KEPT_S`` of every stream the second buoy may send, read once."""
    return bag_faults.read_records(OTHER_BAG, IMU + GNSS + ANEMOMETER, KEPT_S)


@pytest.fixture(scope="module")
def truth() -> Truth:
    """The truth of the buoy's own bag, which the second buoy sends none of. Wind samples are
    matched to it by their stamps, so every kept sample finds its truth, even the last ones,
    whose truth is logged just after the kept seconds."""
    return Truth(OWN_BAG)


def run_case(
    base: Path,
    own: list[bag_faults.Record],
    other_streams: list[bag_faults.Record],
    offset_s: float,
    topics: list[str],
):
    """(process_bag's summary, stamps ns, winds, covariances of wind/true_with_covariance,
    first stamp s) of ``own`` (records of ``bags/sea_state``) with the second buoy's
    ``topics`` (of ``other_streams``) in it."""
    sent = set(topics)
    other = [r for r in other_streams if r.topic in sent]
    # Delivered as stamped, as the nodes of a live run deliver them, not in the bursts of the
    # recorder that wrote the bag (which let the two IMU streams' stamps meet).
    own = bag_faults.logged_at_stamps(topics)(own)
    records = bag_faults.intruder(other, topics, *INTRUSION_S, offset_s)(own)
    bag, out = base / "in", base / "out"
    bag_faults.write_records(records, bag)
    summary = process_bag(
        bag,
        out,
        fusion_config_from_files([BUOY_PARAMETERS]),
        compensator_config_from_files([BUOY_PARAMETERS]),
    )
    first_s = bag_faults.header_stamp_ns(own[0]) / NANOSECONDS_PER_SECOND
    return summary, *published(out), first_s


def rejections(summary, kind: str) -> dict[str, int]:
    """An input's (``imu`` or an aiding source's kind) rejection counts by reason, from the
    fusion's summary line."""
    (line,) = [line for line in summary.fusion_lines if line.split()[0] == kind]
    listed = line.split("rejected:")[1].split("suspensions")[0].strip()
    if listed == "none":
        return {}
    pairs = (item.strip().rsplit(" ", 1) for item in listed.split(","))
    return {reason: int(count) for reason, count in pairs}


@functools.cache  # the same counts for every case
def intruding(*topics: str) -> int:
    """Messages of ``topics`` the second buoy sends."""
    return len(bag_faults.read_records(OTHER_BAG, topics, INTRUSION_S[1])) - len(
        bag_faults.read_records(OTHER_BAG, topics, INTRUSION_S[0])
    )


def judge(case, truth: Truth, intruding_imu_samples: int):
    summary, stamps_ns, winds, covariances, first_s = case
    figures = "; ".join(summary.fusion_lines)
    assert not [line for line in summary.fusion_lines if "IMU clock stepped" in line], figures
    rejected = rejections(summary, "imu")
    assert sum(rejected.values()) >= intruding_imu_samples, figures
    errors = normalised_errors(truth, stamps_ns, winds, covariances)
    assert np.count_nonzero(np.abs(errors) > 5.0) == 0, f"{np.abs(errors).max():.1f} σ; {figures}"
    t_s = stamps_ns * 1e-9 - first_s
    after = t_s >= INTRUSION_S[1] + RECOVERY_S
    valid = np.all(np.isfinite(winds[after]), axis=1)
    assert valid.mean() >= MIN_VALID_SHARE_AFTER, f"{valid.mean():.3f} valid after; {figures}"
    return rejected


@pytest.mark.parametrize(
    ("offset_s", "topics", "reason"),
    [
        (-5.0, IMU + GNSS + ANEMOMETER, "stamp_not_increasing"),
        (40.0, IMU, "out_of_sequence"),
        (0.3, IMU, "out_of_sequence"),
        (0.3, IMU + GNSS + ANEMOMETER, "out_of_sequence"),
    ],
)
def test_a_second_buoy_never_corrupts_the_fusion(
    tmp_path, own_records, other_records, truth, offset_s, topics, reason
):
    case = run_case(tmp_path, own_records, other_records, offset_s, topics)
    other_imu = intruding(*IMU)
    rejected = judge(case, truth, other_imu)
    assert rejected.get(reason, 0) > other_imu // 3, rejected
    summary = case[0]
    # Measurements behind those already processed are too late for the fusion.
    gnss_reason = "too_late" if offset_s < 0 else reason
    for topic, kind in GNSS_KINDS.items():
        if topic in topics:
            assert rejections(summary, kind).get(gnss_reason, 0) >= intruding(topic), kind
    if ANEMOMETER[0] in topics:
        rejected_winds = summary.wind.rejected_messages
        assert rejected_winds[reason] >= intruding(*ANEMOMETER), rejected_winds


@pytest.mark.ros
@pytest.mark.long
def test_live_equals_offline_with_a_second_buoy(tmp_path, nodes, own_records, other_records):
    """The second buoy's IMU, GNSS and anemometer 0.3 s ahead, replayed to ``fusion_node`` and
    ``compensation_node``: they publish what ``process_bag`` writes, sample for sample."""
    run_case(tmp_path, own_records, other_records, 0.3, IMU + GNSS + ANEMOMETER)
    recorded = tmp_path / "live"
    figures = replay(
        nodes, tmp_path / "in", [BUOY_PARAMETERS], tmp_path / "out", recorded, SENSOR_TOPICS
    )
    failures = differences_from_offline(recorded, tmp_path / "out")
    assert not failures, "\n".join(failures) + f"\n{figures}"
