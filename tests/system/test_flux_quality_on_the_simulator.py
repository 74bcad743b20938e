"""The named flux tests on simulated windows of known fluxes (tools/bench_flux_quality.py; ``make
bench`` runs the same over 30-min windows): twenty minutes of ``open_ocean`` with a surface layer
carrying u* 0.31 m/s in a 10 m/s wind, in two 10-min windows. The true and the corrected wind pass
every test; a tenfold stress over the same mean wind fails the drag coefficient and nothing else;
half the buoy's motion left in the wind raises σw/u* past the integral turbulence test's 30 %,
and the motion-left test, which sees the buoy's heave in w, fails it.
"""

from __future__ import annotations

import pytest

from buoy_common.contract import QualityFlag
from tools import bench_flux_quality
from wind_comp.flux_quality import FLUX_FLAG_TESTS

pytestmark = pytest.mark.long

DURATION_S = 1200.0
WINDOW_S = 600.0
TESTS = [test.name for test in FLUX_FLAG_TESTS]


@pytest.fixture(scope="module")
def cases(tmp_path_factory) -> dict[str, list[dict]]:
    results = bench_flux_quality.run(DURATION_S, WINDOW_S, tmp_path_factory.mktemp("quality"))
    by_case = {case: [] for case in bench_flux_quality.CASES}
    for row in results["flux_quality"]:
        by_case[row["case"]].append(row)
    return by_case


def test_the_true_and_the_corrected_fluxes_pass_every_test(cases):
    assert len(cases["truth"]) == len(cases["corrected"]) == 2
    for row in cases["truth"] + cases["corrected"]:
        assert {row[name] for name in TESTS} == {QualityFlag.GOOD}, row
        # a surface layer of the bulk relation's order: the tests pass it by its physics
        assert 0.5 < row["drag_ratio"] < 1.5 and 1.1 < row["sigma_w_over_u_star"] < 1.45, row


def test_a_tenfold_stress_fails_the_drag_coefficient_alone(cases):
    for stressed, corrected in zip(cases["tenfold_stress"], cases["corrected"], strict=True):
        assert stressed["drag_ratio"] == pytest.approx(10 * corrected["drag_ratio"], rel=1e-6)
        assert stressed["drag_coefficient"] == QualityFlag.BAD, stressed
        # the same eddies, stronger: every other test says what it said of the corrected wind
        others = [name for name in TESTS if name != "drag_coefficient"]
        assert [stressed[name] for name in others] == [corrected[name] for name in others]
        assert stressed["quality_flag"] == QualityFlag.BAD


def test_motion_left_in_the_wind_is_suspect_by_its_turbulence_and_fails_the_motion_left(cases):
    for left, corrected in zip(cases["motion_left"], cases["corrected"], strict=True):
        # the buoy's heave adds variance to w, hardly any covariance to u'w'
        assert left["sigma_w_over_u_star"] > corrected["sigma_w_over_u_star"] + 0.3, left
        assert left["itc"] == QualityFlag.SUSPECT, left
        # half the platform's vertical velocity left in w, coherent with it
        assert left["motion_left"] == QualityFlag.BAD, left
        assert left["quality_flag"] == QualityFlag.BAD
