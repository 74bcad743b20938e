"""A navigation solution's vectors from the nominal state, in one compiled call.

The bias-corrected rates, ω_nb, the bias-corrected force, the velocity and the ``map``
position of a solution, written into one vector: what a built solution
(:class:`buoy_nav.solution.NavSolution`) holds as its arrays and what a row
(:mod:`buoy_nav.solution_rows`) copies, computed once for both.
"""

import numba
import numpy as np

from buoy_nav import earth
from buoy_nav.strapdown_kernel import (
    ACCEL_BIAS,
    ALTITUDE,
    ATTITUDE,
    GYRO_BIAS,
    LATITUDE,
    LONGITUDE,
    NAV_FRAME_RATE,
    ROTATION,
    STATE_SIZE,
    VELOCITY,
)

# The slices of the vector.
ATTITUDE_XYZW = slice(0, 4)
ANGULAR_RATE = slice(4, 7)
ANGULAR_RATE_NB = slice(7, 10)
SPECIFIC_FORCE = slice(10, 13)
VELOCITY_ENU = slice(13, 16)
POSITION_MAP = slice(16, 19)
SIZE = 19

_ecef_from_geodetic_scalar = numba.njit(cache=True)(earth.ecef_from_geodetic_scalar)
_enu_from_ecef_scalar = numba.njit(cache=True)(earth.enu_from_ecef_scalar)


@numba.njit(cache=True)
def solution_vector(state, gx, gy, gz, fx, fy, fz, plane_terms):
    """The arrays of the solution of the nominal ``state`` (strapdown_kernel's layout) with
    the raw gyro (body rad/s) and specific force (body m/s²) there, in one vector (the slices
    above): the attitude, the bias-corrected rate ω_ib and ω_nb = ω_ib − R_nbᵀ ω_in, the
    bias-corrected force, the velocity and the ``map`` position (m) of the plane whose
    ``scalar_terms`` are ``plane_terms``. The sums are grouped as the interpreter groups
    them (the position by the plane's own scalar conversion, compiled), so a solution is the
    same to the bit whichever computes it."""
    vector = np.empty(SIZE)
    for i in range(4):
        vector[i] = state[ATTITUDE + i]
    wx = gx - state[GYRO_BIAS]
    wy = gy - state[GYRO_BIAS + 1]
    wz = gz - state[GYRO_BIAS + 2]
    vector[4], vector[5], vector[6] = wx, wy, wz
    ie, in_, iu = state[NAV_FRAME_RATE], state[NAV_FRAME_RATE + 1], state[NAV_FRAME_RATE + 2]
    for i, w in enumerate((wx, wy, wz)):
        r0, r1, r2 = state[ROTATION + i], state[ROTATION + 3 + i], state[ROTATION + 6 + i]
        vector[7 + i] = w - (r0 * ie + r1 * in_ + r2 * iu)
    vector[10] = fx - state[ACCEL_BIAS]
    vector[11] = fy - state[ACCEL_BIAS + 1]
    vector[12] = fz - state[ACCEL_BIAS + 2]
    for i in range(3):
        vector[13 + i] = state[VELOCITY + i]
    x, y, z = _ecef_from_geodetic_scalar(state[LATITUDE], state[LONGITUDE], state[ALTITUDE])
    vector[16], vector[17], vector[18] = _enu_from_ecef_scalar(x, y, z, plane_terms)
    return vector


def load_compiled_solution_vector() -> None:
    """Compile the solution's vector, or load it from the cache, now (see
    :func:`buoy_nav.mechanization.load_compiled_kernels`)."""
    state = np.zeros(STATE_SIZE)
    state[ATTITUDE + 3] = 1.0
    solution_vector(state, 0.0, 0.0, 0.0, 0.0, 0.0, 9.8, np.zeros(12))
