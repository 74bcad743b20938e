"""Eddy-covariance fluxes of the corrected wind per averaging window, as a stream: the flux
products of ``compensation_node`` (``wind/fluxes_<window>``) and of ``process_bag``.

Windows are aligned to multiples of their length in sensor time, as the wind products'
(:mod:`wind_comp.products`); the fluxes of a window are :func:`wind_comp.fluxes.window_fluxes`
of its corrected wind samples and, when ``anemometer/temperature`` is there, of the sonic
temperature paired with each of them: the temperature sample nearest in stamp, within half the
wind's sampling interval (a sonic reports both from one record, with one stamp), NaN where
there is none.

A window closes once the corrected wind has passed its end and, if sonic temperatures stamped
inside it came, once the temperature has passed its end too (or the wind has passed it by
:data:`TEMPERATURE_WAIT_S`, for a temperature stream that stopped). Both conditions are on
stamps, not on arrival, so that the live node, which hands over every message at once, and
``process_bag``, which hands over stretches of a few hundred, close the same windows on the same
samples.

Quality flags (IOOS QARTOD, :class:`buoy_common.contract.QualityFlag`): each window gets the
named tests of :data:`wind_comp.flux_quality.FLUX_FLAG_TESTS` (coverage, spikes, stationarity,
integral turbulence characteristics, drag coefficient, cross-wind stress, buoyancy flux and
the "motion left" test of :mod:`wind_comp.wave_motion_left` on the platform vertical velocity
each corrected sample was corrected with), each in its own ``<name>_flag`` field, and
``quality_flag``, the worst of them.
"""

from __future__ import annotations

import bisect
import dataclasses
import math
from dataclasses import dataclass

import numpy as np

from wind_comp.flux_quality import (
    FluxDiagnostics,
    FluxEvidence,
    FluxQualityLimits,
    flux_diagnostics,
    flux_flags,
    worst_flag,
)
from wind_comp.fluxes import (
    STANDARD_PRESSURE_PA,
    FluxError,
    PlanarFit,
    window_fluxes,
)
from wind_comp.products import (
    MIN_RATE_INTERVALS,
    RATE_MEMORY_INTERVALS,
    window_coverage,
)
from wind_comp.wave_motion_left import (
    DEFAULT_THRESHOLDS,
    MotionLeftThresholds,
    wave_motion_left,
)

DEFAULT_FLUX_WINDOW_S = 1800.0
"""Averaging window of the fluxes unless configured otherwise, s (30 min: long enough for the
largest eddies of the marine surface layer, short enough to stay stationary)."""
DEFAULT_QUALITY_LIMITS = FluxQualityLimits()
TEMPERATURE_WAIT_S = 10.0
"""How far the wind may pass a window's end before the window closes without waiting for a
temperature that has stopped coming, s."""


@dataclass(frozen=True)
class _FluxWindowFigures:
    """The first fields of a :class:`FluxProduct`: the window's bookkeeping, its fluxes (in the
    frame of the mean wind: u along it, w up), its overall flag and the "motion left" test's
    figures and flag."""

    window_s: float
    window_start_s: float
    window_end_s: float
    first_sample_s: float
    last_sample_s: float
    n_valid: int
    n_invalid: int
    n_temperature: int
    """Wind samples paired with a sonic temperature."""
    mean_speed_mps: float
    tilt_deg: float
    u_w_m2_s2: float
    v_w_m2_s2: float
    friction_velocity_mps: float
    stress_n_m2: float
    air_density_kg_m3: float
    w_ts_k_mps: float
    spikes_u: int
    spikes_v: int
    spikes_w: int
    spikes_ts: int
    """Vickers–Mahrt spikes of u, v, w (frame of the mean wind) and Ts: counted, and taken out
    of the fluxes when the averager despikes."""
    invalid_share: float
    stationarity_u_w_percent: float
    stationarity_w_ts_percent: float
    coverage: float
    quality_flag: int
    """The worst of the ``*_flag`` fields (:func:`wind_comp.flux_quality.worst_flag`)."""
    wave_band_low_hz: float
    wave_band_high_hz: float
    """The window's wave band, Hz, from its platform vertical velocity
    (:mod:`wind_comp.wave_motion_left`)."""
    motion_left_coherence: float
    """Mean coherence of the corrected w with the platform vertical velocity over the band."""
    motion_left_coherence_threshold: float
    """The coherence unrelated series would not exceed, above which the share counts."""
    motion_left_share: float
    """Share of the platform vertical velocity left in the corrected w over the band."""
    motion_left_flag: int
    """QARTOD flag of the "motion left" test (a test of
    :data:`wind_comp.flux_quality.FLUX_FLAG_TESTS`, published with its figures)."""


@dataclass(frozen=True)
class _FluxTestFlags:
    """The last fields of a :class:`FluxProduct`: with ``motion_left_flag``, one per test of
    :data:`wind_comp.flux_quality.FLUX_FLAG_TESTS`, in its order."""

    coverage_flag: int
    spikes_flag: int
    stationarity_flag: int
    itc_flag: int
    drag_coefficient_flag: int
    cross_wind_stress_flag: int
    buoyancy_flux_flag: int


