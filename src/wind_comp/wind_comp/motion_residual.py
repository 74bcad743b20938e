"""How much of the platform's wave motion a motion correction leaves in the vertical wind.

Two figures over the wave band, for the vertical wind before and after correction:

- the wave-band variance of the corrected w as a share of the uncorrected (Welch spectra
  integrated over the band); the turbulence's own variance in the band stays, so a perfect
  correction leaves the share of the band variance that the air carries, not zero;
- the mean magnitude-squared coherence of w with the buoy's vertical acceleration over the band:
  the turbulence is not coherent with the buoy's heave, so what is coherent is motion left in w
  (with about 40 spectral segments, coherence below ~0.05 is the estimator's noise floor).

The buoy's vertical acceleration is taken as the magnitude of the specific force minus its
mean: it needs no attitude (neither ours nor the reference's), and the horizontal acceleration
of a buoy enters it only to second order (a 1 m/s² horizontal acceleration adds 0.05 m/s²).
The wave band is where the spectrum of that acceleration exceeds a tenth of its peak, as a
contiguous band around the peak.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

SEGMENT_S = 60.0
"""Welch segment length, s: resolves 1/60 Hz, leaves ~40 half-overlapping segments in 20 min."""
BAND_FRACTION = 0.1
WAVE_FREQUENCY_LIMITS_HZ = (0.03, 1.0)
"""Ocean waves that move a buoy lie within these frequencies (30 s to 1 s periods)."""


@dataclass(frozen=True)
class MotionResidual:
    band_hz: tuple[float, float]
    variance_share: float
    """Wave-band variance of the corrected w over that of the uncorrected."""
    coherence_before: float
    """Mean coherence of the uncorrected w with the vertical acceleration over the band."""
    coherence_after: float


def scipy_signal():
    """``scipy.signal``, imported on first use: importing it (it brings scipy.stats along) takes
    most of a second, which every command and node that can compute a spectrum would otherwise
    pay at start-up."""
    from scipy import signal

    return signal


def gaps_filled(values) -> np.ndarray:
    """``values`` with NaN gaps filled by linear interpolation (spectra need every sample)."""
    values = np.asarray(values, dtype=float)
    valid = np.isfinite(values)
    if valid.all():
        return values
    if valid.sum() < 2:
        raise ValueError("a spectrum needs at least two valid samples")
    index = np.arange(values.size)
    return np.interp(index, index[valid], values[valid])


def vertical_acceleration_mps2(specific_force_mps2) -> np.ndarray:
    """The buoy's vertical acceleration (m/s², mean removed) from (N, 3) specific force in any
    body axes: |f| − mean |f| (see the module docstring)."""
    magnitude = np.linalg.norm(np.asarray(specific_force_mps2, dtype=float), axis=1)
    return magnitude - np.nanmean(magnitude)


def _segment(rate_hz: float, count: int) -> int:
    return int(min(round(SEGMENT_S * rate_hz), count))


def wave_band_hz(vertical_acceleration, rate_hz: float) -> tuple[float, float]:
    """The contiguous band around the spectral peak of the vertical acceleration where its
    spectrum exceeds :data:`BAND_FRACTION` of the peak, within the wave frequencies, Hz."""
    x = gaps_filled(vertical_acceleration)
    frequency, density = scipy_signal().welch(x, fs=rate_hz, nperseg=_segment(rate_hz, x.size))
    return band_around_peak_hz(frequency, density)


def band_around_peak_hz(frequency_hz: np.ndarray, density: np.ndarray) -> tuple[float, float]:
    """The contiguous band (Hz) around the peak of the spectrum ``density`` of a vertical
    acceleration at ``frequency_hz`` where it exceeds :data:`BAND_FRACTION` of the peak, within
    the wave frequencies (ValueError when the spectrum holds none of them)."""
    frequency = frequency_hz
    low, high = WAVE_FREQUENCY_LIMITS_HZ
    inside = (frequency >= low) & (frequency <= high)
    if not inside.any():
        raise ValueError(f"a spectrum up to {frequency[-1]:g} Hz holds no wave frequency")
    peak = np.flatnonzero(inside)[np.argmax(density[inside])]
    above = inside & (density >= BAND_FRACTION * density[peak])
    start = peak
    while start > 0 and above[start - 1]:
        start -= 1
    end = peak
    while end + 1 < frequency.size and above[end + 1]:
        end += 1
    return float(frequency[start]), float(frequency[end])


def band_variance(values, rate_hz: float, band_hz: tuple[float, float]) -> float:
    """Variance of ``values`` within ``band_hz`` (Welch spectrum integrated over the band)."""
    x = gaps_filled(values)
    frequency, density = scipy_signal().welch(x, fs=rate_hz, nperseg=_segment(rate_hz, x.size))
    inside = (frequency >= band_hz[0]) & (frequency <= band_hz[1])
    return float(np.sum(density[inside]) * (frequency[1] - frequency[0]))


def band_coherence(a, b, rate_hz: float, band_hz: tuple[float, float]) -> float:
    """Mean magnitude-squared coherence of ``a`` and ``b`` over ``band_hz``."""
    x, y = gaps_filled(a), gaps_filled(b)
    frequency, coherence = scipy_signal().coherence(
        x, y, fs=rate_hz, nperseg=_segment(rate_hz, x.size)
    )
    inside = (frequency >= band_hz[0]) & (frequency <= band_hz[1])
    return float(np.mean(coherence[inside]))


def platform_velocity_left(
    corrected_w_mps, platform_up_velocity_mps, rate_hz: float, band_hz: tuple[float, float]
) -> complex:
    """How much of the platform's vertical velocity (m/s, ENU up) the corrected vertical wind
    (m/s) still carries over ``band_hz``: the cross-spectrum over the platform's spectrum, summed
    over the band. The real part is the share left in phase (a correction that applies a platform
    velocity too small by 10 % leaves +0.1), the imaginary part the share a quarter period out of
    phase (what a timing offset between the sensors leaves). Turbulence, uncorrelated with the
    platform, adds only estimator noise, so a sound correction of sound sensors leaves about 0."""
    x, y = gaps_filled(platform_up_velocity_mps), gaps_filled(corrected_w_mps)
    segment = _segment(rate_hz, x.size)
    frequency, cross = scipy_signal().csd(x, y, fs=rate_hz, nperseg=segment)
    _, platform = scipy_signal().welch(x, fs=rate_hz, nperseg=segment)
    inside = (frequency >= band_hz[0]) & (frequency <= band_hz[1])
    return complex(np.sum(cross[inside]) / np.sum(platform[inside]))


def motion_residual(
    uncorrected_w_mps, corrected_w_mps, vertical_acceleration, rate_hz: float, band_hz=None
) -> MotionResidual:
    """The wave-band figures of one correction of the vertical wind (equal-length series at
    ``rate_hz``); the band from the vertical acceleration unless given."""
    band = band_hz or wave_band_hz(vertical_acceleration, rate_hz)
    return MotionResidual(
        band_hz=band,
        variance_share=band_variance(corrected_w_mps, rate_hz, band)
        / band_variance(uncorrected_w_mps, rate_hz, band),
        coherence_before=band_coherence(uncorrected_w_mps, vertical_acceleration, rate_hz, band),
        coherence_after=band_coherence(corrected_w_mps, vertical_acceleration, rate_hz, band),
    )
