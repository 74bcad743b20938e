"""Initial alignment at sea: levelling from specific force, heading from the antenna baseline.

A buoy is never still, so the levelling window is made insensitive to its rotation: every
specific-force increment is turned into the body frame at the start of the window with the
gyro-integrated relative rotation ``R_b0b`` before it is averaged (in that frame, inertially
fixed for the few seconds of the window, gravity keeps its direction however the buoy rolls).
The mean is then turned into the body frame at the alignment instant, where roll and pitch follow
from ``f^b ≈ R_nb^T (0, 0, g)`` (paper 000 eq. 2-3 written for forward-left-up axes)::

    roll = atan2(f_y, f_z),   pitch = atan2(−f_x, √(f_y² + f_z²)).

What is left is the mean wave acceleration over the window (and the accelerometer bias), which
tilts the estimate by ``a/g``. Its 1-σ is sized from the variance of the horizontal specific force
in the window (the window mean of an oscillation is bounded by a fraction of its amplitude, so
the full standard deviation is a conservative bound), plus the accelerometer bias over g and the
gyro-bias rotation over half the window.

The heading is solved exactly for the levelled attitude and any antenna geometry (paper 000
eq. 4 generalised): with ``R_nb = Rz(ψ) R_L``, ``R_L = Ry(pitch) Rx(roll)``, the baseline azimuth
is ``ψ + atan2(w_y, w_x)`` where ``w = R_L (l_s − l_p)``, so ``ψ = ψ_measured − atan2(w_y, w_x)``.
The attitude covariance carries the correlation this creates between yaw and tilt errors.

The same solution serves any heading reference that gives the azimuth of a known body vector:
the magnetometer (the calibrated field, whose azimuth is magnetic north) and a motion pack's
attitude (its body x axis) as well as the antenna baseline.

Position and velocity come from the latest fix and GNSS velocity, with the lever arm removed.
Without GNSS (a moored buoy with a magnetometer or a motion pack) the position is the site
(``site.*``, else ``origin.*``) with :data:`_SITE_POSITION_SIGMA_M`, and the velocity zero with
the spread of the wave motion seen in the levelling window.
"""

import enum
import math
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from buoy_nav import earth
from buoy_nav.antenna_geometry import MIN_HORIZONTAL_BASELINE_FRACTION, horizontal_fraction
from buoy_nav.config import FusionConfig
from buoy_nav.error_state_filter import ERROR_STATES, ImuErrorModel, NavState
from buoy_nav.rotations import (
    IDENTITY_QUATERNION,
    cross_components,
    euler_from_rotation_matrix,
    normalize_quaternion,
    quaternion_from_rotation_matrix,
    quaternion_from_rotation_vector,
    quaternion_multiply,
    rotation_matrix_elements,
    rotation_matrix_from_euler,
    rotation_matrix_from_quaternion,
    wrap_angle,
)
from buoy_nav.state_layout import StateLayout

# Floor of the tilt 1-σ (rad): the levelling is never trusted beyond 0.05°.
_TILT_SIGMA_FLOOR_RAD = math.radians(0.05)
# Velocity 1-σ (m/s) assumed when no GNSS velocity is available at alignment.
_UNKNOWN_VELOCITY_SIGMA_MPS = 5.0
# Position 1-σ (m) of a site without a fix: a mooring's watch circle.
_SITE_POSITION_SIGMA_M = 100.0


class AlignmentState(enum.Enum):
    """Progress of the alignment."""

    WAITING_FOR_IMU = "waiting_for_imu"
    LEVELLING = "levelling"
    WAITING_FOR_GNSS = "waiting_for_gnss"
    ALIGNED = "aligned"


@dataclass(frozen=True)
class AlignmentResult:
    """Initial state and covariance of the filter.

    t_s: alignment instant (s). state: nominal state there. covariance: initial P of the
    aligner's error states.
    roll_rad, pitch_rad, yaw_rad: the aligned Euler angles. tilt_sigma_rad: 1-σ of roll/pitch.
    """

    t_s: float
    state: NavState
    covariance: np.ndarray
    roll_rad: float
    pitch_rad: float
    yaw_rad: float
    tilt_sigma_rad: float


@dataclass(frozen=True)
class _Fix:
    t_s: float
    latitude_rad: float
    longitude_rad: float
    altitude_m: float
    covariance_enu_m2: np.ndarray


@dataclass(frozen=True)
class _Velocity:
    t_s: float
    velocity_enu_mps: np.ndarray
    covariance_m2s2: np.ndarray


