"""Eddy-covariance fluxes of the motion-corrected wind, per averaging window.

For each window (:mod:`wind_comp.flux_products` aligns them to multiples of their length in
sensor time, like the wind products):

1. Rotation into the mean wind. Double rotation (Kaimal and Finnigan 1994): a yaw about the
   vertical so that the mean cross-wind v̄ = 0, then a tilt about the new cross-wind axis so
   that the mean vertical w̄ = 0; the tilt is reported. Planar fit (Wilczak et al. 2001) as an
   option: the tilt comes from the plane fitted to the mean winds of many windows
   (:func:`fit_plane`), each window then only yawed into its mean wind, so w̄ keeps what the
   plane does not explain.
2. Linear detrending of each rotated component and of the sonic temperature (least squares on
   the valid samples).
3. Covariances: along-wind u'w' and cross-wind v'w' momentum flux (m²/s²), friction velocity
   u* = (u'w'² + v'w'²)^¼ (m/s), stress τ = ρ·u*² (N/m²), buoyancy flux w'Ts' (K·m/s) when a
   sonic temperature is given.
4. Quality control: Vickers and Mahrt (1997) spike counts per component (samples further than
   3.5 σ of a moving 5-min window, in runs of at most 3, the threshold raised by 0.1 on each
   pass until no new spike is found; with ``despike``, the same spikes are taken out of the
   window before steps 1–3), the share of invalid samples, the Foken and Wichura (1996)
   stationarity (the relative difference, %, between the mean covariance of the window's 5-min
   sub-windows and the covariance of the window; < 30 % is stationary; NaN for a window shorter
   than two sub-windows), the standard deviations of w and Ts, and the tilt of the rotation.
   The tests that judge these are :mod:`wind_comp.flux_quality`'s.

Air density for the stress: ρ = p / (R_d·T_v), with the sonic temperature taken as the virtual
temperature (they differ by ~0.1 K, a sonic measures T(1 + 0.51 q) to within its crosswind
correction) and p the ``pressure_pa`` given (default the standard atmosphere, 101 325 Pa: a
±30 hPa weather system changes ρ by 3 %); without a temperature, 15 °C.

Inputs are wind vectors in any right-handed frame with z up (``wind/true`` is ENU); NaN marks an
invalid sample.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

DRY_AIR_GAS_CONSTANT_J_KG_K = 287.05
STANDARD_PRESSURE_PA = 101_325.0
STANDARD_TEMPERATURE_DEGC = 15.0
STATIONARITY_SUBWINDOW_S = 300.0
"""Foken and Wichura (1996): the sub-windows of the steady-state test last 5 min."""
MIN_WINDOW_SAMPLES = 12
"""Fewer valid samples give no fluxes."""


class FluxError(ValueError):
    """An unusable flux configuration; the message names it."""


@dataclass(frozen=True)
class SpikeTest:
    """Vickers and Mahrt (1997) spike detection."""

    window_s: float = 300.0
    threshold_sigma: float = 3.5
    threshold_step_sigma: float = 0.1
    max_run_samples: int = 3
    max_passes: int = 20


@dataclass(frozen=True)
class PlanarFit:
    """A plane fitted to the mean winds of many windows: w̄ = offset + b_u·ū + b_v·v̄."""

    offset_mps: float
    slope_u: float
    slope_v: float

    @property
    def normal(self) -> np.ndarray:
        """Unit normal of the plane (the mean streamline's vertical), z > 0."""
        normal = np.array([-self.slope_u, -self.slope_v, 1.0])
        return normal / np.linalg.norm(normal)

    @property
    def tilt_deg(self) -> float:
        return math.degrees(math.acos(self.normal[2]))


@dataclass(frozen=True)
class FluxWindow:
    """Fluxes and quality control of one averaging window."""

    window_start_s: float
    window_end_s: float
    samples: int
    invalid_share: float
    """Share of the window's samples that are invalid (NaN in any wind component)."""
    mean_speed_mps: float
    """Mean wind speed along the rotated x axis."""
    tilt_deg: float
    """Tilt of the rotation: of the mean wind (double rotation) or of the plane (planar fit)."""
    u_w_m2_s2: float
    v_w_m2_s2: float
    friction_velocity_mps: float
    stress_n_m2: float
    air_density_kg_m3: float
    w_ts_k_mps: float
    """Buoyancy flux w'Ts'; NaN without a sonic temperature."""
    spikes: tuple[int, int, int, int]
    """Vickers–Mahrt spikes in u, v, w, Ts (Ts: 0 without a temperature)."""
    stationarity_u_w_percent: float
    stationarity_w_ts_percent: float
    sigma_w_mps: float
    """Standard deviation of the detrended vertical wind (frame of the mean wind)."""
    sigma_ts_k: float
    """Standard deviation of the detrended sonic temperature; NaN without one."""
    mean_sonic_temperature_degc: float
    """NaN without a sonic temperature."""


def rotation_into_mean_wind(mean_wind_mps) -> tuple[np.ndarray, float]:
    """Double rotation: the 3×3 matrix taking vectors into the frame whose x axis is the mean
    wind ``mean_wind_mps`` (any right-handed frame, z up, m/s), and its tilt (rad, positive for
    a rising mean wind)."""
    u, v, w = (float(c) for c in mean_wind_mps)
    yaw = math.atan2(v, u)
    tilt = math.atan2(w, math.hypot(u, v))
    cos_yaw, sin_yaw = math.cos(yaw), math.sin(yaw)
    cos_tilt, sin_tilt = math.cos(tilt), math.sin(tilt)
    yawed = np.array([[cos_yaw, sin_yaw, 0.0], [-sin_yaw, cos_yaw, 0.0], [0.0, 0.0, 1.0]])
    tilted = np.array([[cos_tilt, 0.0, sin_tilt], [0.0, 1.0, 0.0], [-sin_tilt, 0.0, cos_tilt]])
    return tilted @ yawed, tilt


def fit_plane(mean_winds_mps) -> PlanarFit:
    """Least-squares plane w̄ = b0 + b1·ū + b2·v̄ through the (M, 3) mean winds of M windows
    (Wilczak et al. 2001); needs windows of several wind directions (FluxError otherwise)."""
    means = np.asarray(mean_winds_mps, dtype=float).reshape(-1, 3)
    means = means[np.all(np.isfinite(means), axis=1)]
    design = np.column_stack([np.ones(len(means)), means[:, 0], means[:, 1]])
    if len(means) < 3 or np.linalg.matrix_rank(design) < 3:
        raise FluxError("planar fit needs at least three windows of different wind directions")
    (offset, slope_u, slope_v), *_ = np.linalg.lstsq(design, means[:, 2], rcond=None)
    return PlanarFit(float(offset), float(slope_u), float(slope_v))


def rotation_into_plane(plane: PlanarFit) -> np.ndarray:
    """3×3 matrix taking vectors into a frame whose z axis is the plane's normal (the rotation
    about the axis normal × z, no yaw)."""
    normal = plane.normal
    axis = np.cross(normal, [0.0, 0.0, 1.0])
    sine = np.linalg.norm(axis)
    if sine < 1e-12:
        return np.eye(3)
    axis /= sine
    cosine = normal[2]
    cross = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
    return np.eye(3) + sine * cross + (1 - cosine) * cross @ cross


def linear_detrend(time_s, values) -> np.ndarray:
    """``values`` minus their least-squares line in time; NaN stays NaN (the line is fitted to
    the finite samples)."""
    values = np.asarray(values, dtype=float)
    valid = np.isfinite(values)
    if valid.sum() < 2:
        return np.full_like(values, np.nan)
    t = np.asarray(time_s, dtype=float)
    t0 = t[valid].mean()
    slope, intercept = np.polyfit(t[valid] - t0, values[valid], 1)
    return values - (intercept + slope * (t - t0))


def _runs(mask: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Start indices and lengths of the runs of True in ``mask``."""
    edges = np.diff(np.concatenate([[0], mask.astype(np.int8), [0]]))
    starts = np.flatnonzero(edges == 1)
    return starts, np.flatnonzero(edges == -1) - starts


def vickers_mahrt_spikes(values, rate_hz: float, test: SpikeTest = SpikeTest()) -> np.ndarray:
    """Boolean mask of the Vickers–Mahrt spikes of a series sampled at ``rate_hz``: samples
    beyond ``threshold_sigma`` of the moving mean, in runs of at most ``max_run_samples``
    (longer runs may be real and are kept); repeated, with the spikes removed and the threshold
    raised by ``threshold_step_sigma``, until a pass finds none."""
    # Imported here: scipy.ndimage adds almost half a second to every start-up otherwise.
    from scipy.ndimage import uniform_filter1d

    values = np.asarray(values, dtype=float)
    spikes = np.zeros(values.size, dtype=bool)
    width = max(3, round(test.window_s * rate_hz) | 1)
    threshold = test.threshold_sigma
    for _ in range(test.max_passes):
        valid = np.isfinite(values) & ~spikes
        if valid.sum() < 3:
            break
        weight = uniform_filter1d(valid.astype(float), width, mode="constant")
        x = np.where(valid, values, 0.0)
        mean = uniform_filter1d(x, width, mode="constant") / np.maximum(weight, 1e-12)
        square = uniform_filter1d(x * x, width, mode="constant") / np.maximum(weight, 1e-12)
        sigma = np.sqrt(np.maximum(square - mean * mean, 0.0))
        outside = valid & (np.abs(values - mean) > threshold * sigma)
        starts, lengths = _runs(outside)
        new = np.zeros_like(spikes)
        for start, length in zip(starts, lengths, strict=True):
            if length <= test.max_run_samples:
                new[start : start + length] = True
        if not new.any():
            break
        spikes |= new
        threshold += test.threshold_step_sigma
    return spikes


def _covariance(a: np.ndarray, b: np.ndarray) -> float:
    valid = np.isfinite(a) & np.isfinite(b)
    if valid.sum() < 2:
        return math.nan
    return float(np.mean((a[valid] - a[valid].mean()) * (b[valid] - b[valid].mean())))


def stationarity_percent(time_s, a, b, start_s: float, end_s: float) -> float:
    """Foken–Wichura non-stationarity of the covariance of ``a`` and ``b`` sampled at
    ``time_s`` (s) over the window [``start_s``, ``end_s``): |mean of the covariances of its
    sub-windows of about :data:`STATIONARITY_SUBWINDOW_S` − the whole window's| / |the whole
    window's|, %; NaN for a window shorter than two sub-windows."""
    t = np.asarray(time_s, dtype=float)
    a, b = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
    subwindows = round((end_s - start_s) / STATIONARITY_SUBWINDOW_S)
    whole = _covariance(a, b)
    if subwindows < 2 or not math.isfinite(whole) or whole == 0.0:
        return math.nan
    index = np.clip(((t - start_s) * subwindows / (end_s - start_s)).astype(int), 0, subwindows - 1)
    parts = [_covariance(a[index == k], b[index == k]) for k in range(subwindows)]
    if not np.isfinite(parts).all():
        return math.nan
    return 100.0 * abs(float(np.mean(parts)) - whole) / abs(whole)


def air_density_kg_m3(temperature_degc: float, pressure_pa: float = STANDARD_PRESSURE_PA) -> float:
    """Density of air of virtual temperature ``temperature_degc`` at ``pressure_pa`` (ideal
    gas, dry-air constant)."""
    if not math.isfinite(temperature_degc):
        temperature_degc = STANDARD_TEMPERATURE_DEGC
    return pressure_pa / (DRY_AIR_GAS_CONSTANT_J_KG_K * (temperature_degc + 273.15))


def window_fluxes(
    time_s,
    wind_mps,
    sonic_temperature_degc=None,
    *,
    window_start_s: float | None = None,
    window_end_s: float | None = None,
    plane: PlanarFit | None = None,
    pressure_pa: float = STANDARD_PRESSURE_PA,
    spike_test: SpikeTest = SpikeTest(),
    despike: bool = False,
) -> FluxWindow:
    """Fluxes and QC of the samples given as one window (stamps s, (N, 3) wind m/s, optional
    sonic temperature °C). The window's bounds default to its first and last stamp.

    ``despike``: the Vickers–Mahrt spikes counted in ``spikes`` are taken out (NaN in their own
    component: u, v, w of the rotated wind, Ts) before the rotation (taken again without the
    samples that carry a spike), the detrending and the covariances. Off, they are only
    counted."""
    t = np.asarray(time_s, dtype=float)
    wind = np.asarray(wind_mps, dtype=float).reshape(-1, 3)
    temperature = None
    if sonic_temperature_degc is not None:
        temperature = np.asarray(sonic_temperature_degc, dtype=float)
    valid = np.all(np.isfinite(wind), axis=1)
    count = t.size
    rate_hz = 1.0 / float(np.median(np.diff(t))) if count > 1 else math.nan
    start = float(t[0]) if window_start_s is None and count else window_start_s
    end = float(t[-1]) if window_end_s is None and count else window_end_s
    nan = math.nan
    if valid.sum() < MIN_WINDOW_SAMPLES:
        return FluxWindow(
            start, end, count, 1.0 - valid.mean() if count else 1.0, nan, nan, nan, nan, nan,
            nan, nan, nan, (0, 0, 0, 0), nan, nan, nan, nan, nan,
        )  # fmt: skip
    rotated, tilt_deg = _rotated(wind, valid, plane)
    series = [rotated[:, 0], rotated[:, 1], rotated[:, 2]]
    if temperature is not None:
        series.append(temperature)
    spike_masks = [vickers_mahrt_spikes(x, rate_hz, spike_test) for x in series]
    if despike:
        # The spikes were found in the frame of the mean wind with them in it; the rotation
        # is taken again without the samples that carry one, and each spike is then NaN in
        # its own component (its sample still counts in the others).
        wind_spike = np.any(spike_masks[:3], axis=0)
        rotated, tilt_deg = _rotated(wind, valid & ~wind_spike, plane)
        rotated[np.column_stack(spike_masks[:3])] = np.nan
        if temperature is not None:
            temperature = np.where(spike_masks[3], np.nan, temperature)
    u, v, w = (linear_detrend(t, rotated[:, axis]) for axis in range(3))
    w_ts = stationarity_w_ts = sigma_ts = nan
    mean_temperature = nan
    if temperature is not None:
        mean_temperature = float(np.nanmean(temperature))
        temperature_detrended = linear_detrend(t, temperature)
        w_ts = _covariance(w, temperature_detrended)
        sigma_ts = math.sqrt(_covariance(temperature_detrended, temperature_detrended))
        stationarity_w_ts = stationarity_percent(t, rotated[:, 2], temperature, start, end)
    spikes = tuple(int(mask.sum()) for mask in spike_masks)
    u_w, v_w = _covariance(u, w), _covariance(v, w)
    along = rotated[valid, 0]
    friction_velocity = (u_w * u_w + v_w * v_w) ** 0.25
    density = air_density_kg_m3(mean_temperature, pressure_pa)
    return FluxWindow(
        window_start_s=start,
        window_end_s=end,
        samples=count,
        invalid_share=float(1.0 - valid.mean()),
        mean_speed_mps=float(np.mean(along[np.isfinite(along)])),
        tilt_deg=tilt_deg,
        u_w_m2_s2=u_w,
        v_w_m2_s2=v_w,
        friction_velocity_mps=friction_velocity,
        stress_n_m2=density * friction_velocity**2,
        air_density_kg_m3=density,
        w_ts_k_mps=w_ts,
        spikes=(*spikes, 0) if len(spikes) == 3 else spikes,
        stationarity_u_w_percent=stationarity_percent(t, rotated[:, 0], rotated[:, 2], start, end),
        stationarity_w_ts_percent=stationarity_w_ts,
        sigma_w_mps=math.sqrt(_covariance(w, w)),
        sigma_ts_k=sigma_ts,
        mean_sonic_temperature_degc=mean_temperature,
    )


def _rotated(wind: np.ndarray, used: np.ndarray, plane: PlanarFit | None):
    """(N, 3) ``wind`` (m/s) in the frame of the mean wind of the ``used`` samples (double
    rotation, or the ``plane`` and a yaw), and the tilt of the rotation (deg)."""
    if plane is None:
        rotation, tilt = rotation_into_mean_wind(wind[used].mean(axis=0))
        return wind @ rotation.T, math.degrees(tilt)
    levelled = (wind - [0.0, 0.0, plane.offset_mps]) @ rotation_into_plane(plane).T
    rotation, _ = rotation_into_mean_wind(levelled[used].mean(axis=0) * [1.0, 1.0, 0.0])
    return levelled @ rotation.T, plane.tilt_deg
