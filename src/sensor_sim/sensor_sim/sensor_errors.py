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
from buoy_common.parameter_declarations import (
    NON_NEGATIVE,
    POSITIVE,
    at_least,
    broken_rules,
    closed_interval,
    custom_rule,
    half_open_interval,
    one_of,
    parameter,
)

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


def check_declared_rules(config: object) -> None:
    """Each parameter field of config must keep its declared rule."""
    for key, broken in broken_rules(config):
        raise InvalidConfigValueError(key, getattr(config, key), f"must be {broken}")


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

    gyro_noise_deg_sqrt_h: float = parameter(
        0.2, unit="deg/√h", meaning="gyro angle random walk", rule=NON_NEGATIVE
    )
    gyro_turn_on_bias_deg_s: float = parameter(
        0.02, unit="deg/s", meaning="1σ gyro bias per axis, drawn at start", rule=NON_NEGATIVE
    )
    gyro_bias_instability_deg_h: float = parameter(
        5.0,
        unit="deg/h",
        meaning="1σ of the first-order Gauss-Markov gyro bias drift",
        rule=NON_NEGATIVE,
    )
    gyro_bias_correlation_time_s: float = parameter(
        300.0, unit="s", meaning="correlation time of the gyro bias drift", rule=POSITIVE
    )
    accel_noise_mps_sqrt_h: float = parameter(
        0.05, unit="m/s/√h", meaning="accelerometer velocity random walk", rule=NON_NEGATIVE
    )
    accel_turn_on_bias_mg: float = parameter(
        5.0, unit="mg", meaning="1σ accelerometer bias per axis, drawn at start", rule=NON_NEGATIVE
    )
    accel_bias_instability_mg: float = parameter(
        0.1,
        unit="mg",
        meaning="1σ of the first-order Gauss-Markov accelerometer bias drift",
        rule=NON_NEGATIVE,
    )
    accel_bias_correlation_time_s: float = parameter(
        600.0, unit="s", meaning="correlation time of the accelerometer bias drift", rule=POSITIVE
    )
    scale_factor_error_percent: float = parameter(
        0.1,
        unit="%",
        meaning="1σ scale-factor error per axis of gyros and accelerometers, drawn at start",
        rule=NON_NEGATIVE,
    )

    def __post_init__(self) -> None:
        check_declared_rules(self)

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


INTERVALS = custom_rule(
    "[start, end) intervals with start < end",
    lambda intervals: all(start < end for start, end in intervals),
)


def _near_identity(matrix) -> bool:
    return len(matrix) == 9 and abs(np.linalg.det(np.reshape(matrix, (3, 3)))) > 0.1


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

    position_noise_horizontal_m: float = parameter(
        0.02, unit="m", meaning="1σ position noise per horizontal axis", rule=NON_NEGATIVE
    )
    position_noise_vertical_m: float = parameter(
        0.04, unit="m", meaning="1σ vertical position noise", rule=NON_NEGATIVE
    )
    velocity_noise_horizontal_mps: float = parameter(
        0.02, unit="m/s", meaning="1σ velocity noise per horizontal axis", rule=NON_NEGATIVE
    )
    velocity_noise_vertical_mps: float = parameter(
        0.04, unit="m/s", meaning="1σ vertical velocity noise", rule=NON_NEGATIVE
    )
    baseline_noise_horizontal_m: float = parameter(
        0.003,
        unit="m",
        meaning="1σ moving-baseline noise per horizontal axis; the heading follows from it",
        rule=NON_NEGATIVE,
    )
    baseline_noise_vertical_m: float = parameter(
        0.006, unit="m", meaning="1σ vertical moving-baseline noise", rule=NON_NEGATIVE
    )
    receiver: Literal["dual_antenna", "single_antenna", "none"] = parameter(
        "dual_antenna",
        meaning="dual_antenna: fix, velocity, heading, baseline; single_antenna: fix and "
        "velocity; none: no GNSS topic",
        rule=one_of("dual_antenna", "single_antenna", "none"),
    )
    fix_outages_s: tuple[tuple[float, float], ...] = parameter(
        (),
        unit="s",
        meaning="scenario-time intervals without fix (then without any GNSS solution)",
        rule=INTERVALS,
    )
    velocity_outages_s: tuple[tuple[float, float], ...] = parameter(
        (), unit="s", meaning="scenario-time intervals without velocity", rule=INTERVALS
    )
    heading_outages_s: tuple[tuple[float, float], ...] = parameter(
        (), unit="s", meaning="scenario-time intervals without heading and baseline", rule=INTERVALS
    )
    silent_outages_s: tuple[tuple[float, float], ...] = parameter(
        (),
        unit="s",
        meaning="scenario-time intervals in which no GNSS topic publishes at all",
        rule=INTERVALS,
    )

    def __post_init__(self) -> None:
        check_declared_rules(self)


