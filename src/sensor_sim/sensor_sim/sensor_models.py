"""Sensor error models: MEMS IMU, dual-antenna GNSS receiver, 3-D sonic anemometer.

Each simulator evaluates the shared truth at its own sample times and adds its errors. Random
errors come from a private stream np.random.default_rng([*seed, SENSOR_KEY]) (seed: the
scenario seed, or any sequence of non-negative integers that starts with it), so a sensor's
output depends only on the scenario, the seed and its own sample times: every node that owns a
sensor reproduces it exactly, and no two sensors share a stream. Within a simulator, one fixed
block of normal draws is consumed per sample, so splitting the same sample times into several
``measure`` calls gives the same output as one call.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import ArrayLike
from scipy.spatial.transform import Rotation
from scipy.special import ndtri

from sensor_sim.geodesy import (
    earth_rate_enu_rad_s,
    offset_geodetic,
    transport_rate_enu_rad_s,
    wgs84_normal_gravity_mps2,
)
from sensor_sim.sensor_errors import (
    STANDARD_GRAVITY_MPS2,
    AnemometerErrorConfig,
    DvlErrorConfig,
    GnssErrorConfig,
    ImuErrorConfig,
)

if TYPE_CHECKING:
    from sensor_sim.truth import TruthModel, TruthState

__all__ = [
    "AnemometerSimulator",
    "DvlSimulator",
    "GnssSample",
    "GnssSimulator",
    "ImuSimulator",
    "ideal_imu",
    "wgs84_normal_gravity_mps2",
]

IMU_STREAM_KEY = 1
GNSS_STREAM_KEY = 2
ANEMOMETER_STREAM_KEY = 3
# The third antenna's baseline noise draws from a stream of its own, so a receiver with or
# without it gives the same measurements of the other kinds.
GNSS_TERTIARY_STREAM_KEY = 4
DVL_STREAM_KEY = 5
SONIC_TEMPERATURE_STREAM_KEY = 6

_DEG = np.pi / 180.0
# Keeps exp(-elapsed/tau) far from underflow inside one vectorised Gauss-Markov block.
_MAX_DECAY_PER_BLOCK = 50.0


def ideal_imu(state: TruthState) -> tuple[np.ndarray, np.ndarray]:
    """Error-free gyro (rad/s) and specific force (m/s²), body axes, from a truth state.

    gyro = omega_nb^b + R_nb^T (omega_ie^n + omega_en^n);
    f^b = R_nb^T (a^n + (2 omega_ie^n + omega_en^n) x v^n - g^n), g^n = (0, 0, -gamma(lat, h)).
    """
    latitude = np.deg2rad(state.latitude_deg)
    earth_rate = earth_rate_enu_rad_s(latitude)
    transport_rate = transport_rate_enu_rad_s(latitude, state.altitude_m, state.velocity_enu_mps)
    gyro = state.angular_rate_body_rad_s + state.attitude.inv().apply(earth_rate + transport_rate)
    gravity = np.zeros_like(state.velocity_enu_mps)
    gravity[:, 2] = -wgs84_normal_gravity_mps2(latitude, state.altitude_m)
    coriolis = np.cross(2.0 * earth_rate + transport_rate, state.velocity_enu_mps)
    specific_force = state.attitude.inv().apply(state.acceleration_enu_mps2 + coriolis - gravity)
    return gyro, specific_force


def sensor_rng(seed: int | Sequence[int], stream_key: int) -> np.random.Generator:
    """The private random stream of one sensor: default_rng([*seed, stream_key])."""
    entropy = [int(value) for value in np.atleast_1d(np.asarray(seed, dtype=object))]
    if any(value < 0 for value in entropy):
        raise ValueError(f"seed {seed!r}: must be non-negative integers")
    return np.random.default_rng([*entropy, stream_key])


def _sample_times(t_s: ArrayLike) -> np.ndarray:
    t = np.atleast_1d(np.asarray(t_s, dtype=float)).ravel()
    if not np.all(np.isfinite(t)):
        raise ValueError("sample times must be finite")
    return t


def _in_intervals(t: np.ndarray, intervals: tuple[tuple[float, float], ...]) -> np.ndarray:
    inside = np.zeros(t.shape, dtype=bool)
    for start, end in intervals:
        inside |= (t >= start) & (t < end)
    return inside


def _gauss_markov_sequence(
    initial: np.ndarray, decay: np.ndarray, drive: np.ndarray, elapsed_over_tau: np.ndarray
) -> np.ndarray:
    """Solve b_k = decay_k b_(k-1) + drive_k for k = 0..N-1, vectorised in blocks.

    initial: (3,) state before the first sample; decay: (N,) = exp(-dt_k/tau);
    drive: (N,3); elapsed_over_tau: (N,) dt_k/tau, used to size the blocks.
    """
    result = np.empty_like(drive)
    state = initial
    start = 0
    n = decay.size
    while start < n:
        budget = np.cumsum(elapsed_over_tau[start:])
        stop = start + max(1, int(np.searchsorted(budget, _MAX_DECAY_PER_BLOCK, side="right")))
        stop = min(stop, n)
        if stop - start == 1:
            # A lone step may decay past underflow; propagate it directly.
            state = decay[start] * state + drive[start]
            result[start] = state
            start = stop
            continue
        cumulative = np.exp(-budget[: stop - start])[:, None]
        block = cumulative * (state + np.cumsum(drive[start:stop] / cumulative, axis=0))
        result[start:stop] = block
        state = block[-1]
        start = stop
    return result


class ImuSimulator:
    """Strapdown IMU at the base_link origin (imu_link = base_link) with MEMS errors.

    measured = (1 + scale_error) * ideal + turn_on_bias + gauss_markov_bias + white_noise,
    per axis. White noise on a sample has sigma = density / sqrt(dt), dt being the spacing to
    the previous sample (first_interval_s for the very first one). The Gauss-Markov biases are
    propagated with the exact discretisation
    b_k = e^(-dt/tau) b_(k-1) + sigma sqrt(1 - e^(-2 dt/tau)) w_k.
    """

    def __init__(
        self,
        truth: TruthModel,
        config: ImuErrorConfig,
        seed: int | Sequence[int],
        first_interval_s: float = 0.01,
    ):
        """truth: shared truth model; config: error budget; seed: scenario seed;
        first_interval_s: spacing (s) assumed before the first sample for its noise level."""
        if not first_interval_s > 0.0:
            raise ValueError(f"first_interval_s = {first_interval_s!r}: must be > 0")
        self.truth = truth
        self.config = config
        self._rng = sensor_rng(seed, IMU_STREAM_KEY)
        draws = self._rng.standard_normal((6, 3))
        self.gyro_turn_on_bias_rad_s = draws[0] * config.gyro_turn_on_bias_deg_s * _DEG
        self.accel_turn_on_bias_mps2 = (
            draws[1] * config.accel_turn_on_bias_mg * 1e-3 * STANDARD_GRAVITY_MPS2
        )
        self.gyro_scale_factor_error = draws[2] * config.scale_factor_error_percent / 100.0
        self.accel_scale_factor_error = draws[3] * config.scale_factor_error_percent / 100.0
        self._gyro_markov_rad_s = draws[4] * config.gyro_bias_instability_rad_s
        self._accel_markov_mps2 = draws[5] * config.accel_bias_instability_mps2
        self._first_interval_s = float(first_interval_s)
        self._last_t_s: float | None = None

    def ideal(self, t_s: ArrayLike) -> tuple[np.ndarray, np.ndarray]:
        """Error-free (gyro rad/s (N,3), specific force m/s² (N,3)) in body axes."""
        return ideal_imu(self.truth.evaluate(_sample_times(t_s)))

    def measure(self, t_s: ArrayLike) -> tuple[np.ndarray, np.ndarray]:
        """Measured (gyro rad/s (N,3), specific force m/s² (N,3)); times must keep increasing."""
        t = _sample_times(t_s)
        if t.size == 0:
            return np.empty((0, 3)), np.empty((0, 3))
        previous = self._last_t_s if self._last_t_s is not None else t[0] - self._first_interval_s
        intervals = np.diff(t, prepend=previous)
        if np.any(intervals <= 0.0):
            raise ValueError("IMU sample times must be strictly increasing across calls")
        gyro_ideal, force_ideal = self.ideal(t)
        normals = self._rng.standard_normal((t.size, 4, 3))
        config = self.config

        gyro_markov = self._markov(
            self._gyro_markov_rad_s,
            intervals / config.gyro_bias_correlation_time_s,
            config.gyro_bias_instability_rad_s,
            normals[:, 2],
        )
        accel_markov = self._markov(
            self._accel_markov_mps2,
            intervals / config.accel_bias_correlation_time_s,
            config.accel_bias_instability_mps2,
            normals[:, 3],
        )
        self._gyro_markov_rad_s = gyro_markov[-1]
        self._accel_markov_mps2 = accel_markov[-1]
        self._last_t_s = float(t[-1])

        root_interval = np.sqrt(intervals)[:, None]
        gyro = (
            (1.0 + self.gyro_scale_factor_error) * gyro_ideal
            + self.gyro_turn_on_bias_rad_s
            + gyro_markov
            + normals[:, 0] * config.gyro_noise_density_rad_s_sqrt_hz / root_interval
        )
        specific_force = (
            (1.0 + self.accel_scale_factor_error) * force_ideal
            + self.accel_turn_on_bias_mps2
            + accel_markov
            + normals[:, 1] * config.accel_noise_density_mps2_sqrt_hz / root_interval
        )
        return gyro, specific_force

    @staticmethod
    def _markov(
        state: np.ndarray, elapsed_over_tau: np.ndarray, sigma: float, normals: np.ndarray
    ) -> np.ndarray:
        decay = np.exp(-elapsed_over_tau)
        drive = normals * (sigma * np.sqrt(-np.expm1(-2.0 * elapsed_over_tau)))[:, None]
        return _gauss_markov_sequence(state, decay, drive, elapsed_over_tau)


@dataclass(frozen=True)
class GnssSample:
    """Dual-antenna GNSS output over N samples (fields NaN where the matching flag is False).

    latitude_deg, longitude_deg, altitude_m: (N,) primary antenna, WGS-84, ellipsoidal height.
    position_covariance_enu_m2: (N,3,3). velocity_enu_mps: (N,3) primary antenna over ground.
    velocity_covariance_enu_m2s2: (N,3,3). baseline_enu_m: (N,3) primary -> secondary, measured.
    heading_yaw_rad: (N,) ENU azimuth atan2(bN, bE) of the measured baseline's horizontal part.
    heading_variance_rad2: (N,) sigma_h² / (horizontal baseline length)².
    tertiary_baseline_enu_m: (N,3) primary -> tertiary, measured; None without a third antenna.
    """

    t_s: np.ndarray
    latitude_deg: np.ndarray
    longitude_deg: np.ndarray
    altitude_m: np.ndarray
    position_covariance_enu_m2: np.ndarray
    velocity_enu_mps: np.ndarray
    velocity_covariance_enu_m2s2: np.ndarray
    baseline_enu_m: np.ndarray
    heading_yaw_rad: np.ndarray
    heading_variance_rad2: np.ndarray
    fix_valid: np.ndarray
    velocity_valid: np.ndarray
    heading_valid: np.ndarray
    tertiary_baseline_enu_m: np.ndarray | None = None


class GnssSimulator:
    """GNSS receiver: primary antenna position and velocity; with two antennas the baseline and
    heading, and with a third the primary -> tertiary baseline (same noise as the first)."""

    def __init__(
        self,
        truth: TruthModel,
        config: GnssErrorConfig,
        primary_antenna_body_m: ArrayLike,
        secondary_antenna_body_m: ArrayLike,
        seed: int | Sequence[int],
        tertiary_antenna_body_m: ArrayLike | None = None,
    ):
        """Antenna phase centres are in base_link (FLU), metres (the tertiary one None or NaN
        for a dual-antenna receiver); seed is the scenario seed."""
        self.truth = truth
        self.config = config
        self.primary_antenna_body_m = _body_vector(primary_antenna_body_m, "primary_antenna")
        self.secondary_antenna_body_m = _body_vector(secondary_antenna_body_m, "secondary_antenna")
        baseline = self.secondary_antenna_body_m - self.primary_antenna_body_m
        if not np.linalg.norm(baseline) > 0.0:
            raise ValueError("primary and secondary antennas must not coincide")
        self._rng = sensor_rng(seed, GNSS_STREAM_KEY)
        self.tertiary_antenna_body_m = None
        if tertiary_antenna_body_m is not None and not np.isnan(tertiary_antenna_body_m).any():
            self.tertiary_antenna_body_m = _body_vector(tertiary_antenna_body_m, "tertiary_antenna")
        self._tertiary_rng = sensor_rng(seed, GNSS_TERTIARY_STREAM_KEY)

    def noise_sigmas(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """1-sigma per ENU axis of the position (m), velocity (m/s) and baseline (m) noise."""
        config = self.config

        def horizontal_and_vertical(horizontal: float, vertical: float) -> np.ndarray:
            return np.array([horizontal, horizontal, vertical])

        return (
            horizontal_and_vertical(
                config.position_noise_horizontal_m, config.position_noise_vertical_m
            ),
            horizontal_and_vertical(
                config.velocity_noise_horizontal_mps, config.velocity_noise_vertical_mps
            ),
            horizontal_and_vertical(
                config.baseline_noise_horizontal_m, config.baseline_noise_vertical_m
            ),
        )

    def validity(self, t: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(fix, velocity, heading) valid at scenario times t (s): outside their outages, and
        a heading only from a dual-antenna receiver."""
        config = self.config
        fix_valid = ~_in_intervals(t, config.fix_outages_s)
        velocity_valid = fix_valid & ~_in_intervals(t, config.velocity_outages_s)
        heading_valid = fix_valid & ~_in_intervals(t, config.heading_outages_s)
        if config.receiver != "dual_antenna":
            heading_valid[:] = False
        return fix_valid, velocity_valid, heading_valid

    def measure(self, t_s: ArrayLike) -> GnssSample:
        """Measurements at times t_s (s), one block of 9 normal draws per sample."""
        t = _sample_times(t_s)
        state = self.truth.evaluate(t)
        normals = self._rng.standard_normal((t.size, 3, 3))
        position_sigma, velocity_sigma, baseline_sigma = self.noise_sigmas()
        latitude, longitude, altitude = self._antenna_position(
            state, normals[:, 0] * position_sigma
        )
        velocity = self._antenna_velocity(state, normals[:, 1] * velocity_sigma)
        baseline = (
            state.attitude.apply(self.secondary_antenna_body_m - self.primary_antenna_body_m)
            + normals[:, 2] * baseline_sigma
        )
        heading = np.arctan2(baseline[:, 1], baseline[:, 0])
        horizontal_length_sq = baseline[:, 0] ** 2 + baseline[:, 1] ** 2
        heading_variance = self.config.baseline_noise_horizontal_m**2 / horizontal_length_sq

        fix_valid, velocity_valid, heading_valid = self.validity(t)
        no_fix = ~fix_valid
        no_heading = ~heading_valid
        latitude_deg = np.where(no_fix, np.nan, np.rad2deg(latitude))
        longitude_deg = np.where(no_fix, np.nan, np.rad2deg(longitude))
        altitude = np.where(no_fix, np.nan, altitude)
        velocity[~velocity_valid] = np.nan
        baseline[no_heading] = np.nan
        heading = np.where(no_heading, np.nan, heading)
        heading_variance = np.where(no_heading, np.nan, heading_variance)
        return GnssSample(
            t_s=t,
            latitude_deg=latitude_deg,
            longitude_deg=longitude_deg,
            altitude_m=altitude,
            position_covariance_enu_m2=np.broadcast_to(
                np.diag(position_sigma**2), (t.size, 3, 3)
            ).copy(),
            velocity_enu_mps=velocity,
            velocity_covariance_enu_m2s2=np.broadcast_to(
                np.diag(velocity_sigma**2), (t.size, 3, 3)
            ).copy(),
            baseline_enu_m=baseline,
            heading_yaw_rad=heading,
            heading_variance_rad2=heading_variance,
            fix_valid=fix_valid,
            velocity_valid=velocity_valid,
            heading_valid=heading_valid,
            tertiary_baseline_enu_m=self._tertiary_baseline(state, baseline_sigma, no_heading),
        )

    def _antenna_position(self, state: TruthState, noise_enu_m: np.ndarray):
        """(latitude rad, longitude rad, ellipsoidal height m) of the primary antenna, its
        position moved by noise_enu_m (N, 3; ENU, m)."""
        lever_enu = state.attitude.apply(self.primary_antenna_body_m)
        return offset_geodetic(
            np.deg2rad(state.latitude_deg),
            np.deg2rad(state.longitude_deg),
            state.altitude_m,
            lever_enu + noise_enu_m,
        )

    def _antenna_velocity(self, state: TruthState, noise_enu_mps: np.ndarray) -> np.ndarray:
        """Velocity over ground of the primary antenna (N, 3; ENU, m/s) plus noise_enu_mps."""
        lever_velocity_body = np.cross(state.angular_rate_body_rad_s, self.primary_antenna_body_m)
        return state.velocity_enu_mps + state.attitude.apply(lever_velocity_body) + noise_enu_mps

    def _tertiary_baseline(
        self, state: TruthState, baseline_sigma_m: np.ndarray, no_heading: np.ndarray
    ) -> np.ndarray | None:
        """Measured primary → tertiary vector (N, 3; ENU, m), NaN where there is no heading;
        None without a third antenna."""
        if self.tertiary_antenna_body_m is None:
            return None
        tertiary = (
            state.attitude.apply(self.tertiary_antenna_body_m - self.primary_antenna_body_m)
            + self._tertiary_rng.standard_normal((len(no_heading), 3)) * baseline_sigma_m
        )
        tertiary[no_heading] = np.nan
        return tertiary


