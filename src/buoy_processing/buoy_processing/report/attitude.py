"""Attitude in the report's terms: Euler angles of the navigation, their 1σ from the filter's
covariance, and their errors against the truth.

Euler angles follow the suite's convention, R = Rz(yaw)·Ry(pitch)·Rx(roll) (yaw from East,
counter-clockwise); headings are clockwise from North. Angles are rad unless the name says
``_deg``.
"""

import numpy as np
from scipy.spatial.transform import Rotation, Slerp


def rpy_rad_from_quaternions(quat_xyzw) -> np.ndarray:
    """(M, 3) roll, pitch, yaw (rad) of body→ENU quaternions (x, y, z, w), for ReportData."""
    yaw_pitch_roll = Rotation.from_quat(np.asarray(quat_xyzw, dtype=float)).as_euler("ZYX")
    return yaw_pitch_roll[..., ::-1]


def rpy_sigma_rad(rpy_rad, attitude_covariance_enu_rad2) -> np.ndarray:
    """(M, 3) 1σ (rad) of roll, pitch and yaw (R = Rz(yaw)·Ry(pitch)·Rx(roll)) at attitudes
    ``rpy_rad`` (M, 3) whose error is the ENU rotation vector φ (R_true = Exp(φ)·R) with
    covariance ``attitude_covariance_enu_rad2`` (M, 3, 3).

    To first order the Euler errors are J·φ with J the inverse of the map from Euler increments
    to the rotation they make in ENU, [Rz·Ry·x̂ | Rz·ŷ | ẑ]; their covariance is J·P·Jᵀ.
    """
    _, pitch, yaw = np.moveaxis(np.asarray(rpy_rad, dtype=float), -1, 0)
    cos_yaw, sin_yaw, cos_pitch = np.cos(yaw), np.sin(yaw), np.cos(pitch)
    zeros, ones = np.zeros_like(yaw), np.ones_like(yaw)
    jacobian = np.stack(
        [
            np.stack([cos_yaw / cos_pitch, sin_yaw / cos_pitch, zeros], axis=-1),
            np.stack([-sin_yaw, cos_yaw, zeros], axis=-1),
            np.stack([cos_yaw * np.tan(pitch), sin_yaw * np.tan(pitch), ones], axis=-1),
        ],
        axis=-2,
    )
    covariance = jacobian @ np.asarray(attitude_covariance_enu_rad2, dtype=float)
    variances = np.einsum("...ij,...ij->...i", covariance, jacobian)
    return np.sqrt(np.maximum(variances, 0.0))


def interpolate_rpy_rad(stamps_ns: np.ndarray, source_stamps_ns, source_quat_xyzw) -> np.ndarray:
    """(N, 3) roll, pitch, yaw (rad) of the source attitudes slerped to ``stamps_ns`` (ns);
    NaN outside the span of the source stamps or when fewer than two source samples exist."""
    rpy = np.full((len(stamps_ns), 3), np.nan)
    unique_stamps, first = np.unique(
        np.asarray(source_stamps_ns, dtype=np.int64), return_index=True
    )
    if unique_stamps.size < 2:
        return rpy
    origin_ns = unique_stamps[0]
    slerp = Slerp((unique_stamps - origin_ns) * 1e-9, Rotation.from_quat(source_quat_xyzw[first]))
    t_s = (np.asarray(stamps_ns, dtype=np.int64) - origin_ns) * 1e-9
    inside = (t_s >= 0.0) & (t_s <= (unique_stamps[-1] - origin_ns) * 1e-9)
    if np.any(inside):
        rpy[inside] = rpy_rad_from_quaternions(slerp(t_s[inside]).as_quat())
    return rpy


def attitude_errors_deg(nav_rpy_rad: np.ndarray, truth_rpy_rad: np.ndarray) -> np.ndarray:
    """(M, 3) roll, pitch and heading errors, deg, wrapped to [-180, 180).

    Heading is measured clockwise from North, so its error is the negated yaw error.
    """
    errors = np.degrees(nav_rpy_rad - truth_rpy_rad)
    errors[:, 2] = -errors[:, 2]
    return (errors + 180.0) % 360.0 - 180.0
