"""Error budgets of the simulated sensors: MEMS IMU, GNSS, sonic anemometer, magnetometer and
the motion pack's AHRS.

The budgets are in the units data sheets use and are validated on construction, so a scenario
file or a parameter with an impossible value is refused with a message naming the key.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Literal

import numpy as np

from buoy_common.extrinsics import check_shared_fields, shared_field

STANDARD_GRAVITY_MPS2 = 9.80665
_DEG = np.pi / 180.0
_SECONDS_PER_HOUR = 3600.0


class InvalidConfigValueError(ValueError):
    """A configuration field holds a value outside its physical range."""

    def __init__(self, key: str, value: object, requirement: str):
        super().__init__(f"{key} = {value!r}: {requirement}")
        self.key = key
        self.value = value
        self.requirement = requirement


def check_field(config: object, key: str, ok: bool, requirement: str) -> None:
    """Raise InvalidConfigValueError for config.key unless ok."""
    if not ok:
        raise InvalidConfigValueError(key, getattr(config, key), requirement)


def check_non_negative(config: object, *keys: str) -> None:
    """Each named field of config must be >= 0."""
    for key in keys:
        check_field(config, key, getattr(config, key) >= 0.0, "must be >= 0")


def check_positive(config: object, *keys: str) -> None:
    """Each named field of config must be > 0."""
    for key in keys:
        check_field(config, key, getattr(config, key) > 0.0, "must be > 0")


@dataclass(frozen=True)
class ImuErrorConfig:
    """MEMS IMU error budget, in the units data sheets use (1-sigma per axis).

    Noise densities are angle/velocity random walks; turn-on biases and scale-factor errors are
    drawn once when the simulator starts; bias instabilities are the stationary standard
    deviations of first-order Gauss-Markov processes with the given correlation times.
    """

    gyro_noise_deg_sqrt_h: float = 0.2
    gyro_turn_on_bias_deg_s: float = 0.02
    gyro_bias_instability_deg_h: float = 5.0
    gyro_bias_correlation_time_s: float = 300.0
    accel_noise_mps_sqrt_h: float = 0.05
    accel_turn_on_bias_mg: float = 5.0
    accel_bias_instability_mg: float = 0.1
    accel_bias_correlation_time_s: float = 600.0
    scale_factor_error_percent: float = 0.1

    def __post_init__(self) -> None:
        check_non_negative(
            self,
            "gyro_noise_deg_sqrt_h",
            "gyro_turn_on_bias_deg_s",
            "gyro_bias_instability_deg_h",
            "accel_noise_mps_sqrt_h",
            "accel_turn_on_bias_mg",
            "accel_bias_instability_mg",
            "scale_factor_error_percent",
        )
        check_positive(self, "gyro_bias_correlation_time_s", "accel_bias_correlation_time_s")

    @property
    def gyro_noise_density_rad_s_sqrt_hz(self) -> float:
        """Gyro white-noise density, rad/s/sqrt(Hz) (= rad/sqrt(s))."""
        return self.gyro_noise_deg_sqrt_h * _DEG / np.sqrt(_SECONDS_PER_HOUR)

    @property
    def accel_noise_density_mps2_sqrt_hz(self) -> float:
        """Accelerometer white-noise density, m/s²/sqrt(Hz) (= m/s/sqrt(s))."""
        return self.accel_noise_mps_sqrt_h / np.sqrt(_SECONDS_PER_HOUR)

    @property
    def gyro_bias_instability_rad_s(self) -> float:
        """Stationary sigma of the gyro Gauss-Markov bias, rad/s."""
        return self.gyro_bias_instability_deg_h * _DEG / _SECONDS_PER_HOUR

    @property
    def accel_bias_instability_mps2(self) -> float:
        """Stationary sigma of the accelerometer Gauss-Markov bias, m/s²."""
        return self.accel_bias_instability_mg * 1e-3 * STANDARD_GRAVITY_MPS2


def check_intervals(config: object, *keys: str) -> None:
    """Each named field of config holds [start, end) intervals with start < end."""
    for key in keys:
        for start, end in getattr(config, key):
            if not start < end:
                raise InvalidConfigValueError(
                    key, getattr(config, key), f"interval [{start}, {end}) must have start < end"
                )


@dataclass(frozen=True)
class GnssErrorConfig:
    """GNSS receiver errors, 1-sigma per ENU axis, white.

    ``receiver``: ``dual_antenna`` (moving-baseline RTK: fix, velocity, heading, baseline),
    ``single_antenna`` (fix and velocity) or ``none`` (no GNSS topic at all).
    Outages are [start, end) intervals in scenario time (s), one list per topic: the message is
    then published with NaN values and ``status -1`` (as a receiver without a solution does). A
    receiver without a fix has no velocity, heading or baseline either, so fix outages blank
    every GNSS topic; heading outages blank the heading and the baseline (one carrier-phase
    solution). ``silent_outages_s`` are [start, end) intervals in which the receiver publishes
    nothing at all, on any of its topics (a receiver that lost power or its serial link): the
    topics simply stop, as they do on a buoy whose GNSS is out for minutes.
    """

    position_noise_horizontal_m: float = 0.02
    position_noise_vertical_m: float = 0.04
    velocity_noise_horizontal_mps: float = 0.02
    velocity_noise_vertical_mps: float = 0.04
    baseline_noise_horizontal_m: float = 0.003
    baseline_noise_vertical_m: float = 0.006
    receiver: Literal["dual_antenna", "single_antenna", "none"] = "dual_antenna"
    fix_outages_s: tuple[tuple[float, float], ...] = ()
    velocity_outages_s: tuple[tuple[float, float], ...] = ()
    heading_outages_s: tuple[tuple[float, float], ...] = ()
    silent_outages_s: tuple[tuple[float, float], ...] = ()

    def __post_init__(self) -> None:
        check_non_negative(
            self,
            "position_noise_horizontal_m",
            "position_noise_vertical_m",
            "velocity_noise_horizontal_mps",
            "velocity_noise_vertical_mps",
            "baseline_noise_horizontal_m",
            "baseline_noise_vertical_m",
        )
        check_field(
            self,
            "receiver",
            self.receiver in ("dual_antenna", "single_antenna", "none"),
            "must be dual_antenna, single_antenna or none",
        )
        check_intervals(
            self, "fix_outages_s", "velocity_outages_s", "heading_outages_s", "silent_outages_s"
        )


@dataclass(frozen=True)
class AnemometerErrorConfig:
    """Sonic anemometer white noise, m/s, 1-sigma per axis, and of its sonic temperature, K."""

    noise_mps: float = 0.02
    temperature_noise_k: float = 0.02

    def __post_init__(self) -> None:
        check_non_negative(self, "noise_mps", "temperature_noise_k")


@dataclass(frozen=True)
class DvlErrorConfig:
    """Doppler velocity log in water-track mode: errors and lost pings.

    measured = (1 + scale_factor_error_percent / 100) · v + bias_mps + noise, per axis of
    ``dvl_link``, with v the DVL's true velocity through the water. The systematic part is the
    accuracy the paper gives for its DVL, "0.2 % ± 0.2 cm/s", taken at its bound and held for
    the run: a scale error common to all axes (a sound-speed or beam-angle error scales every
    beam alike) and a constant offset per axis. ``noise_mps`` is white noise per axis and ping
    (1σ); the paper gives none. Averaging removes the noise, never the systematic part.

    A ping is lost (published with NaN components, as a DVL flags a bad ping) inside an
    ``outages_s`` interval ([start, end) in scenario time, s), when the transducer is less than
    ``min_depth_m`` below the sea surface (bubbles swept under the hull, or out of the water),
    or at random with ``ping_loss_probability``.
    """

    scale_factor_error_percent: float = 0.2
    bias_mps: tuple[float, float, float] = (0.002, 0.002, 0.002)
    noise_mps: float = 0.005
    min_depth_m: float = 0.5
    ping_loss_probability: float = 0.0
    outages_s: tuple[tuple[float, float], ...] = ()

    def __post_init__(self) -> None:
        check_non_negative(self, "noise_mps", "min_depth_m")
        check_field(
            self,
            "scale_factor_error_percent",
            abs(self.scale_factor_error_percent) <= 10.0,
            "must be within [-10, 10] %",
        )
        check_field(
            self,
            "bias_mps",
            len(self.bias_mps) == 3 and all(abs(b) <= 1.0 for b in self.bias_mps),
            "must be three offsets within [-1, 1] m/s",
        )
        check_field(
            self,
            "ping_loss_probability",
            0.0 <= self.ping_loss_probability < 1.0,
            "must be in [0, 1)",
        )
        for start, end in self.outages_s:
            if not start < end:
                raise InvalidConfigValueError(
                    "outages_s", self.outages_s, f"interval [{start}, {end}) must have start < end"
                )


_IDENTITY_3X3 = (1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0)


@dataclass(frozen=True)
class MagnetometerErrorConfig:
    """Three-axis magnetometer on the IMU (``imu_link``), uncalibrated as the contract says.

    measured = soft_iron · B_body + hard_iron + white noise (tesla), with B_body the
    geomagnetic field of the IGRF at the scenario's place turned into the body frame.
    ``soft_iron`` is a row-major 3×3 matrix (dimensionless), ``hard_iron_ut`` the constant
    offset (µT) of the buoy's own permanent magnetism. ``disturbances_s`` are [start, end)
    intervals during which a passing steel hull turns the local horizontal field by
    ``disturbance_heading_bias_deg`` (clockwise seen from above: the compass heading grows by
    it). ``fitted: false``: no magnetometer.
    """

    fitted: bool = False
    sample_every: int = 10
    noise_ut: float = 0.1
    hard_iron_ut: tuple[float, float, float] = (0.0, 0.0, 0.0)
    soft_iron: tuple[float, ...] = _IDENTITY_3X3
    disturbances_s: tuple[tuple[float, float], ...] = ()
    disturbance_heading_bias_deg: float = 30.0

    def __post_init__(self) -> None:
        check_non_negative(self, "noise_ut")
        check_field(self, "sample_every", self.sample_every >= 1, "must be >= 1")
        check_field(
            self, "soft_iron", len(self.soft_iron) == 9, "must be 9 numbers (3×3, row-major)"
        )
        check_field(
            self,
            "soft_iron",
            abs(np.linalg.det(np.reshape(self.soft_iron, (3, 3)))) > 0.1,
            "must be an invertible matrix near the identity (|det| > 0.1)",
        )
        check_field(self, "hard_iron_ut", len(self.hard_iron_ut) == 3, "must be 3 numbers")
        check_intervals(self, "disturbances_s")


@dataclass(frozen=True)
class AhrsErrorConfig:
    """A motion pack's own attitude solution (``imu/data``), from a filter of its own.

    The pack's filter follows the attitude with a first-order lag of time constant
    ``lag_time_constant_s`` (what a complementary filter that trusts its gyro over
    ``lag_time_constant_s`` does to wave motion); its slow error is a first-order Gauss-Markov
    rotation (1-σ ``error_deg`` per axis, correlation ``error_correlation_time_s``), its sample
    noise white (``noise_deg``). Its yaw is referenced as ``ahrs.yaw_reference`` says; with
    ``magnetic_north`` the IGRF declination at the scenario's place is in it. ``fitted: false``:
    no motion pack. One sample every ``sample_every`` IMU samples.

    ``claimed_sigma_deg``: the roll, pitch and yaw 1-σ the pack's ``orientation_covariance``
    states (on its diagonal, x, y, z, as packs' drivers put them), whatever its real error; a
    pack's data sheet figure (e.g. 0.1/0.1/0.5°) holds for slow motion and leaves out the lag's
    error in waves. Three NaN (the default): the honest σ of the slow error and the noise,
    sqrt(error_deg² + noise_deg²) on every axis, which also leaves the lag out.
    """

    fitted: bool = False
    sample_every: int = 10
    lag_time_constant_s: float = 0.2
    error_deg: float = 0.3
    error_correlation_time_s: float = 120.0
    noise_deg: float = 0.05
    yaw_reference: str = shared_field("ahrs.yaw_reference")
    claimed_sigma_deg: tuple[float, float, float] = (math.nan, math.nan, math.nan)

    def __post_init__(self) -> None:
        check_non_negative(self, "lag_time_constant_s", "error_deg", "noise_deg")
        claimed = self.claimed_sigma_deg
        check_field(
            self,
            "claimed_sigma_deg",
            len(claimed) == 3
            and (all(math.isnan(c) for c in claimed) or all(0.0 <= c < 180.0 for c in claimed)),
            "must be three standard deviations in [0, 180) deg (roll, pitch, yaw), or three NaN",
        )
        check_field(self, "sample_every", self.sample_every >= 1, "must be >= 1")
        check_positive(self, "error_correlation_time_s")
        try:
            check_shared_fields(self)
        except ValueError as error:
            raise InvalidConfigValueError("yaw_reference", self.yaw_reference, str(error)) from None

    def claimed_orientation_variance_rad2(self) -> np.ndarray:
        """The orientation variances (rad², x, y, z) the pack's messages state."""
        if all(math.isnan(c) for c in self.claimed_sigma_deg):
            honest = (self.error_deg * _DEG) ** 2 + (self.noise_deg * _DEG) ** 2
            return np.full(3, honest)
        return (np.asarray(self.claimed_sigma_deg) * _DEG) ** 2
