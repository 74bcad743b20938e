"""GNSS velocity of the primary antenna.

The antenna at lever arm ``l`` (``base_link``, m) moves over ground with

    v_ant = v + R_nb (ω_nb × l),   ω_nb = ω_ib − R_nb^T ω_in

(ENU, m/s), where ω_ib = ω_raw − b_g is the bias-corrected gyro rate (body, rad/s) and
ω_in = ω_ie + ω_en the rotation of ENU (rad/s). Equivalently
``v_ant = v + R_nb (ω_ib × l) − ω_in × (R_nb l)``.

Jacobian under the convention of :func:`buoy_nav.error_state_filter.inject_error_state`
(``R_true = Exp([φ×]) R_nb``, ``v_true = v + δv``, ``b_true = b + δb`` so ``ω_true = ω − δb``)::

    ∂v_ant/∂φ   = −[(R_nb (ω_ib × l))×] + [ω_in×][(R_nb l)×]
    ∂v_ant/∂δv  = I
    ∂v_ant/∂δb_g = R_nb [l×]

(the change of ω_in with δv, below 1e-6 of the other terms, is left out).
"""

import numpy as np

from buoy_nav.error_state_filter import ATTITUDE, GYRO_BIAS, STATE_DIM, VELOCITY
from buoy_nav.measurements import MeasurementModel, floored_covariance
from buoy_nav.rotations import cross, skew


def predicted_antenna_velocity_enu_mps(
    velocity_enu_mps,
    rotation_nb,
    angular_rate_ib_body_rad_s,
    nav_frame_rate_enu_rad_s,
    lever_arm_body_m,
) -> np.ndarray:
    """Velocity over ground of a point at ``lever_arm_body_m`` of ``base_link`` (ENU, m/s)."""
    rotation = np.asarray(rotation_nb, dtype=float)
    lever_arm = np.asarray(lever_arm_body_m, dtype=float)
    return (
        np.asarray(velocity_enu_mps, dtype=float)
        + rotation @ cross(angular_rate_ib_body_rad_s, lever_arm)
        - cross(nav_frame_rate_enu_rad_s, rotation @ lever_arm)
    )


def velocity_model(
    measured_velocity_enu_mps,
    covariance_m2s2,
    velocity_enu_mps,
    rotation_nb,
    raw_gyro_rad_s,
    gyro_bias_rad_s,
    nav_frame_rate_enu_rad_s,
    lever_arm_body_m,
    variance_floor_m2s2: float = 0.0,
) -> MeasurementModel:
    """Linearised antenna-velocity measurement.

    measured_velocity_enu_mps: receiver velocity of the antenna (ENU, m/s).
    covariance_m2s2: its 3×3 covariance, diagonal raised to at least ``variance_floor_m2s2``.
    velocity_enu_mps, rotation_nb, gyro_bias_rad_s: nominal state (base_link origin velocity
    ENU, R_nb, body gyro bias). raw_gyro_rad_s: gyro sample at the measurement stamp (body).
    nav_frame_rate_enu_rad_s: ω_ie + ω_en at the nominal state. lever_arm_body_m: antenna
    position in ``base_link`` (m).
    """
    rotation = np.asarray(rotation_nb, dtype=float)
    lever_arm = np.asarray(lever_arm_body_m, dtype=float)
    rate = np.asarray(raw_gyro_rad_s, dtype=float) - np.asarray(gyro_bias_rad_s, dtype=float)
    frame_rate = np.asarray(nav_frame_rate_enu_rad_s, dtype=float)
    lever_enu = rotation @ lever_arm
    rotation_velocity = rotation @ cross(rate, lever_arm)
    predicted = (
        np.asarray(velocity_enu_mps, dtype=float) + rotation_velocity - cross(frame_rate, lever_enu)
    )
    jacobian = np.zeros((3, STATE_DIM))
    jacobian[:, ATTITUDE] = -skew(rotation_velocity) + skew(frame_rate) @ skew(lever_enu)
    jacobian[:, VELOCITY] = np.eye(3)
    jacobian[:, GYRO_BIAS] = rotation @ skew(lever_arm)
    return MeasurementModel(
        predicted=predicted,
        innovation=np.asarray(measured_velocity_enu_mps, dtype=float) - predicted,
        jacobian=jacobian,
        covariance=floored_covariance(covariance_m2s2, variance_floor_m2s2),
    )
