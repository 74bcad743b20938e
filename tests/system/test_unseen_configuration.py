"""A buoy unlike the default one, processed with its own parameters only.

The simulator is given antennas off the x axis at different heights, an anemometer off the mast
axis and turned 120° on its mount, sensor rates of 200 / 5 / 16 Hz and stamps that never line
up between sensors. ``process_bag`` with the same parameter file must give the corrected wind
and the attitude as well as for the default buoy; with the default parameters instead, the
wind must be badly wrong, which shows the parameters are what is used.
"""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from scipy.spatial.transform import Rotation, Slerp

from buoy_common.bag_io import BagReader
from buoy_nav.config import fusion_config_from_files
from wind_comp.bag_processing import process_bag
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
"""
# Attitude: a few times the default buoy's errors (tens of millidegrees); heading noise of one
# dual-antenna fix over this 1.3 m baseline is about 0.2 deg.
MAX_TILT_ERROR_DEG = 0.3
MAX_HEADING_ERROR_DEG = 0.25
# Wind: anemometer noise 0.02 m/s, attitude error x ~10 m/s, velocity error, and linear
# interpolation of the 50 Hz turbulent truth to the 16 Hz anemometer stamps.
MAX_WIND_RMS_MPS = 0.08
# A mount turned by 120 deg that is taken as 0 deg turns a ~8 m/s wind by 120 deg.
MIN_WRONG_PARAMETERS_RMS_MPS = 2.0


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


def wind_rms_error_mps(processed_bag: Path, after_s: float) -> np.ndarray:
    """Per-axis RMS of wind/true − truth/wind (truth interpolated to the wind stamps)."""
    corrected = decoded(processed_bag, "wind/true")
    truth = decoded(processed_bag, "truth/wind")
    t_wind, t_truth = stamps_s(corrected), stamps_s(truth)
    wind = np.array([(m.vector.x, m.vector.y, m.vector.z) for m in corrected])
    true = np.array([(m.vector.x, m.vector.y, m.vector.z) for m in truth])
    keep = (t_wind > after_s) & (t_wind < t_truth[-1])
    assert np.all(np.isfinite(wind[keep])), "invalid wind/true after the filter settled"
    interpolated = np.column_stack([np.interp(t_wind[keep], t_truth, true[:, i]) for i in range(3)])
    return np.sqrt(np.mean((wind[keep] - interpolated) ** 2, axis=0))


def test_every_anemometer_sample_of_the_unaligned_sensors_is_answered(processed):
    anemometer = stamps_s(decoded(processed, "anemometer/wind"))
    corrected = stamps_s(decoded(processed, "wind/true"))
    np.testing.assert_array_equal(corrected, anemometer)
    assert len(anemometer) == pytest.approx(16 * DURATION_S, abs=1)


def test_attitude_follows_the_truth_with_off_axis_antennas(processed):
    navigation = decoded(processed, "nav/odometry")
    truth = decoded(processed, "truth/odometry")
    t_nav, t_truth = stamps_s(navigation), stamps_s(truth)
    assert np.median(np.diff(t_nav)) == pytest.approx(1 / 200, rel=1e-3)  # float epoch stamps

    def attitudes(messages):
        return Rotation.from_quat(
            [(o.x, o.y, o.z, o.w) for o in (m.pose.pose.orientation for m in messages)]
        )

    keep = (t_nav > t_nav[0] + SETTLED_AFTER_ALIGNMENT_S) & (t_nav < t_truth[-1])
    true_attitude = Slerp(t_truth, attitudes(truth))(t_nav[keep])
    error = attitudes(navigation)[keep] * true_attitude.inv()  # rotation error in ENU
    error_deg = np.degrees(np.abs(error.as_rotvec()))
    assert error_deg[:, :2].max() < MAX_TILT_ERROR_DEG, error_deg.max(axis=0)
    assert error_deg[:, 2].max() < MAX_HEADING_ERROR_DEG, error_deg.max(axis=0)


def test_wind_is_corrected_with_the_buoys_own_parameters(processed):
    first_nav_s = stamps_s(decoded(processed, "nav/odometry"))[0]
    rms = wind_rms_error_mps(processed, first_nav_s + SETTLED_AFTER_ALIGNMENT_S)
    assert np.all(rms < MAX_WIND_RMS_MPS), rms


def test_default_parameters_on_this_buoy_give_wrong_wind(simulated, tmp_path):
    bag, _ = simulated
    out = tmp_path / "default_parameters"
    process_bag(bag, out, fusion_config_from_files([]), compensator_config_from_files([]))
    first_nav_s = stamps_s(decoded(out, "nav/odometry"))[0]
    rms = wind_rms_error_mps(out, first_nav_s + SETTLED_AFTER_ALIGNMENT_S)
    assert np.linalg.norm(rms) > MIN_WRONG_PARAMETERS_RMS_MPS, rms
