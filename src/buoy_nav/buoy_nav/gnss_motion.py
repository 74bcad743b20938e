"""The buoy's motion over ground as the GNSS receiver measured it, without the filter.

The filter judges each source against its own state; a source that pulls the state along (a
biased velocity followed after the integrity monitor widened the covariance) or a constraint
that passes its gate while it is wrong (a mooring on a drifting buoy) can only be caught by
setting measurements against each other directly. :class:`GnssMotion` keeps the recent fixes
and velocities of the primary antenna (both of the same antenna, so the lever arm cancels) and
gives

- the **mean velocity** over a span, from the displacement between its first and last fix
  (the wave excursions about the mean enter once at each end), else from the mean of the
  velocities;
- the **velocity against the fixes**: the velocities integrated over the time between two
  fixes (trapezoidal rule) less the displacement between them, divided by that time. Both
  measure the same motion, so it is zero within the noise of both plus the error of the
  trapezoidal rule on the wave motion between epochs, which is estimated from the velocities'
  second differences (the rule's error on one interval is ``Δt³ v''/12``).

Positions are east, north, up metres in the tangent plane at the first fix kept.
"""

from __future__ import annotations

from collections import deque
from typing import NamedTuple

import numpy as np

from buoy_nav import earth
from buoy_nav.aiding.base import floored_covariance
from buoy_nav.aiding.gnss_fix import GnssFix
from buoy_nav.aiding.gnss_velocity import GnssVelocity


class MeanVelocity(NamedTuple):
    """A mean velocity over ground (ENU, m/s) over ``span_s`` (s), the covariance of its
    measurement noise (3×3, m²/s²), and what it was measured by (``fixes``, ``velocities``)."""

    velocity_enu_mps: np.ndarray
    covariance_m2s2: np.ndarray
    span_s: float
    measured_by: str


class _Fix(NamedTuple):
    t_s: float
    position_enu_m: np.ndarray
    covariance_m2: np.ndarray


class _Velocity(NamedTuple):
    t_s: float
    velocity_enu_mps: np.ndarray
    covariance_m2s2: np.ndarray


