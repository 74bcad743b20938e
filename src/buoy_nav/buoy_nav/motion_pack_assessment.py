"""What a motion pack's own record says of its gyro's slow bias wander and of the sea's excursion:
the figures a moored buoy without GNSS must state to the fusion.

**The gyro's wander.** The pack publishes its rates (``imu/data_raw``) and its own attitude
(``imu/data``). The body rate implied by the attitude is the rotation between consecutive
orientations over their interval, ``ω = rotvec(R_kᵀ R_{k+1}) / Δt`` (body axes, rad/s). The raw
rate minus it is the gyro's error plus the rate of the pack's own attitude error. Its mean is the
turn-on bias; what remains below a cut-off frequency ``f_c`` (the mean removed, the spectrum cut
above ``f_c``) is the bias's slow wander, whose 1σ this module reports per axis at
:data:`WANDER_CUTOFFS_HZ`. A first-order Gauss-Markov bias of 1σ ``σ_b`` and correlation time
``τ`` (the fusion's gyro model) keeps the share ``(2/π)·atan(2π f_c τ)`` of its variance below
``f_c``; ``τ`` is read from the wander itself, as the one for which that share grows from the lowest
cut-off to the highest as the measured variance does (the x and y axes' mean). The suggested
``fusion.gyro_bias_instability_deg_h`` is ``σ_b`` from the x and y figures below
:data:`SUGGESTION_CUTOFF_HZ` (their RMS): the tilt axes, whose wander the fusion's
velocity integrates as ``g·δθ``. The z axis is reported too, but the pack's heading is often
magnetic and wanders on its own. The pack's own slow attitude error adds its rate to the
difference, so the figure is an upper bound of the gyro's wander: a stated σ on the safe side.

**The sea's excursion.** The specific force turned to the world by the pack's attitude has the
vertical acceleration (plus gravity) as its up component; its mean removed and divided by
``(2πf)²`` in the frequency domain over the wave band :data:`WAVE_BAND_HZ` it is the heave,
whose 1σ is the suggested
``fusion.moored_position_sigma_horizontal_m`` (a moored buoy's orbit in deep water is as wide
as it is high). The magnitude of the specific force is not used: the square of the horizontal
acceleration over ``2g`` in it has a slow part, from the beat of the waves, that the division
by ``(2πf)²`` makes metres of at the band's low end (on the simulator it doubles the heave).

Both series are first resampled on a uniform grid at the raw IMU's median interval, linearly
across any gap; gaps longer than :data:`MAX_GAP_S` are refused.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np
from scipy import optimize
from scipy.spatial.transform import Rotation, Slerp

WANDER_CUTOFFS_HZ = (0.005, 0.01, 0.02)
SUGGESTION_CUTOFF_HZ = 0.01
"""The fusion's slow tilt is set by what the gyro does over minutes: below 0.01 Hz."""
MIN_CORRELATION_TIME_S = 10.0
WAVE_BAND_HZ = (0.05, 2.0)
MIN_DURATION_S = 300.0
"""Three periods of the lowest cut-off (0.01 Hz) at least, else its 1σ is a guess."""
MAX_GAP_S = 5.0
RAD_S_TO_DEG_H = math.degrees(1.0) * 3600.0


class MotionPackRecord(NamedTuple):
    """A pack's two streams, each in time order: raw stamps (s), rates (rad/s, body x, y, z),
    specific force (m/s², body); attitude stamps (s) and orientations (body to world)."""

    raw_t_s: np.ndarray
    gyro_rad_s: np.ndarray
    specific_force_mps2: np.ndarray
    attitude_t_s: np.ndarray
    attitude: Rotation


class MotionPackAssessment(NamedTuple):
    """The figures (see the module docstring)."""

    duration_s: float
    wander_deg_h: dict[float, np.ndarray]
    """Per cut-off (Hz): the 1σ wander below it, body x, y, z (°/h)."""
    correlation_time_s: float
    gyro_bias_instability_deg_h: float
    heave_sigma_m: float


class AssessmentError(ValueError):
    """A record that cannot give the figures, with the reason."""


def uniform_grid(record: MotionPackRecord) -> np.ndarray:
    """Times (s) at the raw IMU's median interval over the span both streams cover."""
    start = max(record.raw_t_s[0], record.attitude_t_s[0])
    end = min(record.raw_t_s[-1], record.attitude_t_s[-1])
    if end - start < MIN_DURATION_S:
        raise AssessmentError(
            f"the raw rates and the pack's attitude overlap for {max(end - start, 0.0):.0f} s; "
            f"at least {MIN_DURATION_S:.0f} s are needed for the wander below "
            f"{SUGGESTION_CUTOFF_HZ} Hz"
        )
    for name, stamps in (("imu/data_raw", record.raw_t_s), ("imu/data", record.attitude_t_s)):
        gap = float(np.max(np.diff(stamps)))
        if gap > MAX_GAP_S:
            raise AssessmentError(f"{name} has a gap of {gap:.1f} s (at most {MAX_GAP_S} s)")
    interval = float(np.median(np.diff(record.raw_t_s)))
    return start + interval * np.arange(int((end - start) / interval) + 1)


