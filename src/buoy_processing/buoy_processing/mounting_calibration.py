"""The anemometer's mounting angles from recorded data, in the manner of Brooks (2008).

A sonic on a buoy mast cannot be levelled and aimed to 0.1° by hand, and a tilt or yaw of its
axes biases the corrected wind. Two facts of the air over a uniform sea surface fix the
mounting instead (Brooks 2008, J. Atmos. Oceanic Technol. 25, for ship-mounted sonics):

- the mean vertical wind is zero; a tilt of the sonic turns part of the horizontal relative
  wind into vertical, and as the buoy turns on its mooring, the relative wind comes from
  different directions of the sonic's axes, which separates roll from pitch;
- the corrected wind does not follow the platform's motion; a mounting error leaves a part of
  the relative air velocity induced by the waves (the swing of the mast, the buoy's drift and
  heave) in the corrected wind. That part is what observes the yaw, which the mean wind alone
  cannot: a yawed sonic turns the mean wind, which is unknown, but it also turns the wave-
  induced velocity, which is known.

The correction is linear in the mounting rotation R_bw: W = R_nb·(R_bw·u + ω×B) + V, so the
corrected wind of another mounting is W + R_nb·(R_new − R_bw)·u, exactly. The small rotation δ
(rotation vector in the sonic's axes) with R_new = R_bw·exp(δ) is found by Gauss-Newton least
squares of

    vertical:    W_up(δ) = 0                             (every sample)
    horizontal:  W_east,north(δ) = mean of its window    (the window means are nuisance
                                                           parameters: the unknown wind)

over samples the compensation corrected. Turbulence is the noise; it is correlated over
seconds, so the uncertainty is a cluster-robust (sandwich) covariance with each averaging
window a cluster, not the textbook one that would assume independent samples. The angles are
refused when that uncertainty exceeds what was asked for, with the reason: too little data,
too little motion, too few relative wind directions, too turbulent a wind.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from scipy.spatial.transform import Rotation

MIN_DURATION_S = 120.0
"""Shortest record worth fitting: a few wave groups and averaging windows."""
DEFAULT_WINDOW_S = 30.0
"""Averaging window of the horizontal nuisance means, s: long against wave periods (≤ 15 s), so
the wave-induced signal stays in the fit, short against the drift of the mean wind."""
DEFAULT_MAX_UNCERTAINTY_DEG = 0.1
"""Largest 1σ of any angle for the angles to be given (2σ = 0.2°, the accuracy a sonic's
mounting should have for 1 % of the wind speed in the vertical)."""
ITERATIONS = 5
RANK_TOLERANCE = 1e-10
CONVERGED_RAD = 1e-9


class CalibrationError(ValueError):
    """The data cannot determine the mounting angles; the message says why."""


class MountingEstimate(NamedTuple):
    """The mounting found and how well the data determine it."""

    rpy_deg: tuple[float, float, float]
    """Roll, pitch, yaw of ``anemometer_link`` in ``base_link``, deg, R = Rz(yaw)·Ry(pitch)·Rx(roll)
    (parameter ``anemometer.rpy_deg``)."""
    sigma_rpy_deg: tuple[float, float, float]
    """1σ of each angle, deg (cluster-robust: turbulence correlated within a window)."""
    change_deg: tuple[float, float, float]
    """The rotation applied to the mounting the data were corrected with, as a rotation vector in
    the sonic's axes, deg."""
    samples: int
    windows: int
    mean_vertical_before_mps: float
    """Mean vertical corrected wind with the original mounting, m/s."""
    mean_vertical_after_mps: float
    """The same with the estimated mounting, m/s."""


def _skew_rows(vectors: np.ndarray) -> np.ndarray:
    """(N, 3, 3) cross-product matrices [v]× of (N, 3) vectors."""
    x, y, z = vectors.T
    zero = np.zeros_like(x)
    return np.stack(
        [np.stack([zero, -z, y], -1), np.stack([z, zero, -x], -1), np.stack([-y, x, zero], -1)],
        axis=1,
    )


def _rpy_deg(rotation: Rotation) -> np.ndarray:
    yaw, pitch, roll = rotation.as_euler("ZYX", degrees=True)
    return np.array([roll, pitch, yaw])


