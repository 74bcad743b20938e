"""The compiled covariance arithmetic of the error-state filter: the propagation, the
innovation gate, the stacked update in Joseph form and the covariance reset after the
injection, each one call on the filter's covariance
(:class:`buoy_nav.error_state_filter.ErrorStateFilter` is the one caller; every aiding
source's measurement goes through them).

Compiled (numba, cached on disk) because at a motion pack's 10 Hz each sample carries one or two
measurements, and the interpreter's cost of the few dozen small matrix operations of a gate and
an update (3 × 15 and 15 × 15) outweighed the arithmetic many times; the products are loops
that skip the zeros of the sparse Jacobians and transition matrices, which at these sizes
also beat a BLAS call. The loops sum in another order than numpy's BLAS, so results differ
from a numpy formulation of the same algebra by the rounding of float64 (relative 1e-16 a
product, far below 1e-12 after an update).
"""

import math

import numba
import numpy as np


@numba.njit(cache=True)
def _cholesky_lower(matrix):
    """The lower Cholesky factor of the symmetric ``matrix`` and whether it is positive
    definite (the factor is then incomplete)."""
    size = matrix.shape[0]
    factor = np.zeros((size, size))
    for j in range(size):
        pivot = matrix[j, j]
        for k in range(j):
            pivot -= factor[j, k] * factor[j, k]
        if not pivot > 0.0:
            return factor, False
        root = math.sqrt(pivot)
        factor[j, j] = root
        for i in range(j + 1, size):
            value = matrix[i, j]
            for k in range(j):
                value -= factor[i, k] * factor[j, k]
            factor[i, j] = value / root
    return factor, True


@numba.njit(cache=True)
def _solve_with_cholesky(factor, right_hand_sides):
    """X of (L Lᵀ) X = B, L = ``factor`` (m × m lower), B = ``right_hand_sides`` (m × k)."""
    size, columns = right_hand_sides.shape
    solution = right_hand_sides.copy()
    for c in range(columns):
        for i in range(size):
            value = solution[i, c]
            for k in range(i):
                value -= factor[i, k] * solution[k, c]
            solution[i, c] = value / factor[i, i]
        for i in range(size - 1, -1, -1):
            value = solution[i, c]
            for k in range(i + 1, size):
                value -= factor[k, i] * solution[k, c]
            solution[i, c] = value / factor[i, i]
    return solution


@numba.njit(cache=True)
def _symmetrise(matrix):
    """½ (A + Aᵀ) in place."""
    size = matrix.shape[0]
    for i in range(size):
        for j in range(i + 1, size):
            mean = 0.5 * (matrix[i, j] + matrix[j, i])
            matrix[i, j] = mean
            matrix[j, i] = mean


@numba.njit(cache=True)
def _product(a, b):
    """A B of two C-ordered matrices, by loops: at these sizes a BLAS call costs more than the
    arithmetic."""
    rows, inner = a.shape
    columns = b.shape[1]
    result = np.zeros((rows, columns))
    for i in range(rows):
        for k in range(inner):
            a_ik = a[i, k]
            if a_ik != 0.0:
                for j in range(columns):
                    result[i, j] += a_ik * b[k, j]
    return result


@numba.njit(cache=True)
def _innovation_covariance(hp, jacobian, measurement_covariance):
    """S = (H P) Hᵀ + R, symmetrised."""
    s = _product(hp, jacobian.T.copy()) + measurement_covariance
    _symmetrise(s)
    return s


@numba.njit(cache=True)
def propagated(covariance, transition, process_noise):
    """Φ P Φᵀ + Q_d, symmetrised: the covariance ``covariance`` P carried over one propagation
    interval by the transition matrix ``transition`` Φ with the process noise
    ``process_noise`` Q_d (all n × n, error-state units)."""
    result = _product(_product(transition, covariance), transition.T.copy()) + process_noise
    _symmetrise(result)
    return result


@numba.njit(cache=True)
def innovation_test(covariance, innovation, jacobian, measurement_covariance):
    """Normalised innovation squared νᵀ S⁻¹ ν and S = H P Hᵀ + R (symmetrised); NaN when S is
    not positive definite. ``covariance`` P (n × n), ``innovation`` ν (m,), ``jacobian`` H
    (m × n), ``measurement_covariance`` R (m × m), in the units of the error state and the
    measurement."""
    s = _innovation_covariance(_product(jacobian, covariance), jacobian, measurement_covariance)
    return _normalised_squared(innovation, s), s


@numba.njit(cache=True)
def _normalised_squared(innovation, innovation_covariance):
    """νᵀ S⁻¹ ν; NaN when S is not positive definite."""
    factor, positive = _cholesky_lower(innovation_covariance)
    if not positive:
        return math.nan
    solved = _solve_with_cholesky(factor, innovation.reshape(-1, 1).copy())
    nis = 0.0
    for i in range(innovation.shape[0]):
        nis += innovation[i] * solved[i, 0]
    return nis