class _WindowSpread(NamedTuple):
    """What the levelling window's specific force says of the alignment's uncertainty.

    gravity_mps2: normal gravity at the fix. acceleration_variance_m2_s4: the window's
    specific-force variance summed over the axes. motion_tilt_variance_rad2: tilt variance from
    the motion and the gyro bias; tilt_variance_rad2: with the accelerometer bias, whose variance
    is accel_bias_variance_m2_s4.
    """

    gravity_mps2: float
    acceleration_variance_m2_s4: float
    motion_tilt_variance_rad2: float
    accel_bias_variance_m2_s4: float
    tilt_variance_rad2: float


class InMotionAligner:
    """Collects IMU motion and GNSS measurements until an alignment can be made.

    ``states`` names the error states of the initial covariance.
    """

    def __init__(
        self, config: FusionConfig, imu_model: ImuErrorModel, states: StateLayout = ERROR_STATES
    ):
        self._config = config
        self._imu = imu_model
        self._states = states
        self._primary = np.array(config.primary_antenna_body_m)
        self._baseline = np.array(config.baseline_body_m)
        self._fix: _Fix | None = None
        self._velocity: _Velocity | None = None
        self._site = _site_of(config)
        self.restart()

    def restart(self):
        """Forget the levelling window (after an IMU gap); GNSS measurements are kept."""
        self._relative: tuple[float, float, float, float] = IDENTITY_QUATERNION
        self._duration_s = 0.0
        self._force_sum = [0.0, 0.0, 0.0]
        """Σ of the velocity increments rotated into the window's first body frame (m/s)."""
        self._force_sq_sum = [0.0, 0.0, 0.0]
        """Σ of their squares over the step (m²/s³), for the window's specific-force scatter."""
        self._has_imu = False

    @property
    def state(self) -> AlignmentState:
        """Current progress (never ALIGNED: the aligner hands over at alignment)."""
        if not self._has_imu:
            return AlignmentState.WAITING_FOR_IMU
        if self._duration_s < self._config.alignment_window_s:
            return AlignmentState.LEVELLING
        return AlignmentState.WAITING_FOR_GNSS

    def add_motion(self, dt_s: float, gyro_start, gyro_end, force_start, force_end):
        """One IMU step of ``dt_s`` between raw samples (body rad/s and m/s²)."""
        if self._duration_s >= 2.0 * self._config.alignment_window_s:
            # A long wait for GNSS lets gyro bias accumulate in R_b0b: start a fresh window.
            self.restart()
        self._has_imu = True
        # Scalar arithmetic: this runs at the IMU rate until alignment, where numpy's per-call
        # cost on 3-vectors is many times the arithmetic.
        half_dt = 0.5 * dt_s
        (g0x, g0y, g0z), (g1x, g1y, g1z) = gyro_start, gyro_end
        (f0x, f0y, f0z), (f1x, f1y, f1z) = force_start, force_end
        dtheta = ((g0x + g1x) * half_dt, (g0y + g1y) * half_dt, (g0z + g1z) * half_dt)
        dvel = ((f0x + f1x) * half_dt, (f0y + f1y) * half_dt, (f0z + f1z) * half_dt)
        sx, sy, sz = cross_components(dtheta, dvel)
        dx, dy, dz = dvel[0] + 0.5 * sx, dvel[1] + 0.5 * sy, dvel[2] + 0.5 * sz
        r00, r01, r02, r10, r11, r12, r20, r21, r22 = rotation_matrix_elements(*self._relative)
        rotated = (
            r00 * dx + r01 * dy + r02 * dz,
            r10 * dx + r11 * dy + r12 * dz,
            r20 * dx + r21 * dy + r22 * dz,
        )
        force_sum, force_sq_sum = self._force_sum, self._force_sq_sum
        for axis, component in enumerate(rotated):
            force_sum[axis] += component
            force_sq_sum[axis] += component * component / dt_s
        self._duration_s += dt_s
        self._relative = normalize_quaternion(
            quaternion_multiply(self._relative, quaternion_from_rotation_vector(*dtheta))
        )

    def add_fix(self, t_s, latitude_rad, longitude_rad, altitude_m, covariance_enu_m2):
        """Remember the latest primary-antenna fix (rad, rad, m; ENU covariance m²)."""
        self._fix = _Fix(
            t_s, latitude_rad, longitude_rad, altitude_m, np.array(covariance_enu_m2, dtype=float)
        )

    def add_velocity(self, t_s, velocity_enu_mps, covariance_m2s2):
        """Remember the latest primary-antenna velocity (ENU m/s, covariance m²/s²)."""
        self._velocity = _Velocity(
            t_s, np.array(velocity_enu_mps, dtype=float), np.array(covariance_m2s2, dtype=float)
        )

    def levelled_rotation(self) -> np.ndarray | None:
        """R_nb at the end of the levelling window with the yaw left at 0 (what a heading
        reference's vertical component is judged with); None before the window is full."""
        if self.state is not AlignmentState.WAITING_FOR_GNSS:
            return None
        mean_start_frame = np.array(self._force_sum) / self._duration_s
        mean_force = rotation_matrix_from_quaternion(self._relative).T @ mean_start_frame
        return rotation_matrix_from_euler(*_roll_pitch(mean_force), 0.0)

    def _level_and_head(self, mean_force, yaw_rad: float, body_vector) -> np.ndarray | None:
        """R_nb from the mean specific force (body) and the azimuth of ``body_vector``; None if
        the vector is too steep."""
        roll, pitch = _roll_pitch(mean_force)
        levelled = rotation_matrix_from_euler(roll, pitch, 0.0)
        if horizontal_fraction(levelled, body_vector) < MIN_HORIZONTAL_BASELINE_FRACTION:
            return None
        levelled_vector = levelled @ body_vector
        yaw = wrap_angle(yaw_rad - math.atan2(levelled_vector[1], levelled_vector[0]))
        return rotation_matrix_from_euler(roll, pitch, yaw)

    def add_heading(
        self,
        t_s: float,
        yaw_rad: float,
        variance_rad2: float,
        gyro_rad_s,
        body_vector=None,
    ) -> AlignmentResult | None:
        """Try to complete the alignment at a heading measurement's stamp: ``yaw_rad`` is the
        azimuth (ENU, rad) of the horizontal projection of ``body_vector`` (``base_link``;
        default: the antenna baseline), ``variance_rad2`` its variance.

        The IMU motion must already be integrated up to ``t_s``; ``gyro_rad_s`` is the raw gyro
        rate there (body, rad/s), used to remove the lever-arm velocity. Returns None while the
        window is short, no recent fix exists (and no site is configured to stand for one), or
        the vector is too steep.
        """
        if self.state is not AlignmentState.WAITING_FOR_GNSS:
            return None
        body_vector = self._baseline if body_vector is None else np.asarray(body_vector, float)
        fix = self._recent_fix(t_s)
        if fix is None:
            return None
        rotation = self._window_attitude(fix, yaw_rad, body_vector)
        if rotation is None:
            return None
        spread = self._window_spread(fix)
        states = self._states
        covariance = np.zeros((states.dim, states.dim))
        attitude_bias_covariance = _attitude_and_accel_bias_covariance(
            rotation,
            rotation @ body_vector,
            spread.motion_tilt_variance_rad2,
            max(variance_rad2, 0.0),
            spread.accel_bias_variance_m2_s4,
            spread.gravity_mps2,
        )
        for row, rows in enumerate((states.attitude, states.accel_bias)):
            for column, columns in enumerate((states.attitude, states.accel_bias)):
                covariance[rows, columns] = attitude_bias_covariance[
                    3 * row : 3 * row + 3, 3 * column : 3 * column + 3
                ]
        covariance[states.gyro_bias, states.gyro_bias] = (
            np.eye(3) * self._imu.initial_gyro_bias_variance_rad2_s2
        )
        state = self._antenna_state(t_s, fix, rotation, gyro_rad_s, spread, covariance)
        roll, pitch, yaw = euler_from_rotation_matrix(rotation)
        return AlignmentResult(
            t_s=t_s,
            state=state,
            covariance=covariance,
            roll_rad=roll,
            pitch_rad=pitch,
            yaw_rad=yaw,
            tilt_sigma_rad=math.sqrt(spread.tilt_variance_rad2),
        )

    def _recent_fix(self, t_s: float) -> _Fix | None:
        """The fix the alignment at ``t_s`` (s) starts from: the latest, or the configured site
        when there is none; None when it is older than ``alignment_max_fix_age_s``."""
        fix = self._fix
        if fix is None and self._site is not None:
            fix = self._site_fix(t_s)
        if fix is None or t_s - fix.t_s > self._config.alignment_max_fix_age_s:
            return None
        return fix

    def _window_attitude(self, fix: _Fix, yaw_rad: float, body_vector) -> np.ndarray | None:
        """R_nb at the end of the window from its mean specific force and the azimuth
        ``yaw_rad`` (ENU, rad) of ``body_vector`` (body); None if the vector is too steep."""
        duration = self._duration_s
        mean_start_frame = np.array(self._force_sum) / duration
        relative = rotation_matrix_from_quaternion(self._relative)
        mean_force = relative.T @ mean_start_frame
        earth_rate = earth.earth_rate_enu_rad_s(fix.latitude_rad)
        rotation = self._level_and_head(mean_force, yaw_rad, body_vector)
        if rotation is None:
            return None
        # The window's frame is inertial, so gravity turned with the Earth during it: the mean
        # lags the end-of-window direction by ω_ie × T/2. Correct with the first solution.
        mean_force = mean_force + np.cross(rotation.T @ earth_rate, mean_force) * (0.5 * duration)
        return self._level_and_head(mean_force, yaw_rad, body_vector)

    def _window_spread(self, fix: _Fix) -> _WindowSpread:
        """The tilt uncertainty the window's motion and the IMU's biases leave, at ``fix``."""
        duration = self._duration_s
        mean_start_frame = np.array(self._force_sum) / duration
        gravity = earth.normal_gravity_mps2(fix.latitude_rad, fix.altitude_m)
        variance = np.maximum(np.array(self._force_sq_sum) / duration - mean_start_frame**2, 0.0)
        motion_tilt_variance = (
            0.5 * (variance[0] + variance[1]) / gravity**2
            + self._imu.initial_gyro_bias_variance_rad2_s2 * (0.5 * duration) ** 2
            + _TILT_SIGMA_FLOOR_RAD**2
        )
        accel_bias_variance = self._imu.initial_accel_bias_variance_m2_s4
        return _WindowSpread(
            gravity_mps2=gravity,
            acceleration_variance_m2_s4=float(np.sum(variance)),
            motion_tilt_variance_rad2=motion_tilt_variance,
            accel_bias_variance_m2_s4=accel_bias_variance,
            tilt_variance_rad2=motion_tilt_variance + accel_bias_variance / gravity**2,
        )

    def _antenna_state(
        self,
        t_s: float,
        fix: _Fix,
        rotation: np.ndarray,
        gyro_rad_s,
        spread: _WindowSpread,
        covariance: np.ndarray,
    ) -> NavState:
        """The state of ``base_link`` at ``t_s`` (s) with attitude ``rotation`` (R_nb): the
        antenna measurements moved back along the lever arm (raw gyro ``gyro_rad_s`` there,
        body rad/s). Their variances go to the velocity and position blocks of ``covariance``:
        the measurements may be up to ``alignment_max_fix_age_s`` old, and the motion since
        widens them (the window's acceleration for velocity, the speed for position), as does
        the tilt's uncertainty over the lever arm."""
        config = self._config
        states = self._states
        lever_enu = rotation @ self._primary
        latitude, longitude, altitude = earth.geodetic_offset(
            fix.latitude_rad, fix.longitude_rad, fix.altitude_m, -lever_enu
        )
        rate = np.asarray(gyro_rad_s, dtype=float)
        velocity, velocity_variance = self._lever_arm_velocity(
            t_s, rotation, rate, latitude, altitude, spread.acceleration_variance_m2_s4
        )
        speed_sq = float(velocity @ velocity + np.sum(velocity_variance))
        position_variance = np.diag(fix.covariance_enu_m2) + speed_sq * (t_s - fix.t_s) ** 2
        lever_sq = float(self._primary @ self._primary)
        tilt_variance = spread.tilt_variance_rad2
        position_variance = position_variance + tilt_variance * lever_sq
        velocity_variance = velocity_variance + tilt_variance * float(rate @ rate) * lever_sq
        covariance[states.velocity, states.velocity] = np.diag(
            np.maximum(velocity_variance, config.gnss_velocity_variance_floor_m2s2)
        )
        covariance[states.position, states.position] = np.diag(
            np.maximum(position_variance, config.gnss_position_variance_floor_m2)
        )
        return NavState(
            attitude_xyzw=quaternion_from_rotation_matrix(rotation),
            velocity_enu_mps=velocity,
            latitude_rad=latitude,
            longitude_rad=longitude,
            altitude_m=altitude,
            gyro_bias_rad_s=np.zeros(3),
            accel_bias_mps2=np.zeros(3),
        )

    def _lever_arm_velocity(
        self,
        t_s: float,
        rotation: np.ndarray,
        rate: np.ndarray,
        latitude_rad: float,
        altitude_m: float,
        acceleration_variance_m2_s4: float,
    ) -> tuple[np.ndarray, np.ndarray]:
        """(velocity ENU m/s, its variances m²/s²) of ``base_link`` at ``t_s`` (s) from the
        latest antenna velocity, less the lever-arm velocity of the body rate ``rate`` (rad/s);
        without a recent one, zero with a wide variance."""
        velocity = np.zeros(3)
        velocity_variance = np.full(3, _UNKNOWN_VELOCITY_SIGMA_MPS**2)
        if self._fix is None:
            # At a site without GNSS the buoy moves with the waves about a fixed mean: the
            # window's acceleration spread over a wave's angular frequency bounds the speed.
            velocity_variance = np.full(3, max(acceleration_variance_m2_s4, 0.01))
        measured = self._velocity
        if measured is None or t_s - measured.t_s > self._config.alignment_max_fix_age_s:
            return velocity, velocity_variance
        frame_rate = earth.navigation_frame_rate_enu_rad_s(
            latitude_rad, altitude_m, measured.velocity_enu_mps
        )
        velocity = (
            measured.velocity_enu_mps
            - rotation @ np.cross(rate, self._primary)
            + np.cross(frame_rate, rotation @ self._primary)
        )
        velocity_variance = (
            np.diag(measured.covariance_m2s2)
            + acceleration_variance_m2_s4 * (t_s - measured.t_s) ** 2
        )
        return velocity, velocity_variance

    def latest_position_rad(self) -> tuple[float, float] | None:
        """(latitude, longitude) in rad of the latest fix, else of the site; None: neither."""
        if self._fix is not None:
            return self._fix.latitude_rad, self._fix.longitude_rad
        return self._site

    def _site_fix(self, t_s: float) -> _Fix:
        """The configured site standing for a fix at ``t_s`` (sea level, watch-circle σ)."""
        latitude_rad, longitude_rad = self._site
        return _Fix(
            t_s,
            latitude_rad,
            longitude_rad,
            0.0,
            np.eye(3) * _SITE_POSITION_SIGMA_M**2,
        )


