"""Screening of IMU samples against their predecessor: a change no platform can make.

The magnitude limits (``max_angular_rate_rad_s``, ``max_specific_force_mps2``) stop values no
sensor reports, but a spike well inside them (a single 30 rad/s gyro sample, a 100 m/s²
accelerometer sample) passes, and a strapdown integrator turns it into an attitude or velocity
error that no aiding can explain afterwards. A rigid body cannot change its angular rate by more
than its largest angular acceleration allows, nor its specific force by more than its largest
jerk allows, so between a sample and the last accepted one, ``Δt`` apart,

    |ω − ω_last| ≤ α_max · Δt + k · √2 · σ_ω(Δt_sample)
    |f − f_last| ≤ j_max · Δt + k · √2 · σ_f(Δt_sample)

where α_max is ``max_angular_acceleration_rad_s2``, j_max is ``max_jerk_mps3``, σ_ω and σ_f are
the white noises of one sample (angle and velocity random walk over the sample interval) and k
is :data:`NOISE_SIGMAS`. A sample beyond the bound is rejected; the next one is compared with the
last accepted sample over the longer interval, so a spike of any length is dropped whole while
real motion, whose change grows no faster than the bound, is accepted after at most a few
samples. The strapdown integration bridges the rejected samples by interpolation, as it bridges
any gap shorter than ``max_imu_gap_s``.

The bound is a physical limit of the platform, not a statistical gate: a moored or drifting buoy
in breaking seas reaches angular accelerations of a few tens of rad/s² (10 m waves of 5 s period
roll it at ~π²·0.5 ≈ 5 rad/s² for a 30° roll amplitude; slamming adds short peaks) and jerks of a
few hundred m/s³. The defaults (50 rad/s², 2000 m/s³) are ten times that and a hundred
times what the simulated scenarios reach (below 1 rad/s² and 10 m/s³ including the sensor
noise); they let through no single-sample spike larger than 0.5 rad/s or 20 m/s² at 100 Hz.
"""

import math

NOISE_SIGMAS = 6.0
"""Standard deviations of the per-sample noise difference allowed on top of the motion bound."""


class ImuPlausibility:
    """Accepts an IMU sample only if its change from the last accepted one is physically possible.

    max_angular_acceleration_rad_s2: largest angular acceleration of the platform (rad/s²).
    max_jerk_mps3: largest rate of change of specific force (m/s³).
    gyro_noise_rad_sqrt_s, accel_noise_mps_sqrt_s: white-noise densities of the sensor
      (angle random walk rad/√s, velocity random walk m/s/√s).
    """

    def __init__(
        self,
        max_angular_acceleration_rad_s2: float,
        max_jerk_mps3: float,
        gyro_noise_rad_sqrt_s: float,
        accel_noise_mps_sqrt_s: float,
    ):
        self._max_angular_acceleration = max_angular_acceleration_rad_s2
        self._max_jerk = max_jerk_mps3
        self._gyro_noise = gyro_noise_rad_sqrt_s
        self._accel_noise = accel_noise_mps_sqrt_s
        self._last: tuple[float, tuple, tuple] | None = None
        self._sample_interval_s: float | None = None
        self._gyro_noise_bound = 0.0
        self._force_noise_bound = 0.0
        self.rejected_in_a_row = 0
        """Samples rejected since the last accepted one."""

    @property
    def steady(self) -> bool:
        """Whether the screening is in its steady course: a last sample to compare with, none
        refused since, the sample interval learnt."""
        return (
            self._last is not None
            and self.rejected_in_a_row == 0
            and self._sample_interval_s is not None
        )

    @property
    def last(self) -> tuple[float, tuple, tuple] | None:
        """The last accepted sample (stamp s, gyro body rad/s, force body m/s²)."""
        return self._last

    @last.setter
    def last(self, sample: tuple[float, tuple, tuple]) -> None:
        self._last = sample

    def limits(self) -> tuple[float, float, float, float, float]:
        """(largest angular acceleration rad/s², largest jerk m/s³, the rate's and the force's
        noise allowances, the sample interval learnt s) (:mod:`buoy_nav.imu_stretch`)."""
        return (
            self._max_angular_acceleration,
            self._max_jerk,
            self._gyro_noise_bound,
            self._force_noise_bound,
            self._sample_interval_s,
        )

    def restart(self) -> None:
        """Forget the last sample (after a gap in the data, nothing to compare with)."""
        self._last = None
        self.rejected_in_a_row = 0

    def plausible(self, t_s: float, gyro_rad_s: tuple, force_mps2: tuple) -> bool:
        """Whether the sample at ``t_s`` (s; body ω_ib rad/s; body specific force m/s²) is
        reachable from the last accepted one; an accepted sample becomes the new reference."""
        last = self._last
        if last is None:
            self._last = (t_s, gyro_rad_s, force_mps2)
            return True
        t0, gyro0, force0 = last
        dt = t_s - t0
        if self.rejected_in_a_row == 0:
            self._learn_sample_interval(dt)
        gx, gy, gz = gyro_rad_s
        hx, hy, hz = gyro0
        fx, fy, fz = force_mps2
        ex, ey, ez = force0
        rate_bound = self._max_angular_acceleration * dt + self._gyro_noise_bound
        force_bound = self._max_jerk * dt + self._force_noise_bound
        if (gx - hx) ** 2 + (gy - hy) ** 2 + (gz - hz) ** 2 > rate_bound * rate_bound or (
            fx - ex
        ) ** 2 + (fy - ey) ** 2 + (fz - ez) ** 2 > force_bound * force_bound:
            self.rejected_in_a_row += 1
            return False
        self._last = (t_s, gyro_rad_s, force_mps2)
        self.rejected_in_a_row = 0
        return True

    def _learn_sample_interval(self, dt: float) -> None:
        """The noise allowance follows the shortest sample interval seen (the sensor's rate)."""
        if dt <= 0.0 or (self._sample_interval_s is not None and dt >= self._sample_interval_s):
            return
        self._sample_interval_s = dt
        per_sample = NOISE_SIGMAS * math.sqrt(2.0 / dt)
        self._gyro_noise_bound = per_sample * self._gyro_noise
        self._force_noise_bound = per_sample * self._accel_noise
