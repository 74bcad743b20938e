"""15-state error-state Kalman filter (closed loop) of the strapdown navigation.

Error state (:data:`ERROR_STATES`; code addresses it by these block names only, see
:mod:`buoy_nav.state_layout`):

==========  =====  ===========================================================
block       size   meaning
==========  =====  ===========================================================
attitude    3      φ, attitude error, ENU (rad)
velocity    3      δv, velocity error, ENU (m/s)
position    3      δp, position error, ENU metres of the local tangent plane at
                   the nominal position (better conditioned than δL, δλ, δh)
gyro_bias   3      δb_g, gyro bias error, body (rad/s)
accel_bias  3      δb_a, accelerometer bias error, body (m/s²)
==========  =====  ===========================================================

**Error-injection convention** (the single definition, :func:`inject_error_state`): the true
state is the nominal state with the error applied as

* ``R_nb,true = Exp([φ×]) · R_nb``  (φ is a rotation of the ENU frame),
* ``v_true = v + δv``,
* ``position_true = position moved by δp`` (ENU metres: Δlat = δp_N / (R_M + h),
  Δlon = δp_E / ((R_N + h) cos lat), Δh = δp_U),
* ``b_true = b + δb`` for both biases (the bias-corrected rate is ``ω = ω_raw − b``).

The closed-loop correction applies the estimated error with the same function and resets it to
zero; the measurement Jacobians are derived, and tested, under the same convention.

Continuous error model (paper 001 eq. 1-5, rewritten for this convention and for δp in metres;
ω_in = ω_ie + ω_en, f^n = R_nb f the specific force in ENU)::

    φ̇  = −ω_in × φ − ∂ω_en/∂v · δv − R_nb δb_g − R_nb n_g
    δv̇ = −f^n × φ − (2ω_ie + ω_en) × δv + (2g/R) δp_U e_U − R_nb δb_a − R_nb n_a
    δṗ = δv
    δḃ = w_b                            (random walk of density 2σ²/τ, both biases)

The sensor bias is a constant switch-on part plus a first-order Gauss-Markov drift (σ, τ). A
Gauss-Markov *error* state would decay towards its stationary σ (0.1 mg, 5 °/h) within τ and so
forget the switch-on bias, which is far larger and does not decay; on a still buoy, where the
horizontal accelerometer bias is unobservable, that made the filter overconfident. The bias
error is therefore a random walk driven by the Gauss-Markov process's own noise density 2σ²/τ:
the same short-term growth, no decay, and a long-term growth that only errs on the safe side.

The terms dropped are the Earth-rate and Coriolis changes with position and velocity error
(∂ω_ie/∂p δp, δω × v), all below 1e-9 rad/s or 1e-7 m/s² for a buoy's metre-level errors and
sub-m/s speeds.

Discretisation over a propagation interval T that may span several IMU steps: the
time-varying coupling blocks are replaced by their exact integrals over the interval taken from
the mechanization (``∫R_nb dt`` and ``∫f^n dt``, see :class:`PropagationSums`), which is exact to
first order in T whatever the motion during the interval; ``Φ = I + A + A²/2`` with ``A`` the
integrated ``F·T``. The neglected third-order terms chain three blocks (e.g. gyro bias →
attitude → velocity → position, ``b_g f T³/6`` ≈ 1e-6 m per 0.02 °/s over T = 0.1 s), far below
the process noise of the same interval.

Discrete process noise: white-noise densities integrated over T, ``Q_d = Q_c T`` for attitude
and velocity (the cross terms ``F Q_c T²/2``, e.g. gyro noise into velocity, are below 1 % of
the retained terms for T ≤ 0.1 s), and ``2σ²T/τ`` for the bias random walks. Gyro and
accelerometer white noise are isotropic, so their ENU covariance does not depend on the
attitude. The scale-factor error (not estimated) adds, per body axis, a white noise of density
``(s·ω)² τ_s`` on the gyro and ``(s·a)² τ_s`` on the accelerometer, where ``a`` is the specific
force beyond gravity and ``τ_s`` (:data:`SCALE_FACTOR_CORRELATION_TIME_S`) is the time over which
that error is treated as coherent before the aiding measurements correct it; the gravity part
of the accelerometer scale-factor error is constant and is added to the initial
accelerometer-bias variance instead.
"""

