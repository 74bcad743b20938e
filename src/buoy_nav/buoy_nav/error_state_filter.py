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

The error dynamics (Φ, Q_d and the covariance's propagation) are :mod:`buoy_nav.error_dynamics`.
"""

import itertools
import math
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from buoy_nav import kalman_kernel
from buoy_nav import strapdown_kernel as kernel
from buoy_nav.chi_square import chi_square_quantile
from buoy_nav.config import FusionConfig
from buoy_nav.rotations import (
    rotation_matrix_from_quaternion,
)
from buoy_nav.state_layout import StateLayout

ERROR_STATES = StateLayout(
    ("attitude", 3), ("velocity", 3), ("position", 3), ("gyro_bias", 3), ("accel_bias", 3)
)
"""The error state of this filter (see the module docstring). States added for a richer model
(gyro Gauss-Markov drift as ``("gyro_drift", 3)``) are appended here, with their dynamics in
:func:`buoy_nav.error_dynamics.discrete_error_model` and :func:`inject_error_state`."""
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
# Smallest eigenvalue kept when a covariance has to be repaired, relative to the largest one.
_EIGENVALUE_FLOOR_RELATIVE = 1e-15
_NO_GATE_COVARIANCE = np.zeros((0, 0))
"""The compiled gated update's gate covariance when the gates take R."""


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


def strapdown_vector(state: NavState) -> np.ndarray:
    """The strapdown state vector of ``state`` (:mod:`buoy_nav.strapdown_kernel`'s layout; what a
    :class:`NavState` does not hold is zero)."""
    nominal = np.zeros(kernel.STATE_SIZE)
    nominal[kernel.ATTITUDE : kernel.ATTITUDE + 4] = state.attitude_xyzw
    nominal[kernel.VELOCITY : kernel.VELOCITY + 3] = state.velocity_enu_mps
    nominal[kernel.LATITUDE] = state.latitude_rad
    nominal[kernel.LONGITUDE] = state.longitude_rad
    nominal[kernel.ALTITUDE] = state.altitude_m
    nominal[kernel.GYRO_BIAS : kernel.GYRO_BIAS + 3] = state.gyro_bias_rad_s
    nominal[kernel.ACCEL_BIAS : kernel.ACCEL_BIAS + 3] = state.accel_bias_mps2
    return nominal


def inject_error_state(state: NavState, error) -> NavState:
    """Apply an error state of :data:`ERROR_STATES` to a nominal state (THE error-injection
    convention, :func:`buoy_nav.strapdown_kernel.inject_error_state`, which the integrator
    applies to its own state in place)."""
    nominal = strapdown_vector(state)
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


class StackedUpdate(NamedTuple):
    """What :meth:`ErrorStateFilter.gated_update` made of a stack of measurements: the gate of
    each; whether each passed and the update was made; the covariance after the update and the
    reset (else the one given), the correction (error state; zeros when not made) and whether
    that covariance is positive definite."""

    gates: list[GateResult]
    accepted: bool
    covariance: np.ndarray
    correction: np.ndarray
    positive_definite: bool


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

    def gated_update(
        self,
        innovation,
        jacobian,
        measurement_covariance,
        dimensions,
        probabilities,
        gate_covariance=None,
    ) -> "StackedUpdate":
        """Gate each measurement of a stack (``dimensions``: the rows of each, in order) at its
        chi-square ``probabilities`` and, when each passes, apply the stack in Joseph form and
        reset after the injection, in one compiled call; nothing is changed here. The same
        arithmetic as :meth:`gate` of each, :meth:`update` and :meth:`reset_after_injection`.

        innovation ν (m,), jacobian H (m × states), measurement covariance R (m × m, block
        diagonal), stacked; ``gate_covariance`` the noise the gates take, stacked as R (None:
        R)."""
        nu, h, r = _measurement_arrays(innovation, jacobian, measurement_covariance)
        gate_r = _NO_GATE_COVARIANCE
        if gate_covariance is not None:
            gate_r = np.ascontiguousarray(gate_covariance, dtype=float)
        thresholds = [
            self.gate_threshold(dimension, probability)
            for dimension, probability in zip(dimensions, probabilities, strict=True)
        ]
        ends = list(itertools.accumulate(dimensions))
        nis, innovation_covariance, accepted, covariance, correction, positive = (
            kalman_kernel.gated_stacked_update(
                self.covariance,
                nu,
                h,
                r,
                np.array(ends),
                np.array(thresholds),
                self.states.attitude.start,
                gate_r,
            )
        )
        gates = []
        start = 0
        for end, threshold, block_nis in zip(ends, thresholds, nis.tolist(), strict=True):
            gates.append(
                GateResult(
                    block_nis <= threshold,
                    block_nis,
                    threshold,
                    innovation_covariance[start:end, start:end].copy(),
                )
            )
            start = end
        return StackedUpdate(gates, accepted, covariance, correction, positive)

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