def estimate_mounting(
    t_s: np.ndarray,
    corrected_enu_mps: np.ndarray,
    measured_sensor_mps: np.ndarray,
    attitude_xyzw: np.ndarray,
    mounting_rpy_deg,
    window_s: float = DEFAULT_WINDOW_S,
    max_uncertainty_deg: float = DEFAULT_MAX_UNCERTAINTY_DEG,
) -> MountingEstimate:
    """The anemometer mounting that makes the mean vertical wind zero and the corrected wind
    free of the platform's motion.

    Args:
        t_s: (N,) sample stamps, s (any origin).
        corrected_enu_mps: (N, 3) the corrected wind (``wind/true``), ENU, m/s; NaN rows skipped.
        measured_sensor_mps: (N, 3) the measured wind (``anemometer/wind``), sonic axes, m/s.
        attitude_xyzw: (N, 4) body→ENU attitude at each sample.
        mounting_rpy_deg: the mounting the corrected wind was computed with (roll, pitch, yaw,
            deg, parameter ``anemometer.rpy_deg``).
        window_s: averaging window of the horizontal mean wind, s.
        max_uncertainty_deg: largest 1σ of any angle accepted, deg.

    Raises CalibrationError, naming the reason, when the data cannot determine the angles.
    """
    t_s = np.asarray(t_s, dtype=float)
    usable = np.isfinite(corrected_enu_mps).all(1) & np.isfinite(measured_sensor_mps).all(1)
    usable &= np.isfinite(attitude_xyzw).all(1)
    t_s, corrected = t_s[usable], np.asarray(corrected_enu_mps, dtype=float)[usable]
    measured = np.asarray(measured_sensor_mps, dtype=float)[usable]
    attitude = Rotation.from_quat(np.asarray(attitude_xyzw, dtype=float)[usable]).as_matrix()
    duration_s = float(t_s[-1] - t_s[0]) if t_s.size else 0.0
    if duration_s < MIN_DURATION_S:
        raise CalibrationError(
            f"{duration_s:.0f} s of corrected wind; the mounting needs at least "
            f"{MIN_DURATION_S:.0f} s (better 30 min or more, with the buoy moving)"
        )
    window_index = ((t_s - t_s[0]) // window_s).astype(int)
    _, window_index = np.unique(window_index, return_inverse=True)
    windows = int(window_index.max()) + 1
    nominal = Rotation.from_euler("ZYX", np.asarray(mounting_rpy_deg, dtype=float)[::-1], True)
    delta = np.zeros(3)
    for _ in range(ITERATIONS):
        mounting = nominal * Rotation.from_rotvec(delta)
        design, residual = _linear_system(
            attitude, measured, corrected, nominal, mounting, window_index, windows
        )
        step, *_ = np.linalg.lstsq(design, -residual, rcond=RANK_TOLERANCE)
        delta = delta + step
        if np.max(np.abs(step)) < CONVERGED_RAD:
            break
    mounting = nominal * Rotation.from_rotvec(delta)
    design, residual = _linear_system(
        attitude, measured, corrected, nominal, mounting, window_index, windows
    )
    rpy_sigma = np.maximum(
        _rpy_sigma_deg(
            mounting, _cluster_robust_covariance(design, residual, np.tile(window_index, 3))
        ),
        _rpy_sigma_deg(mounting, _independent_covariance(design, residual)),
    )
    final_vertical = corrected[:, 2] + _mounting_shift(attitude, measured, nominal, mounting)[:, 2]
    estimate = MountingEstimate(
        rpy_deg=tuple(float(a) for a in _rpy_deg(mounting)),
        sigma_rpy_deg=tuple(float(s) for s in rpy_sigma),
        change_deg=tuple(float(a) for a in np.degrees(delta)),
        samples=int(t_s.size),
        windows=windows,
        mean_vertical_before_mps=float(np.mean(corrected[:, 2])),
        mean_vertical_after_mps=float(np.mean(final_vertical)),
    )
    undetermined = [
        f"{name} ±{sigma:.2f}°"
        for name, sigma in zip(("roll", "pitch", "yaw"), rpy_sigma, strict=True)
        if not sigma <= max_uncertainty_deg
    ]
    if undetermined:
        raise CalibrationError(
            f"the data do not determine the mounting to {max_uncertainty_deg:g}° (1σ): "
            f"{', '.join(undetermined)} over {duration_s:.0f} s. Tilt needs the relative wind "
            "from several directions (the buoy turning on its mooring) and yaw needs wave "
            "motion; both need a steadier wind or a longer record (uncertainty falls as "
            "1/sqrt(duration))"
        )
    return estimate


def _mounting_shift(attitude, measured, nominal: Rotation, mounting: Rotation) -> np.ndarray:
    """(N, 3) what the corrected wind gains, ENU, m/s, when the mounting ``nominal`` it was
    computed with becomes ``mounting``: R_nb·(R_new − R_old)·u, exactly (the correction is
    linear in the mounting)."""
    change = mounting.as_matrix() - nominal.as_matrix()
    return np.einsum("nij,jk,nk->ni", attitude, change, measured)


def _window_demeaned(values: np.ndarray, window_index: np.ndarray, windows: int) -> np.ndarray:
    """``values`` (N, ...) less the mean of its window: the window means eliminated as
    nuisance parameters (Frisch-Waugh), without a column per window."""
    flat = values.reshape(values.shape[0], -1)
    sums = np.zeros((windows, flat.shape[1]))
    np.add.at(sums, window_index, flat)
    counts = np.bincount(window_index, minlength=windows)[:, None]
    return (flat - (sums / counts)[window_index]).reshape(values.shape)


def _linear_system(attitude, measured, corrected, nominal, mounting, window_index, windows):
    """Design (3N, 3) and residual (3N,) of one Gauss-Newton step for δ: rows east and north
    less their window means, then up; the wind of the current ``mounting``."""
    wind = corrected + _mounting_shift(attitude, measured, nominal, mounting)
    # d W / d δ = −R_nb·R_bw·[u]×, for a rotation δ applied on the sonic's side.
    jacobian = -np.einsum("nij,jk,nkl->nil", attitude, mounting.as_matrix(), _skew_rows(measured))
    horizontal_jacobian = _window_demeaned(jacobian[:, :2, :], window_index, windows)
    horizontal_wind = _window_demeaned(wind[:, :2], window_index, windows)
    design = np.vstack(
        [horizontal_jacobian[:, 0, :], horizontal_jacobian[:, 1, :], jacobian[:, 2, :]]
    )
    residual = np.concatenate([horizontal_wind[:, 0], horizontal_wind[:, 1], wind[:, 2]])
    return design, residual


def _inverse_normal_matrix(design: np.ndarray) -> np.ndarray:
    """(DᵀD)⁻¹; infinite where a combination of the angles is not observed at all (no motion,
    one wind direction), rather than the zero a pseudo-inverse would give it."""
    normal = design.T @ design
    eigenvalues = np.linalg.eigvalsh(normal)
    if eigenvalues[0] <= RANK_TOLERANCE * eigenvalues[-1]:
        return np.full(normal.shape, np.inf)
    return np.linalg.inv(normal)


def _cluster_robust_covariance(design: np.ndarray, residual: np.ndarray, cluster: np.ndarray):
    """Covariance of the least-squares parameters with residuals correlated inside each
    cluster (the sandwich estimator)."""
    bread = _inverse_normal_matrix(design)
    if not np.isfinite(bread).all():
        return bread
    per_cluster = np.zeros((int(cluster.max()) + 1, design.shape[1]))
    np.add.at(per_cluster, cluster, design * residual[:, None])
    return bread @ (per_cluster.T @ per_cluster) @ bread


def _independent_covariance(design: np.ndarray, residual: np.ndarray):
    """Covariance of the least-squares parameters with independent residuals: the floor of the
    sandwich, whose scores vanish identically where the regressors carry only the measured
    wind itself (a rotation of the wind is orthogonal to it), with no motion to observe."""
    variance = float(residual @ residual) / max(residual.size - design.shape[1], 1)
    return variance * _inverse_normal_matrix(design)


def _rpy_sigma_deg(mounting: Rotation, delta_covariance_rad2: np.ndarray) -> np.ndarray:
    """1σ of roll, pitch, yaw (deg) from the covariance of the rotation vector δ (rad²),
    propagated through the Euler angles by numerical derivatives."""
    if not np.isfinite(delta_covariance_rad2).all():
        return np.full(3, np.inf)
    base = _rpy_deg(mounting)
    derivative = np.empty((3, 3))
    for axis in range(3):
        step = np.zeros(3)
        step[axis] = 1e-6
        derivative[:, axis] = (_rpy_deg(mounting * Rotation.from_rotvec(step)) - base) / 1e-6
    return np.sqrt(np.clip(np.diag(derivative @ delta_covariance_rad2 @ derivative.T), 0, None))