import math
from dataclasses import dataclass

import numba
import numpy as np

from buoy_nav import earth, kalman_kernel
from buoy_nav import strapdown_kernel as kernel
from buoy_nav.chi_square import chi_square_quantile
from buoy_nav.config import FusionConfig
from buoy_nav.rotations import (
    rotation_matrix_from_quaternion,
)
from buoy_nav.state_layout import EAST, NORTH, UP, StateLayout

ERROR_STATES = StateLayout(
    ("attitude", 3), ("velocity", 3), ("position", 3), ("gyro_bias", 3), ("accel_bias", 3)
)
"""The error state of this filter (see the module docstring). States added for a richer model
(gyro Gauss-Markov drift as ``("gyro_drift", 3)``) are appended here, with their dynamics in
:func:`discrete_error_model` and :func:`inject_error_state`."""
_S = ERROR_STATES
if (_S.attitude.start, _S.velocity.start, _S.position.start, _S.gyro_bias.start) != (
    kernel.ERROR_ATTITUDE,
    kernel.ERROR_VELOCITY,
    kernel.ERROR_POSITION,
    kernel.ERROR_GYRO_BIAS,
) or _S.accel_bias.start != kernel.ERROR_ACCEL_BIAS:
    raise ImportError("the compiled error injection's blocks differ from ERROR_STATES")

STANDARD_GRAVITY_MPS2 = 9.80665
DEG = math.pi / 180.0
# Time (s) over which the unestimated scale-factor error is treated as coherent: a few times the
# 0.1 s between aiding measurements, about the time constant with which the heading and
# velocity measurements pull the attitude back.
SCALE_FACTOR_CORRELATION_TIME_S = 3.0
# Smallest eigenvalue kept when a covariance has to be repaired, relative to the largest one.
_EIGENVALUE_FLOOR_RELATIVE = 1e-15


def _measurement_arrays(innovation, jacobian, measurement_covariance):
    """ν (m,), H (m × states) and R (m × m) as contiguous float arrays for the compiled
    update."""
    return (
        _contiguous_floats(innovation, 1),
        _contiguous_floats(jacobian, 2),
        _contiguous_floats(measurement_covariance, 2),
    )


def _contiguous_floats(values, ndim: int) -> np.ndarray:
    """``values`` as a C-contiguous float64 array of at least ``ndim`` (1 or 2) dimensions:
    the array itself when it is one already (the compiled update only reads it)."""
    if (
        type(values) is np.ndarray
        and values.ndim == ndim
        and values.dtype == np.float64
        and values.flags.c_contiguous
    ):
        return values
    at_least = np.atleast_1d(values) if ndim == 1 else np.atleast_2d(values)
    return np.ascontiguousarray(at_least, dtype=float)


def block_diagonal(blocks) -> np.ndarray:
    """The square matrix with the square ``blocks`` on its diagonal and zeros elsewhere: the
    measurement covariance of a stacked update. (scipy.linalg.block_diag gives the same matrix
    at some 20 times the cost, which showed at the aiding rate.)"""
    size = sum(block.shape[0] for block in blocks)
    matrix = np.zeros((size, size))
    offset = 0
    for block in blocks:
        end = offset + block.shape[0]
        matrix[offset:end, offset:end] = block
        offset = end
    return matrix


@dataclass(frozen=True)
class NavState:
    """Nominal navigation state (the filter's linearisation point).

    attitude_xyzw: quaternion of R_nb (body FLU → ENU).
    velocity_enu_mps: ENU velocity of the ``base_link`` origin (m/s).
    latitude_rad, longitude_rad, altitude_m: WGS-84 position of the ``base_link`` origin.
    gyro_bias_rad_s, accel_bias_mps2: IMU bias estimates (body, rad/s and m/s²).
    """

    attitude_xyzw: tuple[float, float, float, float]
    velocity_enu_mps: np.ndarray
    latitude_rad: float
    longitude_rad: float
    altitude_m: float
    gyro_bias_rad_s: np.ndarray
    accel_bias_mps2: np.ndarray

    @property
    def rotation_nb(self) -> np.ndarray:
        """R_nb (3×3)."""
        return rotation_matrix_from_quaternion(self.attitude_xyzw)


