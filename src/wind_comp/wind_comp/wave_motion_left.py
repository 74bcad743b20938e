"""The wave motion a correction leaves in the vertical wind of one flux window, and the
"motion left" flag test.

Per window, from the window's own samples:

- the wave band: where the spectrum of the platform's vertical acceleration, (2πf)² times that
  of its vertical velocity, exceeds a tenth of its peak, around the peak
  (:func:`wind_comp.motion_residual.band_around_peak_hz`);
- the mean magnitude-squared coherence of the corrected vertical wind with the platform's
  vertical velocity over that band: the air's turbulence is not coherent with the buoy's
  heave, so what is coherent is motion left in w; and the coherence that unrelated series
  would not exceed (:func:`coherence_threshold`);
- the share of the platform's vertical velocity left in w: the magnitude of their
  cross-spectrum over the platform velocity's spectrum, summed over the band (as
  :func:`wind_comp.motion_residual.platform_velocity_left`; a correction that applies 80 % of
  the platform velocity leaves 0.2, one late by a quarter wave period about 1.4).

The platform's vertical velocity is the one the correction applied to each sample: the
navigation's (``nav/odometry``) ENU velocity of the body origin, up, at the sample's stamp (the
translation term of :mod:`wind_comp.miller`), so the live node and ``process_bag`` see the same.

The spectra are Welch averages over the half-overlapping segments of :data:`SEGMENT_S` that
lie wholly within runs of valid, evenly spaced samples: an invalid sample or a missing one
(a stamp step beyond 1.5 sampling intervals) ends a run, so nothing is bridged or invented.
A window needs :data:`MIN_SEGMENTS` such segments; with fewer, or with an unknown sampling
interval or a platform that does not move, the test is not evaluated (its figures NaN).

The test (IOOS QARTOD flags): where the coherence exceeds its threshold, fail where the share
reaches :attr:`MotionLeftThresholds.fail_share` and suspect where it reaches
:attr:`MotionLeftThresholds.suspect_share`; pass otherwise (a share that no coherence carries
is the estimator's noise over a band where the air dominates the buoy's heave). Not evaluated,
the figures still given, where the share's own standard error
(:func:`share_standard_error`) exceeds :attr:`MotionLeftThresholds.max_share_standard_error`:
a buoy that barely heaves (a few cm/s, the noise of the navigation's vertical velocity) under
the air's turbulence gives shares above 1 and coherences past their threshold that say nothing
about the correction, whether of the corrected wind or of the true one.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from buoy_common.contract import QualityFlag
from wind_comp.motion_residual import band_around_peak_hz, scipy_signal

SEGMENT_S = 30.0
"""Welch segment length, s: resolves 1/30 Hz, the longest waves that move a buoy
(:data:`wind_comp.motion_residual.WAVE_FREQUENCY_LIMITS_HZ`), and short enough that a window
broken by invalid stretches still holds whole segments."""
MIN_SEGMENTS = 20
"""Fewest segments a window needs (5.25 min of valid samples in one run): the mean coherence of
two unrelated series over K segments is about 1/K, so 20 keep that noise floor near 0.05."""
NULL_COHERENCE_SPREAD = 1.2
"""Standard deviation of the mean coherence of unrelated series over M frequencies of K
segments, in units of 1/(K·√M): 1.0 to 1.17 measured on white noise for K of 22 to 119 and M of
2 to 23 (half-overlapping Hann segments correlate neighbouring frequencies), rounded up."""
RUN_BREAK_INTERVALS = 1.5
"""A stamp step longer than this many sampling intervals (a missing sample) ends a run."""


@dataclass(frozen=True)
class MotionLeftThresholds:
    """Where the "motion left" test turns suspect and fail (the parameters
    ``compensation.motion_left_*``), dimensionless."""

    suspect_share: float
    fail_share: float
    coherence_sigmas: float
    """How many standard deviations of unrelated series' coherence above its mean the coherence
    must lie for the share to count."""
    max_share_standard_error: float
    """The largest standard error of the share (:func:`share_standard_error`) at which the test
    is evaluated."""


DEFAULT_THRESHOLDS = MotionLeftThresholds(
    suspect_share=0.1, fail_share=0.3, coherence_sigmas=3.0, max_share_standard_error=0.1
)
"""The parameters' defaults: a sound correction of sound sensors leaves a few hundredths of the
platform's vertical velocity in w (the estimator's noise), so a tenth is suspect and three
tenths fail; unrelated series exceed a coherence 3σ above their mean in a few windows of a
thousand at most (the distribution is skewed); a share known to within a tenth keeps a failing
share (0.3) two standard errors above a suspect one (0.1)."""


@dataclass(frozen=True)
class WaveMotionLeft:
    """The wave motion left in one window's corrected vertical wind, and its flag."""

    band_low_hz: float
    band_high_hz: float
    coherence: float
    """Mean coherence of the corrected w with the platform's vertical velocity over the band."""
    coherence_threshold: float
    """The coherence above which the share counts (:func:`coherence_threshold`)."""
    share: float
    """Share of the platform's vertical velocity left in the corrected w over the band."""
    flag: QualityFlag
    n_segments: int = 0
    """Welch segments the figures average."""
    share_standard_error: float = math.nan
    """Standard error of the share (:func:`share_standard_error`)."""


