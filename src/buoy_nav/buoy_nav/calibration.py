"""Sensor calibration (paper 004): the IMU from static positions, the magnetometer from a turn.

**IMU, six positions.** The buoy's IMU is held still in (at least) six attitudes, each axis up
and down. Still stretches are found by the spread of the gyro and the specific force; each gives
its mean specific force f_k and gyro rate ω_k. The accelerometer model is
``f_raw = s ⊙ f + b`` per axis (scale s, bias b), so a still sensor satisfies
``|(f_k − b) ⊘ s| = g``: six unknowns fitted by least squares over the positions (scipy), which
needs every axis seen both up and down. The gyro bias is the mean of the positions' rates: the
Earth's rate (15°/h) cancels between an axis up and the same axis down.

**Magnetometer, a turning buoy.** The raw field lies on an ellipsoid,
``m_raw = W⁻¹ m + h`` with |m| constant. Hard iron by the paper's min/max:
``h_i = (max_i + min_i) / 2``; then a least-squares ellipsoid (the quadric
``mᵀ A m + bᵀ m + c = 0`` fitted to all samples, singular-value decomposition) gives the centre
h = −A⁻¹ b / 2 and the soft-iron matrix W = (A / k)^½ (symmetric: a rotation of the sensor
axes leaves |m| alike and cannot be seen), scaled so the mean calibrated magnitude is the mean
raw magnitude. The residual is the spread of the calibrated magnitude. Both need the field to
sweep the sphere: headings all round and tilt enough for the vertical axis.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.linalg import sqrtm
from scipy.optimize import least_squares

STILL_WINDOW_S = 1.0
STILL_GYRO_STD_RAD_S = math.radians(0.1)
STILL_FORCE_STD_MPS2 = 0.05
MIN_STILL_S = 10.0
SAME_POSITION_DEG = 20.0
AXIS_UP_FRACTION = 0.7
"""An axis counts as up (down) in a position where it carries 70 % of gravity or more."""
HEADING_BINS = 12
MIN_VERTICAL_RANGE_FRACTION = 0.3
AXES = "xyz"


class CalibrationError(ValueError):
    """The recording cannot calibrate: the message says what is missing."""


@dataclass(frozen=True)
class ImuCalibration:
    """accel_bias_mps2, accel_scale, gyro_bias_rad_s (body, per axis); positions: the still
    positions used (mean specific force, m/s²); residual_mps2: RMS of |f| − g after the fit;
    accel_bias_sigma_mps2: the fit's 1-σ of the bias per axis."""

    accel_bias_mps2: np.ndarray
    accel_scale: np.ndarray
    gyro_bias_rad_s: np.ndarray
    positions: np.ndarray
    residual_mps2: float
    accel_bias_sigma_mps2: np.ndarray


def still_positions(t_s, gyro_rad_s, force_mps2):
    """(mean force (P, 3), mean gyro (P, 3), seconds still (P,)) of each still position, still
    stretches of the same attitude merged."""
    t = np.asarray(t_s, dtype=float)
    gyro = np.asarray(gyro_rad_s, dtype=float)
    force = np.asarray(force_mps2, dtype=float)
    if t.size < 2:
        raise CalibrationError("the recording holds fewer than two IMU samples")
    dt = float(np.median(np.diff(t)))
    window = max(3, round(STILL_WINDOW_S / dt))
    count = t.size // window
    if count == 0:
        raise CalibrationError("the recording is shorter than one still window (1 s)")
    shape = (count, window, 3)
    gyro_w = gyro[: count * window].reshape(shape)
    force_w = force[: count * window].reshape(shape)
    still = (gyro_w.std(axis=1).max(axis=1) < STILL_GYRO_STD_RAD_S) & (
        force_w.std(axis=1).max(axis=1) < STILL_FORCE_STD_MPS2
    )
    positions: list[list] = []  # [force sum, gyro sum, windows]
    for k in np.flatnonzero(still):
        mean_force = force_w[k].mean(axis=0)
        for position in positions:
            reference = position[0] / position[2]
            cosine = (
                reference @ mean_force / (np.linalg.norm(reference) * np.linalg.norm(mean_force))
            )
            if cosine > math.cos(math.radians(SAME_POSITION_DEG)):
                position[0] = position[0] + mean_force
                position[1] = position[1] + gyro_w[k].mean(axis=0)
                position[2] += 1
                break
        else:
            positions.append([mean_force, gyro_w[k].mean(axis=0), 1])
    seconds = np.array([p[2] for p in positions], dtype=float) * window * dt
    keep = seconds >= MIN_STILL_S
    forces = np.array([p[0] / p[2] for p in positions]).reshape(-1, 3)[keep]
    gyros = np.array([p[1] / p[2] for p in positions]).reshape(-1, 3)[keep]
    return forces, gyros, seconds[keep]


