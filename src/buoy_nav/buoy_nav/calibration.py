"""Sensor calibration (paper 004): the IMU from static positions, the magnetometer from its record.

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
raw magnitude. The residual is the spread of the calibrated magnitude.

Whether the record determines them is judged from the fit itself, not from how far the buoy
turned: the sensor's noise is measured from the record (third differences), the fit's 1σ of
every hard- and soft-iron element follows from that noise and the directions the field took
(the Jacobian of the calibrated magnitude), and a record is refused when the magnitude still
varies beyond twice the noise (a partial arc fits a wrong ellipsoid as closely as the algebra
allows) or when a σ exceeds its limit. A moored buoy that only swings on its mooring leaves the
horizontal part undetermined; one that barely tilts, the vertical part
(``tools/bench_magnetometer_calibration.py`` tabulates which motions determine them).
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
AXES = "xyz"
SOFT_IRON_ELEMENTS = ((0, 0), (1, 1), (2, 2), (0, 1), (0, 2), (1, 2))
"""The free elements of the symmetric soft-iron matrix, in the order the fit's Jacobian has
them."""
IRON_PARTS = {
    "horizontal": ((0, 1), ((0, 0), (1, 1), (0, 1)), "the heading's swing determines it"),
    "vertical": ((2,), ((2, 2), (0, 2), (1, 2)), "the tilt and the swing together determine it"),
}
"""The hard-iron axes and soft-iron elements a moored buoy's heading swing determines (the
body x-y plane, nearly level) and those that also need its tilt, with what determines each."""
SINGULAR_INFORMATION_RATIO = 1e-12
"""An information matrix whose eigenvalues span more than this leaves a direction free."""
MAX_RESIDUAL_OVER_NOISE = 2.0
"""A right ellipsoid leaves the sensor's noise in the magnitude; twice that is a wrong one."""
NOISE_FLOOR_T = 1e-12
"""The noise a record is credited with at least: a noise-free (simulated) field still leaves
rounding in the magnitude."""
LEVELLING_TIME_S = 30.0
"""Time constant with which record_motion's vertical follows the specific force's."""
FULL_TURN_DEG = 360.0
WANTED_TILT_DEG = 10.0
"""What to ask of a new record after a refusal: the motions under which the bench
(tools/bench_magnetometer_calibration.py) finds the iron determined."""
EARTH_FIELD_RANGE_T = (22e-6, 67e-6)
"""The Earth's field strength anywhere at sea level (World Magnetic Model)."""
MAX_HARD_IRON_SIGMA_FIELD_SHARE = 0.01
MAX_SOFT_IRON_SIGMA = 0.01
"""Largest 1σ of the hard iron (a share of the field) and of a soft-iron element accepted: each
alone turns the magnetic heading by about 1° (1σ) where the horizontal field is 60 % of the
field (dip 53°), less where it is stronger."""


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
    field_t: mean calibrated magnitude. noise_t: the sensor's per-axis noise the record shows
    (third differences). hard_iron_sigma_t (3,), soft_iron_sigma (3×3): the fit's 1σ from that
    noise (or the residual, when larger) and the directions the record's field took (infinite
    when undetermined)."""

    hard_iron_t: np.ndarray
    soft_iron: np.ndarray
    min_max_hard_iron_t: np.ndarray
    residual_t: float
    min_max_residual_t: float
    field_t: float
    noise_t: float
    hard_iron_sigma_t: np.ndarray
    soft_iron_sigma: np.ndarray


@dataclass(frozen=True)
class RecordMotion:
    """How a record moved the buoy, from its IMU: heading_swing_deg, the range of the heading,
    and tilt_deg, the 95th percentile of the tilt, both of the attitude the gyro integrates,
    levelled slowly by the specific force (a gyro bias of 0.02°/s adds 12° of heading over ten
    minutes: the swing is an upper bound)."""

    heading_swing_deg: float
    tilt_deg: float

    def describe(self) -> str:
        return (
            f"the heading swung over about {self.heading_swing_deg:.0f}° and the buoy tilted up "
            f"to about {self.tilt_deg:.0f}°"
        )

    def advice(self) -> str:
        """The motion a new record needs, beyond this one's (empty when it had both)."""
        wanted = []
        if self.heading_swing_deg < FULL_TURN_DEG:
            wanted.append("through a full turn")
        if self.tilt_deg < WANTED_TILT_DEG:
            wanted.append(f"while it tilts by {WANTED_TILT_DEG:.0f}° or more")
        return f"record the buoy {' and '.join(wanted)}" if wanted else ""


def _rotation_of(vector_rad: np.ndarray) -> np.ndarray:
    """The rotation matrix of a rotation vector (rad), Rodrigues' formula."""
    angle = float(np.linalg.norm(vector_rad))
    if angle < 1e-12:
        return np.eye(3)
    axis = vector_rad / angle
    cross = np.array([[0.0, -axis[2], axis[1]], [axis[2], 0.0, -axis[0]], [-axis[1], axis[0], 0.0]])
    return np.eye(3) + math.sin(angle) * cross + (1.0 - math.cos(angle)) * cross @ cross


