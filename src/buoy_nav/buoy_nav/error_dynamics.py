"""The dynamics of the filter's error state (:data:`buoy_nav.error_state_filter.ERROR_STATES`):
the transition matrix Φ and the process noise Q_d over a propagation interval, and the
covariance carried over it in one compiled call.

Continuous error model (paper 001 eq. 1-5, rewritten for the error-injection convention of
:mod:`buoy_nav.error_state_filter` and for δp in metres;
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

import numba
import numpy as np

from buoy_nav import earth, kalman_kernel
from buoy_nav import strapdown_kernel as kernel
from buoy_nav.error_state_filter import ERROR_STATES, ImuErrorModel
from buoy_nav.state_layout import EAST, NORTH, UP

# Time (s) over which the unestimated scale-factor error is treated as coherent: a few times the
# 0.1 s between aiding measurements, about the time constant with which the heading and
# velocity measurements pull the attitude back.
SCALE_FACTOR_CORRELATION_TIME_S = 3.0


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
        noise_coefficients(imu, gyro_drift_scale, accel_noise_scale),
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
    return propagated_covariance_kernel(
        integrator_state,
        covariance,
        noise_coefficients(imu, gyro_drift_scale, accel_noise_scale),
    )


def stepped_covariance(
    integrator_state: np.ndarray,
    covariance: np.ndarray,
    step_s: float,
    gyro_start,
    gyro_end,
    force_start,
    force_end,
    corrections: tuple[bool, bool],
    imu: ImuErrorModel,
    gyro_drift_scale: float = 1.0,
    accel_noise_scale: float = 1.0,
) -> tuple[np.ndarray, np.ndarray]:
    """The strapdown step of ``step_s`` (s) between the raw samples (body rad/s, m/s²; the
    (coning, sculling) ``corrections`` asked for) in place of ``integrator_state``, then
    :func:`propagated_covariance` over the interval it closes: Φ and the covariance carried
    over it, in one compiled call, for the step to a stamp a measurement is applied at."""
    g0x, g0y, g0z = gyro_start
    g1x, g1y, g1z = gyro_end
    f0x, f0y, f0z = force_start
    f1x, f1y, f1z = force_end
    return stepped_covariance_kernel(
        integrator_state,
        covariance,
        step_s,
        (g0x, g0y, g0z, g1x, g1y, g1z),
        (f0x, f0y, f0z, f1x, f1y, f1z),
        corrections,
        noise_coefficients(imu, gyro_drift_scale, accel_noise_scale),
    )


def noise_coefficients(
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
def propagated_covariance_kernel(state, covariance, noise_terms):
    """:func:`propagated_covariance` (``noise_terms``: those of :func:`noise_coefficients`)."""
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
def stepped_covariance_kernel(state, covariance, step_s, gyro, force, corrections, noise_terms):
    """:func:`stepped_covariance` (the samples' components as (start x, y, z, end x, y, z))."""
    kernel.strapdown_step(
        state,
        step_s,
        gyro[0],
        gyro[1],
        gyro[2],
        gyro[3],
        gyro[4],
        gyro[5],
        force[0],
        force[1],
        force[2],
        force[3],
        force[4],
        force[5],
        corrections[0],
        corrections[1],
    )
    return propagated_covariance_kernel(state, covariance, noise_terms)


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
    at its end and the ``noise_terms`` of :func:`noise_coefficients`; the Earth's rates as
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


_DIM = ERROR_STATES.dim
_ATTITUDE = ERROR_STATES.attitude.start
_VELOCITY = ERROR_STATES.velocity.start
_POSITION = ERROR_STATES.position.start
_GYRO_BIAS = ERROR_STATES.gyro_bias.start
_ACCEL_BIAS = ERROR_STATES.accel_bias.start


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