def attitude_body_rates_rad_s(t_s: np.ndarray, attitude: Rotation) -> tuple:
    """(midpoint times s, body rates rad/s (N-1, 3)) implied by consecutive orientations."""
    steps = (attitude[:-1].inv() * attitude[1:]).as_rotvec()
    return 0.5 * (t_s[:-1] + t_s[1:]), steps / np.diff(t_s)[:, None]


def resampled(t_s: np.ndarray, values: np.ndarray, grid_s: np.ndarray) -> np.ndarray:
    return np.column_stack([np.interp(grid_s, t_s, column) for column in values.T])


def low_passed(values: np.ndarray, interval_s: float, cutoff_hz: float) -> np.ndarray:
    """``values`` (N, k) without their mean and without what lies above ``cutoff_hz``."""
    spectrum = np.fft.rfft(values - values.mean(axis=0), axis=0)
    frequencies = np.fft.rfftfreq(len(values), interval_s)
    spectrum[frequencies > cutoff_hz] = 0.0
    return np.fft.irfft(spectrum, len(values), axis=0)


def markov_share(cutoff_hz: float, correlation_s: float) -> float:
    """Share of a first-order Gauss-Markov process's variance below ``cutoff_hz`` for a
    correlation time ``correlation_s``."""
    return 2.0 / math.pi * math.atan(2.0 * math.pi * cutoff_hz * correlation_s)


def correlation_time_s(lowest_variance: float, highest_variance: float, duration_s: float) -> float:
    """The Gauss-Markov correlation time (s) whose variance below the highest of
    :data:`WANDER_CUTOFFS_HZ` is ``highest_variance / lowest_variance`` times that below the
    lowest, within [:data:`MIN_CORRELATION_TIME_S`, a third of ``duration_s``] (a longer one is
    not measured by the record, a shorter one is noise, not a bias)."""
    low, high = WANDER_CUTOFFS_HZ[0], WANDER_CUTOFFS_HZ[-1]
    bounds = (MIN_CORRELATION_TIME_S, duration_s / 3.0)
    ratio = highest_variance / lowest_variance

    def excess(log_correlation_s: float) -> float:
        correlation = math.exp(log_correlation_s)
        return markov_share(high, correlation) / markov_share(low, correlation) - ratio

    logs = tuple(math.log(bound) for bound in bounds)
    if excess(logs[0]) <= 0.0:
        return bounds[0]
    if excess(logs[1]) >= 0.0:
        return bounds[1]
    return math.exp(optimize.brentq(excess, *logs))


def markov_sigma_from_band(band_sigma: float, cutoff_hz: float, correlation_s: float) -> float:
    """1σ of a first-order Gauss-Markov process whose part below ``cutoff_hz`` has
    ``band_sigma`` (same unit), for a correlation time ``correlation_s``."""
    return band_sigma / math.sqrt(markov_share(cutoff_hz, correlation_s))


def heave_sigma_m(vertical_force_mps2: np.ndarray, interval_s: float) -> float:
    """1σ heave (m) over :data:`WAVE_BAND_HZ` from the up component of the specific force
    (m/s², world frame) at a uniform ``interval_s``."""
    vertical = vertical_force_mps2
    spectrum = np.fft.rfft(vertical - vertical.mean())
    frequencies = np.fft.rfftfreq(len(vertical), interval_s)
    low, high = WAVE_BAND_HZ
    band = (frequencies >= low) & (frequencies <= high)
    heave = np.zeros_like(spectrum)
    heave[band] = -spectrum[band] / (2.0 * math.pi * frequencies[band]) ** 2
    return float(np.std(np.fft.irfft(heave, len(vertical))))


def assess_motion_pack(record: MotionPackRecord) -> MotionPackAssessment:
    """The pack's gyro wander and the sea's heave (see the module docstring)."""
    grid = uniform_grid(record)
    interval = float(grid[1] - grid[0])
    rate_t, attitude_rates = attitude_body_rates_rad_s(record.attitude_t_s, record.attitude)
    difference = resampled(record.raw_t_s, record.gyro_rad_s, grid) - resampled(
        rate_t, attitude_rates, grid
    )
    wander = {
        cutoff: np.std(low_passed(difference, interval, cutoff), axis=0) * RAD_S_TO_DEG_H
        for cutoff in WANDER_CUTOFFS_HZ
    }
    duration = float(grid[-1] - grid[0])
    tilt_variance = {cutoff: float(np.mean(w[:2] ** 2)) for cutoff, w in wander.items()}
    correlation = correlation_time_s(
        tilt_variance[WANDER_CUTOFFS_HZ[0]], tilt_variance[WANDER_CUTOFFS_HZ[-1]], duration
    )
    suggested_band = math.sqrt(tilt_variance[SUGGESTION_CUTOFF_HZ])
    force_body = resampled(record.raw_t_s, record.specific_force_mps2, grid)
    levelled = Slerp(record.attitude_t_s, record.attitude)(grid).apply(force_body)
    return MotionPackAssessment(
        duration_s=duration,
        wander_deg_h=wander,
        correlation_time_s=correlation,
        gyro_bias_instability_deg_h=markov_sigma_from_band(
            suggested_band, SUGGESTION_CUTOFF_HZ, correlation
        ),
        heave_sigma_m=heave_sigma_m(levelled[:, 2], interval),
    )