def inject_error_state(state: NavState, error) -> NavState:
    """Apply an error state of :data:`ERROR_STATES` to a nominal state (THE error-injection
    convention, :func:`buoy_nav.strapdown_kernel.inject_error_state`, which the integrator
    applies to its own state in place)."""
    nominal = np.zeros(kernel.STATE_SIZE)
    nominal[kernel.ATTITUDE : kernel.ATTITUDE + 4] = state.attitude_xyzw
    nominal[kernel.VELOCITY : kernel.VELOCITY + 3] = state.velocity_enu_mps
    nominal[kernel.LATITUDE] = state.latitude_rad
    nominal[kernel.LONGITUDE] = state.longitude_rad
    nominal[kernel.ALTITUDE] = state.altitude_m
    nominal[kernel.GYRO_BIAS : kernel.GYRO_BIAS + 3] = state.gyro_bias_rad_s
    nominal[kernel.ACCEL_BIAS : kernel.ACCEL_BIAS + 3] = state.accel_bias_mps2
    kernel.inject_error_state(nominal, np.asarray(error, dtype=float))
    return NavState(
        attitude_xyzw=tuple(nominal[kernel.ATTITUDE : kernel.ATTITUDE + 4].tolist()),
        velocity_enu_mps=nominal[kernel.VELOCITY : kernel.VELOCITY + 3].copy(),
        latitude_rad=float(nominal[kernel.LATITUDE]),
        longitude_rad=float(nominal[kernel.LONGITUDE]),
        altitude_m=float(nominal[kernel.ALTITUDE]),
        gyro_bias_rad_s=nominal[kernel.GYRO_BIAS : kernel.GYRO_BIAS + 3].copy(),
        accel_bias_mps2=nominal[kernel.ACCEL_BIAS : kernel.ACCEL_BIAS + 3].copy(),
    )


@dataclass(frozen=True)
class ImuErrorModel:
    """IMU error parameters in SI units.

    gyro_noise_psd_rad2_s: angle-random-walk density (rad²/s).
    accel_noise_psd_m2_s3: velocity-random-walk density (m²/s³).
    gyro_turn_on_sigma_rad_s, accel_turn_on_sigma_mps2: 1-σ switch-on biases.
    gyro_markov_sigma_rad_s, accel_markov_sigma_mps2: 1-σ Gauss-Markov bias drifts.
    gyro_correlation_time_s, accel_correlation_time_s: their correlation times.
    scale_factor: 1-σ scale-factor error (dimensionless).
    """

    gyro_noise_psd_rad2_s: float
    accel_noise_psd_m2_s3: float
    gyro_turn_on_sigma_rad_s: float
    accel_turn_on_sigma_mps2: float
    gyro_markov_sigma_rad_s: float
    accel_markov_sigma_mps2: float
    gyro_correlation_time_s: float
    accel_correlation_time_s: float
    scale_factor: float

    @classmethod
    def from_config(cls, config: FusionConfig) -> "ImuErrorModel":
        """Convert the data-sheet units of :class:`FusionConfig` to SI."""
        milli_g = 1e-3 * STANDARD_GRAVITY_MPS2
        return cls(
            gyro_noise_psd_rad2_s=(config.gyro_noise_deg_sqrt_h * DEG / 60.0) ** 2,
            accel_noise_psd_m2_s3=(config.accel_noise_mps_sqrt_h / 60.0) ** 2,
            gyro_turn_on_sigma_rad_s=config.gyro_turn_on_bias_deg_s * DEG,
            accel_turn_on_sigma_mps2=config.accel_turn_on_bias_mg * milli_g,
            gyro_markov_sigma_rad_s=config.gyro_bias_instability_deg_h * DEG / 3600.0,
            accel_markov_sigma_mps2=config.accel_bias_instability_mg * milli_g,
            gyro_correlation_time_s=config.gyro_bias_correlation_time_s,
            accel_correlation_time_s=config.accel_bias_correlation_time_s,
            scale_factor=config.scale_factor_error_percent / 100.0,
        )

    @property
    def initial_gyro_bias_variance_rad2_s2(self) -> float:
        """Prior variance of each gyro bias at switch-on (turn-on plus drift)."""
        return self.gyro_turn_on_sigma_rad_s**2 + self.gyro_markov_sigma_rad_s**2

    @property
    def initial_accel_bias_variance_m2_s4(self) -> float:
        """Prior variance of each accelerometer bias: turn-on, drift and scale factor × g."""
        return (
            self.accel_turn_on_sigma_mps2**2
            + self.accel_markov_sigma_mps2**2
            + (self.scale_factor * STANDARD_GRAVITY_MPS2) ** 2
        )


