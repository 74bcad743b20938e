"""The sea's water velocity: a surface current (mean and tidal) and the waves' orbital motion.

The current is horizontal and uniform over the top layer where a buoy's or a ship's DVL
measures: a mean plus one tidal constituent whose velocity traces an ellipse,

    c(t) = c_mean + A cos(ω t + φ) e_major + B sin(ω t + φ) e_minor,

with e_major the flood direction (oceanographic: where the water flows TOWARD, clockwise from
true North), e_minor e_major turned 90° counter-clockwise (seen from above), A the amplitude
along the major axis and B along the minor one (B > 0: the current vector turns
counter-clockwise, B < 0: clockwise, B = 0: a rectilinear tide), ω = 2π / tidal period.
A platform that drifts with the current moves by its time integral.

The waves move the water as well: under a linear deep-water wave of surface orbital velocity
amplitude U and angular frequency ω the water at depth d below the instantaneous surface moves
with U·exp(−k d), k = ω²/g (measured from the instantaneous surface: Wheeler stretching, so
that a sensor riding with a wave follower keeps the velocity of its own depth). That orbital
motion is not current: it averages out over wave periods (see :mod:`sensor_sim.waves` and
:class:`sensor_sim.motion.BuoyMotion` for the two sources of waves).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike

from sensor_sim.scenario import CurrentConfig

Derivatives = tuple[np.ndarray, np.ndarray, np.ndarray]


def toward_unit_en(direction_deg: float) -> np.ndarray:
    """(east, north) unit vector of an oceanographic direction (toward, clockwise from North)."""
    azimuth = np.deg2rad(direction_deg)
    return np.array([np.sin(azimuth), np.cos(azimuth)])


class SurfaceCurrent:
    """Mean plus tidal current of a scenario's ``current`` section (see the module docstring)."""

    def __init__(self, config: CurrentConfig):
        self.config = config
        self.mean_en_mps = config.speed_mps * toward_unit_en(config.direction_deg)
        major = toward_unit_en(config.tidal_direction_deg)
        minor = np.array([-major[1], major[0]])
        self._major_en_mps = config.tidal_amplitude_mps * major
        self._minor_en_mps = config.tidal_minor_amplitude_mps * minor
        self._tidal_rad_s = 2.0 * np.pi / config.tidal_period_s
        self._tidal_phase_rad = np.deg2rad(config.tidal_phase_deg)

    def velocity_enu_mps(self, t_s: ArrayLike) -> np.ndarray:
        """Current at times t_s (s), ENU, (N, 3) m/s (no vertical part)."""
        _, velocity, _ = self.drift_en_m(t_s)
        return np.column_stack([velocity, np.zeros(velocity.shape[0])])

    def drift_en_m(self, t_s: ArrayLike) -> Derivatives:
        """Horizontal displacement (east, north) of a particle carried by the current since
        t = 0, m, with its first and second time derivatives; each (N, 2)."""
        t = np.atleast_1d(np.asarray(t_s, dtype=float)).ravel()
        displacement = t[:, None] * self.mean_en_mps
        velocity = np.broadcast_to(self.mean_en_mps, (t.size, 2)).copy()
        acceleration = np.zeros((t.size, 2))
        if self._major_en_mps.any() or self._minor_en_mps.any():
            w, phase = self._tidal_rad_s, self._tidal_phase_rad
            angle = w * t + phase
            cos_a, sin_a = np.cos(angle)[:, None], np.sin(angle)[:, None]
            displacement += (sin_a - np.sin(phase)) / w * self._major_en_mps
            displacement += (np.cos(phase) - cos_a) / w * self._minor_en_mps
            velocity += cos_a * self._major_en_mps + sin_a * self._minor_en_mps
            acceleration += w * (-sin_a * self._major_en_mps + cos_a * self._minor_en_mps)
        return displacement, velocity, acceleration