@numba.njit(cache=True)
def joseph_update(covariance, innovation, jacobian, measurement_covariance):
    """The posterior covariance (I − K H) P (I − K H)ᵀ + K R Kᵀ (Joseph form, symmetrised) and
    the error estimate K ν of the stacked measurement (ν, H, R as :func:`innovation_test`), and
    whether S was positive definite (else the covariance is returned unchanged and the estimate
    is zero)."""
    hp = _product(jacobian, covariance)
    return _joseph_posterior(
        covariance,
        innovation,
        jacobian,
        measurement_covariance,
        hp,
        _innovation_covariance(hp, jacobian, measurement_covariance),
    )


@numba.njit(cache=True)
def _joseph_posterior(covariance, innovation, jacobian, measurement_covariance, hp, s):
    """:func:`joseph_update` from H P (``hp``) and S (``s``) already formed."""
    size = covariance.shape[0]
    factor, positive = _cholesky_lower(s)
    if not positive:
        return covariance, np.zeros(size), False
    gain_t = _solve_with_cholesky(factor, hp)
    gain = gain_t.T.copy()
    i_kh = -_product(gain, jacobian)
    for i in range(size):
        i_kh[i, i] += 1.0
    posterior = _product(_product(i_kh, covariance), i_kh.T.copy())
    posterior += _product(_product(gain, measurement_covariance), gain_t)
    _symmetrise(posterior)
    correction = np.zeros(size)
    for i in range(size):
        for k in range(innovation.shape[0]):
            correction[i] += gain[i, k] * innovation[k]
    return posterior, correction, True


@numba.njit(cache=True)
def attitude_reset(covariance, correction, attitude_start):
    """The covariance after the injection of ``correction`` and the reset of the error mean:
    the attitude rows and columns (the 3 from ``attitude_start``) transformed by
    G = I + ½[δφ̂×] (see :meth:`ErrorStateFilter.reset_after_injection`), symmetrised; and
    whether it is positive definite."""
    half = 0.5 * correction[attitude_start : attitude_start + 3]
    g = np.eye(3)
    g[0, 1], g[0, 2] = -half[2], half[1]
    g[1, 0], g[1, 2] = half[2], -half[0]
    g[2, 0], g[2, 1] = -half[1], half[0]
    size = covariance.shape[0]
    a = attitude_start
    reset = covariance.copy()
    for i in range(3):
        for j in range(size):
            reset[a + i, j] = (g[i, 0] * covariance[a, j] + g[i, 1] * covariance[a + 1, j]) + g[
                i, 2
            ] * covariance[a + 2, j]
    for i in range(size):
        r0, r1, r2 = reset[i, a], reset[i, a + 1], reset[i, a + 2]
        for j in range(3):
            reset[i, a + j] = (r0 * g[j, 0] + r1 * g[j, 1]) + r2 * g[j, 2]
    _symmetrise(reset)
    return reset, _cholesky_lower(reset)[1]


@numba.njit(cache=True)
def is_positive_definite(matrix):
    """Whether the symmetric ``matrix`` is positive definite."""
    return _cholesky_lower(matrix)[1]


@numba.njit(cache=True)
def gated_stacked_update(
    covariance,
    innovation,
    jacobian,
    measurement_covariance,
    block_ends,
    gate_thresholds,
    attitude_start,
    gate_covariance,
):
    """The innovation test of each measurement of a stack (:func:`innovation_test` of its rows, up
    to ``block_ends[k]``, with its diagonal block of the ``gate_covariance``, or of R when that is
    empty, 0 × 0) and, when each passes its ``gate_thresholds[k]``, the stacked
    :func:`joseph_update` with R and the :func:`attitude_reset` after the injection: the NIS of
    each, the gates' S (each one's S on its diagonal), whether every one passed and S of the stack
    was positive definite, and then the covariance after the update and the reset, the error
    estimate and whether that covariance is positive definite (else ``covariance``, zeros and True).
    The same arithmetic as gating each measurement alone and updating with the stack."""
    count = block_ends.shape[0]
    # Each block's rows of H P and its diagonal block of the stack's S are, element by element,
    # those of the block alone: the stack forms them once.
    hp = _product(jacobian, covariance)
    s = _innovation_covariance(hp, jacobian, measurement_covariance)
    gate_s = s
    if gate_covariance.shape[0] > 0:
        gate_s = _innovation_covariance(hp, jacobian, gate_covariance)
    nis = np.empty(count)
    passed = True
    start = 0
    for k in range(count):
        end = block_ends[k]
        nis[k] = _normalised_squared(
            innovation[start:end].copy(), gate_s[start:end, start:end].copy()
        )
        passed = passed and nis[k] <= gate_thresholds[k]
        start = end
    unchanged = np.zeros(covariance.shape[0])
    if not passed:
        return nis, gate_s, False, covariance, unchanged, True
    posterior, correction, positive = _joseph_posterior(
        covariance, innovation, jacobian, measurement_covariance, hp, s
    )
    if not positive:
        return nis, gate_s, False, covariance, unchanged, True
    reset, positive_definite = attitude_reset(posterior, correction, attitude_start)
    return nis, gate_s, True, reset, correction, positive_definite