def discrete_error_model(
    sums,
    latitude_rad: float,
    altitude_m: float,
    velocity_enu_mps,
    imu: ImuErrorModel,
    gyro_drift_scale: float = 1.0,
    accel_noise_scale: float = 1.0,
) -> tuple[np.ndarray, np.ndarray]:
    """Transition matrix Φ and process noise Q_d (:data:`ERROR_STATES`) over one
    propagation interval, with the σ of the gyro's drift widened by ``gyro_drift_scale`` and that
    of the accelerometer's velocity random walk by ``accel_noise_scale``.

    sums: :class:`buoy_nav.mechanization.PropagationSums` of the interval.
    latitude_rad, altitude_m, velocity_enu_mps: nominal state at the end of the interval (the
    rates evaluated from them change by far less than 1e-9 rad/s within an interval).
    """
    return _error_model(
        sums.duration_s,
        np.ascontiguousarray(sums.rotation_integral_s, dtype=float),
        np.ascontiguousarray(sums.specific_force_increment_enu_mps, dtype=float),
        np.ascontiguousarray(sums.gyro_rate_sq_integral_rad2_s, dtype=float),
        np.ascontiguousarray(sums.force_deviation_sq_integral_m2_s3, dtype=float),
        latitude_rad,
        altitude_m,
        float(velocity_enu_mps[0]),
        float(velocity_enu_mps[1]),
        _noise_coefficients(imu, gyro_drift_scale, accel_noise_scale),
    )


def propagated_covariance(
    integrator_state: np.ndarray,
    covariance: np.ndarray,
    imu: ImuErrorModel,
    gyro_drift_scale: float = 1.0,
    accel_noise_scale: float = 1.0,
) -> tuple[np.ndarray, np.ndarray]:
    """Φ of :func:`discrete_error_model` over the interval whose sums the integrator's state
    vector ``integrator_state`` (:mod:`buoy_nav.strapdown_kernel`'s layout) holds, and
    ``covariance`` carried over it, Φ P Φᵀ + Q_d (:meth:`ErrorStateFilter.propagate`); the
    sums are restarted (:meth:`StrapdownIntegrator.take_propagation_sums`). One compiled call."""
    return _propagated_covariance(
        integrator_state,
        covariance,
        _noise_coefficients(imu, gyro_drift_scale, accel_noise_scale),
    )


def _noise_coefficients(
    imu: ImuErrorModel, gyro_drift_scale: float, accel_noise_scale: float
) -> tuple[float, ...]:
    """The IMU's noise terms of Q_d before the interval's duration multiplies them: the
    scale factor's s² τ, the gyro's and the (scaled) accelerometer's white-noise densities, and
    the gyro's and the accelerometer's drift 2σ² with their correlation times. Squared here,
    by the interpreter, so that every path to Q_d rounds them alike."""
    return (
        imu.scale_factor**2 * SCALE_FACTOR_CORRELATION_TIME_S,
        imu.gyro_noise_psd_rad2_s,
        accel_noise_scale**2 * imu.accel_noise_psd_m2_s3,
        2.0 * (gyro_drift_scale * imu.gyro_markov_sigma_rad_s) ** 2,
        imu.gyro_correlation_time_s,
        2.0 * imu.accel_markov_sigma_mps2**2,
        imu.accel_correlation_time_s,
    )


_radii_of_curvature_m = numba.njit(cache=True)(earth.radii_of_curvature_m)
_normal_gravity_mps2 = numba.njit(cache=True)(earth.normal_gravity_mps2)