def missing_imu_attitudes(forces_mps2: np.ndarray, gravity_mps2: float) -> list[str]:
    """The axis directions no still position covers (``+x up`` …)."""
    missing = []
    for axis, name in enumerate(AXES):
        components = forces_mps2[:, axis] / gravity_mps2 if forces_mps2.size else np.empty(0)
        if not np.any(components >= AXIS_UP_FRACTION):
            missing.append(f"+{name} up")
        if not np.any(components <= -AXIS_UP_FRACTION):
            missing.append(f"+{name} down")
    return missing


def calibrate_imu(t_s, gyro_rad_s, force_mps2, gravity_mps2: float) -> ImuCalibration:
    """The IMU calibration from a recording of still positions (see the module docstring).

    Raises CalibrationError naming the attitudes the recording lacks."""
    forces, gyros, _ = still_positions(t_s, gyro_rad_s, force_mps2)
    missing = missing_imu_attitudes(forces, gravity_mps2)
    if missing:
        raise CalibrationError(
            f"{len(forces)} still position(s) of at least {MIN_STILL_S:g} s found; none with "
            f"{', '.join(missing)} (each axis must be held still up and down, "
            f"≥ {AXIS_UP_FRACTION:.0%} of gravity along it)"
        )

    def residuals(parameters):
        bias, scale = parameters[:3], parameters[3:]
        return np.linalg.norm((forces - bias) / scale, axis=1) - gravity_mps2

    fit = least_squares(residuals, np.concatenate([np.zeros(3), np.ones(3)]))
    residual = float(np.sqrt(np.mean(fit.fun**2)))
    dof = max(len(forces) - 6, 1)
    noise_variance = max(float(fit.fun @ fit.fun) / dof, 1e-10)
    covariance = np.linalg.pinv(fit.jac.T @ fit.jac) * noise_variance
    return ImuCalibration(
        accel_bias_mps2=fit.x[:3],
        accel_scale=fit.x[3:],
        gyro_bias_rad_s=gyros.mean(axis=0),
        positions=forces,
        residual_mps2=residual,
        accel_bias_sigma_mps2=np.sqrt(np.diag(covariance)[:3]),
    )


@dataclass(frozen=True)
class MagnetometerCalibration:
    """hard_iron_t (3,), soft_iron (3×3): calibrated = soft_iron (raw − hard_iron), T.
    min_max_hard_iron_t: the paper's min/max centre. residual_t: RMS of |calibrated| − its
    mean; min_max_residual_t: the same with the min/max centre and per-axis scales only.
    field_t: mean calibrated magnitude."""

    hard_iron_t: np.ndarray
    soft_iron: np.ndarray
    min_max_hard_iron_t: np.ndarray
    residual_t: float
    min_max_residual_t: float
    field_t: float