class AnemometerSimulator:
    """3-D sonic anemometer on a lever arm, mounted with a fixed rotation, white noise.

    measured = R_bw^T R_nb^T (wind - v_b - R_nb (omega_nb^b x B)) + noise, in anemometer axes,
    with R_bw = Rz(yaw) Ry(pitch) Rx(roll) of mounting_rpy_deg (anemometer axes -> body) and B
    the anemometer position in base_link.
    """

    def __init__(
        self,
        truth: TruthModel,
        config: AnemometerErrorConfig,
        position_body_m: ArrayLike,
        mounting_rpy_deg: ArrayLike,
        seed: int | Sequence[int],
    ):
        """position_body_m: measurement centre in base_link (FLU), m; mounting_rpy_deg: roll,
        pitch, yaw of anemometer_link relative to base_link, degrees; seed: scenario seed."""
        self.truth = truth
        self.config = config
        self.position_body_m = _body_vector(position_body_m, "anemometer position")
        roll, pitch, yaw = _body_vector(mounting_rpy_deg, "anemometer mounting rpy")
        self.mounting = Rotation.from_euler("ZYX", [yaw, pitch, roll], degrees=True)
        self._rng = sensor_rng(seed, ANEMOMETER_STREAM_KEY)
        self._temperature_rng = sensor_rng(seed, SONIC_TEMPERATURE_STREAM_KEY)

    def ideal(self, t_s: ArrayLike) -> np.ndarray:
        """Error-free air velocity relative to the sensor (N,3), anemometer axes, m/s."""
        state = self.truth.evaluate(_sample_times(t_s))
        lever_velocity_body = np.cross(state.angular_rate_body_rad_s, self.position_body_m)
        relative_air_enu = (
            state.wind_enu_mps - state.velocity_enu_mps - state.attitude.apply(lever_velocity_body)
        )
        return self.mounting.inv().apply(state.attitude.inv().apply(relative_air_enu))

    def measure(self, t_s: ArrayLike) -> np.ndarray:
        """Measured air velocity relative to the sensor (N,3), anemometer axes, m/s."""
        ideal = self.ideal(t_s)
        return ideal + self._rng.standard_normal(ideal.shape) * self.config.noise_mps

    def measure_temperature(self, t_s: ArrayLike) -> np.ndarray | None:
        """Measured sonic temperature (N,), °C, with white noise; None when the scenario's air
        has no sonic temperature."""
        temperature = self.truth.wind.sonic_temperature_degc(_sample_times(t_s))
        if temperature is None:
            return None
        noise = self._temperature_rng.standard_normal(temperature.shape)
        return temperature + noise * self.config.temperature_noise_k


