"""The FDCHP path against the simulator's truth: a simulated FDCHP record (sonic 0.753 m above a
motion pack, 10 Hz, no GNSS, moored) written in the OOI L0 layout, imported with the shipped
column map and processed with the motion-pack set. The real record has no truth; this does."""

from __future__ import annotations

import pytest

from tools import fdchp_simulated


@pytest.fixture(scope="module")
def open_ocean_figures(tmp_path_factory):
    """Truth's and our figures on open_ocean's JONSWAP sea (Hs 3 m, Tp 9 s), 20 min."""
    rows, _ = fdchp_simulated.compare_sea("jonswap_tp_9_s", None, tmp_path_factory.mktemp("fdchp"))
    return {row["correction"]: row for row in rows}


def test_the_correction_reaches_the_floor_the_truth_sets(open_ocean_figures):
    """The wave-band share and the coherence with the heave of our corrected w are those of the
    true w: what stays is the air's own motion, not the buoy's."""
    truth, ours = open_ocean_figures["truth"], open_ocean_figures["ours"]
    assert ours["variance_share"] < truth["variance_share"] * 1.03
    assert ours["coherence_after"] < truth["coherence_after"] + 0.02


def test_no_platform_velocity_is_left_in_the_vertical_wind(open_ocean_figures):
    """Neither a gain (in phase) nor a delay (in quadrature) between the corrected w and the
    platform's vertical velocity beyond what the truth itself shows (estimator noise)."""
    truth, ours = open_ocean_figures["truth"], open_ocean_figures["ours"]
    for part in ("platform_velocity_left_in_phase", "platform_velocity_left_quadrature"):
        assert abs(ours[part] - truth[part]) < 0.02, part


def test_the_vertical_wind_error_in_the_wave_band_is_a_small_part_of_the_motion(
    open_ocean_figures,
):
    """Less than 0.2 % of the uncorrected w's wave-band variance is error, and the error over all
    frequencies stays within a few cm/s."""
    ours = open_ocean_figures["ours"]
    assert (
        ours["error_wave_band_variance_m2_s2"]
        < 0.002 * ours["uncorrected_wave_band_variance_m2_s2"]
    )
    assert ours["error_rms_mps"] < 0.06
