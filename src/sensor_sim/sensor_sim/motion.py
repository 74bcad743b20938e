"""Platform motion: Euler-angle and translation time series with analytic derivatives.

BuoyMotion turns a MotionConfig (plus the wave and current sections) into functions of time:
roll, pitch, yaw (ZYX Euler angles of R_nb, radians) and a curvilinear east/north/up
displacement of the base_link origin from where it was at t = 0 (metres), each with its first
and second time derivatives. Every component is a closed-form waveform, so the truth model never
differentiates numerically and every node sees the same motion at its own sample times.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike

from sensor_sim.scenario import CurrentConfig, MotionConfig, WaveConfig
from sensor_sim.waveforms import RampProfile, Sinusoids
from sensor_sim.waves import WaveField

MOTION_PHASE_STREAM_KEY = 101
WAVE_STREAM_KEY = 102
# Profiles are laid out this far past the end of the run, so late sample times still move.
_PROFILE_MARGIN_S = 120.0

Derivatives = tuple[np.ndarray, np.ndarray, np.ndarray]


@dataclass(frozen=True)
class MotionSample:
    """Motion at N times; each field is (N,3) and each tuple is (value, d/dt, d²/dt²).

    euler_rad: (roll, pitch, yaw) of R_nb = Rz(yaw) Ry(pitch) Rx(roll), radians, yaw unwrapped.
    displacement_enu_m: curvilinear (east, north, up) displacement of the base_link origin since
    t = 0, metres (east/north are distances along the ellipsoid at the origin's radii).
    """

    euler_rad: Derivatives
    displacement_enu_m: Derivatives


def _add(*terms: Derivatives) -> Derivatives:
    return tuple(sum(parts) for parts in zip(*terms, strict=True))


class BuoyMotion:
    """Sum of the motion components configured in a scenario (see MotionConfig)."""

    def __init__(
        self,
        motion: MotionConfig,
        waves: WaveConfig,
        current: CurrentConfig | None,
        seed: int,
        duration_s: float,
    ):
        """motion, waves, current: scenario sections; seed: scenario seed; duration_s: run
        length (s), which sets how far the sway and rotation profiles are laid out."""
        self.config = motion
        phases = np.random.default_rng([seed, MOTION_PHASE_STREAM_KEY]).uniform(
            0.0, 2.0 * np.pi, size=7
        )
        deg = np.deg2rad
        self._angle_offsets_rad = deg([motion.roll_deg, motion.pitch_deg, motion.yaw_deg])
        self._angle_sinusoids = [
            Sinusoids.single(deg(motion.roll_amplitude_deg), motion.roll_period_s, phases[0]),
            Sinusoids.single(deg(motion.pitch_amplitude_deg), motion.pitch_period_s, phases[1]),
            Sinusoids.single(deg(motion.yaw_amplitude_deg), motion.yaw_period_s, phases[2]),
        ]
        self._mooring_yaw = Sinusoids.single(
            deg(motion.mooring_yaw_amplitude_deg), motion.mooring_yaw_period_s, phases[3]
        )
        self._heave, self._surge, self._lateral = (
            _displacement_of_velocity_sinusoid(amplitude, period, phase)
            for amplitude, period, phase in (
                (motion.heave_velocity_amplitude_mps, motion.heave_period_s, phases[4]),
                (motion.surge_velocity_amplitude_mps, motion.surge_period_s, phases[5]),
                (motion.lateral_velocity_amplitude_mps, motion.lateral_period_s, phases[6]),
            )
        )
        heading = self._angle_offsets_rad[2]
        self._surge_axis_en = np.array([np.cos(heading), np.sin(heading)])
        self._lateral_axis_en = np.array([-np.sin(heading), np.cos(heading)])

        end_s = duration_s + _PROFILE_MARGIN_S
        self._sway = _sway_profile(motion, end_s)
        self._rotation = _rotation_profile(motion, end_s)
        self._positions = _positions_progress(motion)

        self.waves: WaveField | None = None
        self.wave_tilt_gain = 0.0
        if waves.significant_height_m > 0.0:
            self.waves = WaveField(
                waves.significant_height_m,
                waves.peak_period_s,
                waves.peak_enhancement,
                waves.spreading_exponent,
                waves.direction_deg,
                waves.components,
                np.random.default_rng([seed, WAVE_STREAM_KEY]),
            )
            slope_sigma = np.sqrt(self.waves.slope_variance())
            self.wave_tilt_gain = np.deg2rad(waves.max_tilt_deg) / (3.0 * slope_sigma)
            # The buoy starts at the origin: displacements count from the surface state at t = 0.
            at_start = self.waves.evaluate(np.zeros(1))
            self._wave_start_elevation_m = at_start.elevation_m[0][0]
            self._wave_start_displacement_en_m = at_start.orbital_displacement_en_m[0][0]

        self.current_enu_mps: np.ndarray | None = None
        if current is not None:
            toward = np.deg2rad(current.direction_deg)
            self.current_enu_mps = current.speed_mps * np.array(
                [np.sin(toward), np.cos(toward), 0.0]
            )

    def evaluate(self, t_s: ArrayLike) -> MotionSample:
        """Motion at times t_s (s), flattened to shape (N,)."""
        t = np.atleast_1d(np.asarray(t_s, dtype=float)).ravel()
        roll = _add(_constant(t, self._angle_offsets_rad[0]), self._angle_sinusoids[0].evaluate(t))
        pitch = _add(_constant(t, self._angle_offsets_rad[1]), self._angle_sinusoids[1].evaluate(t))
        yaw = _add(
            _constant(t, self._angle_offsets_rad[2]),
            self._angle_sinusoids[2].evaluate(t),
            self._mooring_yaw.evaluate(t),
        )
        if self._sway is not None:
            sway = self._sway.evaluate(t)
            if self.config.sway_axis == "roll":
                roll = _add(roll, sway)
            else:
                pitch = _add(pitch, sway)
        if self._rotation is not None:
            yaw = _add(yaw, self._rotation.evaluate(t))
        if self._positions is not None:
            for axis, angles in enumerate(self._position_angles(t)):
                if axis == 0:
                    roll = _add(roll, angles)
                elif axis == 1:
                    pitch = _add(pitch, angles)
                else:
                    yaw = _add(yaw, angles)

        east_north = [np.zeros((t.size, 2)) for _ in range(3)]
        up = list(self._heave(t))
        for k, (surge, lateral) in enumerate(zip(self._surge(t), self._lateral(t), strict=True)):
            east_north[k] += surge[:, None] * self._surge_axis_en
            east_north[k] += lateral[:, None] * self._lateral_axis_en

        if self.waves is not None:
            wave = self.waves.evaluate(t)
            wave_roll, wave_pitch = self._wave_tilt(wave.slope_en, yaw)
            roll = _add(roll, wave_roll)
            pitch = _add(pitch, wave_pitch)
            up[0] = up[0] + wave.elevation_m[0] - self._wave_start_elevation_m
            up[1] = up[1] + wave.elevation_m[1]
            up[2] = up[2] + wave.elevation_m[2]
            east_north[0] += wave.orbital_displacement_en_m[0] - self._wave_start_displacement_en_m
            east_north[1] += wave.orbital_displacement_en_m[1]
            east_north[2] += wave.orbital_displacement_en_m[2]

        if self.current_enu_mps is not None:
            east_north[0] += t[:, None] * self.current_enu_mps[:2]
            east_north[1] += self.current_enu_mps[:2]

        euler = tuple(np.stack(parts, axis=-1) for parts in zip(roll, pitch, yaw, strict=True))
        displacement = tuple(
            np.column_stack([horizontal, vertical])
            for horizontal, vertical in zip(east_north, up, strict=True)
        )
        return MotionSample(euler, displacement)

    def _position_angles(self, t: np.ndarray) -> list[Derivatives]:
        """Roll, pitch and yaw of the static positions (calibration table): piecewise linear
        in a progress s(t) that ramps from position k to k + 1 and holds there, so the angles
        change together and are still during the holds."""
        progress, progress_rate, progress_accel = self._positions.evaluate(t)
        angles = np.deg2rad(np.asarray(self.config.positions_rpy_deg, dtype=float))
        segment = np.clip(np.floor(progress).astype(int), 0, len(angles) - 2)
        slope = angles[segment + 1] - angles[segment]
        fraction = (progress - segment)[:, None]
        value = angles[segment] + fraction * slope
        rate = slope * progress_rate[:, None]
        accel = slope * progress_accel[:, None]
        return [(value[:, k], rate[:, k], accel[:, k]) for k in range(3)]

    def _wave_tilt(
        self, slope_en: Derivatives, yaw: Derivatives
    ) -> tuple[Derivatives, Derivatives]:
        """Roll and pitch of a body following the surface slope, with derivatives.

        The slope gradient g (east, north) is resolved in the yawed body axes,
        s = Q(yaw) g with Q = [[cos, sin], [-sin, cos]]; the body tips its up axis toward the
        downhill side: roll = +gain * s_left, pitch = -gain * s_forward. With J = [[0, 1],
        [-1, 0]], dQ/dyaw = J Q, hence s' = Q g' + yaw' J Q g and
        s'' = Q g'' + 2 yaw' J Q g' + (yaw'' J - yaw'^2) Q g.
        """
        g, g_rate, g_accel = slope_en
        psi, psi_rate, psi_accel = yaw
        cos_psi, sin_psi = np.cos(psi), np.sin(psi)

        def rotate(vector: np.ndarray) -> np.ndarray:
            return np.column_stack(
                [
                    cos_psi * vector[:, 0] + sin_psi * vector[:, 1],
                    -sin_psi * vector[:, 0] + cos_psi * vector[:, 1],
                ]
            )

        def turn(vector: np.ndarray) -> np.ndarray:
            return np.column_stack([vector[:, 1], -vector[:, 0]])

        qg, qg_rate, qg_accel = rotate(g), rotate(g_rate), rotate(g_accel)
        s = qg
        s_rate = qg_rate + psi_rate[:, None] * turn(qg)
        s_accel = (
            qg_accel
            + 2.0 * psi_rate[:, None] * turn(qg_rate)
            + psi_accel[:, None] * turn(qg)
            - (psi_rate**2)[:, None] * qg
        )
        gain = self.wave_tilt_gain
        roll = (gain * s[:, 1], gain * s_rate[:, 1], gain * s_accel[:, 1])
        pitch = (-gain * s[:, 0], -gain * s_rate[:, 0], -gain * s_accel[:, 0])
        return roll, pitch


def _constant(t: np.ndarray, value: float) -> Derivatives:
    return np.full_like(t, value), np.zeros_like(t), np.zeros_like(t)


def _displacement_of_velocity_sinusoid(amplitude_mps: float, period_s: float, phase_rad: float):
    """Displacement x(t) (m) whose velocity is amplitude sin(2 pi t/period + phase), x(0) = 0."""
    omega = 2.0 * np.pi / period_s
    # x = (A/w)(cos(phase) - cos(w t + phase)) and -cos(u) = sin(u - pi/2).
    shifted = Sinusoids.single(amplitude_mps / omega, period_s, phase_rad - np.pi / 2.0)
    offset = amplitude_mps / omega * np.cos(phase_rad)

    def evaluate(t: np.ndarray) -> Derivatives:
        value, rate, accel = shifted.evaluate(t)
        return value + offset, rate, accel

    return evaluate


def _sway_profile(motion: MotionConfig, end_s: float) -> RampProfile | None:
    """Table sway from level: 0 -> +A, then -A/+A swings, back to 0 after sway_cycles."""
    if motion.sway_amplitude_deg == 0.0:
        return None
    amplitude = np.deg2rad(motion.sway_amplitude_deg)
    rate = np.deg2rad(motion.sway_rate_deg_s)
    minimum_period = motion.minimum_sway_period_s()
    period = motion.sway_period_s if motion.sway_period_s is not None else minimum_period
    hold = (period - minimum_period) / 2.0
    if motion.sway_cycles is not None:
        targets = [amplitude] + [-amplitude, amplitude] * (motion.sway_cycles - 1)
        targets += [-amplitude, 0.0]
    else:
        cycles = int(np.ceil((end_s - motion.still_before_s) / period)) + 1
        targets = [amplitude] + [-amplitude, amplitude] * cycles
    holds = [hold] * len(targets)
    return RampProfile.from_waypoints(
        motion.still_before_s, 0.0, targets, holds, rate, motion.corner_time_s
    )


def _positions_progress(motion: MotionConfig) -> RampProfile | None:
    """Progress through the static positions: k → k + 1 in position_transition_s (rounded),
    held position_dwell_s at each, from still_before_s."""
    count = len(motion.positions_rpy_deg)
    if count == 0:
        return None
    if count == 1:
        return RampProfile.from_waypoints(0.0, 0.0, [], [], 1.0, 1.0)
    rate = 1.0 / motion.position_transition_s
    targets = [float(k) for k in range(1, count)]
    holds = [motion.position_dwell_s] * len(targets)
    return RampProfile.from_waypoints(
        motion.still_before_s, 0.0, targets, holds, rate, 0.5 * motion.position_transition_s
    )


def _rotation_profile(motion: MotionConfig, end_s: float) -> RampProfile | None:
    """Turntable yaw: 0 -> range -> 0 ..., dwelling rotation_dwell_s at each end."""
    if motion.rotation_range_deg == 0.0:
        return None
    span = np.deg2rad(motion.rotation_range_deg)
    rate = np.deg2rad(motion.rotation_rate_deg_s)
    travel_time = abs(span) / rate
    period = 2.0 * (travel_time + min(motion.corner_time_s, travel_time) + motion.rotation_dwell_s)
    cycles = int(np.ceil((end_s - motion.still_before_s) / period)) + 1
    targets = [span, 0.0] * cycles
    holds = [motion.rotation_dwell_s] * len(targets)
    return RampProfile.from_waypoints(
        motion.still_before_s, 0.0, targets, holds, rate, motion.corner_time_s
    )
