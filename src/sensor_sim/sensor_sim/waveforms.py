"""Smooth scalar waveforms with analytic first and second time derivatives.

Every waveform evaluates at arbitrary times (float seconds, any shape) and returns the value
together with its first and second derivatives, so the truth model can differentiate motion
exactly instead of numerically. Units are whatever the caller puts in (radians, metres).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike


@dataclass(frozen=True)
class Sinusoids:
    """Sum of sinusoids x(t) = sum_k amplitude_k * sin(angular_frequency_k * t + phase_k)."""

    amplitudes: np.ndarray
    angular_frequencies_rad_s: np.ndarray
    phases_rad: np.ndarray

    @classmethod
    def single(cls, amplitude: float, period_s: float, phase_rad: float) -> Sinusoids:
        """One sinusoid of the given amplitude, period (s) and phase at t = 0 (rad)."""
        return cls(
            np.array([amplitude], dtype=float),
            np.array([2.0 * np.pi / period_s]),
            np.array([phase_rad], dtype=float),
        )

    def evaluate(self, t_s: ArrayLike) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Value, first and second time derivative at times t_s (s); each shaped like t_s."""
        t = np.asarray(t_s, dtype=float)
        angle = t[..., None] * self.angular_frequencies_rad_s + self.phases_rad
        sin_a, cos_a = np.sin(angle), np.cos(angle)
        w = self.angular_frequencies_rad_s
        value = sin_a @ self.amplitudes
        rate = cos_a @ (self.amplitudes * w)
        accel = -(sin_a @ (self.amplitudes * w**2))
        return value, rate, accel


@dataclass(frozen=True)
class RampProfile:
    """Piecewise motion between waypoints with a capped rate and rounded (raised-cosine) corners.

    Each ramp moves from the previous waypoint to the next one: the rate rises from zero to
    ``rate`` along half a cosine lasting ``corner_s``, stays at ``rate``, and falls back the same
    way, so the rate and its derivative are continuous everywhere. The ramp covers its travel
    exactly: a ramp of travel D lasts D/rate + corner_s (shorter ramps use a shorter corner so
    that they still peak at ``rate``). After a ramp the value holds for that waypoint's hold
    time. Before the first ramp and after the last hold the value is constant.
    """

    start_times_s: np.ndarray
    start_values: np.ndarray
    travels: np.ndarray
    corners_s: np.ndarray
    plateaus_s: np.ndarray
    rate: float

    @classmethod
    def from_waypoints(
        cls,
        start_s: float,
        initial_value: float,
        targets: Sequence[float],
        holds_s: Sequence[float],
        rate: float,
        corner_s: float,
    ) -> RampProfile:
        """Ramps from initial_value through each target in turn, beginning at start_s (s).

        rate is the peak rate (value units per second, > 0), corner_s the rounding time
        (s, > 0), holds_s[k] the time spent at targets[k] after reaching it.
        """
        if rate <= 0.0 or corner_s <= 0.0:
            raise ValueError("ramp rate and corner time must be positive")
        values = np.concatenate([[initial_value], np.asarray(targets, dtype=float)])
        travels = np.diff(values)
        travel_times = np.abs(travels) / rate
        corners = np.minimum(corner_s, travel_times)
        plateaus = travel_times - corners
        durations = travel_times + corners + np.asarray(holds_s, dtype=float)
        starts = start_s + np.concatenate([[0.0], np.cumsum(durations)[:-1]])
        return cls(starts, values[:-1], travels, corners, plateaus, float(rate))

    def evaluate(self, t_s: ArrayLike) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Value, first and second time derivative at times t_s (s); each shaped like t_s."""
        t = np.asarray(t_s, dtype=float)
        if self.travels.size == 0:
            zeros = np.zeros_like(t)
            return zeros, zeros, zeros
        index = np.clip(np.searchsorted(self.start_times_s, t, side="right") - 1, 0, None)
        before_start = t < self.start_times_s[0]
        s = np.where(before_start, 0.0, t - self.start_times_s[index])
        v0 = self.start_values[index]
        travel = self.travels[index]
        tau = self.corners_s[index]
        plateau = self.plateaus_s[index]
        direction = np.sign(travel)
        r = self.rate

        ramp_end = 2.0 * tau + plateau
        safe_tau = np.where(tau > 0.0, tau, 1.0)
        in_rise = s < tau
        in_fall = (s >= tau + plateau) & (s < ramp_end)
        in_plateau = (s >= tau) & (s < tau + plateau)
        to_end = ramp_end - s

        def corner_distance(u: np.ndarray) -> np.ndarray:
            # Distance covered u seconds into a raised-cosine corner.
            return 0.5 * r * (u - safe_tau / np.pi * np.sin(np.pi * u / safe_tau))

        progress = np.select(
            [in_rise, in_plateau, in_fall],
            [
                corner_distance(s),
                0.5 * r * tau + r * (s - tau),
                np.abs(travel) - corner_distance(to_end),
            ],
            default=np.abs(travel),
        )
        speed = np.select(
            [in_rise, in_plateau, in_fall],
            [
                0.5 * r * (1.0 - np.cos(np.pi * s / safe_tau)),
                np.full_like(s, r),
                0.5 * r * (1.0 - np.cos(np.pi * to_end / safe_tau)),
            ],
            default=0.0,
        )
        speed_rate = np.select(
            [in_rise, in_fall],
            [
                0.5 * r * np.pi / safe_tau * np.sin(np.pi * s / safe_tau),
                -0.5 * r * np.pi / safe_tau * np.sin(np.pi * to_end / safe_tau),
            ],
            default=0.0,
        )
        value = v0 + direction * progress
        return value, direction * speed, direction * speed_rate