@dataclass(frozen=True)
class AnemometerErrorConfig:
    """Sonic anemometer white noise, m/s, 1-sigma per axis, and of its sonic temperature, K."""

    noise_mps: float = parameter(
        0.02, unit="m/s", meaning="white noise of the wind, 1σ per axis", rule=NON_NEGATIVE
    )
    temperature_noise_k: float = parameter(
        0.02, unit="K", meaning="white noise of the sonic temperature, 1σ", rule=NON_NEGATIVE
    )

    def __post_init__(self) -> None:
        check_declared_rules(self)


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

    scale_factor_error_percent: float = parameter(
        0.2,
        unit="%",
        meaning="scale error common to all axes, held for the run",
        rule=closed_interval(-10.0, 10.0),
    )
    bias_mps: tuple[float, float, float] = parameter(
        (0.002, 0.002, 0.002),
        unit="m/s",
        meaning="offset per DVL axis, held for the run",
        rule=custom_rule(
            "three offsets within [-1, 1] m/s",
            lambda bias: len(bias) == 3 and all(abs(b) <= 1.0 for b in bias),
        ),
    )
    noise_mps: float = parameter(
        0.005, unit="m/s", meaning="white noise per axis and ping, 1σ", rule=NON_NEGATIVE
    )
    min_depth_m: float = parameter(
        0.5,
        unit="m",
        meaning="pings are lost while the transducer is shallower than this (bubbles)",
        rule=NON_NEGATIVE,
    )
    ping_loss_probability: float = parameter(
        0.0, meaning="pings lost at random", rule=half_open_interval(0.0, 1.0)
    )
    outages_s: tuple[tuple[float, float], ...] = parameter(
        (), unit="s", meaning="scenario-time intervals without valid pings", rule=INTERVALS
    )

    def __post_init__(self) -> None:
        check_declared_rules(self)


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

    fitted: bool = parameter(False, meaning="publish imu/mag")
    sample_every: int = parameter(
        10, meaning="one magnetometer sample every this many IMU samples", rule=at_least(1)
    )
    noise_ut: float = parameter(0.1, unit="µT", meaning="white noise, 1σ", rule=NON_NEGATIVE)
    hard_iron_ut: tuple[float, float, float] = parameter(
        (0.0, 0.0, 0.0),
        unit="µT",
        meaning="constant offset of the buoy's own permanent magnetism",
        rule=custom_rule("3 numbers", lambda offset: len(offset) == 3),
    )
    soft_iron: tuple[float, ...] = parameter(
        _IDENTITY_3X3,
        meaning="row-major 3×3 matrix applied to the field in the body",
        rule=custom_rule("9 numbers, an invertible matrix near the identity", _near_identity),
    )
    disturbances_s: tuple[tuple[float, float], ...] = parameter(
        (),
        unit="s",
        meaning="scenario-time intervals in which a passing hull turns the field",
        rule=INTERVALS,
    )
    disturbance_heading_bias_deg: float = parameter(
        30.0, unit="deg", meaning="how far the disturbance turns the heading, clockwise"
    )

    def __post_init__(self) -> None:
        check_declared_rules(self)


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

    fitted: bool = parameter(False, meaning="publish imu/data, the motion pack's own attitude")
    sample_every: int = parameter(
        10, meaning="one attitude sample every this many IMU samples", rule=at_least(1)
    )
    lag_time_constant_s: float = parameter(
        0.2, unit="s", meaning="time constant of the pack's first-order lag", rule=NON_NEGATIVE
    )
    error_deg: float = parameter(
        0.3, unit="deg", meaning="1σ Gauss-Markov attitude error per axis", rule=NON_NEGATIVE
    )
    error_correlation_time_s: float = parameter(
        120.0, unit="s", meaning="correlation time of the attitude error", rule=POSITIVE
    )
    noise_deg: float = parameter(0.05, unit="deg", meaning="white noise, 1σ", rule=NON_NEGATIVE)
    yaw_reference: str = shared_field("ahrs.yaw_reference")
    claimed_sigma_deg: tuple[float, float, float] = parameter(
        (math.nan, math.nan, math.nan),
        unit="deg",
        meaning="roll, pitch, yaw 1σ the orientation_covariance claims; NaN: the true error's",
        rule=custom_rule(
            "three values in [0, 180), or three NaN",
            lambda claimed: (
                len(claimed) == 3
                and (all(math.isnan(c) for c in claimed) or all(0.0 <= c < 180.0 for c in claimed))
            ),
        ),
    )

    def __post_init__(self) -> None:
        check_declared_rules(self)
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