def missing_magnetometer_coverage(field_t: np.ndarray, centre_t: np.ndarray) -> list[str]:
    """What a turn lacks for the fit: field azimuths (about ``centre_t``, body x-y plane)
    never seen, too little tilt."""
    centred = field_t - centre_t
    magnitude = float(np.mean(np.linalg.norm(centred, axis=1)))
    azimuth = np.degrees(np.arctan2(centred[:, 1], centred[:, 0])) % 360.0
    width = 360.0 / HEADING_BINS
    seen = np.unique((azimuth // width).astype(int))
    missing = []
    unseen = sorted(set(range(HEADING_BINS)) - set(seen.tolist()))
    if unseen:
        sectors = ", ".join(f"{b * width:.0f}–{(b + 1) * width:.0f}°" for b in unseen)
        missing.append(
            f"field azimuths in the body x-y plane never seen: {sectors} "
            "(turn the buoy through a full circle)"
        )
    vertical_range = float(np.ptp(centred[:, 2]))
    if vertical_range < MIN_VERTICAL_RANGE_FRACTION * magnitude:
        missing.append(
            f"the z axis saw a range of {vertical_range * 1e6:.1f} µT, under "
            f"{MIN_VERTICAL_RANGE_FRACTION:.0%} of the field ({magnitude * 1e6:.1f} µT): tilt "
            "the buoy more while it turns"
        )
    return missing


def calibrate_magnetometer(field_t) -> MagnetometerCalibration:
    """Hard and soft iron from a turning recording (see the module docstring).

    Raises CalibrationError naming what the turn lacks."""
    field = np.asarray(field_t, dtype=float)
    field = field[np.all(np.isfinite(field), axis=1)]
    if len(field) < 50:
        raise CalibrationError(f"{len(field)} finite magnetometer samples: at least 50 needed")
    low, high = field.min(axis=0), field.max(axis=0)
    min_max_centre = 0.5 * (high + low)
    half_ranges = 0.5 * (high - low)
    min_max = (field - min_max_centre) / half_ranges * half_ranges.mean()
    min_max_magnitude = np.linalg.norm(min_max, axis=1)

    # Quadric x'Ax + b'x + c = 0 in scaled coordinates (conditioning), least squares by SVD.
    scale = float(np.mean(np.abs(field - min_max_centre)))
    x, y, z = ((field - min_max_centre) / scale).T
    design = np.column_stack(
        [x * x, y * y, z * z, 2 * x * y, 2 * x * z, 2 * y * z, x, y, z, np.ones_like(x)]
    )
    _, _, vt = np.linalg.svd(design, full_matrices=False)
    a_xx, a_yy, a_zz, a_xy, a_xz, a_yz, b_x, b_y, b_z, c = vt[-1]
    quadric = np.array([[a_xx, a_xy, a_xz], [a_xy, a_yy, a_yz], [a_xz, a_yz, a_zz]])
    linear = np.array([b_x, b_y, b_z])
    if np.linalg.det(quadric) < 0:
        quadric, linear, c = -quadric, -linear, -c
    centre_scaled = -0.5 * np.linalg.solve(quadric, linear)
    k = float(centre_scaled @ quadric @ centre_scaled - c)
    if not (k > 0 and np.all(np.linalg.eigvalsh(quadric) > 0)):
        raise CalibrationError(
            "the samples do not lie on an ellipsoid (a disturbed or too short turn)"
        )
    soft = np.real(sqrtm(quadric / k))
    hard = min_max_centre + centre_scaled * scale
    # Coverage judged about the fitted centre: a partial arc would centre min/max on itself.
    missing = missing_magnetometer_coverage(field, hard)
    if missing:
        raise CalibrationError("; ".join(missing))
    calibrated = (field - hard) @ soft.T
    magnitude = np.linalg.norm(calibrated, axis=1)
    target = float(np.mean(np.linalg.norm(field - hard, axis=1)))
    soft = soft * target / float(magnitude.mean())
    magnitude = magnitude * target / float(magnitude.mean())
    return MagnetometerCalibration(
        hard_iron_t=hard,
        soft_iron=soft,
        min_max_hard_iron_t=min_max_centre,
        residual_t=float(magnitude.std()),
        min_max_residual_t=float(min_max_magnitude.std()),
        field_t=float(magnitude.mean()),
    )


def parameter_yaml(values: dict[str, list[float] | float], comment: str) -> str:
    """A ROS parameter file (``/**`` section) setting ``values``, preceded by comment lines."""
    lines = [f"# {line}" for line in comment.splitlines()]
    lines += ["/**:", "  ros__parameters:"]
    for name, value in values.items():
        if isinstance(value, list):
            text = "[" + ", ".join(f"{v:.9g}" for v in value) + "]"
        else:
            text = f"{value:.9g}"
        lines.append(f"    {name}: {text}")
    return "\n".join(lines) + "\n"
