"""A buoy unlike the default one, processed with its own parameters only.

The simulator is given antennas off the x axis at different heights, an anemometer off the mast
axis and turned 120° on its mount, sensor rates of 200 / 5 / 16 Hz and stamps that never line
up between sensors. ``process_bag`` with the same parameter file must give the corrected wind
and the attitude within the budgets of the sensors (:mod:`error_budget`) as for the default
buoy; with the default parameters instead, the wind must be badly wrong, which shows the
parameters are what is used.
"""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from against_truth import (
    Truth,
    assert_navigation_within_limits,
    assert_wind_within_budget,
    odometry_errors,
)
from buoy_common.bag_io import BagReader
from buoy_nav.config import fusion_config_from_files
from buoy_processing.bag_processing import process_bag
from error_budget import navigation_limits
from wind_comp.config import compensator_config_from_files

BIN = Path(sys.executable).parent
DURATION_S = 100.0
SETTLED_AFTER_ALIGNMENT_S = 40.0
PARAMETERS = """
/**:
  ros__parameters:
    gnss:
      primary_antenna: [0.4, -0.6, 1.3]
      secondary_antenna: [-0.5, 0.7, 1.1]
    anemometer:
      position: [0.3, 0.2, 2.5]
      rpy_deg: [3.0, -2.0, 120.0]
/**/imu_sim_node:
  ros__parameters:
    rate_hz: 200.0
    time_offset_s: 0.0013
/**/gnss_sim_node:
  ros__parameters:
    rate_hz: 5.0
    time_offset_s: 0.037
/**/anemometer_sim_node:
  ros__parameters:
    rate_hz: 16.0
    time_offset_s: 0.011
/**/truth_node:
  ros__parameters:
    rate_hz: 16.0
    time_offset_s: 0.011
"""
# The truth is stamped with the anemometer, so that the wind is judged without interpolating
# turbulence between truth samples.
IMU_RATE_HZ = 200.0
# A mount turned by 120 deg that is taken as 0 deg turns a ~8 m/s wind by 120 deg; what the
# filter still trusts under the wrong geometry stays over twenty times the wind error budget.
MIN_WRONG_PARAMETERS_RMS_MPS = 1.0


def stamps_s(messages) -> np.ndarray:
    return np.array([m.header.stamp.sec + m.header.stamp.nanosec * 1e-9 for m in messages])


def decoded(bag: Path, topic: str) -> list:
    with BagReader(bag) as reader:
        return [reader.decode(message) for message in reader.messages([topic])]


@pytest.fixture(scope="module")
def simulated(tmp_path_factory) -> tuple[Path, Path]:
    folder = tmp_path_factory.mktemp("unseen")
    parameters = folder / "other_buoy.yaml"
    parameters.write_text(PARAMETERS)
    bag = folder / "sim"
    subprocess.run(
        [
            str(BIN / "simulate_bag"),
            "sea_state",
            str(bag),
            "--set",
            f"duration_s={DURATION_S}",
            "--params-file",
            str(parameters),
        ],
        check=True,
        capture_output=True,
    )
    return bag, parameters


@pytest.fixture(scope="module")
def processed(simulated, tmp_path_factory) -> Path:
    bag, parameters = simulated
    out = tmp_path_factory.mktemp("unseen_processed") / "own_parameters"
    process_bag(
        bag,
        out,
        fusion_config_from_files([parameters]),
        compensator_config_from_files([parameters]),
    )
    return out


def wind_errors_mps(processed_bag: Path, after_s: float) -> np.ndarray:
    """wind/true − truth/wind (M, 3) at the stamps they share after ``after_s``."""
    corrected = decoded(processed_bag, "wind/true")
    t_wind = stamps_s(corrected)
    wind = np.array([(m.vector.x, m.vector.y, m.vector.z) for m in corrected])
    keep = t_wind > after_s
    assert np.all(np.isfinite(wind[keep])), "invalid wind/true after the filter settled"
    stamps_ns = [m.header.stamp.sec * 1_000_000_000 + m.header.stamp.nanosec for m in corrected]
    return Truth(processed_bag).wind_errors(np.array(stamps_ns)[keep], wind[keep])


def test_every_anemometer_sample_of_the_unaligned_sensors_is_answered(processed):
    anemometer = stamps_s(decoded(processed, "anemometer/wind"))
    corrected = stamps_s(decoded(processed, "wind/true"))
    np.testing.assert_array_equal(corrected, anemometer)
    assert len(anemometer) == pytest.approx(16 * DURATION_S, abs=1)


def test_attitude_follows_the_truth_with_off_axis_antennas(processed, simulated):
    navigation = decoded(processed, "nav/odometry")
    assert np.median(np.diff(stamps_s(navigation))) == pytest.approx(1 / IMU_RATE_HZ, rel=1e-3)
    config = fusion_config_from_files([simulated[1]])
    errors = odometry_errors(Truth(processed), navigation, SETTLED_AFTER_ALIGNMENT_S)
    limits = navigation_limits(config.primary_antenna_body_m, config.secondary_antenna_body_m)
    print(assert_navigation_within_limits(errors, limits, "unseen buoy"))


def test_wind_is_corrected_with_the_buoys_own_parameters(processed, simulated):
    first_nav_s = stamps_s(decoded(processed, "nav/odometry"))[0]
    errors = wind_errors_mps(processed, first_nav_s + SETTLED_AFTER_ALIGNMENT_S)
    measured = decoded(processed, "anemometer/wind")
    print(
        assert_wind_within_budget(
            errors,
            [(m.vector.x, m.vector.y, m.vector.z) for m in measured],
            compensator_config_from_files([simulated[1]]).anemometer_position_body_m,
            "unseen buoy",
            IMU_RATE_HZ,
        )
    )


def test_default_parameters_on_this_buoy_never_give_a_right_wind(simulated, tmp_path):
    # The wrong geometry must show: as navigation the filter stops trusting (its wind NaN) or as
    # a wind far from the truth, never as a valid wind that passes for right.
    bag, _ = simulated
    out = tmp_path / "default_parameters"
    process_bag(bag, out, fusion_config_from_files([]), compensator_config_from_files([]))
    first_nav_s = stamps_s(decoded(out, "nav/odometry"))[0]
    corrected = decoded(out, "wind/true")
    wind = np.array([(m.vector.x, m.vector.y, m.vector.z) for m in corrected])
    keep = (stamps_s(corrected) > first_nav_s + SETTLED_AFTER_ALIGNMENT_S) & np.all(
        np.isfinite(wind), axis=1
    )
    if not np.any(keep):
        return
    stamps_ns = [m.header.stamp.sec * 1_000_000_000 + m.header.stamp.nanosec for m in corrected]
    errors = Truth(out).wind_errors(np.array(stamps_ns)[keep], wind[keep])
    rms = np.sqrt(np.mean(errors**2, axis=0))
    assert np.linalg.norm(rms) > MIN_WRONG_PARAMETERS_RMS_MPS, rms
