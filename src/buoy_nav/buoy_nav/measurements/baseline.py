"""Dual-antenna baseline-vector measurement (paper 001, eq. 12–18).

A moving-baseline RTK receiver measures the primary → secondary antenna vector in ENU,
``b = R_nb · (l_s − l_p)``. Fusing the vector instead of only its azimuth also observes the
tilt of the baseline: with the antennas along body x, pitch, which an accelerometer bias
otherwise hides (a bias of β g reads as a tilt of β rad).

Jacobian under the convention ``R_true = Exp([φ×]) R_nb``: ``b_true = b + φ × b``, so

    ∂b/∂φ = −[b×]

and zero for every other state. The rotation about the baseline itself is not observed.
"""

import math

import numpy as np

from buoy_nav.error_state_filter import ATTITUDE, STATE_DIM
from buoy_nav.measurements import MeasurementModel
from buoy_nav.rotations import skew


def baseline_vector_model(
    measured_baseline_enu_m,
    sigma_horizontal_m: float,
    sigma_vertical_m: float,
    rotation_nb,
    baseline_body_m,
) -> MeasurementModel:
    """Linearised baseline-vector measurement.

    measured_baseline_enu_m: primary → secondary antenna vector from the receiver (ENU, m).
    sigma_horizontal_m, sigma_vertical_m: its 1-σ error per horizontal axis and vertically (m).
    rotation_nb: nominal attitude R_nb (3×3). baseline_body_m: l_s − l_p in ``base_link`` (m).
    """
    predicted = np.asarray(rotation_nb, dtype=float) @ np.asarray(baseline_body_m, dtype=float)
    jacobian = np.zeros((3, STATE_DIM))
    jacobian[:, ATTITUDE] = -skew(predicted)
    horizontal_variance = sigma_horizontal_m * sigma_horizontal_m
    return MeasurementModel(
        predicted=predicted,
        innovation=np.asarray(measured_baseline_enu_m, dtype=float) - predicted,
        jacobian=jacobian,
        covariance=np.diag((horizontal_variance, horizontal_variance, sigma_vertical_m**2)),
    )


def baseline_azimuth_rad(baseline_enu_m) -> tuple[float, float]:
    """Azimuth (rad, ENU, 0 = East, CCW) of a baseline's horizontal projection and the length
    of that projection (m)."""
    east, north = float(baseline_enu_m[0]), float(baseline_enu_m[1])
    return math.atan2(north, east), math.hypot(east, north)
