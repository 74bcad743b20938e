"""Error budgets of the simulated sensors: MEMS IMU, dual-antenna GNSS, sonic anemometer.

The budgets are in the units data sheets use and are validated on construction, so a scenario
file or a parameter with an impossible value is refused with a message naming the key.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

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


@dataclass(frozen=True)
class GnssErrorConfig:
    """Dual-antenna GNSS (moving-baseline RTK) errors, 1-sigma per ENU axis, white.

    Outages are [start, end) intervals in scenario time (s). A receiver without a fix has no
    heading either, so heading is also invalid during fix outages.
    """

    position_noise_horizontal_m: float = 0.02
    position_noise_vertical_m: float = 0.04
    velocity_noise_horizontal_mps: float = 0.02
    velocity_noise_vertical_mps: float = 0.04
    baseline_noise_horizontal_m: float = 0.003
    baseline_noise_vertical_m: float = 0.006
    fix_outages_s: tuple[tuple[float, float], ...] = ()
    heading_outages_s: tuple[tuple[float, float], ...] = ()

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
        for key in ("fix_outages_s", "heading_outages_s"):
            for start, end in getattr(self, key):
                if not start < end:
                    raise InvalidConfigValueError(
                        key, getattr(self, key), f"interval [{start}, {end}) must have start < end"
                    )


@dataclass(frozen=True)
class AnemometerErrorConfig:
    """Sonic anemometer white noise, m/s, 1-sigma per axis."""

    noise_mps: float = 0.02

    def __post_init__(self) -> None:
        check_non_negative(self, "noise_mps")


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