def record_motion(t_s, gyro_rad_s, force_mps2) -> RecordMotion:
    """The heading swing and tilt of a record (see RecordMotion) from body-frame gyro rates
    (rad/s) and specific forces (m/s²) at times t_s (s).

    The attitude R_nb is integrated from the gyro, so a buoy rolling and pitching at one period
    (coning: a steady body-z rate without any change of heading) does not count as turning; its
    vertical is pulled toward the specific force's with LEVELLING_TIME_S, over which the waves'
    accelerations average out."""
    t = np.asarray(t_s, dtype=float)
    gyro = np.asarray(gyro_rad_s, dtype=float).reshape(-1, 3)
    force = np.asarray(force_mps2, dtype=float).reshape(-1, 3)
    up_measured = force / np.linalg.norm(force, axis=1)[:, None]
    roll = math.atan2(up_measured[0, 1], up_measured[0, 2])
    pitch = math.asin(-float(np.clip(up_measured[0, 0], -1.0, 1.0)))
    attitude = _rotation_of(np.array([0.0, pitch, 0.0])) @ _rotation_of(np.array([roll, 0.0, 0.0]))
    heading = np.empty(t.size)
    tilt = np.empty(t.size)
    for k in range(t.size):
        if k:
            dt = t[k] - t[k - 1]
            levelling = np.cross(up_measured[k], attitude[2]) * dt / LEVELLING_TIME_S
            attitude = attitude @ _rotation_of(gyro[k] * dt + levelling)
        heading[k] = math.atan2(attitude[1, 0], attitude[0, 0])
        tilt[k] = math.acos(float(np.clip(attitude[2, 2], -1.0, 1.0)))
    return RecordMotion(
        heading_swing_deg=float(np.degrees(np.ptp(np.unwrap(heading)))),
        tilt_deg=float(np.degrees(np.percentile(tilt, 95.0))),
    )


def noise_from_third_differences(field_t: np.ndarray) -> float:
    """The per-axis white noise (T) of a field sampled fast against the buoy's motion: the
    third difference of white noise has variance (1 + 9 + 9 + 1) σ², while a wave's smooth
    motion leaves almost nothing in it."""
    third = np.diff(field_t, n=3, axis=0)
    return float(np.mean(np.std(third, axis=0)) / math.sqrt(20.0))


