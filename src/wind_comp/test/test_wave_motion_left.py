"""The wave motion left in a window's vertical wind, on series whose answer is known: a buoy
heaving in a narrow band of waves, turbulence the heave does not move, and a correction that
applies a known share of the platform velocity, or applies it late."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy import signal

from buoy_common.contract import QualityFlag
from wind_comp.flux_products import FluxAverager
from wind_comp.flux_quality import FLUX_FLAG_TESTS, worst_flag
from wind_comp.wave_motion_left import (
    DEFAULT_THRESHOLDS,
    MIN_SEGMENTS,
    SEGMENT_S,
    MotionLeftThresholds,
    coherence_threshold,
    motion_left_flag,
    platform_wave_band_hz,
    valid_runs,
    wave_motion_left,
)

RATE_HZ = 10.0
WINDOW_S = 1800.0
START_S = 1_767_225_600.0  # a multiple of 30 min
WAVE_BAND_HZ = (0.08, 0.2)
HEAVE_STD_MPS = 0.5
TURBULENCE_STD_MPS = 0.3
# Turbulence adds to the share of a window an error of about √(S_air / S_platform / K) over the
# band: with 119 segments and the air's band variance a twentieth of the heave's, 0.02.
SHARE_TOLERANCE = 0.06


def heaving_buoy(seed: int, duration_s: float = WINDOW_S):
    """Stamps (s), the platform's vertical velocity (m/s, band-limited noise in
    :data:`WAVE_BAND_HZ`) and white turbulence of w (m/s), independent of it."""
    rng = np.random.default_rng(seed)
    samples = int(duration_s * RATE_HZ)
    band = signal.butter(4, WAVE_BAND_HZ, btype="band", fs=RATE_HZ, output="sos")
    heave = signal.sosfiltfilt(band, rng.normal(size=samples))
    heave *= HEAVE_STD_MPS / heave.std()
    turbulence = rng.normal(0.0, TURBULENCE_STD_MPS, samples)
    return START_S + np.arange(samples) / RATE_HZ, heave, turbulence


def left(t_s, w, platform, thresholds=DEFAULT_THRESHOLDS):
    return wave_motion_left(t_s, w, platform, 1.0 / RATE_HZ, thresholds)


@pytest.mark.parametrize(
    ("applied", "flag"),
    [(1.0, QualityFlag.GOOD), (0.8, QualityFlag.SUSPECT), (0.5, QualityFlag.BAD)],
)
def test_the_share_left_is_what_the_correction_did_not_apply(applied, flag):
    t_s, heave, turbulence = heaving_buoy(seed=1)
    # The anemometer reads the air less the platform's velocity; the correction adds back
    # ``applied`` of it.
    w = turbulence - heave + applied * heave
    result = left(t_s, w, heave)
    assert result.share == pytest.approx(1.0 - applied, abs=SHARE_TOLERANCE)
    assert result.flag == flag
    assert result.band_low_hz <= 0.14 <= result.band_high_hz
    assert (
        WAVE_BAND_HZ[0] - 0.05 < result.band_low_hz < result.band_high_hz < WAVE_BAND_HZ[1] + 0.05
    )


def test_a_late_platform_velocity_leaves_the_share_of_a_phase_shift():
    # One swell of 7.5 s (a frequency the 30-s segments resolve): applied τ late, the velocity
    # left is v(t) − v(t − τ), of amplitude 2·|sin(π f τ)| of the swell's.
    frequency_hz, delay_s = 1.0 / 7.5, 0.4
    t_s, _, turbulence = heaving_buoy(seed=2)
    heave = HEAVE_STD_MPS * math.sqrt(2) * np.sin(2 * np.pi * frequency_hz * (t_s - START_S))
    late = (
        HEAVE_STD_MPS * math.sqrt(2) * np.sin(2 * np.pi * frequency_hz * (t_s - START_S - delay_s))
    )
    result = left(t_s, turbulence + heave - late, heave)
    expected = 2.0 * abs(math.sin(math.pi * frequency_hz * delay_s))
    assert result.share == pytest.approx(expected, abs=SHARE_TOLERANCE)
    assert result.coherence > 0.9


def test_turbulence_alone_is_not_coherent_with_the_heave():
    t_s, heave, turbulence = heaving_buoy(seed=3)
    result = left(t_s, turbulence, heave)
    # about 1/K for K segments of unrelated series
    assert result.coherence < 3.0 / result.n_segments
    assert result.flag == QualityFlag.GOOD


def test_invalid_stretches_and_missing_samples_leave_the_share_as_it_is():
    t_s, heave, turbulence = heaving_buoy(seed=4)
    w = turbulence - 0.5 * heave
    whole = left(t_s, w, heave)
    gappy = w.copy()
    gappy[3000:7000] = np.nan  # 400 s invalid
    gappy[12_000:12_050] = np.nan
    kept = np.ones(t_s.size, dtype=bool)
    kept[15_000:15_020] = False  # 2 s of messages that never came
    result = left(t_s[kept], gappy[kept], heave[kept])
    assert result.n_segments < whole.n_segments
    assert result.share == pytest.approx(0.5, abs=SHARE_TOLERANCE)
    assert result.flag == QualityFlag.BAD


def test_runs_end_at_invalid_and_missing_samples():
    t_s = np.array([0.0, 0.1, 0.2, 0.3, 0.6, 0.7, 0.8, 0.9])
    valid = np.array([True, True, False, True, True, True, True, True])
    assert valid_runs(t_s, valid, 0.1) == [slice(0, 2), slice(3, 4), slice(4, 8)]


def test_too_short_unknown_or_still_windows_are_not_evaluated():
    t_s, heave, turbulence = heaving_buoy(seed=5)
    enough = int((MIN_SEGMENTS + 1) * SEGMENT_S / 2 * RATE_HZ)
    assert left(t_s[:enough], turbulence[:enough], heave[:enough]).flag == QualityFlag.GOOD
    short = enough - int(SEGMENT_S * RATE_HZ)
    assert left(t_s[:short], turbulence[:short], heave[:short]).flag == QualityFlag.NOT_EVALUATED
    unknown = wave_motion_left(t_s, turbulence, heave, math.nan, DEFAULT_THRESHOLDS)
    assert unknown.flag == QualityFlag.NOT_EVALUATED and math.isnan(unknown.share)
    still = left(t_s, turbulence, np.zeros_like(heave))
    assert still.flag == QualityFlag.NOT_EVALUATED
    assert left(t_s, np.full_like(heave, np.nan), heave).flag == QualityFlag.NOT_EVALUATED


@pytest.mark.parametrize(
    ("applied", "heave_std_mps"), [(0.5, 0.5), (1.0, 0.5), (0.5, 0.1), (1.0, 0.03)]
)
def test_the_shares_standard_error_bounds_its_error_over_many_windows(applied, heave_std_mps):
    # 40 windows of 400 s (25 segments): the RMS error of the share against the share the
    # correction left lies below its stated standard error, by no more than a factor of 3
    errors, stated = [], []
    for seed in range(40):
        t_s, heave, turbulence = heaving_buoy(seed, duration_s=400.0)
        heave *= heave_std_mps / HEAVE_STD_MPS
        result = left(t_s, turbulence - heave + applied * heave, heave)
        errors.append(result.share - (1.0 - applied))
        stated.append(result.share_standard_error)
    ratio = math.sqrt(np.mean(np.square(errors))) / np.mean(stated)
    assert 1.0 / 3.0 < ratio < 1.0, ratio


def test_a_buoy_that_barely_heaves_is_not_evaluated_but_its_figures_are_given():
    # heave of 0.014 m/s (the sea_state buoy's) under 0.3 m/s of turbulence: the share is the
    # estimator's noise, with a standard error far above the limit
    t_s, heave, turbulence = heaving_buoy(seed=6)
    heave *= 0.014 / HEAVE_STD_MPS
    still = left(t_s, turbulence, heave)
    assert still.share_standard_error > DEFAULT_THRESHOLDS.max_share_standard_error
    assert still.flag == QualityFlag.NOT_EVALUATED
    assert math.isfinite(still.share) and math.isfinite(still.coherence)
    heaving = left(t_s, turbulence, heave * HEAVE_STD_MPS / 0.014)
    assert heaving.share_standard_error < DEFAULT_THRESHOLDS.max_share_standard_error
    assert heaving.flag == QualityFlag.GOOD


def test_the_flag_follows_the_thresholds():
    thresholds = MotionLeftThresholds(
        suspect_share=0.1, fail_share=0.3, coherence_sigmas=3.0, max_share_standard_error=0.1
    )
    assert motion_left_flag(0.05, 0.5, 0.1, thresholds) == QualityFlag.GOOD
    assert motion_left_flag(0.1, 0.5, 0.1, thresholds) == QualityFlag.SUSPECT
    assert motion_left_flag(0.3, 0.5, 0.1, thresholds) == QualityFlag.BAD
    # a share the heave does not carry coherently is noise over a band the air dominates
    assert motion_left_flag(0.6, 0.05, 0.1, thresholds) == QualityFlag.GOOD
    assert motion_left_flag(math.nan, 0.5, 0.1, thresholds) == QualityFlag.NOT_EVALUATED
    # a share known no better than its limit is not evaluated, however coherent
    assert motion_left_flag(0.3, 0.5, 0.1, thresholds, 0.1) == QualityFlag.BAD
    assert motion_left_flag(0.3, 0.5, 0.1, thresholds, 0.11) == QualityFlag.NOT_EVALUATED


@pytest.mark.parametrize(("segments", "frequencies"), [(22, 2), (25, 23), (119, 4)])
def test_unrelated_series_rarely_exceed_the_coherence_threshold(segments, frequencies):
    # The mean coherence over a band of unrelated white noise, window after window, sits at 1/K
    # and lies above the 3σ threshold in about 1 % of the windows (its tail is heavier than a
    # normal's 0.13 %; 0.7 to 1.4 % over 3,000 windows of each case), 2.5 % at most.
    rng = np.random.default_rng(segments)
    segment = round(SEGMENT_S * RATE_HZ)
    samples = segment // 2 * (segments + 1)
    windows = (600, samples)
    _, coherence = signal.coherence(
        rng.normal(size=windows), rng.normal(size=windows), fs=RATE_HZ, nperseg=segment
    )
    means = coherence[:, 5 : 5 + frequencies].mean(axis=1)
    threshold = coherence_threshold(segments, frequencies, 3.0)
    assert np.count_nonzero(means > threshold) <= 0.025 * means.size
    assert np.mean(means) == pytest.approx(1.0 / segments, rel=0.1)


def test_a_records_wave_band_is_its_heaves():
    t_s, heave, _ = heaving_buoy(seed=6)
    low, high = platform_wave_band_hz(t_s, heave, 1.0 / RATE_HZ)
    assert low <= 0.14 <= high
    assert platform_wave_band_hz(t_s[:100], heave[:100], 1.0 / RATE_HZ) is None


def test_each_flux_window_carries_its_wave_motion_left_and_is_flagged_by_it():
    t_s, heave, turbulence = heaving_buoy(seed=7, duration_s=2 * WINDOW_S)
    wind = np.column_stack((np.full(t_s.size, 6.0), np.full(t_s.size, -2.0), turbulence))
    wind[t_s >= START_S + WINDOW_S, 2] += 0.5 * heave[t_s >= START_S + WINDOW_S]
    averager = FluxAverager(WINDOW_S)
    # as process_bag hands them over, in stretches
    windows = []
    for part in np.array_split(np.arange(t_s.size), 37):
        windows += averager.add_batch(t_s[part], wind[part], heave[part])
    windows += averager.flush()
    assert [w.window_start_s for w in windows] == [START_S, START_S + WINDOW_S]
    for window in windows:
        inside = (t_s >= window.window_start_s) & (t_s < window.window_end_s)
        expected = left(t_s[inside], wind[inside, 2], heave[inside])
        # the same arithmetic, at the sampling interval the averager measures from the stamps
        # (epoch seconds resolve 0.24 µs)
        assert window.motion_left_share == pytest.approx(expected.share, rel=1e-9)
        assert window.motion_left_coherence == pytest.approx(expected.coherence, rel=1e-9)
        assert window.wave_band_low_hz == pytest.approx(expected.band_low_hz, rel=1e-5)
        assert window.wave_band_high_hz == pytest.approx(expected.band_high_hz, rel=1e-5)
        assert window.motion_left_flag == expected.flag
    assert [w.motion_left_flag for w in windows] == [QualityFlag.GOOD, QualityFlag.BAD]
    assert windows[1].quality_flag == QualityFlag.BAD


def test_without_a_platform_velocity_the_test_is_not_evaluated():
    t_s, _, turbulence = heaving_buoy(seed=8)
    wind = np.column_stack((np.full(t_s.size, 6.0), np.zeros(t_s.size), turbulence))
    averager = FluxAverager(WINDOW_S)
    (window,) = averager.add_batch(t_s, wind) + averager.flush()
    assert window.motion_left_flag == QualityFlag.NOT_EVALUATED
    assert math.isnan(window.motion_left_share)
    # a test not evaluated does not count in the window's flag
    others = [getattr(window, test.field) for test in FLUX_FLAG_TESTS if test.name != "motion_left"]
    assert window.quality_flag == worst_flag(others) == QualityFlag.BAD
