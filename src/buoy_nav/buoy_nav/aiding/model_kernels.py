"""What the aiding sources' compiled measurement functions share (numba, cached on disk): the
vector algebra, compiled from its one source in :mod:`buoy_nav.rotations`, the tangent plane's
offsets from :mod:`buoy_nav.earth`'s, the floored
measurement covariance and the placing of a Jacobian's blocks; and the checks of a measurement's
arrays that every source's validation makes (:mod:`buoy_nav.aiding.base`), a few tenths of a
microsecond compiled against two for numpy's calls on arrays this small.

A source's measurement function is one compiled call from the measurement and the nominal
state to the predicted measurement, innovation, Jacobian and noise, so that the engine can
model, gate and update a stamp's measurements without the interpreter's cost of their few
dozen small array operations. Products of a matrix and a vector, or of two 3×3 matrices, are
``np.dot``, which numba hands to the BLAS that numpy's ``@`` calls: a compiled model equals the
numpy formulation of the same algebra to the bit (a loop would sum in another order)."""

import math

import numba
import numpy as np

from buoy_nav import earth, rotations

# What a compiled stretch's measurement function makes of a measurement (its ``fate``): a
# model, none for want of geometry (the engine's ``None``), a refusal (the source's
# ``stretch_refusal`` reason), or a case the engine is to take (the measurement's values taken
# for a place the filter has left).
HOLDS, NO_GEOMETRY, REFUSED, LEFT_TO_THE_ENGINE = range(4)

cross = numba.njit(cache=True)(rotations.cross)
skew = numba.njit(cache=True)(rotations.skew)
enu_offset = numba.njit(cache=True)(earth.enu_offset_scalar)
wrap_angle = numba.njit(cache=True)(rotations.wrap_angle)


@numba.njit(cache=True)
def floored_covariance(covariance, variance_floor):
    """The square ``covariance`` symmetrised, ½ (C + Cᵀ), with every variance on its diagonal
    raised to at least ``variance_floor`` (same units), as a new array."""
    size = covariance.shape[0]
    result = np.empty((size, size))
    for i in range(size):
        for j in range(size):
            result[i, j] = 0.5 * (covariance[i, j] + covariance[j, i])
    for i in range(size):
        if result[i, i] < variance_floor:
            result[i, i] = variance_floor
    return result


@numba.njit(cache=True)
def place_block(jacobian, column_start, block):
    """Write ``block`` (rows × 3) into the columns of ``jacobian`` from ``column_start``: the
    derivative by one three-component error state (:mod:`buoy_nav.state_layout`)."""
    for i in range(block.shape[0]):
        for j in range(block.shape[1]):
            jacobian[i, column_start + j] = block[i, j]


@numba.njit(cache=True)
def place_identity(jacobian, column_start):
    """Write the 3 × 3 identity into the columns of ``jacobian`` from ``column_start``."""
    for i in range(3):
        jacobian[i, column_start + i] = 1.0


# Division by a zero horizontal length gives inf, not an exception: the caller judges the
# geometry from the vector returned and discards such a model.
@numba.njit(cache=True, error_model="numpy")
def azimuth_model(rotation_nb, body_vector, attitude_start, state_count):
    """The azimuth of a body vector's horizontal projection at the nominal R_nb: the vector in
    ENU (the units of ``body_vector``), its horizontal length squared, the predicted azimuth
    (rad, ENU, 0 = East, counter-clockwise) and the Jacobian (1 × ``state_count``) on the
    attitude from ``attitude_start``, ∂ψ/∂φ = (−e·u/h², −n·u/h², 1)."""
    vector = np.dot(rotation_nb, body_vector)
    east, north, up = vector[0], vector[1], vector[2]
    horizontal_sq = east * east + north * north
    jacobian = np.zeros((1, state_count))
    jacobian[0, attitude_start] = -east * up / horizontal_sq
    jacobian[0, attitude_start + 1] = -north * up / horizontal_sq
    jacobian[0, attitude_start + 2] = 1.0
    return vector, horizontal_sq, math.atan2(north, east), jacobian


@numba.njit(cache=True)
def all_finite(values):
    """Whether every element of the float array ``values`` is finite."""
    for value in values.flat:  # noqa: SIM110 (numba compiles no generator expression)
        if not math.isfinite(value):
            return False
    return True


@numba.njit(cache=True)
def has_non_positive_diagonal(matrix):
    """Whether an element on the diagonal of the square float ``matrix`` is zero or negative
    (NaN is neither)."""
    for i in range(matrix.shape[0]):  # noqa: SIM110 (numba compiles no generator expression)
        if matrix[i, i] <= 0.0:
            return True
    return False


def load_compiled_model_kernels() -> None:
    """Compile what the interpreter calls here, or load it from the cache, now (the sources'
    compiled models load with each source): the engine calls this when it is built."""
    floored_covariance(np.eye(3), 0.0)
    all_finite(np.zeros(3))
    all_finite(np.eye(3))
    has_non_positive_diagonal(np.eye(3))
