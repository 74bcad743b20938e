"""GNSS position of the primary antenna.

The measured antenna position (WGS-84) is expressed in the ENU tangent plane at the nominal
``base_link`` position, where the prediction is the lever arm turned into ENU, ``R_nb l``. The
position error δp is in ENU metres of that plane (better conditioned than δL, δλ, δh), so under
the convention of :func:`buoy_nav.error_state_filter.inject_error_state`::

    p_ant = δp + Exp([φ×]) R_nb l   ⇒   ∂p_ant/∂φ = −[(R_nb l)×],   ∂p_ant/∂δp = I.
"""

import numpy as np

from buoy_nav.earth import enu_offset_scalar
from buoy_nav.error_state_filter import ATTITUDE, POSITION, STATE_DIM
from buoy_nav.measurements import MeasurementModel, floored_covariance
from buoy_nav.rotations import skew


def position_model(
    measured_latitude_rad: float,
    measured_longitude_rad: float,
    measured_altitude_m: float,
    covariance_enu_m2,
    latitude_rad: float,
    longitude_rad: float,
    altitude_m: float,
    rotation_nb,
    lever_arm_body_m,
    variance_floor_m2: float = 0.0,
) -> MeasurementModel:
    """Linearised antenna-position measurement, in ENU metres at the nominal position.

    measured_*: antenna latitude, longitude (rad) and ellipsoidal altitude (m) from the receiver.
    covariance_enu_m2: its 3×3 ENU covariance, diagonal raised to at least ``variance_floor_m2``.
    latitude_rad, longitude_rad, altitude_m, rotation_nb: nominal ``base_link`` position and R_nb.
    lever_arm_body_m: antenna position in ``base_link`` (m).
    """
    measured = np.array(
        enu_offset_scalar(
            latitude_rad,
            longitude_rad,
            altitude_m,
            measured_latitude_rad,
            measured_longitude_rad,
            measured_altitude_m,
        )
    )
    lever_enu = np.asarray(rotation_nb, dtype=float) @ np.asarray(lever_arm_body_m, dtype=float)
    jacobian = np.zeros((3, STATE_DIM))
    jacobian[:, ATTITUDE] = -skew(lever_enu)
    jacobian[:, POSITION] = np.eye(3)
    return MeasurementModel(
        predicted=lever_enu,
        innovation=measured - lever_enu,
        jacobian=jacobian,
        covariance=floored_covariance(covariance_enu_m2, variance_floor_m2),
    )
