"""A flux buoy's motion pack: a magnetometer (``imu/mag``) and the pack's own AHRS attitude
(``imu/data``).

The geomagnetic field is the IGRF (package ``ppigrf``) at the scenario's place and start date,
held constant over the run (a moored buoy moves metres; the field changes by nT per year). The
fusion computes declination with a different model (the WMM), so a sign or convention error in
either shows up as a heading error instead of cancelling out.

Both carry the imperfections of the packs on real flux buoys when the scenario gives them: the
magnetometer its hard iron (the buoy's own magnetism, tens of µT) and soft iron (a matrix a few
per cent off the identity), uncalibrated as the contract says; the AHRS a first-order lag of
the attitude (``lag_time_constant_s``) while its ``orientation_covariance`` states the data
sheet's σ (``claimed_sigma_deg``), far below the lag's error in waves.

Both sensors draw from their own random streams (keys :data:`MAGNETOMETER_STREAM_KEY`,
:data:`AHRS_STREAM_KEY`), one fixed block of draws per sample, so splitting the sample times
into several ``measure`` calls gives the same output as one call.
"""

from __future__ import annotations

import datetime
from collections.abc import Sequence
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import ArrayLike
from scipy.spatial.transform import Rotation

from sensor_sim.sensor_errors import AhrsErrorConfig, MagnetometerErrorConfig
from sensor_sim.sensor_models import ideal_imu, sensor_rng

if TYPE_CHECKING:
    from sensor_sim.scenario import Scenario
    from sensor_sim.truth import TruthModel

MAGNETOMETER_STREAM_KEY = 4
AHRS_STREAM_KEY = 5

NANOTESLA = 1e-9
MICROTESLA = 1e-6
_DEG = np.pi / 180.0


def igrf_field_enu_t(latitude_deg: float, longitude_deg: float, altitude_m: float, when_ns: int):
    """The IGRF main field (East, North, Up; tesla) at a geodetic place and a time (ns since
    the epoch)."""
    date = datetime.datetime.fromtimestamp(when_ns * 1e-9, tz=datetime.UTC).replace(tzinfo=None)
    # Imported here: ppigrf brings pandas along, almost half a second of every node's start-up.
    import ppigrf

    east, north, up = ppigrf.igrf(longitude_deg, latitude_deg, altitude_m * 1e-3, date)
    return np.array([float(np.ravel(c)[0]) for c in (east, north, up)]) * NANOTESLA


def igrf_declination_deg(scenario: Scenario) -> float:
    """Declination (deg, east positive) of the IGRF at the scenario's place and start."""
    east, north, _ = igrf_field_enu_t(
        scenario.origin_latitude_deg,
        scenario.origin_longitude_deg,
        scenario.origin_altitude_m,
        scenario.start_time_ns,
    )
    return float(np.degrees(np.arctan2(east, north)))


def _times(t_s: ArrayLike) -> np.ndarray:
    t = np.atleast_1d(np.asarray(t_s, dtype=float)).ravel()
    if not np.all(np.isfinite(t)):
        raise ValueError("sample times must be finite")
    return t


class MagnetometerSimulator:
    """Uncalibrated magnetometer: soft iron · B_body + hard iron + noise (tesla)."""

    def __init__(
        self,
        truth: TruthModel,
        config: MagnetometerErrorConfig,
        scenario: Scenario,
        seed: int | Sequence[int],
    ):
        self.truth = truth
        self.config = config
        self.field_enu_t = igrf_field_enu_t(
            scenario.origin_latitude_deg,
            scenario.origin_longitude_deg,
            scenario.origin_altitude_m,
            scenario.start_time_ns,
        )
        self._soft_iron = np.reshape(np.asarray(config.soft_iron, dtype=float), (3, 3))
        self._hard_iron_t = np.asarray(config.hard_iron_ut, dtype=float) * MICROTESLA
        self._rng = sensor_rng(seed, MAGNETOMETER_STREAM_KEY)

    def field_in_map_t(self, t: np.ndarray) -> np.ndarray:
        """The field the buoy feels (N, 3; ENU, tesla): the IGRF, turned about the vertical
        inside the disturbance intervals (a turn clockwise seen from above by the bias makes
        the compass read a heading larger by the bias)."""
        field = np.broadcast_to(self.field_enu_t, (t.size, 3)).copy()
        disturbed = np.zeros(t.size, dtype=bool)
        for start, end in self.config.disturbances_s:
            disturbed |= (t >= start) & (t < end)
        if np.any(disturbed):
            # The field turned counter-clockwise (ENU yaw +bias) points the buoy's compass
            # north further left, so the heading it reads grows by the bias.
            turn = Rotation.from_rotvec([0.0, 0.0, self.config.disturbance_heading_bias_deg * _DEG])
            field[disturbed] = turn.apply(field[disturbed])
        return field

    def measure(self, t_s: ArrayLike) -> np.ndarray:
        """Measured field (N, 3; imu_link, tesla)."""
        t = _times(t_s)
        noise = self._rng.standard_normal((t.size, 3)) * self.config.noise_ut * MICROTESLA
        if t.size == 0:
            return np.empty((0, 3))
        attitude = self.truth.evaluate(t).attitude
        body = attitude.inv().apply(self.field_in_map_t(t))
        return body @ self._soft_iron.T + self._hard_iron_t + noise


