"""The moored buoy's mean-velocity watch: a filter whose velocity σ covers its slow error is
never widened; one whose slow error is larger has the gyro's drift widened at once, by the
variance its blocks show, with the filter's covariance raised by as much, and narrowed again
once its blocks are well within their σ."""

import math

import numpy as np
import pytest

from buoy_nav.mean_velocity_watch import GYRO_DRIFT, VELOCITY_NOISE, MeanVelocityWatch

WINDOW_S = 300.0
EXCURSION_SIGMA_M = 0.075
SCALE_LIMIT = 50.0
STATED_SIGMA_MPS = 0.2


def feed(
    watch: MeanVelocityWatch,
    start_s: float,
    duration_s: float,
    slow_error_mps: float,
    seed: int,
    block_s: float = GYRO_DRIFT.block_s,
) -> list[bool]:
    """One velocity a second: a slow error (one normal value of ``slow_error_mps`` per axis and
    block, as a tilt error at minutes' periods leaves) plus wave velocity that averages out
    over a block; the stated covariance STATED_SIGMA_MPS² I. Whether each changed the scale."""
    rng = np.random.default_rng(seed)
    covariance = STATED_SIGMA_MPS**2 * np.eye(3)
    changed = []
    slow = np.zeros(3)
    for t_s in np.arange(start_s, start_s + duration_s):
        if (t_s - start_s) % block_s == 0:
            slow = np.append(slow_error_mps * rng.standard_normal(2), 0.0)
        wave = 1.5 * np.sin(2.0 * math.pi * t_s / 10.0) * np.array((1.0, 0.5, 0.0))
        changed.append(watch.add(float(t_s), slow + wave, covariance))
    return changed


def test_a_slow_error_within_the_stated_sigma_is_never_widened():
    watch = MeanVelocityWatch(WINDOW_S, EXCURSION_SIGMA_M, GYRO_DRIFT, SCALE_LIMIT)
    assert not any(feed(watch, 0.0, 3600.0, STATED_SIGMA_MPS, 1))
    assert watch.scale == 1.0 and watch.warning == ""
    assert watch.take_covariance_factor() == 1.0
    assert 0.7 < watch.ratio() < 1.3


def test_a_slow_error_beyond_it_widens_the_drift_and_the_covariance_at_once():
    watch = MeanVelocityWatch(WINDOW_S, EXCURSION_SIGMA_M, GYRO_DRIFT, SCALE_LIMIT)
    changed = feed(watch, 0.0, 4 * GYRO_DRIFT.block_s, 5.0 * STATED_SIGMA_MPS, 2)
    first = changed.index(True)
    # Judged at the end of a block: the first verdict within the first three blocks.
    assert first <= 3 * GYRO_DRIFT.block_s
    assert watch.scale > 2.0
    factor = watch.take_covariance_factor()
    assert factor > 2.0 and watch.take_covariance_factor() == 1.0
    assert "fusion.gyro_bias_instability_deg_h" in watch.warning
    assert "run assess_motion_pack" in watch.warning


def test_the_widening_is_bounded_by_its_limit():
    watch = MeanVelocityWatch(WINDOW_S, EXCURSION_SIGMA_M, GYRO_DRIFT, scale_limit=4.0)
    feed(watch, 0.0, 1800.0, 50.0 * STATED_SIGMA_MPS, 3)
    assert watch.scale == 4.0


def test_a_limit_of_one_never_widens():
    watch = MeanVelocityWatch(WINDOW_S, EXCURSION_SIGMA_M, GYRO_DRIFT, scale_limit=1.0)
    assert not any(feed(watch, 0.0, 1800.0, 10.0 * STATED_SIGMA_MPS, 4))
    assert watch.scale == 1.0


def test_once_well_within_its_sigma_the_drift_narrows_back_to_stated():
    watch = MeanVelocityWatch(WINDOW_S, EXCURSION_SIGMA_M, GYRO_DRIFT, SCALE_LIMIT)
    feed(watch, 0.0, 600.0, 5.0 * STATED_SIGMA_MPS, 5)
    widened = watch.scale
    feed(watch, 600.0, 600.0, 0.1 * STATED_SIGMA_MPS, 6)
    assert 1.0 <= watch.scale < widened
    feed(watch, 1200.0, 7200.0, 0.1 * STATED_SIGMA_MPS, 7)
    assert watch.scale == 1.0 and watch.warning == ""


def test_a_restart_drops_the_block_in_progress():
    watch = MeanVelocityWatch(WINDOW_S, EXCURSION_SIGMA_M, GYRO_DRIFT, SCALE_LIMIT)
    covariance = STATED_SIGMA_MPS**2 * np.eye(3)
    for t_s in range(int(GYRO_DRIFT.block_s) - 1):
        watch.add(float(t_s), np.array((5.0, 5.0, 0.0)), covariance)
    watch.restart()
    for t_s in range(int(GYRO_DRIFT.block_s), int(4 * GYRO_DRIFT.block_s)):
        watch.add(float(t_s), np.zeros(3), covariance)
    assert watch.ratio() < 0.1 and watch.scale == 1.0


@pytest.mark.parametrize("widened", [GYRO_DRIFT, VELOCITY_NOISE], ids=lambda w: w.parameter)
def test_each_watch_judges_its_own_blocks_and_names_its_parameters(widened):
    watch = MeanVelocityWatch(WINDOW_S, EXCURSION_SIGMA_M, widened, SCALE_LIMIT)
    changed = feed(watch, 0.0, 4 * widened.block_s, 5.0 * STATED_SIGMA_MPS, 8, widened.block_s)
    # Judged at the end of its own blocks: the first verdict within three of them.
    assert True in changed and changed.index(True) <= 3 * widened.block_s
    assert f"over {widened.block_s:.0f}-s blocks" in watch.warning
    assert f"fusion.{widened.parameter}" in watch.warning
    assert f"fusion.{widened.limit_parameter}" in watch.warning


def test_an_error_of_twenty_seconds_shows_in_short_blocks_not_in_long_ones():
    """A velocity error of 20-s period averages out over 30-s blocks at every third of them and
    mostly over the rest, while 10-s blocks hold half a period each."""
    short = MeanVelocityWatch(WINDOW_S, EXCURSION_SIGMA_M, VELOCITY_NOISE, SCALE_LIMIT)
    long = MeanVelocityWatch(WINDOW_S, EXCURSION_SIGMA_M, GYRO_DRIFT, SCALE_LIMIT)
    covariance = STATED_SIGMA_MPS**2 * np.eye(3)
    for t_s in np.arange(0.0, 600.0):
        phase = 2.0 * math.pi * (t_s + 0.5) / 20.0
        velocity = 5.0 * STATED_SIGMA_MPS * np.array((math.sin(phase), 0.0, 0.0))
        short.add(float(t_s), velocity, covariance)
        long.add(float(t_s), velocity, covariance)
    assert short.scale > 1.0
    assert long.scale == 1.0
