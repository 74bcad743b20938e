"""The numbers of one solution's ``nav/*`` messages that its arrays do not hold as they are, in
compiled calls: those that turn with the attitude (the body velocity, the twist covariance),
and those of the covariance blocks alone (the 6×6 covariances, the flat 3×3 ones), which
consecutive solutions share until the filter changes them.

A solution's covariance blocks change with every update, at the IMU rate where an aiding source
measures every sample (a motion pack): made by the interpreter, the 6×6 tuples and the rotated
twist covariance cost a tenth of such a row. The call keeps the interpreted order of every
operation: the rotation's elements as :func:`buoy_nav.rotations.rotation_matrix_elements`
forms them, R_nbᵀ·v summed in the order numpy's product sums, and R_nbᵀ·P_v·R_nb through
``np.dot``, which compiled code hands to the same BLAS as numpy's ``@``, so every number is the
interpreter's to the bit (``src/buoy_nav/test/test_nav_numbers.py``).
"""

import numba
import numpy as np

# Where each part begins in :func:`body_numbers` (row-major 6×6).
VELOCITY_BODY = 0  # 3
BODY_TWIST_COVARIANCE = 3  # 36
BODY_NUMBERS = 39
# ... and in :func:`covariance_numbers` (row-major 6×6, then 3×3 blocks).
POSE_COVARIANCE = 0  # 36
ENU_TWIST_COVARIANCE = 36  # 36
ATTITUDE_COVARIANCE = 72  # 9
POSITION_COVARIANCE = 81  # 9
GYRO_BIAS_COVARIANCE = 90  # 9
COVARIANCE_NUMBERS = 99


def body_numbers(
    attitude_xyzw, velocity_enu_mps, velocity_covariance_m2s2, gyro_bias_covariance_rad2_s2
) -> list[float]:
    """The numbers that turn with the attitude, as floats laid out as the offsets above say, of
    a solution with the quaternion ``attitude_xyzw`` of R_nb (body → ENU), the ENU velocity
    (m/s) and the 3×3 covariances of the velocity (ENU, m²/s²) and the gyro bias (body,
    rad²/s²): the body velocity R_nbᵀ·v (m/s), and ``nav/odometry``'s twist covariance,
    R_nbᵀ·P_v·R_nb (body, m²/s²) and the gyro bias's block (the body rate's, rad²/s²) on its
    diagonal."""
    return _body_numbers(
        attitude_xyzw, velocity_enu_mps, velocity_covariance_m2s2, gyro_bias_covariance_rad2_s2
    ).tolist()


def covariance_numbers(
    attitude_covariance_rad2,
    velocity_covariance_m2s2,
    position_covariance_m2,
    gyro_bias_covariance_rad2_s2,
) -> list[float]:
    """The numbers of a solution's 3×3 covariance blocks alone (attitude error ENU rad²,
    velocity ENU m²/s², position ENU m², gyro bias body rad²/s²), as floats laid out as the
    offsets above say: ``nav/odometry``'s pose covariance (the position's block, then the
    attitude's), ``nav/velocity``'s (the velocity's block, then zeros), and the attitude's,
    the position's and the gyro bias's blocks, flat."""
    return _covariance_numbers(
        attitude_covariance_rad2,
        velocity_covariance_m2s2,
        position_covariance_m2,
        gyro_bias_covariance_rad2_s2,
    ).tolist()


def body_numbers_of_solutions(
    attitude_xyzw, velocity_enu_mps, velocity_covariance_m2s2, gyro_bias_covariance_rad2_s2
) -> np.ndarray:
    """:func:`body_numbers` of many solutions at once, one row each (N × :data:`BODY_NUMBERS`),
    from their stacked quaternions (N × 4), ENU velocities (N × 3, m/s) and 3×3 covariances
    (N × 3 × 3: the velocity's, ENU m²/s², the gyro bias's, body rad²/s²); each row the numbers
    of that solution alone, to the bit."""
    return _body_numbers_of_solutions(
        np.ascontiguousarray(attitude_xyzw, dtype=float),
        np.ascontiguousarray(velocity_enu_mps, dtype=float),
        np.ascontiguousarray(velocity_covariance_m2s2, dtype=float),
        np.ascontiguousarray(gyro_bias_covariance_rad2_s2, dtype=float),
    )


@numba.njit(cache=True)
def _body_numbers_of_solutions(attitude, velocity, velocity_cov, gyro_bias_cov):
    rows = np.empty((attitude.shape[0], BODY_NUMBERS))
    for index in range(attitude.shape[0]):
        rows[index] = _body_numbers(
            attitude[index], velocity[index], velocity_cov[index], gyro_bias_cov[index]
        )
    return rows


