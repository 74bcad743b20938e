"""Deterministic truth of a scenario: attitude, rates, position, velocity, wind, current.

The truth is kinematically exact. Attitude comes from the ZYX Euler angles of BuoyMotion and
the body rate from their analytic rates, omega_nb^b = E(roll, pitch) [roll', pitch', yaw']'.
The geodetic trajectory is lat = lat0 + north/(R_M0 + h0), lon = lon0 + east/((R_N0 + h0)
cos lat0), h = h0 + up, with (east, north, up) the motion's curvilinear displacement (metres at
the origin's radii). The velocity is the exact time derivative of that trajectory expressed in
the local ENU frame (vN = lat' (R_M + h), vE = lon' (R_N + h) cos lat, vU = h'), and the
acceleration is the time derivative of those ENU components, so a strapdown integration of
ideal IMU data reproduces the truth. Over the km scale of a drift, the local radii differ from
the origin's by parts in 1e4, which is what separates the velocity from the raw displacement
rate.
"""

from __future__ import annotations

import math
from collections import OrderedDict
from collections.abc import Callable
from dataclasses import dataclass, field
from functools import cached_property

import numpy as np
from numpy.typing import ArrayLike
from scipy.spatial.transform import Rotation

from sensor_sim.geodesy import (
    geodetic_to_enu_m,
    meridian_radius_derivative_m,
    meridian_radius_m,
    prime_vertical_radius_derivative_m,
    prime_vertical_radius_m,
)
from sensor_sim.motion import BuoyMotion
from sensor_sim.scenario import Scenario
from sensor_sim.wind_field import SonicTemperatureConfig, WindField

TURBULENCE_STREAM_KEY = 103
TEMPERATURE_STREAM_KEY = 104
# Turbulence is represented from 1/record length, but never from longer than 10 minutes (the
# standard averaging window), down to the configured highest frequency.
_LONGEST_TURBULENCE_PERIOD_FLOOR_S = 600.0
# Evaluations kept for callers at the same times: the distinct sample grids of one block (the
# IMU's, the magnetometer's, the anemometer's, the GNSS's).
_REMEMBERED_EVALUATIONS = 4


@dataclass(frozen=True)
class TruthState:
    """True state at N times; every array has leading dimension N.

    attitude: Rotation of length N, R_nb (base_link FLU -> local ENU).
    euler_rad: (N,3) roll, pitch, yaw (rad) of R_nb = Rz(yaw) Ry(pitch) Rx(roll), yaw unwrapped.
    angular_rate_body_rad_s: (N,3) omega_nb^b, body rate relative to local-level ENU, body axes.
    angular_accel_body_rad_s2: (N,3) time derivative of angular_rate_body_rad_s.
    position_enu_m: (N,3) base_link origin in the tangent-plane ENU frame at the scenario origin.
    latitude_deg, longitude_deg, altitude_m: (N,) WGS-84 geodetic base_link origin, ellipsoidal.
    velocity_enu_mps: (N,3) base_link origin over ground, local ENU.
    acceleration_enu_mps2: (N,3) time derivative of velocity_enu_mps.
    wind_enu_mps: (N,3) air velocity over ground (direction it moves toward), ENU; evaluated
    when first asked for (most sensors never ask, and it is the dearest part of the truth).
    current_enu_mps: (N,3) surface current (mean and tidal, toward), ENU, or None when not
    simulated.
    """

    t_s: np.ndarray
    attitude: Rotation
    euler_rad: np.ndarray
    angular_rate_body_rad_s: np.ndarray
    angular_accel_body_rad_s2: np.ndarray
    position_enu_m: np.ndarray
    latitude_deg: np.ndarray
    longitude_deg: np.ndarray
    altitude_m: np.ndarray
    velocity_enu_mps: np.ndarray
    acceleration_enu_mps2: np.ndarray
    current_enu_mps: np.ndarray | None
    wind_at: Callable[[np.ndarray], np.ndarray] = field(repr=False, compare=False)
    """The wind (N,3; ENU, m/s) at times (N,) s."""

    @cached_property
    def wind_enu_mps(self) -> np.ndarray:
        return self.wind_at(self.t_s)


