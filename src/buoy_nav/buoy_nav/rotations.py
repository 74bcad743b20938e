"""Rotation conventions and functions of the navigation core.

Conventions (fixed for the whole project):

* ``R_nb`` rotates body (``base_link``, forward-left-up) vectors into ENU (``map``).
* Euler angles: ``R_nb = Rz(yaw) · Ry(pitch) · Rx(roll)``; yaw 0 points East and grows
  counter-clockwise (the same as scipy ``Rotation.from_euler("ZYX", [yaw, pitch, roll])``).
* Quaternions are Hamilton quaternions stored in scipy order ``(x, y, z, w)``; the quaternion
  ``q`` of ``R_nb`` rotates a body vector ``v`` into ``q ⊗ v ⊗ q*``, and the product
  ``a ⊗ b`` has the matrix ``R(a) · R(b)``.

The scalar quaternion functions take and return plain tuples of floats because the strapdown
integrator calls them at the IMU rate, where a numpy call costs more than the arithmetic; the
compiled kernels (numba) compile them from this one source. Those that another scalar function
calls are also registered with numba (``register_jitable``), so that compiled code can call
them there too.
"""

import math

import numpy as np
from numba.extending import register_jitable

Quaternion = tuple[float, float, float, float]

IDENTITY_QUATERNION: Quaternion = (0.0, 0.0, 0.0, 1.0)

# Below this rotation angle (rad) sin(θ/2)/θ and cos(θ/2) use their Taylor series, which are
# exact to double precision there and avoid dividing by a vanishing angle.
_SMALL_ANGLE_RAD = 1e-4


def skew(vector) -> np.ndarray:
    """Cross-product matrix ``[v×]`` (3×3) such that ``skew(a) @ b == cross(a, b)``."""
    x, y, z = float(vector[0]), float(vector[1]), float(vector[2])
    return np.array(((0.0, -z, y), (z, 0.0, -x), (-y, x, 0.0)))


def cross(a, b) -> np.ndarray:
    """Cross product of two 3-vectors (faster than numpy.cross for single vectors)."""
    ax, ay, az = float(a[0]), float(a[1]), float(a[2])
    bx, by, bz = float(b[0]), float(b[1]), float(b[2])
    return np.array((ay * bz - az * by, az * bx - ax * bz, ax * by - ay * bx))


def quaternion_multiply(a: Quaternion, b: Quaternion) -> Quaternion:
    """Hamilton product ``a ⊗ b`` of two (x, y, z, w) quaternions; ``R(a ⊗ b) = R(a) R(b)``.

    The components may also be equally shaped arrays (a batch, elementwise)."""
    ax, ay, az, aw = a
    bx, by, bz, bw = b
    return (
        aw * bx + ax * bw + ay * bz - az * by,
        aw * by - ax * bz + ay * bw + az * bx,
        aw * bz + ax * by - ay * bx + az * bw,
        aw * bw - ax * bx - ay * by - az * bz,
    )


def quaternion_from_rotation_vector(x: float, y: float, z: float) -> Quaternion:
    """Unit (x, y, z, w) quaternion of the rotation vector (x, y, z) (axis × angle, rad)."""
    angle_sq = x * x + y * y + z * z
    if angle_sq < _SMALL_ANGLE_RAD * _SMALL_ANGLE_RAD:
        # sin(θ/2)/θ = 1/2 − θ²/48 + …, cos(θ/2) = 1 − θ²/8 + θ⁴/384 − …
        half_sinc = 0.5 - angle_sq / 48.0
        w = 1.0 - angle_sq / 8.0 + angle_sq * angle_sq / 384.0
    else:
        angle = math.sqrt(angle_sq)
        half_sinc = math.sin(0.5 * angle) / angle
        w = math.cos(0.5 * angle)
    return (x * half_sinc, y * half_sinc, z * half_sinc, w)


@register_jitable
def normalize_quaternion(q: Quaternion) -> Quaternion:
    """Scale an (x, y, z, w) quaternion to unit norm, with a non-negative scalar part."""
    x, y, z, w = q
    norm = math.sqrt(x * x + y * y + z * z + w * w)
    if w < 0.0:
        norm = -norm
    return (x / norm, y / norm, z / norm, w / norm)


def rotation_matrix_elements(x, y, z, w) -> tuple:
    """Row-major elements (r00, r01, r02, r10, ..., r22) of the rotation matrix of the unit
    quaternion (x, y, z, w). The components may be floats or equally shaped arrays: the
    arithmetic is elementwise, so a quaternion gives bit-identical elements alone or in a batch.
    """
    xx, yy, zz = x * x, y * y, z * z
    xy, xz, yz = x * y, x * z, y * z
    wx, wy, wz = w * x, w * y, w * z
    return (
        1.0 - 2.0 * (yy + zz),
        2.0 * (xy - wz),
        2.0 * (xz + wy),
        2.0 * (xy + wz),
        1.0 - 2.0 * (xx + zz),
        2.0 * (yz - wx),
        2.0 * (xz - wy),
        2.0 * (yz + wx),
        1.0 - 2.0 * (xx + yy),
    )


def cross_components(a, b) -> tuple:
    """a × b of two 3-vectors given by components (floats or equally shaped arrays)."""
    a0, a1, a2 = a
    b0, b1, b2 = b
    return (a1 * b2 - a2 * b1, a2 * b0 - a0 * b2, a0 * b1 - a1 * b0)