def _fit_ellipsoid(field_t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(hard iron (T), soft iron up to scale) of the least-squares quadric through the samples
    (singular-value decomposition), in coordinates about the min/max centre for conditioning."""
    low, high = field_t.min(axis=0), field_t.max(axis=0)
    min_max_centre = 0.5 * (high + low)
    scale = float(np.mean(np.abs(field_t - min_max_centre)))
    x, y, z = ((field_t - min_max_centre) / scale).T
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
            "the samples lie on no ellipsoid: the record's field took too few directions to fit "
            "one (or it was disturbed)"
        )
    return min_max_centre + centre_scaled * scale, np.real(sqrtm(quadric / k))


def _fit_sigmas(
    field_t: np.ndarray, hard_t: np.ndarray, soft: np.ndarray, noise_t: float
) -> tuple[np.ndarray, np.ndarray]:
    """1σ of the hard iron (T, (3,)) and of the soft iron ((3×3)) from the Jacobian of the
    calibrated magnitude |S (m − h)| with respect to h and the symmetric S, the magnitude held
    (it fixes the scale), each sample's magnitude carrying ``noise_t``. Infinite where the
    record's directions leave a combination of them free."""
    # In units of the field, so that hard- and soft-iron columns compare in the eigenvalues.
    field_scale_t = float(np.mean(np.linalg.norm(field_t - hard_t, axis=1)))
    offset = (field_t - hard_t) / field_scale_t
    calibrated = offset @ soft.T
    direction = calibrated / np.linalg.norm(calibrated, axis=1)[:, None]
    columns = [-direction @ soft]
    for j, k in SOFT_IRON_ELEMENTS:
        column = direction[:, j] * offset[:, k]
        if j != k:
            column = column + direction[:, k] * offset[:, j]
        columns.append(column[:, None])
    jacobian = np.hstack(columns)
    information = jacobian.T @ jacobian
    eigenvalues = np.linalg.eigvalsh(information)
    if eigenvalues[0] <= eigenvalues[-1] * SINGULAR_INFORMATION_RATIO:
        return np.full(3, np.inf), np.full((3, 3), np.inf)
    sigma = np.sqrt(np.diag(np.linalg.inv(information))) * noise_t / field_scale_t
    soft_sigma = np.empty((3, 3))
    for (j, k), value in zip(SOFT_IRON_ELEMENTS, sigma[3:], strict=True):
        soft_sigma[j, k] = soft_sigma[k, j] = value
    return sigma[:3] * field_scale_t, soft_sigma


def fit_magnetometer(field_t) -> MagnetometerCalibration:
    """Hard and soft iron of the samples (see the module docstring) with the fit's 1σ, whether
    or not the record determines them (:func:`undetermined_iron` judges that).

    Raises CalibrationError when too few samples are finite or no ellipsoid fits."""
    field = np.asarray(field_t, dtype=float).reshape(-1, 3)
    field = field[np.all(np.isfinite(field), axis=1)]
    if len(field) < 50:
        raise CalibrationError(f"{len(field)} finite magnetometer samples: at least 50 needed")
    if np.any(np.ptp(field, axis=0) == 0.0):
        raise CalibrationError(
            "a magnetometer axis reads the same value throughout: a stuck sensor, or a record "
            "in which nothing moved"
        )
    low, high = field.min(axis=0), field.max(axis=0)
    min_max_centre = 0.5 * (high + low)
    half_ranges = 0.5 * (high - low)
    min_max = (field - min_max_centre) / half_ranges * half_ranges.mean()
    hard, soft = _fit_ellipsoid(field)
    magnitude = np.linalg.norm((field - hard) @ soft.T, axis=1)
    target = float(np.mean(np.linalg.norm(field - hard, axis=1)))
    soft = soft * target / float(magnitude.mean())
    magnitude = magnitude * target / float(magnitude.mean())
    noise = noise_from_third_differences(field)
    hard_sigma, soft_sigma = _fit_sigmas(field, hard, soft, max(noise, float(magnitude.std())))
    return MagnetometerCalibration(
        hard_iron_t=hard,
        soft_iron=soft,
        min_max_hard_iron_t=min_max_centre,
        residual_t=float(magnitude.std()),
        min_max_residual_t=float(np.linalg.norm(min_max, axis=1).std()),
        field_t=float(magnitude.mean()),
        noise_t=noise,
        hard_iron_sigma_t=hard_sigma,
        soft_iron_sigma=soft_sigma,
    )


def undetermined_iron(calibration: MagnetometerCalibration) -> list[str]:
    """What the record leaves undetermined, as sentences: a magnitude that still varies beyond
    the sensor's noise (a wrong ellipsoid through too few directions), a hard or soft iron
    whose 1σ exceeds the limits, in the horizontal part (which the heading swing determines)
    or the vertical one (which needs tilt too), a field strength the Earth never has. The
    σ are those of the linearised fit: a wrong ellipsoid through a partial arc can look precise,
    which the magnitude and strength checks catch first."""
    problems = []
    noise_t = max(calibration.noise_t, NOISE_FLOOR_T)
    if calibration.residual_t > MAX_RESIDUAL_OVER_NOISE * noise_t:
        problems.append(
            f"the calibrated field's magnitude still varies by "
            f"{calibration.residual_t * 1e9:.0f} nT RMS, "
            f"{calibration.residual_t / noise_t:.0f} times the sensor's noise "
            f"({calibration.noise_t * 1e9:.0f} nT): the ellipsoid through these few directions "
            "is a wrong one, the iron is not determined"
        )
        return problems
    if not EARTH_FIELD_RANGE_T[0] <= calibration.field_t <= EARTH_FIELD_RANGE_T[1]:
        problems.append(
            f"the fitted field is {calibration.field_t * 1e6:.0f} µT, which the Earth's "
            f"({EARTH_FIELD_RANGE_T[0] * 1e6:.0f}–{EARTH_FIELD_RANGE_T[1] * 1e6:.0f} µT) never "
            "is: the ellipsoid through these few directions is a wrong one, the iron is not "
            "determined"
        )
        return problems
    hard_limit = MAX_HARD_IRON_SIGMA_FIELD_SHARE * calibration.field_t
    for part, (axes, elements, determined_by) in IRON_PARTS.items():
        hard_sigma = float(np.max(calibration.hard_iron_sigma_t[list(axes)]))
        soft_sigma = max(float(calibration.soft_iron_sigma[j, k]) for j, k in elements)
        if hard_sigma > hard_limit or soft_sigma > MAX_SOFT_IRON_SIGMA:
            problems.append(
                f"the {part} hard iron (±{hard_sigma * 1e6:.2g} µT 1σ, at most "
                f"{hard_limit * 1e6:.2g}) or soft iron (±{soft_sigma:.2g}, at most "
                f"{MAX_SOFT_IRON_SIGMA:g}) is not determined ({determined_by})"
            )
    return problems


def calibrate_magnetometer(field_t, motion: RecordMotion | None = None) -> MagnetometerCalibration:
    """Hard and soft iron from a record that determines them (see the module docstring).

    Raises CalibrationError saying what the record leaves undetermined and, with ``motion``
    (the record's own, from its IMU), how far it swung and tilted."""
    try:
        calibration = fit_magnetometer(field_t)
        problems = undetermined_iron(calibration)
    except CalibrationError as error:
        problems = [str(error)]
    if problems:
        if motion is None:
            problems.append(
                f"record the buoy through a full turn while it tilts by {WANTED_TILT_DEG:.0f}° "
                "or more"
            )
        else:
            problems = [motion.describe(), *problems, motion.advice()]
        raise CalibrationError("; ".join(p for p in problems if p))
    return calibration


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