@numba.njit(cache=True)
def _propagated_covariance(state, covariance, noise_terms):
    """:func:`propagated_covariance` (``noise_terms``: those of :func:`_noise_coefficients`)."""
    transition, noise = _error_model(
        state[kernel.DURATION],
        state[kernel.ROTATION_SUM : kernel.ROTATION_SUM + 9].reshape(3, 3).copy(),
        state[kernel.FORCE_SUM : kernel.FORCE_SUM + 3].copy(),
        state[kernel.RATE_SQ_SUM : kernel.RATE_SQ_SUM + 3].copy(),
        state[kernel.FORCE_DEVIATION_SQ_SUM : kernel.FORCE_DEVIATION_SQ_SUM + 3].copy(),
        state[kernel.LATITUDE],
        state[kernel.ALTITUDE],
        state[kernel.VELOCITY],
        state[kernel.VELOCITY + 1],
        noise_terms,
    )
    state[kernel.DURATION :] = 0.0
    return transition, kalman_kernel.propagated(covariance, transition, noise)


@numba.njit(cache=True)
def _error_model(
    duration_s,
    rotation_integral_s,
    force_increment_enu_mps,
    gyro_rate_sq_integral_rad2_s,
    force_deviation_sq_integral_m2_s3,
    latitude_rad,
    altitude_m,
    velocity_east_mps,
    velocity_north_mps,
    noise_terms,
):
    """Φ and Q_d of :func:`discrete_error_model` from the interval's sums, the nominal state
    at its end and the ``noise_terms`` of :func:`_noise_coefficients`; the Earth's rates as
    :mod:`buoy_nav.earth` computes them."""
    (
        scale_sq_time_s,
        gyro_noise_psd_rad2_s,
        accel_noise_psd_m2_s3,
        gyro_drift_twice_variance_rad2_s2,
        gyro_correlation_time_s,
        accel_drift_twice_variance_m2_s4,
        accel_correlation_time_s,
    ) = noise_terms
    meridian, prime_vertical = _radii_of_curvature_m(latitude_rad)
    earth_rate = np.array(
        (
            0.0,
            earth.EARTH_RATE_RAD_S * np.cos(latitude_rad),
            earth.EARTH_RATE_RAD_S * np.sin(latitude_rad),
        )
    )
    east_radius = prime_vertical + altitude_m
    transport_rate = np.array(
        (
            -velocity_north_mps / (meridian + altitude_m),
            velocity_east_mps / east_radius,
            velocity_east_mps * math.tan(latitude_rad) / east_radius,
        )
    )
    transition = np.empty((_DIM, _DIM))
    noise = np.zeros((_DIM, _DIM))
    _fill_error_model(
        transition,
        noise,
        duration_s,
        earth_rate + transport_rate,
        2.0 * earth_rate + transport_rate,
        force_increment_enu_mps,
        rotation_integral_s,
        meridian + altitude_m,
        prime_vertical + altitude_m,
        math.tan(latitude_rad),
        _normal_gravity_mps2(latitude_rad, altitude_m),
        scale_sq_time_s,
        gyro_rate_sq_integral_rad2_s,
        force_deviation_sq_integral_m2_s3,
        gyro_noise_psd_rad2_s * duration_s,
        accel_noise_psd_m2_s3 * duration_s,
        gyro_drift_twice_variance_rad2_s2 * duration_s / gyro_correlation_time_s,
        accel_drift_twice_variance_m2_s4 * duration_s / accel_correlation_time_s,
        _ATTITUDE,
        _VELOCITY,
        _POSITION,
        _GYRO_BIAS,
        _ACCEL_BIAS,
    )
    return transition, noise


_DIM = _S.dim
_ATTITUDE = _S.attitude.start
_VELOCITY = _S.velocity.start
_POSITION = _S.position.start
_GYRO_BIAS = _S.gyro_bias.start
_ACCEL_BIAS = _S.accel_bias.start


