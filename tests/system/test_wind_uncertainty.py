"""The uncertainty each corrected wind sample states is honest, against the simulator's truth:
the published ``wind/true_with_covariance`` of a committed bag, and of the same bag with every
GNSS topic cut for a minute, where the navigation's covariance grows until samples whose σ
exceeds its limit are refused (``uncertainty_too_large``) and those kept are still within
their σ. Normalised errors: at most 1 % beyond 3σ per axis, none beyond 5σ."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from bag_faults import combine, drop, write_faulty_bag

from against_truth import STAMP_MATCH_NS, Truth, vector
from buoy_common.bag_io import BagReader
from buoy_common.contract import WIND_TRUE_WITH_COVARIANCE_TOPIC, Reason
from buoy_nav.config import fusion_config_from_files
from buoy_processing.bag_processing import process_bag
from processed_bags import CASES, processed_bag
from ros_messages import stamp_ns
from wind_comp.config import compensator_config_from_files
from wind_comp.flow_uncertainty import horizontal_and_vertical_sigma

SEA_STATE = CASES["sea_state"]
GNSS_TOPICS = ("/gnss/fix", "/gnss/vel", "/gnss/heading", "/gnss/baseline")
GNSS_CUT_S = (90.0, 150.0)
RECOVERY_S = 5.0
MAX_SHARE_BEYOND_3_SIGMA = 0.01


def published(bag: Path) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(N,) stamps ns, (N, 3) winds m/s and (N, 3, 3) covariances m²/s² of
    ``wind/true_with_covariance``."""
    with BagReader(bag) as reader:
        messages = [
            reader.decode(record) for record in reader.messages([WIND_TRUE_WITH_COVARIANCE_TOPIC])
        ]
    return (
        np.array([stamp_ns(m) for m in messages]),
        np.array([vector(m.twist.twist.linear) for m in messages]),
        np.array([np.reshape(m.twist.covariance, (6, 6))[:3, :3] for m in messages]),
    )


def normalised_errors(truth: Truth, stamps_ns, winds, covariances) -> np.ndarray:
    """(M, 3) errors over their stated σ of the valid samples whose stamp truth/wind shares."""
    after = np.clip(np.searchsorted(truth.wind_ns, stamps_ns), 1, truth.wind_ns.size - 1)
    nearest = np.where(
        np.abs(truth.wind_ns[after] - stamps_ns) < np.abs(truth.wind_ns[after - 1] - stamps_ns),
        after,
        after - 1,
    )
    matched = (np.abs(truth.wind_ns[nearest] - stamps_ns) < STAMP_MATCH_NS) & np.all(
        np.isfinite(winds), axis=1
    )
    errors = winds[matched] - truth.wind_enu_mps[nearest[matched]]
    sigmas = np.sqrt(np.diagonal(covariances[matched], axis1=1, axis2=2))
    return errors / sigmas


def assert_honest(z: np.ndarray, what: str) -> None:
    assert z.shape[0] > 500, f"{what}: too few valid samples against the truth"
    beyond_3 = np.mean(np.abs(z) > 3.0, axis=0)
    assert np.all(beyond_3 <= MAX_SHARE_BEYOND_3_SIGMA), f"{what}: beyond 3σ {beyond_3}"
    assert np.all(np.abs(z) <= 5.0), f"{what}: max |z| {np.abs(z).max(axis=0)}"


def test_the_stated_sigma_holds_against_the_truth(tmp_path_factory):
    bag = processed_bag(tmp_path_factory, "sea_state")
    stamps, winds, covariances = published(bag)
    assert_honest(
        normalised_errors(Truth(SEA_STATE.bag_path), stamps, winds, covariances), "sea_state"
    )
    invalid = ~np.all(np.isfinite(winds), axis=1)
    assert np.isnan(covariances[invalid]).all() and np.isfinite(covariances[~invalid]).all()


@pytest.fixture(scope="module")
def gnss_cut(tmp_path_factory):
    """sea_state with every GNSS topic dropped for a minute, processed."""
    directory = tmp_path_factory.mktemp("gnss_cut")
    faulty = directory / "input"
    write_faulty_bag(
        SEA_STATE.bag_path,
        faulty,
        180.0,
        combine(*(drop(topic, *GNSS_CUT_S) for topic in GNSS_TOPICS)),
    )
    files = SEA_STATE.parameter_files(directory)
    summary = process_bag(
        faulty,
        directory / "output",
        fusion_config_from_files(files),
        compensator_config_from_files(files),
    )
    return faulty, directory / "output", summary, compensator_config_from_files(files)


def test_a_gnss_outage_refuses_the_samples_its_sigma_grows_past_the_limit(gnss_cut):
    faulty, output, summary, config = gnss_cut
    stamps, winds, covariances = published(output)
    refused = summary.wind.status_counts[Reason.UNCERTAINTY_TOO_LARGE]
    assert refused > 100, summary.wind.status_counts
    # Every sample published valid states a σ within the limits; the refused ones are NaN.
    valid = np.all(np.isfinite(winds), axis=1)
    horizontal, vertical = horizontal_and_vertical_sigma(covariances[valid])
    assert horizontal.max() <= config.max_wind_sigma_horizontal_mps
    assert vertical.max() <= config.max_wind_sigma_vertical_mps
    # The refusals lie in the outage and the seconds the filter takes to converge again after
    # it, and the samples kept are still honest.
    start_ns = stamps[0]
    cut = (stamps >= start_ns + GNSS_CUT_S[0] * 1e9) & (
        stamps < start_ns + (GNSS_CUT_S[1] + RECOVERY_S) * 1e9
    )
    assert np.count_nonzero(cut & ~valid) >= refused
    assert_honest(
        normalised_errors(Truth(faulty), stamps, winds, covariances), "sea_state, GNSS cut"
    )