NOT_EVALUATED = WaveMotionLeft(
    math.nan, math.nan, math.nan, math.nan, math.nan, QualityFlag.NOT_EVALUATED
)


def coherence_threshold(n_segments: int, n_frequencies: int, sigmas: float) -> float:
    """The mean coherence over ``n_frequencies`` of ``n_segments`` Welch segments that unrelated
    series exceed with the chance of ``sigmas`` standard deviations: their mean 1/K plus
    ``sigmas`` times :data:`NULL_COHERENCE_SPREAD`/(K·√M). The mean coherence's tail is heavier
    than a normal's: at 3σ about 1 % of windows of unrelated series exceed it, not 0.13 %."""
    spread = NULL_COHERENCE_SPREAD / math.sqrt(n_frequencies)
    return (1.0 + sigmas * spread) / n_segments


def share_standard_error(
    coherence: float, wind_power: float, platform_power: float, n_segments: int
) -> float:
    """Standard error of the share of the platform's vertical velocity left in w, from the mean
    ``coherence`` over the band, the band powers of w and of the platform velocity (same units)
    and the ``n_segments`` averaged: the random error of a transfer function's gain |H|,
    |H|·√(1−γ²)/(|γ|·√(2K)) (Bendat and Piersol 2010, Random Data, eq. 9.90), with |H|/|γ| =
    √(Gww/Gpp), of the band's summed powers. An upper estimate: the band's several frequencies
    average the error down, which it leaves out (on white turbulence over bands of 4 or 5
    frequencies it is 1.3 to 2.2 times the share's RMS error, the bias of a share near zero
    included)."""
    return math.sqrt(max(1.0 - coherence, 0.0) * wind_power / (2 * n_segments * platform_power))


def motion_left_flag(
    share: float,
    coherence: float,
    threshold: float,
    thresholds: MotionLeftThresholds,
    standard_error: float = 0.0,
) -> QualityFlag:
    """The QARTOD flag of the "motion left" test for a ``share`` of the platform's vertical
    velocity left in w, known to ``standard_error``, with mean ``coherence`` over the wave band,
    which counts above ``threshold`` (all dimensionless)."""
    if not (math.isfinite(share) and math.isfinite(coherence)):
        return QualityFlag.NOT_EVALUATED
    if not standard_error <= thresholds.max_share_standard_error:
        return QualityFlag.NOT_EVALUATED
    if coherence <= threshold:
        return QualityFlag.GOOD
    if share >= thresholds.fail_share:
        return QualityFlag.BAD
    if share >= thresholds.suspect_share:
        return QualityFlag.SUSPECT
    return QualityFlag.GOOD


def valid_runs(t_s: np.ndarray, valid: np.ndarray, interval_s: float) -> list[slice]:
    """The runs of consecutive ``valid`` samples at stamps ``t_s`` (s) no further apart than
    :data:`RUN_BREAK_INTERVALS` sampling intervals ``interval_s`` (s)."""
    if not t_s.size:
        return []
    step_ok = np.diff(t_s) <= RUN_BREAK_INTERVALS * interval_s
    starts = valid & np.concatenate(([True], ~valid[:-1] | ~step_ok))
    ends = valid & np.concatenate((~valid[1:] | ~step_ok, [True]))
    return [
        slice(int(start), int(end) + 1)
        for start, end in zip(np.flatnonzero(starts), np.flatnonzero(ends), strict=True)
    ]


@dataclass(frozen=True)
class _Spectra:
    """Welch spectra averaged over the segments of several runs: of the platform's vertical
    velocity (m²/s² per Hz), of w, and their cross-spectrum, at ``frequency_hz``."""

    frequency_hz: np.ndarray
    platform: np.ndarray
    wind: np.ndarray
    cross: np.ndarray
    n_segments: int


