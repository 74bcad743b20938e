"""Geometry of a GNSS antenna baseline: the primary → secondary antenna vector in ENU, its
horizontal share and its azimuth. The aiding sources of the antennas and the alignment share it.
"""

import math

import numpy as np

# The baseline's horizontal projection must keep this fraction of its length for its azimuth to
# carry heading (at 0.2 the yaw noise is 5× the tilt-free value).
MIN_HORIZONTAL_BASELINE_FRACTION = 0.2


def baseline_enu_m(rotation_nb, baseline_body_m) -> np.ndarray:
    """Primary → secondary antenna vector in ENU (m) for attitude R_nb."""
    return np.asarray(rotation_nb, dtype=float) @ np.asarray(baseline_body_m, dtype=float)


def horizontal_fraction(rotation_nb, baseline_body_m) -> float:
    """Length of the baseline's horizontal projection divided by its length (0 = vertical)."""
    return horizontal_fraction_enu(baseline_enu_m(rotation_nb, baseline_body_m))


def horizontal_fraction_enu(baseline_enu) -> float:
    """Length of an ENU baseline's (any unit) horizontal projection divided by its length."""
    return math.hypot(baseline_enu[0], baseline_enu[1]) / float(np.linalg.norm(baseline_enu))


def baseline_azimuth_rad(baseline_enu_m) -> tuple[float, float]:
    """Azimuth (rad, ENU, 0 = East, CCW) of a baseline's horizontal projection and the length
    of that projection (m)."""
    east, north = float(baseline_enu_m[0]), float(baseline_enu_m[1])
    return math.atan2(north, east), math.hypot(east, north)
