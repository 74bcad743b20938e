"""Error budgets of the system tests: how far from the simulator's truth a right result may be.

Every budget is computed from the data sheets the simulator draws its sensor errors from
(:mod:`sensor_sim.sensor_errors`, the defaults with which every committed bag was recorded),
from the buoy's geometry and from the attitude accuracy targets; never from the run being
judged, so a navigation or correction error cannot widen its own tolerance.

Wind. To first order the corrected wind's error is

    δV = R n  −  φ × W  +  δv  +  R (δω × B)

(n anemometer noise, φ attitude error as a rotation vector in ENU, W the air velocity relative
to the sensor in ENU, δv the navigation's velocity error, δω its body-rate error, B the
anemometer's lever arm). The RMS of a sum is at most the sum of the RMS of its terms
(Minkowski), so the budget of each ENU axis is the sum of four terms:

- anemometer noise: σ_a per axis in any axes, and the RMS of N samples of white noise stays
  below σ_a (1 + 5/√(2N)) (its relative spread is 1/√(2N));
- attitude × relative air speed: with tilt errors of RMS θ per horizontal axis and a heading
  error of RMS ψ, independent of the air velocity, the east and north components of φ × W have
  an RMS of at most √(θ² + ψ²)·|W| and the vertical one θ·|W|; |W| is the RMS of the
  anemometer's speed (a sensor reading, rotation invariant), θ and ψ the attitude targets;
- velocity: the fused velocity is never worse than one GNSS velocity, σ_v per axis;
- body rate × lever arm: the rate is the gyro's, bias-corrected, so its error per axis is the
  white noise of one IMU sample plus at most twice the bias instability; |δω × B| has an RMS of
  at most √2 |δω|_axis |B| for errors alike on the three axes.

Navigation (largest error over a run once aligned): a tilt error no larger than three sigma of
the accelerometer turn-on bias over g (still, a tilt and a horizontal bias are the same
measurement); a heading error no larger than two sigma of one dual-antenna heading
(σ_baseline / horizontal baseline length: ten of them a second and a gyro do far better); a
velocity error no larger than three sigma of one GNSS velocity; and, with an IMU whose biases
are constant, a gyro bias estimate within twice the bias instability of the true bias once the
buoy has moved for two minutes (the filter models the bias as drifting by that much).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from sensor_sim.sensor_errors import AnemometerErrorConfig, GnssErrorConfig, ImuErrorConfig

IMU = ImuErrorConfig()
GNSS = GnssErrorConfig()
ANEMOMETER = AnemometerErrorConfig()
IMU_RATE_HZ = 100.0  # of every committed bag and simulator default
STANDARD_GRAVITY_MPS2 = 9.80665

# The accuracy targets of the attitude, RMS once converged (docs/benchmarks.md, the navigation
# table).
ROLL_TARGET_RMS_DEG = 0.05
PITCH_TARGET_RMS_DEG = 0.05
HEADING_TARGET_RMS_DEG = 0.08

# A RMS of N samples of white noise further than 5 of its standard deviations from σ.
NOISE_RMS_SIGMAS = 5.0
AXES = ("E", "N", "U")


def noise_rms_bound(sigma: float, n_samples: int) -> float:
    """Largest RMS of ``n_samples`` draws of zero-mean white noise of standard deviation
    ``sigma`` (same unit), five standard deviations of the RMS above ``sigma``."""
    return sigma * (1.0 + NOISE_RMS_SIGMAS / math.sqrt(2.0 * n_samples))


@dataclass(frozen=True)
class WindBudget:
    """Largest RMS error of the corrected wind per ENU axis (m/s) and the terms it sums."""

    terms_mps: dict[str, np.ndarray]

    @property
    def total_mps(self) -> np.ndarray:
        return np.sum(list(self.terms_mps.values()), axis=0)

    def __str__(self) -> str:
        return "budget E, N, U {} m/s = {}".format(
            np.round(self.total_mps, 4),
            " + ".join(f"{name} {np.round(term, 4)}" for name, term in self.terms_mps.items()),
        )


def wind_budget(
    n_samples: int,
    relative_air_speed_rms_mps: float,
    anemometer_position_body_m,
    imu_rate_hz: float = IMU_RATE_HZ,
) -> WindBudget:
    """Budget of the RMS error per ENU axis of ``n_samples`` corrected wind samples (m/s).

    relative_air_speed_rms_mps: RMS of the anemometer's measured speed over the run (m/s).
    anemometer_position_body_m: the lever arm B in ``base_link`` (m).
    imu_rate_hz: the IMU's sample rate (Hz), which sets the gyro's noise per sample.
    """
    tilt_rad = math.radians(max(ROLL_TARGET_RMS_DEG, PITCH_TARGET_RMS_DEG))
    heading_rad = math.radians(HEADING_TARGET_RMS_DEG)
    attitude = relative_air_speed_rms_mps * np.array(
        [math.hypot(tilt_rad, heading_rad)] * 2 + [tilt_rad]
    )
    gyro_white_rad_s = IMU.gyro_noise_density_rad_s_sqrt_hz * math.sqrt(imu_rate_hz)
    rate_error_rad_s = gyro_white_rad_s + 2.0 * IMU.gyro_bias_instability_rad_s
    lever_arm_m = float(np.linalg.norm(anemometer_position_body_m))
    return WindBudget(
        {
            "anemometer noise": np.full(3, noise_rms_bound(ANEMOMETER.noise_mps, n_samples)),
            "attitude x air speed": attitude,
            "velocity": gnss_velocity_sigma_mps(),
            "rate x lever arm": np.full(3, math.sqrt(2.0) * rate_error_rad_s * lever_arm_m),
        }
    )


def gnss_velocity_sigma_mps() -> np.ndarray:
    """1σ of one GNSS velocity per ENU axis (m/s)."""
    horizontal, vertical = GNSS.velocity_noise_horizontal_mps, GNSS.velocity_noise_vertical_mps
    return np.array([horizontal, horizontal, vertical])


@dataclass(frozen=True)
class NavigationLimits:
    """Largest error of a fused solution once aligned: roll, pitch, heading (deg) and
    velocity per ENU axis (m/s)."""

    roll_deg: float
    pitch_deg: float
    heading_deg: float
    velocity_mps: np.ndarray

    def __str__(self) -> str:
        return (
            f"limits roll {self.roll_deg:.3f}, pitch {self.pitch_deg:.3f}, heading "
            f"{self.heading_deg:.3f} deg, velocity E, N, U {self.velocity_mps} m/s"
        )


def navigation_limits(primary_antenna_body_m, secondary_antenna_body_m) -> NavigationLimits:
    """Limits of the navigation errors for antennas at these ``base_link`` positions (m)."""
    tilt_deg = math.degrees(math.atan(3.0 * IMU.accel_turn_on_bias_mg * 1e-3))
    baseline = np.subtract(secondary_antenna_body_m, primary_antenna_body_m)
    horizontal_length_m = math.hypot(baseline[0], baseline[1])
    heading_deg = math.degrees(2.0 * GNSS.baseline_noise_horizontal_m / horizontal_length_m)
    return NavigationLimits(tilt_deg, tilt_deg, heading_deg, 3.0 * gnss_velocity_sigma_mps())


def gyro_bias_limit_rad_s() -> float:
    """Largest error of the gyro bias estimate per axis (rad/s) of an IMU with constant biases,
    once the buoy has moved for two minutes."""
    return 2.0 * IMU.gyro_bias_instability_rad_s
