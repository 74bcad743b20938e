"""A moored buoy's zero mean velocity, as a pseudo-measurement of its position.

A moored buoy moves by metres per second with the waves but stays on its mooring: over minutes
its mean velocity is zero. Without GNSS velocity nothing else bounds the inertial velocity
error, which grows with every tilt and accelerometer-bias error (g·δθ per second). The constraint
is written on the position, the integral of the velocity: every ``moored_update_period_s`` the
position is measured to equal its own slow mean (the anchor, an exponential mean of the
estimated position with time constant ``moored_anchor_time_constant_s``), with a 1-σ of the wave
excursion about it (``moored_position_sigma_horizontal_m``, ``..._vertical_m``)::

    z = anchor (ENU offset 0),   h(x) = p − anchor,   H = I on the position error.

To the filter the wave excursion is measurement noise, so the constraint is a high-pass on the
inertial motion: displacements that are small against σ at wave periods pass, while a drift of
the velocity (whose position error grows without bound) is pulled back. The time scale where
the two meet is set by σ, the update period and the IMU's accelerometer noise; the bench
(``make bench``, section ``sensor_sets``) reports the wind error it leaves at wave periods and
over minutes.

It runs only while no GNSS fix has been accepted for ``coasting_timeout_s`` and only with
``moored: true`` (a drifting buoy has no zero mean velocity). It aids its own quantity,
:data:`~buoy_nav.aiding.base.MOORING`, so the fix is still reported as coasting.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from buoy_common.contract import Reason
from buoy_nav import earth
from buoy_nav.aiding.base import MOORING, AidingSource, LinearisationPoint, MeasurementModel


class MooringAnchor(NamedTuple):
    """The slow mean position (rad, rad, m) the buoy is held to."""

    latitude_rad: float
    longitude_rad: float
    altitude_m: float


class MooredSource(AidingSource):
    """Zero mean velocity of a moored buoy (see the module docstring)."""

    kind = "moored"
    topic = None
    measurement_type = MooringAnchor
    aids = MOORING
    pseudo = True

    def __init__(self, config, states):
        super().__init__(config, states)
        self._period_s = config.moored_update_period_s
        self._time_constant_s = config.moored_anchor_time_constant_s
        self._covariance = np.diag(
            (
                config.moored_position_sigma_horizontal_m**2,
                config.moored_position_sigma_horizontal_m**2,
                config.moored_position_sigma_vertical_m**2,
            )
        )
        self._gnss_timeout_s = config.coasting_timeout_s
        self._anchor: np.ndarray | None = None
        self._anchor_t_s = -math.inf
        self.next_due_s = -math.inf
        """Stamp (s) from which the engine asks for the next pseudo-measurement."""

    @classmethod
    def enabled_by(cls, config) -> bool:
        return config.moored

    def restart(self) -> None:
        """Forget the anchor (after a realignment)."""
        self._anchor = None
        self.next_due_s = -math.inf

    def pseudo_measurement(self, t_s: float, state, fix_age_s: float) -> MooringAnchor | None:
        """The anchor at ``t_s`` for the nominal ``state``; None while GNSS fixes are accepted
        (``fix_age_s``: time since the last one, s). Moves the anchor toward the state."""
        self.next_due_s = t_s + self._period_s
        position = np.array((state.latitude_rad, state.longitude_rad, state.altitude_m))
        if self._anchor is None or fix_age_s <= self._gnss_timeout_s:
            self._anchor = position
            self._anchor_t_s = t_s
            return None
        weight = -math.expm1(-(t_s - self._anchor_t_s) / self._time_constant_s)
        self._anchor = self._anchor + weight * (position - self._anchor)
        self._anchor_t_s = t_s
        return MooringAnchor(*self._anchor)

    def measurement_from_message(self, message) -> Reason:
        return Reason.MALFORMED

    def validated(self, measurement: MooringAnchor) -> MooringAnchor:
        return measurement

    def model(self, measurement: MooringAnchor, point: LinearisationPoint) -> MeasurementModel:
        state = point.state
        offset = np.array(
            earth.enu_offset_scalar(
                state.latitude_rad,
                state.longitude_rad,
                state.altitude_m,
                measurement.latitude_rad,
                measurement.longitude_rad,
                measurement.altitude_m,
            )
        )
        states = self.states
        jacobian = np.zeros((3, states.dim))
        jacobian[:, states.position] = np.eye(3)
        return MeasurementModel(
            predicted=np.zeros(3),
            innovation=offset,
            jacobian=jacobian,
            covariance=self._covariance,
        )

    def align(self, aligner, t_s: float, measurement, raw_gyro_rad_s) -> None:
        return None