def covariance_numbers_of_solutions(
    attitude_covariance_rad2,
    velocity_covariance_m2s2,
    position_covariance_m2,
    gyro_bias_covariance_rad2_s2,
) -> np.ndarray:
    """:func:`covariance_numbers` of many solutions at once, one row each
    (N × :data:`COVARIANCE_NUMBERS`), from their stacked 3×3 blocks (N × 3 × 3 each, the units
    of :func:`covariance_numbers`)."""
    return _covariance_numbers_of_solutions(
        np.ascontiguousarray(attitude_covariance_rad2, dtype=float),
        np.ascontiguousarray(velocity_covariance_m2s2, dtype=float),
        np.ascontiguousarray(position_covariance_m2, dtype=float),
        np.ascontiguousarray(gyro_bias_covariance_rad2_s2, dtype=float),
    )


@numba.njit(cache=True)
def _covariance_numbers_of_solutions(attitude_cov, velocity_cov, position_cov, gyro_bias_cov):
    rows = np.empty((attitude_cov.shape[0], COVARIANCE_NUMBERS))
    for index in range(attitude_cov.shape[0]):
        rows[index] = _covariance_numbers(
            attitude_cov[index], velocity_cov[index], position_cov[index], gyro_bias_cov[index]
        )
    return rows


@numba.njit(cache=True)
def _body_numbers(attitude, velocity, velocity_cov, gyro_bias_cov):
    x, y, z, w = attitude[0], attitude[1], attitude[2], attitude[3]
    xx, yy, zz = x * x, y * y, z * z
    xy, xz, yz = x * y, x * z, y * z
    wx, wy, wz = w * x, w * y, w * z
    rotation = np.empty((3, 3))
    rotation[0, 0] = 1.0 - 2.0 * (yy + zz)
    rotation[0, 1] = 2.0 * (xy - wz)
    rotation[0, 2] = 2.0 * (xz + wy)
    rotation[1, 0] = 2.0 * (xy + wz)
    rotation[1, 1] = 1.0 - 2.0 * (xx + zz)
    rotation[1, 2] = 2.0 * (yz - wx)
    rotation[2, 0] = 2.0 * (xz - wy)
    rotation[2, 1] = 2.0 * (yz + wx)
    rotation[2, 2] = 1.0 - 2.0 * (xx + yy)
    numbers = np.zeros(BODY_NUMBERS)
    ve, vn, vu = velocity[0], velocity[1], velocity[2]
    for axis in range(3):
        numbers[VELOCITY_BODY + axis] = (
            rotation[0, axis] * ve + rotation[1, axis] * vn
        ) + rotation[2, axis] * vu
    body_velocity_cov = np.dot(np.dot(rotation.T, velocity_cov), rotation)
    _place_block(numbers, BODY_TWIST_COVARIANCE, 0, body_velocity_cov)
    _place_block(numbers, BODY_TWIST_COVARIANCE, 3, gyro_bias_cov)
    return numbers


@numba.njit(cache=True)
def _covariance_numbers(attitude_cov, velocity_cov, position_cov, gyro_bias_cov):
    numbers = np.zeros(COVARIANCE_NUMBERS)
    _place_block(numbers, POSE_COVARIANCE, 0, position_cov)
    _place_block(numbers, POSE_COVARIANCE, 3, attitude_cov)
    _place_block(numbers, ENU_TWIST_COVARIANCE, 0, velocity_cov)
    for row in range(3):
        for column in range(3):
            flat = 3 * row + column
            numbers[ATTITUDE_COVARIANCE + flat] = attitude_cov[row, column]
            numbers[POSITION_COVARIANCE + flat] = position_cov[row, column]
            numbers[GYRO_BIAS_COVARIANCE + flat] = gyro_bias_cov[row, column]
    return numbers


@numba.njit(cache=True)
def _place_block(numbers, start, corner, block):
    """Put the 3×3 ``block`` on the diagonal of the row-major 6×6 at ``numbers[start:]``, its
    first row and column at ``corner`` (0 or 3)."""
    for row in range(3):
        for column in range(3):
            numbers[start + 6 * (corner + row) + corner + column] = block[row, column]


def load_compiled_nav_numbers() -> None:
    """Compile the nav numbers, or load them from the cache, now (see
    :func:`buoy_nav.mechanization.load_compiled_kernels`), for the solutions' read-only
    covariance blocks and for writable ones (the smoother's), and of many solutions at once
    (an offline run)."""
    attitude = np.array([0.0, 0.0, 0.0, 1.0])
    for writable in (True, False):
        blocks = np.eye(3)[np.newaxis].repeat(4, axis=0)
        blocks.setflags(write=writable)
        body_numbers(attitude, np.zeros(3), blocks[1], blocks[3])
        covariance_numbers(*blocks)
    body_numbers_of_solutions(
        attitude[np.newaxis], np.zeros((1, 3)), np.eye(3)[np.newaxis], np.eye(3)[np.newaxis]
    )
    covariance_numbers_of_solutions(*(np.eye(3)[np.newaxis],) * 4)