@numba.njit(cache=True)
def _fill_error_model(
    transition,
    noise,
    duration_s,
    nav_frame_rate_enu_rad_s,
    coriolis_rate_enu_rad_s,
    force_increment_enu_mps,
    rotation_integral_s,
    north_radius_m,
    east_radius_m,
    tan_latitude,
    gravity_mps2,
    scale_sq_time_s,
    gyro_rate_sq_integral_rad2_s,
    force_deviation_sq_integral_m2_s3,
    gyro_noise_rad2,
    accel_noise_m2_s2,
    gyro_drift_rad2_s2,
    accel_drift_m2_s4,
    phi,
    dv,
    dp,
    gyro_bias,
    accel_bias,
):
    """Φ = I + A + A²/2 and Q_d of :func:`discrete_error_model` into ``transition`` and
    ``noise`` (zeros on entry); the blocks start at the indices ``phi`` … ``accel_bias``."""
    dim = transition.shape[0]
    a = np.zeros((dim, dim))
    _set_skew(a, phi, phi, -duration_s * nav_frame_rate_enu_rad_s)
    # ∂ω_en/∂v: ω_en = (−v_N/(R_M+h), v_E/(R_N+h), v_E tan L/(R_N+h)).
    a[phi + EAST, dv + NORTH] = duration_s / north_radius_m
    a[phi + NORTH, dv + EAST] = -duration_s / east_radius_m
    a[phi + UP, dv + EAST] = -duration_s * tan_latitude / east_radius_m
    _set_skew(a, dv, phi, -force_increment_enu_mps)
    _set_skew(a, dv, dv, -duration_s * coriolis_rate_enu_rad_s)
    a[dv + UP, dp + UP] = (
        2.0 * gravity_mps2 / math.sqrt(north_radius_m * east_radius_m) * duration_s
    )
    for row in range(3):
        for column in range(3):
            a[phi + row, gyro_bias + column] = -rotation_integral_s[row, column]
            a[dv + row, accel_bias + column] = -rotation_integral_s[row, column]
        a[dp + row, dv + row] = duration_s

    # Products written as loops: numba's matrix product would add seconds to the first compile.
    for row in range(dim):
        for column in range(dim):
            product = 0.0
            for inner in range(dim):
                product += a[row, inner] * a[inner, column]
            transition[row, column] = 0.5 * product + a[row, column]
        transition[row, row] += 1.0

    # Scale-factor noise: M diag(s² τ ∫ω²) Mᵀ and M diag(s² τ ∫(f − g)²) Mᵀ with M = ∫R dt / T.
    for row in range(3):
        for column in range(3):
            gyro_sum = 0.0
            force_sum = 0.0
            for axis in range(3):
                both = rotation_integral_s[row, axis] * rotation_integral_s[column, axis]
                gyro_sum += both * gyro_rate_sq_integral_rad2_s[axis]
                force_sum += both * force_deviation_sq_integral_m2_s3[axis]
            scale = scale_sq_time_s / (duration_s * duration_s)
            noise[phi + row, phi + column] = scale * gyro_sum
            noise[dv + row, dv + column] = scale * force_sum
    for axis in range(3):
        noise[phi + axis, phi + axis] += gyro_noise_rad2
        noise[dv + axis, dv + axis] += accel_noise_m2_s2
        noise[gyro_bias + axis, gyro_bias + axis] = gyro_drift_rad2_s2
        noise[accel_bias + axis, accel_bias + axis] = accel_drift_m2_s4


@numba.njit(cache=True)
def _set_skew(matrix, row, column, vector):
    """The 3×3 block of ``matrix`` at (``row``, ``column``) to [vector×]."""
    x, y, z = vector[0], vector[1], vector[2]
    matrix[row, column + 1] = -z
    matrix[row, column + 2] = y
    matrix[row + 1, column] = z
    matrix[row + 1, column + 2] = -x
    matrix[row + 2, column] = -y
    matrix[row + 2, column + 1] = x


@dataclass(frozen=True)
class GateResult:
    """Chi-square test of one measurement against the predicted covariance.

    accepted: nis ≤ threshold. nis: ν^T S^{-1} ν (NaN when S is not positive definite).
    threshold: chi-square quantile it was compared with. innovation_covariance: S = H P H^T + R.
    """

    accepted: bool
    nis: float
    threshold: float
    innovation_covariance: np.ndarray