class DvlSimulator:
    """Doppler velocity log in water-track mode on a lever arm, mounted with a fixed rotation.

    ideal = R_bd^T R_nb^T (v_b + R_nb (omega_nb^b x p) - w), in DVL axes: the velocity of the
    DVL through the water, with R_bd = Rz(yaw) Ry(pitch) Rx(roll) of mounting_rpy_deg (DVL axes
    -> body), p the DVL position in base_link, v_b the velocity of base_link over ground and w
    the water's velocity at the DVL (current plus wave orbital velocity at its depth,
    TruthModel.water_at). measured = (1 + s) ideal + bias + noise; lost pings are NaN
    (DvlErrorConfig). One block of 4 normal draws per ping (3 noise, 1 for the random loss).
    """

    def __init__(
        self,
        truth: TruthModel,
        config: DvlErrorConfig,
        position_body_m: ArrayLike,
        mounting_rpy_deg: ArrayLike,
        seed: int | Sequence[int],
    ):
        """position_body_m: DVL measurement centre in base_link (FLU), m; mounting_rpy_deg:
        roll, pitch, yaw of dvl_link relative to base_link, degrees; seed: scenario seed."""
        self.truth = truth
        self.config = config
        self.position_body_m = _body_vector(position_body_m, "DVL position")
        roll, pitch, yaw = _body_vector(mounting_rpy_deg, "DVL mounting rpy")
        self.mounting = Rotation.from_euler("ZYX", [yaw, pitch, roll], degrees=True)
        self._rng = sensor_rng(seed, DVL_STREAM_KEY)
        # A ping is lost at random when its loss draw, a standard normal, falls below this.
        self._loss_threshold = ndtri(config.ping_loss_probability)

    def ideal(self, t_s: ArrayLike) -> tuple[np.ndarray, np.ndarray]:
        """Error-free velocity through the water (N,3), DVL axes, m/s, and the DVL's depth
        below the surface (N,), m."""
        state = self.truth.evaluate(_sample_times(t_s))
        water = self.truth.water_at(state, self.position_body_m)
        lever_velocity_body = np.cross(state.angular_rate_body_rad_s, self.position_body_m)
        through_water_enu = (
            state.velocity_enu_mps
            + state.attitude.apply(lever_velocity_body)
            - water.velocity_enu_mps
        )
        velocity = self.mounting.inv().apply(state.attitude.inv().apply(through_water_enu))
        return velocity, water.depth_m

    def measure(self, t_s: ArrayLike) -> np.ndarray:
        """Measured velocity through the water (N,3), DVL axes, m/s; NaN rows for lost pings."""
        t = _sample_times(t_s)
        ideal, depth = self.ideal(t)
        config = self.config
        normals = self._rng.standard_normal((t.size, 4))
        measured = (
            (1.0 + config.scale_factor_error_percent / 100.0) * ideal
            + np.asarray(config.bias_mps)
            + normals[:, :3] * config.noise_mps
        )
        lost = (
            _in_intervals(t, config.outages_s)
            | (depth < config.min_depth_m)
            | (normals[:, 3] < self._loss_threshold)
        )
        measured[lost] = np.nan
        return measured


def _body_vector(value: ArrayLike, what: str) -> np.ndarray:
    vector = np.asarray(value, dtype=float)
    if vector.shape != (3,) or not np.all(np.isfinite(vector)):
        raise ValueError(f"{what} must be three finite numbers, got {value!r}")
    return vector