def averaged_spectra(runs, w_mps, platform_up_mps, rate_hz: float) -> _Spectra | None:
    """The spectra of (w, platform vertical velocity) (m/s at ``rate_hz``) averaged over every
    whole segment of :data:`SEGMENT_S` within ``runs``; None when no run holds one."""
    segment = round(SEGMENT_S * rate_hz)
    step = segment - segment // 2
    sums, total = None, 0
    for run in runs:
        length = run.stop - run.start
        if length < segment:
            continue
        count = (length - segment) // step + 1
        x, y = platform_up_mps[run], w_mps[run]
        signal = scipy_signal()
        frequency, cross = signal.csd(x, y, fs=rate_hz, nperseg=segment)
        spectra = (
            signal.welch(x, fs=rate_hz, nperseg=segment)[1],
            signal.welch(y, fs=rate_hz, nperseg=segment)[1],
            cross,
        )
        weighted = [count * spectrum for spectrum in spectra]
        sums = weighted if sums is None else [a + b for a, b in zip(sums, weighted, strict=True)]
        total += count
    if sums is None:
        return None
    return _Spectra(frequency, *(spectrum / total for spectrum in sums), total)


def _wave_band_hz(spectra: _Spectra) -> tuple[float, float] | None:
    """The wave band (Hz) of the platform's vertical acceleration, whose spectrum is (2πf)²
    times its velocity's; None when the spectra reach no wave frequency."""
    frequency = spectra.frequency_hz
    try:
        return band_around_peak_hz(frequency, (2 * np.pi * frequency) ** 2 * spectra.platform)
    except ValueError:
        return None


def platform_wave_band_hz(
    t_s, platform_up_velocity_mps, interval_s: float
) -> tuple[float, float] | None:
    """The wave band (Hz) of a whole record, as a window's, from the platform's vertical velocity
    (ENU up, m/s, NaN where unknown) at stamps ``t_s`` (s) sampled every ``interval_s`` (s);
    None without one whole segment of :data:`SEGMENT_S`."""
    t_s = np.asarray(t_s, dtype=float)
    platform = np.asarray(platform_up_velocity_mps, dtype=float)
    runs = valid_runs(t_s, np.isfinite(platform), interval_s)
    spectra = averaged_spectra(runs, platform, platform, 1.0 / interval_s)
    return None if spectra is None else _wave_band_hz(spectra)


def wave_motion_left(
    t_s, corrected_w_mps, platform_up_velocity_mps, interval_s: float, thresholds
) -> WaveMotionLeft:
    """The wave motion left in a window's corrected vertical wind (m/s, NaN where invalid) by
    the correction that applied ``platform_up_velocity_mps`` (ENU up, m/s) at the same stamps
    ``t_s`` (s), sampled every ``interval_s`` (s; NaN when unknown), flagged with
    ``thresholds`` (:class:`MotionLeftThresholds`)."""
    if not (math.isfinite(interval_s) and interval_s > 0):
        return NOT_EVALUATED
    t_s = np.asarray(t_s, dtype=float)
    w = np.asarray(corrected_w_mps, dtype=float)
    platform = np.asarray(platform_up_velocity_mps, dtype=float)
    runs = valid_runs(t_s, np.isfinite(w) & np.isfinite(platform), interval_s)
    spectra = averaged_spectra(runs, w, platform, 1.0 / interval_s)
    if spectra is None or spectra.n_segments < MIN_SEGMENTS:
        return NOT_EVALUATED
    wave_band = _wave_band_hz(spectra)
    if wave_band is None:
        return NOT_EVALUATED
    low, high = wave_band
    band = (spectra.frequency_hz >= low) & (spectra.frequency_hz <= high)
    platform_power = float(np.sum(spectra.platform[band]))
    if not platform_power > 0.0:
        return NOT_EVALUATED
    share = abs(complex(np.sum(spectra.cross[band]))) / platform_power
    with np.errstate(divide="ignore", invalid="ignore"):
        coherence = float(
            np.mean(
                np.abs(spectra.cross[band]) ** 2 / (spectra.platform[band] * spectra.wind[band])
            )
        )
    if not math.isfinite(coherence):
        return NOT_EVALUATED
    threshold = coherence_threshold(
        spectra.n_segments, int(np.count_nonzero(band)), thresholds.coherence_sigmas
    )
    error = share_standard_error(
        coherence, float(np.sum(spectra.wind[band])), platform_power, spectra.n_segments
    )
    flag = motion_left_flag(share, coherence, threshold, thresholds, error)
    return WaveMotionLeft(low, high, coherence, threshold, share, flag, spectra.n_segments, error)