class GnssMotion:
    """The fixes and velocities of the last ``keep_s`` seconds (s), their covariances floored
    at ``position_floor_m2`` and ``velocity_floor_m2s2`` as the filter floors them."""

    def __init__(self, keep_s: float, position_floor_m2: float, velocity_floor_m2s2: float):
        self._keep_s = keep_s
        self._position_floor_m2 = position_floor_m2
        self._velocity_floor_m2s2 = velocity_floor_m2s2
        self._origin: tuple[float, float, float] | None = None
        self._fixes: deque[_Fix] = deque()
        self._velocities: deque[_Velocity] = deque()
        # Sums over the velocities kept, for their mean in constant time.
        self._velocity_sum = np.zeros(3)
        self._velocity_covariance_sum = np.zeros((3, 3))

    @property
    def empty(self) -> bool:
        """Whether it keeps no fix and no velocity: nothing to judge by."""
        return not self._fixes and not self._velocities

    def add(self, t_s: float, measurement) -> None:
        """Keep a validated fix or velocity stamped ``t_s`` (s); other measurements are not
        the receiver's motion and are ignored."""
        if isinstance(measurement, GnssFix):
            self._add_fix(t_s, measurement)
        elif isinstance(measurement, GnssVelocity):
            self._add_velocity(t_s, measurement)
        self._forget_before(t_s - self._keep_s)

    def _add_fix(self, t_s: float, fix: GnssFix) -> None:
        latitude, longitude = fix.latitude_rad, fix.longitude_rad
        if self._origin is None:
            self._origin = (latitude, longitude, fix.altitude_m)
        position = np.array(
            earth.enu_offset_scalar(*self._origin, latitude, longitude, fix.altitude_m)
        )
        covariance = floored_covariance(fix.covariance_enu_m2, self._position_floor_m2)
        self._fixes.append(_Fix(t_s, position, covariance))

    def _add_velocity(self, t_s: float, velocity: GnssVelocity) -> None:
        covariance = floored_covariance(velocity.covariance_m2s2, self._velocity_floor_m2s2)
        sample = _Velocity(t_s, np.asarray(velocity.velocity_enu_mps, dtype=float), covariance)
        self._velocities.append(sample)
        self._velocity_sum += sample.velocity_enu_mps
        self._velocity_covariance_sum += covariance

    def _forget_before(self, t_s: float) -> None:
        fixes, velocities = self._fixes, self._velocities
        while fixes and fixes[0].t_s < t_s:
            fixes.popleft()
        while velocities and velocities[0].t_s < t_s:
            old = velocities.popleft()
            self._velocity_sum -= old.velocity_enu_mps
            self._velocity_covariance_sum -= old.covariance_m2s2

    def mean_velocity(self, min_span_s: float) -> MeanVelocity | None:
        """The mean velocity over everything kept, from the fixes when they span at least
        ``min_span_s`` (s), else from the velocities when they do; None when neither does."""
        fixes = self._fixes
        if fixes and fixes[-1].t_s - fixes[0].t_s >= min_span_s:
            first, last = fixes[0], fixes[-1]
            span_s = last.t_s - first.t_s
            return MeanVelocity(
                (last.position_enu_m - first.position_enu_m) / span_s,
                (first.covariance_m2 + last.covariance_m2) / span_s**2,
                span_s,
                "fixes",
            )
        velocities = self._velocities
        if velocities and velocities[-1].t_s - velocities[0].t_s >= min_span_s:
            count = len(velocities)
            return MeanVelocity(
                self._velocity_sum / count,
                self._velocity_covariance_sum / count**2,
                velocities[-1].t_s - velocities[0].t_s,
                "velocities",
            )
        return None

    def velocity_against_fixes(self, from_s: float, to_s: float) -> MeanVelocity | None:
        """The velocities' mean less the fixes' over the longest time between two fixes in
        [``from_s``, ``to_s``] (s) that velocities cover (``measured_by`` ``velocities − fixes``),
        its covariance that of the noise of both and of the trapezoidal rule; None when no
        such time is covered by two velocities at least."""
        velocities = [v for v in self._velocities if from_s <= v.t_s <= to_s]
        if len(velocities) < 2:
            return None
        start_s = max(from_s, velocities[0].t_s)
        end_s = min(to_s, velocities[-1].t_s)
        fixes = [f for f in self._fixes if start_s <= f.t_s <= end_s]
        if len(fixes) < 2 or fixes[-1].t_s <= fixes[0].t_s:
            return None
        first, last = fixes[0], fixes[-1]
        span_s = last.t_s - first.t_s
        displacement, noise, rule_error = _integrated(velocities, first.t_s, last.t_s)
        covariance = (
            noise + first.covariance_m2 + last.covariance_m2 + np.diag(rule_error**2)
        ) / span_s**2
        difference = (displacement - (last.position_enu_m - first.position_enu_m)) / span_s
        return MeanVelocity(difference, covariance, span_s, "velocities − fixes")


def _integrated(velocities: list[_Velocity], start_s: float, end_s: float):
    """The displacement (ENU, m) the ``velocities`` give from ``start_s`` to ``end_s`` (s,
    inside their stamps) by the trapezoidal rule, the covariance of its noise (m²) and the
    rule's error estimated per axis (m)."""
    stamps = np.array([v.t_s for v in velocities])
    values = np.array([v.velocity_enu_mps for v in velocities])
    inside = (stamps > start_s) & (stamps < end_s)
    times = np.concatenate(([start_s], stamps[inside], [end_s]))
    samples = np.vstack(
        [
            _interpolated(stamps, values, start_s),
            values[inside],
            _interpolated(stamps, values, end_s),
        ]
    )
    steps = np.diff(times)
    weights = np.zeros(times.size)
    weights[:-1] += 0.5 * steps
    weights[1:] += 0.5 * steps
    displacement = weights @ samples
    # Interpolated ends carry the noise of their nearest sample: taken as that sample's.
    nearest = np.clip(np.searchsorted(stamps, times), 0, stamps.size - 1)
    noise = sum(w**2 * velocities[i].covariance_m2s2 for w, i in zip(weights, nearest, strict=True))
    if samples.shape[0] < 3:
        return displacement, noise, np.zeros(3)
    # The rule's error on an interval is Δt³ v''/12, and v'' Δt² is a second difference.
    curvature = np.abs(np.diff(samples, n=2, axis=0))
    rule_error = (0.5 * (steps[:-1] + steps[1:]) / 12.0) @ curvature
    return displacement, noise, rule_error


def _interpolated(stamps: np.ndarray, values: np.ndarray, t_s: float) -> np.ndarray:
    """``values`` (N×3) sampled at ``stamps`` (s) linearly interpolated at ``t_s`` (s)."""
    return np.array([np.interp(t_s, stamps, values[:, axis]) for axis in range(3)])
