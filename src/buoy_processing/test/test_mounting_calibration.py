"""The mounting calibration refuses data that cannot determine the angles.

Its accuracy is judged on the simulator, end to end, in ``tests/system/test_calibrate_mounting``;
here, the cases where the data hold no information: a buoy that does not move in a wind from
one direction observes one tilt through the mean vertical wind and nothing else.
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from buoy_processing.mounting_calibration import MIN_DURATION_S, CalibrationError, estimate_mounting

RATE_HZ = 10.0


def still_buoy(duration_s: float, noise_mps: float = 0.05, seed: int = 1):
    """A level buoy that never moves, a steady 8 m/s wind along the sonic's x axis."""
    rng = np.random.default_rng(seed)
    t_s = np.arange(0.0, duration_s, 1.0 / RATE_HZ)
    measured = np.tile([8.0, 0.0, 0.0], (t_s.size, 1)) + rng.normal(0, noise_mps, (t_s.size, 3))
    attitude = np.tile(Rotation.identity().as_quat(), (t_s.size, 1))
    corrected = measured.copy()  # level, still, aligned: the correction changes nothing
    return t_s, corrected, measured, attitude


def test_a_still_buoy_in_a_steady_wind_determines_only_the_tilt_along_the_wind():
    # The mean vertical wind sees the pitch (the wind blows along x); the roll would turn only
    # the cross-wind, which is zero, and the yaw only the unknown mean wind.
    with pytest.raises(CalibrationError, match=r": roll ±[\d.]+°, yaw ±[\d.]+° over") as refused:
        estimate_mounting(*still_buoy(600.0), (0.0, 0.0, 0.0))
    assert "pitch" not in str(refused.value).split("over")[0]


def test_too_short_a_record_is_refused():
    with pytest.raises(CalibrationError, match=f"at least {MIN_DURATION_S:.0f} s"):
        estimate_mounting(*still_buoy(MIN_DURATION_S / 2), (0.0, 0.0, 0.0))


def test_samples_without_a_corrected_wind_are_left_out():
    t_s, corrected, measured, attitude = still_buoy(MIN_DURATION_S * 3)
    corrected[t_s > MIN_DURATION_S / 2] = np.nan
    with pytest.raises(CalibrationError, match="at least"):
        estimate_mounting(t_s, corrected, measured, attitude, (0.0, 0.0, 0.0))