# A dataclass takes its bases' fields in reverse order of its MRO: these bases, listed last to
# first, give the published order: the window's figures, the values the flux tests judge
# (FluxDiagnostics, declared once in wind_comp.flux_quality), the tests' flags.
@dataclass(frozen=True)
class FluxProduct(_FluxTestFlags, FluxDiagnostics, _FluxWindowFigures):
    """Fluxes and quality control of one window (:class:`wind_comp.fluxes.FluxWindow`, with the
    window's bookkeeping): the fields of its figures, then those of
    :class:`~wind_comp.flux_quality.FluxDiagnostics`, then the tests' flags, the order of the
    published messages, CSV columns and NetCDF variables."""


class FluxAverager:
    """The flux products of one window length, from the corrected wind (ENU, m/s) and the sonic
    temperature (°C), as they come."""

    def __init__(
        self,
        window_s: float = DEFAULT_FLUX_WINDOW_S,
        plane: PlanarFit | None = None,
        pressure_pa: float = STANDARD_PRESSURE_PA,
        despike: bool = False,
        motion_left_thresholds: MotionLeftThresholds = DEFAULT_THRESHOLDS,
        quality_limits: FluxQualityLimits = DEFAULT_QUALITY_LIMITS,
    ):
        """Args:
        window_s: window length, s.
        plane: the planar fit to rotate with (Wilczak et al. 2001); None: double rotation.
        pressure_pa: air pressure for the air density of the stress, Pa.
        despike: take the Vickers–Mahrt spikes each window counts out of its fluxes
            (:func:`wind_comp.fluxes.window_fluxes`); False: count them only.
        motion_left_thresholds: where the "motion left" test turns suspect and fail.
        quality_limits: the thresholds of the flux tests (:mod:`wind_comp.flux_quality`).
        """
        if not (math.isfinite(window_s) and window_s > 0):
            raise FluxError(f"flux window_s must be positive, got {window_s}")
        self.window_s = float(window_s)
        self.plane = plane
        self.pressure_pa = float(pressure_pa)
        self.despike = bool(despike)
        self.motion_left_thresholds = motion_left_thresholds
        self.quality_limits = quality_limits
        self.n_rejected_stamps = 0
        self._stamps: list[float] = []
        self._winds: list[np.ndarray] = []
        self._platform_up_mps: list[float] = []
        self._temperature_stamps: list[float] = []
        self._temperatures: list[float] = []
        self._latest_wind_s = -math.inf
        self._latest_temperature_s = -math.inf
        self._interval_stamps = np.empty(0)

    def add_batch(self, t_s, winds_enu_mps, platform_up_velocity_mps=None) -> list[FluxProduct]:
        """(N,) stamps (s) and (N, 3) corrected winds (ENU m/s, NaN when invalid), in output
        order, with the (N,) platform vertical velocity (ENU up, m/s) each was corrected with
        (None: not known, the "motion left" test is not evaluated); returns the windows they
        close."""
        stamps = np.asarray(t_s, dtype=float)
        winds = np.asarray(winds_enu_mps, dtype=float).reshape(-1, 3)
        platform = (
            np.full(stamps.shape, np.nan)
            if platform_up_velocity_mps is None
            else np.asarray(platform_up_velocity_mps, dtype=float)
        )
        closed = []
        for t, wind, up in zip(stamps.tolist(), winds, platform.tolist(), strict=True):
            if not (math.isfinite(t) and t > self._latest_wind_s):
                self.n_rejected_stamps += 1
                continue
            closed += self._close_windows_before(t)
            self._latest_wind_s = t
            self._stamps.append(t)
            self._winds.append(wind)
            self._platform_up_mps.append(up)
        return closed

    def add_temperature(self, t_s: float, temperature_degc: float) -> list[FluxProduct]:
        """One sonic temperature (stamp s, °C; ignored unless later than the previous one);
        returns the windows it lets close."""
        if not (math.isfinite(t_s) and t_s > self._latest_temperature_s):
            return []
        self._latest_temperature_s = t_s
        self._temperature_stamps.append(t_s)
        self._temperatures.append(float(temperature_degc))
        return self._close_windows_before(self._latest_wind_s)

    def flush(self) -> list[FluxProduct]:
        """End of the data: the open windows close, partial as they are."""
        closed = []
        while self._stamps:
            closed.append(self._close(self._window_start(self._stamps[0])))
        return closed

    def _window_start(self, t_s: float) -> float:
        return math.floor(t_s / self.window_s) * self.window_s

    def _close_windows_before(self, wind_t_s: float) -> list[FluxProduct]:
        """Close the open windows the wind at ``wind_t_s`` (s) is past, unless a temperature
        is awaited."""
        closed = []
        while self._stamps:
            start = self._window_start(self._stamps[0])
            end = start + self.window_s
            if wind_t_s < end:
                break
            temperatures = self._temperature_stamps
            awaiting_temperature = (
                bisect.bisect_left(temperatures, start) < bisect.bisect_left(temperatures, end)
                and self._latest_temperature_s < end
                and wind_t_s < end + TEMPERATURE_WAIT_S
            )
            if awaiting_temperature:
                break
            closed.append(self._close(start))
        return closed

    def _close(self, start: float) -> FluxProduct:
        end = start + self.window_s
        count = bisect.bisect_left(self._stamps, end)
        stamps = np.array(self._stamps[:count])
        winds = np.array(self._winds[:count])
        platform_up_mps = np.array(self._platform_up_mps[:count])
        del self._stamps[:count], self._winds[:count], self._platform_up_mps[:count]
        temperature_stamps = np.array(self._temperature_stamps)
        temperatures = np.array(self._temperatures)
        keep = temperature_stamps >= end
        self._temperature_stamps = temperature_stamps[keep].tolist()
        self._temperatures = temperatures[keep].tolist()

        recent = np.concatenate((self._interval_stamps, stamps))[-(RATE_MEMORY_INTERVALS + 1) :]
        self._interval_stamps = recent
        intervals = np.diff(recent)
        interval_s = (
            float(np.median(intervals)) if intervals.size >= MIN_RATE_INTERVALS else math.nan
        )
        paired = _paired_temperatures(
            stamps, temperature_stamps[~keep], temperatures[~keep], interval_s
        )
        valid = np.all(np.isfinite(winds), axis=1)
        n_valid = int(np.count_nonzero(valid))
        n_temperature = int(np.count_nonzero(np.isfinite(paired)))
        fluxes = window_fluxes(
            stamps,
            winds,
            paired if n_temperature else None,
            window_start_s=start,
            window_end_s=end,
            plane=self.plane,
            pressure_pa=self.pressure_pa,
            despike=self.despike,
        )
        coverage = window_coverage(n_valid, interval_s, self.window_s)
        motion_left = wave_motion_left(
            stamps, winds[:, 2], platform_up_mps, interval_s, self.motion_left_thresholds
        )
        diagnostics = flux_diagnostics(fluxes, self.quality_limits)
        flags = flux_flags(
            FluxEvidence(fluxes, diagnostics, coverage, n_valid, motion_left), self.quality_limits
        )
        return FluxProduct(
            window_s=self.window_s,
            window_start_s=start,
            window_end_s=end,
            first_sample_s=float(stamps[0]),
            last_sample_s=float(stamps[-1]),
            n_valid=n_valid,
            n_invalid=int(stamps.size - n_valid),
            n_temperature=n_temperature,
            mean_speed_mps=fluxes.mean_speed_mps,
            tilt_deg=fluxes.tilt_deg,
            u_w_m2_s2=fluxes.u_w_m2_s2,
            v_w_m2_s2=fluxes.v_w_m2_s2,
            friction_velocity_mps=fluxes.friction_velocity_mps,
            stress_n_m2=fluxes.stress_n_m2,
            air_density_kg_m3=fluxes.air_density_kg_m3,
            w_ts_k_mps=fluxes.w_ts_k_mps,
            spikes_u=fluxes.spikes[0],
            spikes_v=fluxes.spikes[1],
            spikes_w=fluxes.spikes[2],
            spikes_ts=fluxes.spikes[3],
            invalid_share=fluxes.invalid_share,
            stationarity_u_w_percent=fluxes.stationarity_u_w_percent,
            stationarity_w_ts_percent=fluxes.stationarity_w_ts_percent,
            coverage=coverage,
            quality_flag=int(worst_flag(flags.values())),
            wave_band_low_hz=motion_left.band_low_hz,
            wave_band_high_hz=motion_left.band_high_hz,
            motion_left_coherence=motion_left.coherence,
            motion_left_coherence_threshold=motion_left.coherence_threshold,
            motion_left_share=motion_left.share,
            **dataclasses.asdict(diagnostics),
            **{name: int(flag) for name, flag in flags.items()},
        )


def _paired_temperatures(
    wind_stamps_s: np.ndarray, stamps_s: np.ndarray, temperatures_degc: np.ndarray, interval_s
) -> np.ndarray:
    """For each wind stamp (s), the temperature (°C) stamped nearest to it within half the
    sampling interval ``interval_s`` (s; 1 ms when unknown), NaN where there is none."""
    paired = np.full(wind_stamps_s.shape, np.nan)
    if not stamps_s.size:
        return paired
    tolerance_s = 0.5 * interval_s if math.isfinite(interval_s) else 1e-3
    right = np.clip(np.searchsorted(stamps_s, wind_stamps_s), 1, stamps_s.size - 1)
    left = right - 1
    if stamps_s.size == 1:
        left = right = np.zeros_like(right)
    nearest = np.where(
        np.abs(stamps_s[left] - wind_stamps_s) <= np.abs(stamps_s[right] - wind_stamps_s),
        left,
        right,
    )
    close = np.abs(stamps_s[nearest] - wind_stamps_s) <= tolerance_s
    paired[close] = temperatures_degc[nearest[close]]
    return paired