def body_rate_from_euler(
    euler_rad: np.ndarray, euler_rate_rad_s: np.ndarray, euler_accel_rad_s2: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Body rate omega_nb^b (N,3, rad/s) and its derivative (rad/s²) from ZYX Euler angles.

    With R_nb = Rz(yaw) Ry(pitch) Rx(roll) and R' = R [omega x]:
    p = roll' - yaw' sin(pitch), q = pitch' cos(roll) + yaw' sin(roll) cos(pitch),
    r = -pitch' sin(roll) + yaw' cos(roll) cos(pitch).
    """
    roll, pitch = euler_rad[:, 0], euler_rad[:, 1]
    roll_rate, pitch_rate, yaw_rate = euler_rate_rad_s.T
    roll_accel, pitch_accel, yaw_accel = euler_accel_rad_s2.T
    sin_r, cos_r = np.sin(roll), np.cos(roll)
    sin_p, cos_p = np.sin(pitch), np.cos(pitch)
    rate = np.column_stack(
        [
            roll_rate - yaw_rate * sin_p,
            pitch_rate * cos_r + yaw_rate * sin_r * cos_p,
            -pitch_rate * sin_r + yaw_rate * cos_r * cos_p,
        ]
    )
    accel = np.column_stack(
        [
            roll_accel - yaw_accel * sin_p - yaw_rate * pitch_rate * cos_p,
            pitch_accel * cos_r
            - pitch_rate * roll_rate * sin_r
            + yaw_accel * sin_r * cos_p
            + yaw_rate * roll_rate * cos_r * cos_p
            - yaw_rate * pitch_rate * sin_r * sin_p,
            -pitch_accel * sin_r
            - pitch_rate * roll_rate * cos_r
            + yaw_accel * cos_r * cos_p
            - yaw_rate * roll_rate * sin_r * cos_p
            - yaw_rate * pitch_rate * cos_r * sin_p,
        ]
    )
    return rate, accel


@dataclass(frozen=True)
class WaterAtSensor:
    """The water at a point fixed to the platform (a DVL), at N times.

    depth_m: (N,) depth below the sea surface, m: base_link floats on the surface, so it is the
    point's height below base_link along the vertical, -(R_nb p)_up.
    current_enu_mps: (N,3) the current there (mean and tidal), ENU, m/s; zero without one.
    velocity_enu_mps: (N,3) the water's velocity there: the current plus the orbital velocity
    of the waves at that depth, ENU, m/s.
    """

    depth_m: np.ndarray
    current_enu_mps: np.ndarray
    velocity_enu_mps: np.ndarray


class TruthModel:
    """Truth of one scenario, evaluable at any times, identical for every caller."""

    def __init__(self, scenario: Scenario):
        self.scenario = scenario
        self.motion = BuoyMotion(
            scenario.motion, scenario.waves, scenario.current, scenario.seed, scenario.duration_s
        )
        wind = scenario.wind
        self.wind = WindField(
            wind.speed_mps,
            wind.direction_deg,
            wind.turbulence_intensity,
            wind.lateral_intensity_ratio,
            wind.vertical_intensity_ratio,
            wind.height_m,
            wind.turbulence_components,
            1.0 / max(scenario.duration_s, _LONGEST_TURBULENCE_PERIOD_FLOOR_S),
            wind.turbulence_max_frequency_hz,
            np.random.default_rng([scenario.seed, TURBULENCE_STREAM_KEY]),
            wind.momentum_flux_correlation,
            None
            if math.isnan(wind.sonic_temperature_degc)
            else SonicTemperatureConfig(
                wind.sonic_temperature_degc,
                wind.temperature_sigma_k,
                wind.heat_flux_correlation,
                np.random.default_rng([scenario.seed, TEMPERATURE_STREAM_KEY]),
            ),
        )
        self.origin_latitude_rad = np.deg2rad(scenario.origin_latitude_deg)
        self.origin_longitude_rad = np.deg2rad(scenario.origin_longitude_deg)
        self.origin_altitude_m = scenario.origin_altitude_m
        self._north_radius_m = meridian_radius_m(self.origin_latitude_rad) + self.origin_altitude_m
        self._east_radius_m = (
            prime_vertical_radius_m(self.origin_latitude_rad) + self.origin_altitude_m
        ) * np.cos(self.origin_latitude_rad)
        self._recent: OrderedDict[bytes, TruthState] = OrderedDict()

    def water_at(self, state: TruthState, position_body_m: ArrayLike) -> WaterAtSensor:
        """The water at ``position_body_m`` (base_link, m) at the times of ``state``."""
        offset_enu = state.attitude.apply(np.asarray(position_body_m, dtype=float))
        depth = -offset_enu[:, 2]
        if state.current_enu_mps is None:
            current = np.zeros((state.t_s.size, 3))
        else:
            current = state.current_enu_mps
        orbital = self.motion.orbital_velocity_enu_mps(state.t_s, depth)
        return WaterAtSensor(depth, current, current + orbital)

    def evaluate(self, t_s: ArrayLike) -> TruthState:
        """Truth at times t_s (s since the scenario start), flattened to shape (N,).

        The sensors of one buoy sample the truth at the same times (the IMU, its motion pack
        and the truth stream, block by block), so the last few evaluations are kept and handed
        out again for the same times: callers share the state and must not modify it."""
        t = np.atleast_1d(np.asarray(t_s, dtype=float)).ravel()
        key = t.tobytes()
        state = self._recent.get(key)
        if state is None:
            state = self._evaluate(t.copy())
            self._recent[key] = state
            if len(self._recent) > _REMEMBERED_EVALUATIONS:
                self._recent.popitem(last=False)
        return state

    def _evaluate(self, t: np.ndarray) -> TruthState:
        """Truth at times t (N,), s since the scenario start."""
        sample = self.motion.evaluate(t)
        euler, euler_rate, euler_accel = sample.euler_rad
        attitude = Rotation.from_euler("ZYX", euler[:, ::-1])
        body_rate, body_accel = body_rate_from_euler(euler, euler_rate, euler_accel)

        displacement, displacement_rate, displacement_accel = sample.displacement_enu_m
        latitude = self.origin_latitude_rad + displacement[:, 1] / self._north_radius_m
        longitude = self.origin_longitude_rad + displacement[:, 0] / self._east_radius_m
        altitude = self.origin_altitude_m + displacement[:, 2]
        latitude_rate = displacement_rate[:, 1] / self._north_radius_m
        altitude_rate = displacement_rate[:, 2]

        # Local-frame scale of each curvilinear axis relative to the origin's, and its rate.
        east_extent = (prime_vertical_radius_m(latitude) + altitude) * np.cos(latitude)
        east_extent_rate = (
            prime_vertical_radius_derivative_m(latitude) * latitude_rate + altitude_rate
        ) * np.cos(latitude) - (prime_vertical_radius_m(latitude) + altitude) * np.sin(
            latitude
        ) * latitude_rate
        north_extent = meridian_radius_m(latitude) + altitude
        north_extent_rate = meridian_radius_derivative_m(latitude) * latitude_rate + altitude_rate
        east_scale = east_extent / self._east_radius_m
        north_scale = north_extent / self._north_radius_m
        velocity = np.column_stack(
            [
                displacement_rate[:, 0] * east_scale,
                displacement_rate[:, 1] * north_scale,
                displacement_rate[:, 2],
            ]
        )
        acceleration = np.column_stack(
            [
                displacement_accel[:, 0] * east_scale
                + displacement_rate[:, 0] * east_extent_rate / self._east_radius_m,
                displacement_accel[:, 1] * north_scale
                + displacement_rate[:, 1] * north_extent_rate / self._north_radius_m,
                displacement_accel[:, 2],
            ]
        )
        position = geodetic_to_enu_m(
            latitude,
            longitude,
            altitude,
            self.origin_latitude_rad,
            self.origin_longitude_rad,
            self.origin_altitude_m,
        )
        current = None
        if self.motion.current is not None:
            current = self.motion.current.velocity_enu_mps(t)
        return TruthState(
            t_s=t,
            attitude=attitude,
            euler_rad=euler,
            angular_rate_body_rad_s=body_rate,
            angular_accel_body_rad_s2=body_accel,
            position_enu_m=position,
            latitude_deg=np.rad2deg(latitude),
            longitude_deg=np.rad2deg(longitude),
            altitude_m=altitude,
            velocity_enu_mps=velocity,
            acceleration_enu_mps2=acceleration,
            current_enu_mps=current,
            wind_at=self.wind.evaluate_enu_mps,
        )
