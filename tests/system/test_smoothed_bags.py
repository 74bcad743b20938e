"""``process_bag --smooth`` on a committed bag: the outputs the contract names, the smoothed
navigation closer to the truth than the forward filter, and the wind corrected with it no worse
than with the forward solution."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from buoy_common.bag_io import BagReader
from buoy_nav.config import fusion_config_from_files
from buoy_processing.bag_processing import process_bag
from processed_bags import BAGS_DIR, BUOY_PARAMETERS, processed_bag
from ros_messages import raw_stamp_ns
from wind_comp.config import compensator_config_from_files

BAG = "sea_state"
CONVERGED_AFTER_S = 30.0


@pytest.fixture(scope="module")
def smoothed_bag(tmp_path_factory):
    out = tmp_path_factory.mktemp("smoothed") / BAG
    process_bag(
        BAGS_DIR / BAG,
        out,
        fusion_config_from_files([BUOY_PARAMETERS]),
        compensator_config_from_files([BUOY_PARAMETERS]),
        smooth=True,
    )
    return out


def odometry_by_stamp(reader: BagReader, topic: str) -> dict[int, object]:
    return {raw_stamp_ns(r.raw): reader.decode(r) for r in reader.messages([topic])}


def quaternion(message) -> list[float]:
    q = message.pose.pose.orientation
    return [q.x, q.y, q.z, q.w]


def attitude_rms_deg(odometry: dict[int, object], truth: dict[int, object], from_ns: int):
    stamps = sorted(t for t in set(odometry) & set(truth) if t >= from_ns)
    estimated = Rotation.from_quat([quaternion(odometry[t]) for t in stamps])
    true = Rotation.from_quat([quaternion(truth[t]) for t in stamps])
    error = (true * estimated.inv()).as_rotvec()
    return np.degrees(np.sqrt(np.mean(error**2, axis=0))), len(stamps)


def test_nav_and_forward_odometry_one_per_solution_and_one_wind_per_sample(smoothed_bag):
    with BagReader(smoothed_bag) as reader:
        topics = reader.topics
        forward = [raw_stamp_ns(r.raw) for r in reader.messages(["nav/forward/odometry"])]
        smoothed = [raw_stamp_ns(r.raw) for r in reader.messages(["nav/odometry"])]
        for topic in ("/nav/imu", "/nav/velocity", "/nav/fix"):
            assert topics[topic].count == len(smoothed)
        assert topics["/wind/true"].count == topics["/anemometer/wind"].count
    assert forward == smoothed
    assert len(smoothed) > 10_000


def test_smoothed_attitude_is_closer_to_the_truth_than_the_forward_one(smoothed_bag):
    with BagReader(smoothed_bag) as reader:
        truth = odometry_by_stamp(reader, "truth/odometry")
        forward = odometry_by_stamp(reader, "nav/forward/odometry")
        smoothed = odometry_by_stamp(reader, "nav/odometry")
    from_ns = min(smoothed) + int(CONVERGED_AFTER_S * 1e9)
    forward_rms, count = attitude_rms_deg(forward, truth, from_ns)
    smoothed_rms, _ = attitude_rms_deg(smoothed, truth, from_ns)
    assert count > 1000
    figures = f"RMS φ E, N, U deg: forward {forward_rms.round(4)}, smoothed {smoothed_rms.round(4)}"
    assert np.linalg.norm(smoothed_rms) < np.linalg.norm(forward_rms), figures


def stamped_vectors(reader: BagReader, topic: str) -> tuple[np.ndarray, np.ndarray]:
    records = list(reader.messages([topic]))
    stamps = np.array([raw_stamp_ns(r.raw) for r in records])
    vectors = np.array([[m.vector.x, m.vector.y, m.vector.z] for m in map(reader.decode, records)])
    return stamps, vectors


def wind_error_rms_mps(bag) -> float:
    """RMS norm of corrected − true wind per sample, on the samples with a truth sample of the
    same stamp."""
    with BagReader(bag) as reader:
        wind_ns, wind = stamped_vectors(reader, "wind/true")
        truth_ns, truth = stamped_vectors(reader, "truth/wind")
    valid = ~np.isnan(wind).any(axis=1)
    _, at_wind, at_truth = np.intersect1d(wind_ns[valid], truth_ns, return_indices=True)
    assert at_wind.size > 1000
    error = wind[valid][at_wind] - truth[at_truth]
    return float(np.sqrt(np.mean(np.sum(error**2, axis=1))))


def test_smoothed_wind_is_no_worse_than_the_forward_wind(smoothed_bag, tmp_path_factory):
    forward = wind_error_rms_mps(processed_bag(tmp_path_factory, BAG))
    smoothed = wind_error_rms_mps(smoothed_bag)
    assert smoothed <= forward, f"wind RMS error: forward {forward:.5f}, smoothed {smoothed:.5f}"
