"""Dual-antenna heading measurement.

The receiver reports the azimuth of the horizontal projection of the primary → secondary
baseline: ``ψ = atan2(b_N, b_E)`` with ``b = R_nb · (l_s − l_p)`` in ENU (yaw convention: 0 East,
counter-clockwise). This is exact for any tilt and any antenna placement, unlike a plain yaw
difference, which only holds for a baseline along body x on a level platform.

Jacobian under the convention ``R_true = Exp([φ×]) R_nb``: ``δb = φ × b``, and
``∂ψ/∂b = (−b_N, b_E, 0) / ρ²`` with ``ρ² = b_E² + b_N²``, so

    ∂ψ/∂φ = (−b_E b_U / ρ², −b_N b_U / ρ², 1)

and zero for every other state. It is singular when the baseline is vertical (ρ → 0).
"""

import math

import numpy as np

from buoy_nav.error_state_filter import ATTITUDE, STATE_DIM
from buoy_nav.measurements import MeasurementModel, floored_covariance
from buoy_nav.rotations import wrap_angle


def baseline_enu_m(rotation_nb, baseline_body_m) -> np.ndarray:
    """Primary → secondary antenna vector in ENU (m) for attitude R_nb."""
    return np.asarray(rotation_nb, dtype=float) @ np.asarray(baseline_body_m, dtype=float)


def predicted_heading_rad(rotation_nb, baseline_body_m) -> float:
    """Azimuth (rad, ENU, 0 = East, CCW) of the horizontal projection of the baseline."""
    baseline = baseline_enu_m(rotation_nb, baseline_body_m)
    return math.atan2(baseline[1], baseline[0])


def horizontal_fraction(rotation_nb, baseline_body_m) -> float:
    """Length of the baseline's horizontal projection divided by its length (0 = vertical)."""
    baseline = baseline_enu_m(rotation_nb, baseline_body_m)
    return math.hypot(baseline[0], baseline[1]) / float(np.linalg.norm(baseline))


def heading_model(
    measured_yaw_rad: float,
    variance_rad2: float,
    rotation_nb,
    baseline_body_m,
    variance_floor_rad2: float = 0.0,
) -> MeasurementModel:
    """Linearised heading measurement (innovation wrapped to (−π, π]).

    measured_yaw_rad: baseline azimuth from the receiver (rad, ENU, 0 = East, CCW).
    variance_rad2: its variance (rad²), raised to at least ``variance_floor_rad2``.
    rotation_nb: nominal attitude R_nb (3×3). baseline_body_m: l_s − l_p in ``base_link`` (m).
    """
    b_east, b_north, b_up = baseline_enu_m(rotation_nb, baseline_body_m)
    horizontal_sq = b_east * b_east + b_north * b_north
    predicted = math.atan2(b_north, b_east)
    jacobian = np.zeros((1, STATE_DIM))
    jacobian[0, ATTITUDE] = (
        -b_east * b_up / horizontal_sq,
        -b_north * b_up / horizontal_sq,
        1.0,
    )
    return MeasurementModel(
        predicted=np.array((predicted,)),
        innovation=np.array((wrap_angle(measured_yaw_rad - predicted),)),
        jacobian=jacobian,
        covariance=floored_covariance(variance_rad2, variance_floor_rad2),
    )
