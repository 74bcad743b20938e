"""The IMU samples the fusion accepts, and why it refuses the others.

A raw sample passes, in this order: three finite numbers each for ω_ib and the specific force
(else ``malformed`` or ``non_finite``); the ``calibrate_imu`` biases and scale removed; magnitudes
a sensor can report (``out_of_range``); its stamp put back on the aiding sources' clock after a
step of the IMU's clock (:mod:`buoy_nav.imu_clock`); a stamp after the last accepted one
(``duplicate_stamp``, ``stamp_not_increasing``); a change from the last accepted sample that a
platform can make (``implausible_change``, :mod:`buoy_nav.imu_screening`).
"""

import math

import numpy as np

from buoy_common.contract import Reason
from buoy_nav.config import FusionConfig
from buoy_nav.imu_clock import ImuClock
from buoy_nav.imu_screening import ImuPlausibility

Triple = tuple[float, float, float]


class ImuInput:
    """Screens raw IMU samples for the engine; holds the newest accepted stamp."""

    def __init__(self, config: FusionConfig):
        self._calibration = config.imu_calibration
        self._max_rate_sq = config.max_angular_rate_rad_s**2
        self._max_force_sq = config.max_specific_force_mps2**2
        self._max_gap_s = config.max_imu_gap_s
        self.clock = ImuClock(config.max_imu_gap_s)
        """The IMU clock's steps, and the aiding stamps it tells them from outages by."""
        self._plausibility = ImuPlausibility(
            config.max_angular_acceleration_rad_s2,
            config.max_jerk_mps3,
            math.radians(config.gyro_noise_deg_sqrt_h) / 60.0,
            config.accel_noise_mps_sqrt_h / 60.0,
        )
        self.latest_stamp_s = -math.inf
        """Stamp of the newest accepted sample (s, on the aiding sources' clock)."""

    def accept(
        self, t_s: float, gyro_rad_s, specific_force_mps2
    ) -> tuple[float, Triple, Triple] | Reason:
        """(stamp s, ω_ib body rad/s, specific force body m/s²) of the sample stamped ``t_s``
        (s) as the fusion uses it, calibrated and re-stamped; or the reason it is refused."""
        try:
            t = float(t_s)
            gx, gy, gz = _float_triple(gyro_rad_s)
            fx, fy, fz = _float_triple(specific_force_mps2)
        except (TypeError, ValueError):
            return Reason.MALFORMED
        if not (math.isfinite(t) and math.isfinite(gx + gy + gz) and math.isfinite(fx + fy + fz)):
            return Reason.NON_FINITE
        if self._calibration is not None:
            (bgx, bgy, bgz), (bax, bay, baz), (sx, sy, sz) = self._calibration
            gx, gy, gz = gx - bgx, gy - bgy, gz - bgz
            fx, fy, fz = (fx - bax) / sx, (fy - bay) / sy, (fz - baz) / sz
        if (
            gx * gx + gy * gy + gz * gz > self._max_rate_sq
            or fx * fx + fy * fy + fz * fz > self._max_force_sq
        ):
            return Reason.OUT_OF_RANGE
        latest = self.latest_stamp_s
        t = self.clock.restamp(t, latest)
        if t <= latest:
            return Reason.DUPLICATE_STAMP if t == latest else Reason.STAMP_NOT_INCREASING
        if t - latest > self._max_gap_s:
            self._plausibility.restart()
        gyro, force = (gx, gy, gz), (fx, fy, fz)
        if not self._plausibility.plausible(t, gyro, force):
            return Reason.IMPLAUSIBLE_CHANGE
        self.clock.accepted(t, latest)
        self.latest_stamp_s = t
        return t, gyro, force


def _float_triple(values) -> Triple:
    """Three floats from a 3-element array or sequence (ValueError/TypeError otherwise)."""
    if isinstance(values, np.ndarray) and values.dtype == np.float64:
        x, y, z = values.tolist()
        return x, y, z
    x, y, z = values
    return float(x), float(y), float(z)