def rotate_by_quaternion_components(quat_xyzw, vector) -> tuple:
    """R(q)·v of a quaternion (x, y, z, w) of any non-zero norm (normalised here) and a
    3-vector, by components: floats or equally shaped arrays, elementwise, so that one vector
    alone and a batch give bit-identical results. v + 2w(u×v) + 2u×(u×v) with u = (x, y, z)
    of the unit quaternion; the conjugate (−x, −y, −z, w) rotates by R(q)ᵀ."""
    x, y, z, w = quat_xyzw
    norm = np.sqrt(x * x + y * y + z * z + w * w)
    axis = (x / norm, y / norm, z / norm)
    scalar = w / norm
    twice_cross = tuple(2.0 * component for component in cross_components(axis, vector))
    return tuple(
        component + scalar * first + second
        for component, first, second in zip(
            vector, twice_cross, cross_components(axis, twice_cross), strict=True
        )
    )


def rotation_matrix_from_quaternion(q) -> np.ndarray:
    """3×3 rotation matrix of a unit (x, y, z, w) quaternion."""
    return np.array(rotation_matrix_elements(*(float(c) for c in q))).reshape(3, 3)


def quaternion_from_rotation_matrix(rotation) -> Quaternion:
    """Unit (x, y, z, w) quaternion (w ≥ 0) of a 3×3 rotation matrix (Shepperd's method)."""
    m = np.asarray(rotation, dtype=float)
    return quaternion_from_rotation_elements(*m.reshape(9).tolist())


def quaternion_from_rotation_elements(m00, m01, m02, m10, m11, m12, m20, m21, m22) -> Quaternion:
    """Unit (x, y, z, w) quaternion (w ≥ 0) of the rotation matrix of row-major elements
    ``m00 … m22`` (Shepperd's method: from the largest of the trace and the diagonal). Floats
    only, so that compiled code (numba) runs the same source."""
    trace = m00 + m11 + m22
    largest, candidate = 0, trace
    if m00 > candidate:
        largest, candidate = 1, m00
    if m11 > candidate:
        largest, candidate = 2, m11
    if m22 > candidate:
        largest = 3
    if largest == 0:
        s = 2.0 * math.sqrt(1.0 + trace)
        q = ((m21 - m12) / s, (m02 - m20) / s, (m10 - m01) / s, s / 4)
    elif largest == 1:
        s = 2.0 * math.sqrt(1.0 + m00 - m11 - m22)
        q = (s / 4, (m01 + m10) / s, (m02 + m20) / s, (m21 - m12) / s)
    elif largest == 2:
        s = 2.0 * math.sqrt(1.0 - m00 + m11 - m22)
        q = ((m01 + m10) / s, s / 4, (m12 + m21) / s, (m02 - m20) / s)
    else:
        s = 2.0 * math.sqrt(1.0 - m00 - m11 + m22)
        q = ((m02 + m20) / s, (m12 + m21) / s, s / 4, (m10 - m01) / s)
    return normalize_quaternion(q)


def rotation_matrix_from_rotation_vector(rotation_vector) -> np.ndarray:
    """Matrix exponential ``Exp([θ×])`` of a rotation vector θ (rad), 3×3."""
    x, y, z = (float(c) for c in rotation_vector)
    return rotation_matrix_from_quaternion(quaternion_from_rotation_vector(x, y, z))


def rotation_vector_from_rotation_matrix(rotation) -> np.ndarray:
    """Matrix logarithm of a rotation matrix as a rotation vector (rad), angle in [0, π]."""
    return np.array(rotation_vector_from_quaternion(*quaternion_from_rotation_matrix(rotation)))


def rotation_vector_from_quaternion(x, y, z, w) -> tuple[float, float, float]:
    """Rotation vector (rad, angle in [0, π]) of a unit (x, y, z, w) quaternion with w ≥ 0.
    Floats only (compiled code runs the same source)."""
    sin_half = math.sqrt(x * x + y * y + z * z)
    if sin_half < 1e-12:
        return 2.0 * x, 2.0 * y, 2.0 * z
    scale = 2.0 * math.atan2(sin_half, w) / sin_half
    return x * scale, y * scale, z * scale


def rotation_matrix_from_euler(roll_rad: float, pitch_rad: float, yaw_rad: float) -> np.ndarray:
    """``R_nb = Rz(yaw) · Ry(pitch) · Rx(roll)`` (body FLU → ENU) from angles in rad."""
    sr, cr = math.sin(roll_rad), math.cos(roll_rad)
    sp, cp = math.sin(pitch_rad), math.cos(pitch_rad)
    sy, cy = math.sin(yaw_rad), math.cos(yaw_rad)
    return np.array(
        (
            (cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr),
            (sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr),
            (-sp, cp * sr, cp * cr),
        )
    )


def euler_from_rotation_matrix(rotation) -> tuple[float, float, float]:
    """(roll, pitch, yaw) in rad of ``R_nb = Rz(yaw) · Ry(pitch) · Rx(roll)``.

    Roll and yaw are in (−π, π], pitch in [−π/2, π/2].
    """
    m = np.asarray(rotation, dtype=float)
    roll = math.atan2(m[2, 1], m[2, 2])
    pitch = math.asin(max(-1.0, min(1.0, -m[2, 0])))
    yaw = math.atan2(m[1, 0], m[0, 0])
    return roll, pitch, yaw


def wrap_angle(angle_rad: float) -> float:
    """Wrap an angle (rad) into (−π, π]. Written for the interpreter and numba alike: ``%`` is
    the C library's fmod with the divisor's sign, in both."""
    wrapped = (angle_rad + math.pi) % (2.0 * math.pi)
    if wrapped <= 0.0:
        wrapped += 2.0 * math.pi
    return wrapped - math.pi
