"""The moored buoys whose published winds were wrong, simulated and processed as a user would
(``simulate_bag``, then ``process_bag`` with the set's parameters; ``tools.bench_uncertainty``),
judged against the simulator's truth:

- a moored buoy without GNSS: 50 Hz IMU, a motion pack whose attitude lags 0.3 s while its
  covariance claims 0.1°/0.1°/0.5°, an uncalibrated magnetometer, a 10 Hz sonic, roll ±9° and
  pitch ±7.5°. Without ``fusion.moored`` nothing bounds the velocity: no sample may be valid.
  With it: roll and pitch within 0.3° and the heading within 2° once converged, the valid
  wind within 0.5 m/s of the truth and within five of its σ, the magnetometer suspended with
  its reason within a minute;
- the same buoy with one GNSS antenna at 1 Hz off the IMU grid and no motion pack: the
  magnetometer never gives the heading, and nothing valid is wrong beyond its σ.
"""

from __future__ import annotations

import re

import pytest

from sensor_sim.scenario import load_scenario
from tools.bench_uncertainty import CASES, run_case

DURATION_S = 240.0
WIND_MAX_ERROR_MPS = 0.5
ROLL_PITCH_MAX_ERROR_DEG = 0.3
HEADING_MAX_ERROR_DEG = 2.0
MAGNETOMETER_SUSPENDED_WITHIN_S = 60.0


@pytest.fixture(scope="module")
def work(tmp_path_factory):
    return tmp_path_factory.mktemp("measured_cases")


def test_moored_without_gnss_keeps_attitude_and_wind_within_bounds_and_sigma(work):
    """Roll, pitch and heading judged after two minutes (``ATTITUDE_SETTLING_S``), the wind from
    its first valid sample."""
    result = run_case("moored_no_gnss", DURATION_S, work)
    wind, attitude = result["wind"], result["attitude"]
    assert wind["valid_share"] > 0.5
    assert max(wind["max_error_mps"]) <= WIND_MAX_ERROR_MPS
    assert wind["beyond_5_sigma"] == [0, 0, 0]
    assert max(wind["beyond_3_sigma_share"]) <= 0.01
    roll, pitch, heading = attitude["fused_max_error_deg"]
    assert max(roll, pitch) <= ROLL_PITCH_MAX_ERROR_DEG
    assert heading <= HEADING_MAX_ERROR_DEG
    (suspension,) = result["suspended"]
    assert "magnetometer suspended" in suspension and "run calibrate_magnetometer" in suspension
    start_s = load_scenario(CASES["moored_no_gnss"].scenario, [], None).start_time_ns * 1e-9
    suspended_at_s = float(re.search(r"stamp ([\d.]+) s", suspension).group(1))
    assert suspended_at_s - start_s <= MAGNETOMETER_SUSPENDED_WITHIN_S


def test_without_the_mooring_no_sample_is_valid(work):
    result = run_case("measured_not_moored", DURATION_S, work)
    assert result["aligned"]
    assert result["wind"]["judged"] > 0
    assert result["wind"]["valid_share"] == 0.0


def test_one_antenna_and_an_uncalibrated_magnetometer_publish_nothing_wrong(work):
    result = run_case("moored_single_gnss", DURATION_S, work)
    assert not result["aligned"]
    assert result["wind"]["judged"] > 0
    assert result["wind"]["valid_share"] == 0.0