class ErrorStateFilter:
    """Covariance bookkeeping of the error-state filter (states named by ``states``).

    The error-state mean is zero between updates (closed loop): :meth:`update` returns the
    correction, the caller injects it with :func:`inject_error_state`, and
    :meth:`reset_after_injection` accounts for the reset in the covariance.
    """

    def __init__(
        self,
        initial_covariance,
        gate_probability: float,
        states: StateLayout = ERROR_STATES,
    ):
        covariance = np.array(initial_covariance, dtype=float)
        if covariance.shape != (states.dim, states.dim):
            raise ValueError(f"initial covariance must be {states.dim}×{states.dim}")
        self.states = states
        self.covariance = 0.5 * (covariance + covariance.T)
        self.gate_probability = gate_probability
        self._identity = np.eye(states.dim)
        self._thresholds: dict[tuple[int, float], float] = {}
        self.covariance_repairs = 0

    def gate_threshold(self, dimension: int, probability: float | None = None) -> float:
        """Chi-square quantile of ``probability`` (default :attr:`gate_probability`) with
        ``dimension`` degrees of freedom."""
        if probability is None:
            probability = self.gate_probability
        key = (dimension, probability)
        if key not in self._thresholds:
            self._thresholds[key] = chi_square_quantile(dimension, probability)
        return self._thresholds[key]

    def propagate(self, transition: np.ndarray, process_noise: np.ndarray):
        """P ← Φ P Φ^T + Q_d."""
        self.covariance = kalman_kernel.propagated(self.covariance, transition, process_noise)

    def gate(
        self, innovation, jacobian, measurement_covariance, probability: float | None = None
    ) -> GateResult:
        """Normalised innovation squared of one measurement and its chi-square test at
        ``probability`` (default :attr:`gate_probability`).

        innovation ν (m,), jacobian H (m × states), measurement covariance R (m×m).
        """
        nu, h, r = _measurement_arrays(innovation, jacobian, measurement_covariance)
        threshold = self.gate_threshold(nu.shape[0], probability)
        nis, s = kalman_kernel.innovation_test(self.covariance, nu, h, r)
        return GateResult(nis <= threshold, nis, threshold, s)

    def update(self, innovation, jacobian, measurement_covariance) -> np.ndarray:
        """Apply a (possibly stacked) measurement in Joseph form; return the error estimate.

        innovation ν (m,), jacobian H (m × states), measurement covariance R (m×m). No gating here:
        gate each measurement with :meth:`gate` first. Raises ``numpy.linalg.LinAlgError`` if
        the innovation covariance is not positive definite (the gate rejects those first).
        """
        nu, h, r = _measurement_arrays(innovation, jacobian, measurement_covariance)
        covariance, correction, positive = kalman_kernel.joseph_update(self.covariance, nu, h, r)
        if not positive:
            raise np.linalg.LinAlgError("innovation covariance is not positive definite")
        self.covariance = covariance
        return correction

    def reset_after_injection(self, correction):
        """Covariance of the error after the correction was injected and the mean reset.

        With ``R_true = Exp(φ) R`` the new attitude error is φ' ≈ φ − δφ̂ + ½ δφ̂ × φ, so the
        attitude rows and columns are transformed by G = I + ½[δφ̂×]; the other states are
        additive and unchanged.
        """
        self.adopt_reset_covariance(
            *kalman_kernel.attitude_reset(
                self.covariance, np.asarray(correction, dtype=float), self.states.attitude.start
            )
        )

    def adopt_reset_covariance(self, covariance: np.ndarray, positive_definite: bool) -> None:
        """Take ``covariance``, the covariance after a correction's injection and reset,
        repaired when it is not ``positive_definite``."""
        self.covariance = covariance
        if not positive_definite:
            self._repair_covariance()

    def ensure_positive_definite(self) -> bool:
        """Repair P if it lost positive definiteness; returns True when a repair was needed."""
        if kalman_kernel.is_positive_definite(self.covariance):
            return False
        self._repair_covariance()
        return True

    def _repair_covariance(self) -> None:
        """Raise the eigenvalues of P to a floor relative to the largest."""
        eigenvalues, eigenvectors = np.linalg.eigh(self.covariance)
        floor = max(float(np.max(np.abs(eigenvalues))), 1e-30) * _EIGENVALUE_FLOOR_RELATIVE
        eigenvalues = np.maximum(eigenvalues, floor)
        covariance = (eigenvectors * eigenvalues) @ eigenvectors.T
        self.covariance = 0.5 * (covariance + covariance.T)
        self.covariance_repairs += 1

    def reset_states(self, indices, variances):
        """Decorrelate the states at ``indices`` (from :attr:`states`, e.g.
        ``states.indices("velocity")``) and set their variances (after an external reset)."""
        index = np.asarray(indices)
        self.covariance[index, :] = 0.0
        self.covariance[:, index] = 0.0
        self.covariance[index, index] = np.asarray(variances, dtype=float)