def _roll_pitch(mean_force_body_mps2) -> tuple[float, float]:
    """Roll and pitch (rad) that put the mean specific force (body, m/s²) up."""
    force = mean_force_body_mps2
    return math.atan2(force[1], force[2]), math.atan2(-force[0], math.hypot(force[1], force[2]))


def _site_of(config: FusionConfig) -> tuple[float, float] | None:
    """(latitude, longitude) in rad of the site (``site.*``, else ``origin.*``); None when
    neither is configured. A latitude given alone stands at longitude 0: the navigation needs
    a longitude, and without GNSS it enters nothing once the declination is a number (the
    configuration requires it); the outputs do not present it as a position."""
    if config.site_position_deg is not None:
        latitude, longitude = config.site_position_deg
    elif config.site_latitude_only_deg is not None:
        latitude, longitude = config.site_latitude_only_deg, 0.0
    else:
        return None
    return math.radians(latitude), math.radians(longitude)


def _attitude_and_accel_bias_covariance(
    rotation_nb,
    baseline_enu,
    motion_tilt_variance: float,
    heading_variance: float,
    accel_bias_variance: float,
    gravity: float,
) -> np.ndarray:
    """Joint 6×6 covariance of (φ, δb_a) right after the alignment.

    The levelling mistakes the horizontal accelerometer bias for tilt: the averaged specific
    force R_nb^T g_up + b gives φ × g_up = (R_nb b)_horizontal, i.e.
    ``φ_E = −(R_nb b)_N / g`` and ``φ_N = (R_nb b)_E / g``, fully correlated with the bias state
    (this is what keeps the filter consistent while the bias stays unobservable, e.g. on a still
    buoy); the wave motion adds an independent tilt error of variance ``motion_tilt_variance``.
    The yaw solved from one heading satisfies H φ = −e (e: heading noise, H = (h_E, h_N, 1) the
    heading Jacobian), so ``φ_U = −e − h_E φ_E − h_N φ_N``.
    """
    b_east, b_north, b_up = baseline_enu
    horizontal_sq = b_east * b_east + b_north * b_north
    h_east = -b_east * b_up / horizontal_sq
    h_north = -b_north * b_up / horizontal_sq
    rotation = np.asarray(rotation_nb, dtype=float)
    # Independent sources z = (bias (3), motion tilt E, N (2), heading noise (1)).
    tilt_from_sources = np.zeros((2, 6))
    tilt_from_sources[0, 0:3] = -rotation[1] / gravity
    tilt_from_sources[1, 0:3] = rotation[0] / gravity
    tilt_from_sources[:, 3:5] = np.eye(2)
    mapping = np.zeros((6, 6))
    mapping[0:2] = tilt_from_sources
    mapping[2] = -h_east * tilt_from_sources[0] - h_north * tilt_from_sources[1]
    mapping[2, 5] = -1.0
    mapping[3:6, 0:3] = np.eye(3)
    source_variances = np.array(
        (accel_bias_variance,) * 3 + (motion_tilt_variance,) * 2 + (heading_variance,)
    )
    return (mapping * source_variances) @ mapping.T