class AhrsSimulator:
    """The motion pack's attitude output: the truth through a first-order lag, a slow
    Gauss-Markov error and white noise, yaw referenced as configured.

    The lag acts on the body-frame attitude error e (R_out = R_true · Exp(e)): each sample the
    pack moves a fraction α = 1 − exp(−dt/τ) of the way to the truth while the truth turns by
    δθ (body rotation vector since the previous sample), e_k = (1 − α)(e_{k−1} − δθ_k) to first
    order (the order the pack's own small-angle filter works to). Rates and specific force are
    the ideal ones plus the pack's own white noise.
    """

    def __init__(
        self,
        truth: TruthModel,
        config: AhrsErrorConfig,
        scenario: Scenario,
        seed: int | Sequence[int],
        rate_hz: float,
    ):
        self.truth = truth
        self.config = config
        self.declination_deg = igrf_declination_deg(scenario)
        self._rng = sensor_rng(seed, AHRS_STREAM_KEY)
        self._dt_s = 1.0 / rate_hz
        self._lag_error_body_rad = np.zeros(3)
        self._slow_error_rad = self._rng.standard_normal(3) * config.error_deg * _DEG
        self._previous_attitude: Rotation | None = None
        self._previous_t_s: float | None = None
        # A magnetic-north yaw is the true one plus the declination (ENU yaw is counter-
        # clockwise from East, a compass heading clockwise from North).
        reference_yaw_rad = (
            self.declination_deg * _DEG if config.yaw_reference == "magnetic_north" else 0.0
        )
        self._reference = Rotation.from_rotvec([0.0, 0.0, reference_yaw_rad])

    def measure(self, t_s: ArrayLike):
        """(attitude Rotation body→ENU of the pack's reference (N), gyro rad/s (N, 3), specific
        force m/s² (N, 3), the orientation variances the pack states, rad² (3,): x, y, z)."""
        t = _times(t_s)
        normals = self._rng.standard_normal((t.size, 4, 3))
        config = self.config
        state = self.truth.evaluate(t)
        attitude = state.attitude
        previous = self._previous_attitude if self._previous_attitude is not None else attitude[0]
        previous_t = self._previous_t_s if self._previous_t_s is not None else t[0] - self._dt_s
        preceding = Rotation.concatenate([previous, attitude[:-1]])
        increments = (preceding.inv() * attitude).as_rotvec()
        intervals = np.diff(t, prepend=previous_t)
        if config.lag_time_constant_s > 0.0:
            keep = np.exp(-intervals / config.lag_time_constant_s)
        else:
            keep = np.zeros(t.size)
        # e_k = keep_k (e_{k-1} − δθ_k), a first-order recursion with a varying gain.
        lag = np.empty((t.size, 3))
        error = self._lag_error_body_rad
        for k in range(t.size):
            error = keep[k] * (error - increments[k])
            lag[k] = error
        self._lag_error_body_rad = error
        decay = np.exp(-intervals / config.error_correlation_time_s)
        drive = normals[:, 0] * (config.error_deg * _DEG * np.sqrt(1.0 - decay**2))[:, None]
        slow = np.empty((t.size, 3))
        state_error = self._slow_error_rad
        for k in range(t.size):
            state_error = decay[k] * state_error + drive[k]
            slow[k] = state_error
        self._slow_error_rad = state_error
        self._previous_attitude = attitude[-1]
        self._previous_t_s = float(t[-1])
        noise = normals[:, 1] * config.noise_deg * _DEG
        output = (
            self._reference
            * Rotation.from_rotvec(slow + noise)
            * attitude
            * Rotation.from_rotvec(lag)
        )
        gyro, force = ideal_imu(state)
        gyro = gyro + normals[:, 2] * 1e-3
        force = force + normals[:, 3] * 1e-2
        return output, gyro, force, config.claimed_orientation_variance_rad2()


__all__ = [
    "AHRS_STREAM_KEY",
    "MAGNETOMETER_STREAM_KEY",
    "AhrsSimulator",
    "MagnetometerSimulator",
    "igrf_declination_deg",
    "igrf_field_enu_t",
]
