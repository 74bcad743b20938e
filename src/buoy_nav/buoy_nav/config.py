"""Typed configuration of the fusion engine.

:class:`FusionConfig` is a frozen dataclass of simple field types (float, int, bool, str, tuple of
floats) with unit-suffixed names, so that a ROS node can declare one parameter per field. The IMU
error fields carry the same names and meanings as the simulator's IMU error configuration, so the
filter can be tuned to a sensor by copying its data sheet (or the simulator's settings) verbatim.
"""

import dataclasses
import math
from dataclasses import dataclass

from buoy_common.extrinsics import check_shared_fields, shared_field
from buoy_common.parameters import (
    build_config,
    check_parameter_files,
    config_parameters,
    load_parameter_files,
)

FUSION_NODE_NAME = "fusion_node"
"""Node name whose parameter-file sections configure the fusion (live and offline)."""
FUSION_PARAMETER_PREFIX = "fusion."
"""ROS parameter of a :class:`FusionConfig` field ``f``: ``fusion.f``, except the shared ones
(interface contract), which are declared with their own names."""
FUSION_FIELDS_NOT_PARAMETERS = ("record_innovations",)
"""Fields for analysis tools only, not ROS parameters."""


class ConfigError(ValueError):
    """A configuration value is missing, of the wrong type or out of range (names the field)."""


@dataclass(frozen=True)
class FusionConfig:
    """Configuration of :class:`buoy_nav.engine.FusionEngine` (defaults in brackets).

    Antennas and map origin
      primary_antenna_body_m: primary antenna phase centre in ``base_link`` (m) [(−0.75, 0, 1)].
      secondary_antenna_body_m: secondary antenna phase centre in ``base_link`` (m) [(0.75, 0, 1)].
      tertiary_antenna_body_m: third antenna phase centre in ``base_link`` (m), whose baseline
        ``gnss/baseline_tertiary`` fixes the rotation about the first baseline; NaN: none
        [(NaN, NaN, NaN)].
      origin_latitude_deg, origin_longitude_deg, origin_altitude_m: origin of the ``map`` ENU
        frame (deg, deg, m ellipsoidal); all NaN = the ``base_link`` position at alignment [NaN].

    IMU error model (same names as the simulator's IMU error configuration)
      gyro_noise_deg_sqrt_h: gyro angle random walk (°/√h) [0.2].
      gyro_turn_on_bias_deg_s: 1-σ gyro bias at switch-on, per axis (°/s) [0.02].
      gyro_bias_instability_deg_h: 1-σ of the first-order Gauss-Markov gyro bias drift (°/h) [5].
      gyro_bias_correlation_time_s: its correlation time (s) [300].
      accel_noise_mps_sqrt_h: accelerometer velocity random walk (m/s/√h) [0.05].
      accel_turn_on_bias_mg: 1-σ accelerometer bias at switch-on, per axis (mg) [5].
      accel_bias_instability_mg: 1-σ of the Gauss-Markov accelerometer bias drift (mg) [0.1].
      accel_bias_correlation_time_s: its correlation time (s) [600].
      scale_factor_error_percent: 1-σ scale-factor error of gyros and accelerometers (%) [0.1];
        not estimated, accounted for as extra process noise proportional to the motion.

    Alignment
      alignment_window_s: length of the levelling window of specific force (s) [10].
      alignment_max_fix_age_s: oldest GNSS fix/velocity (relative to the heading that completes
        the alignment) used to initialise position and velocity (s) [1].

    Measurements
      gate_probability: probability of the chi-square innovation gate [0.9999].
      gate_reset_count: consecutive gate rejections of one kind after which the filter resets the
        corresponding states to that measurement (attitude yaw, velocity or position) [50].
      gnss_position_variance_floor_m2: smallest position variance used per ENU axis (m²) [1e-4].
      gnss_velocity_variance_floor_m2s2: smallest velocity variance per ENU axis (m²/s²) [1e-4].
      gnss_heading_variance_floor_rad2: smallest dual-antenna heading variance (rad²) [1e-6].
      use_gnss_baseline: fuse the receiver's baseline vector (``gnss/baseline``), which observes
        the baseline's tilt as well as its azimuth; a heading with the stamp of a baseline,
        derived from the same vector, is then not fused [True].
      gnss_baseline_sigma_horizontal_m, gnss_baseline_sigma_vertical_m: 1-σ error of the
        baseline vector per horizontal ENU axis and vertically, from the receiver's data sheet
        (m) [0.003, 0.006].
      use_gnss_baseline_tertiary: fuse the primary → tertiary baseline vector
        (``gnss/baseline_tertiary``) when a tertiary antenna is configured [True].
      gnss_tertiary_length_tolerance_m: a tertiary baseline whose length differs from the
        configured primary → tertiary distance by more than this is rejected
        (``out_of_range``) (m) [0.05].
      coasting_timeout_s: a measurement kind not accepted for this long is reported as coasting
        (s) [1].

    Integrity (:mod:`buoy_nav.integrity`)
      integrity_rejection_count: consecutive gate rejections of one source after which the
        navigation is not trusted [3].
      integrity_attitude_sigma_deg, integrity_velocity_sigma_mps: 1σ added to each attitude
        (deg) and velocity (m/s) error state when the trust is lost, and added to the published
        covariance until it returns [5, 1].
      integrity_realign_s: the alignment starts again when the gate still rejects this long
        after the trust was lost (s) [5].
      integrity_recovery_s: the trust returns after this long without a gate rejection (s) [2].

    Timing and input validation
      max_measurement_delay_s: how long measurements may arrive after the IMU sample of the same
        stamp; processing lags the newest IMU stamp by this much (s) [0.3].
      covariance_propagation_interval_s: longest span of IMU samples over which the covariance is
        propagated in one step (s) [0.1].
      max_imu_gap_s: an IMU gap longer than this restarts the alignment (s) [0.5].
      max_angular_rate_rad_s: IMU samples with a larger rate magnitude are rejected (rad/s) [35].
      max_specific_force_mps2: IMU samples with a larger specific force are rejected (m/s²) [160].
      max_angular_acceleration_rad_s2: largest angular acceleration the platform can reach; an
        IMU sample whose rate differs from the last accepted one by more than this times their
        interval (plus the sensor's noise) is rejected as ``implausible_change`` (rad/s²) [50].
      max_jerk_mps3: the same for the specific force: largest rate of change of the platform's
        specific force (m/s³) [2000].

    Sites without GNSS, magnetometer and motion pack (see the aiding sources for the models)
      site_latitude_deg, site_longitude_deg: the site (deg) when there is no GNSS fix; NaN =
        ``origin.*`` [NaN].
      magnetic_declination_deg: declination (deg, east positive); NaN = the WMM at the
        position [NaN].
      ahrs_yaw_reference: what the yaw of ``imu/data`` is referenced to [``true_north``].
      use_magnetometer: fuse ``imu/mag`` [True]. use_ahrs: fuse ``imu/data`` [True].
      magnetometer_hard_iron_t: hard-iron offset subtracted from the raw field (T) [0, 0, 0].
      magnetometer_soft_iron: row-major 3×3 matrix applied after it [identity].
      magnetometer_heading_sigma_deg: 1-σ of the magnetic heading beyond the sensor noise:
        residual calibration, unmodelled local fields (deg) [1].
      magnetometer_full_scale_t: a component this large is a saturated sample (T) [8e-4].
      ahrs_lag_s: the motion pack's own lag (s); its orientation is carried forward by it with
        the gyro [0]. ahrs_lag_uncertainty_s: what is not known of that lag, added as noise
        proportional to the body rate (s) [0.1]. ahrs_variance_floor_rad2: smallest attitude
        variance used per axis (rad²) [1e-5]. ahrs_error_correlation_time_s: how long the
        pack's attitude error stays alike (s): samples closer than this share one error, so
        each is weighted as if it were one of a sample per this time [60].
      moored: constrain a moored buoy's position to its slowly moving mean (zero mean velocity)
        while no GNSS fix is accepted [False]. moored_position_sigma_horizontal_m,
        moored_position_sigma_vertical_m: 1-σ of the wave excursion about that mean (m)
        [3, 1]. moored_anchor_time_constant_s: time constant of the mean (s) [600].
        moored_update_period_s: interval of the constraint (s) [1].
      imu_gyro_bias_rad_s, imu_accel_bias_mps2, imu_accel_scale: calibration of the raw IMU
        (``calibrate_imu``): f = (f_raw − b_a) / scale per axis, ω = ω_raw − b_g
        [0, 0, (1, 1, 1)].

    Output
      realtime_output: emit each solution as soon as its IMU sample arrives, predicted by
        strapdown integration from the filter state ``max_measurement_delay_s`` behind; False:
        emit solutions ``max_measurement_delay_s`` late, with every measurement up to their
        stamp applied [True].
      output_rate_hz: rate of navigation solutions; 0 = one per IMU sample (Hz) [0].
      record_innovations: keep every innovation in ``FusionEngine.innovation_log`` [False].
    """

    primary_antenna_body_m: tuple[float, float, float] = shared_field("gnss.primary_antenna")
    secondary_antenna_body_m: tuple[float, float, float] = shared_field("gnss.secondary_antenna")
    tertiary_antenna_body_m: tuple[float, float, float] = shared_field("gnss.tertiary_antenna")
    origin_latitude_deg: float = shared_field("origin.latitude_deg")
    origin_longitude_deg: float = shared_field("origin.longitude_deg")
    origin_altitude_m: float = shared_field("origin.altitude_m")

    gyro_noise_deg_sqrt_h: float = 0.2
    gyro_turn_on_bias_deg_s: float = 0.02
    gyro_bias_instability_deg_h: float = 5.0
    gyro_bias_correlation_time_s: float = 300.0
    accel_noise_mps_sqrt_h: float = 0.05
    accel_turn_on_bias_mg: float = 5.0
    accel_bias_instability_mg: float = 0.1
    accel_bias_correlation_time_s: float = 600.0
    scale_factor_error_percent: float = 0.1

    alignment_window_s: float = 10.0
    alignment_max_fix_age_s: float = 1.0

    gate_probability: float = 0.9999
    gate_reset_count: int = 50
    gnss_position_variance_floor_m2: float = 1e-4
    gnss_velocity_variance_floor_m2s2: float = 1e-4
    gnss_heading_variance_floor_rad2: float = 1e-6
    use_gnss_baseline: bool = True
    gnss_baseline_sigma_horizontal_m: float = 0.003
    gnss_baseline_sigma_vertical_m: float = 0.006
    use_gnss_baseline_tertiary: bool = True
    gnss_tertiary_length_tolerance_m: float = 0.05
    coasting_timeout_s: float = 1.0

    integrity_rejection_count: int = 3
    integrity_attitude_sigma_deg: float = 5.0
    integrity_velocity_sigma_mps: float = 1.0
    integrity_realign_s: float = 5.0
    integrity_recovery_s: float = 2.0

    max_measurement_delay_s: float = 0.3
    covariance_propagation_interval_s: float = 0.1
    max_imu_gap_s: float = 0.5
    max_angular_rate_rad_s: float = 35.0
    max_specific_force_mps2: float = 160.0
    max_angular_acceleration_rad_s2: float = 50.0
    max_jerk_mps3: float = 2000.0

    site_latitude_deg: float = shared_field("site.latitude_deg")
    site_longitude_deg: float = shared_field("site.longitude_deg")
    magnetic_declination_deg: float = shared_field("magnetic.declination_deg")
    ahrs_yaw_reference: str = shared_field("ahrs.yaw_reference")
    use_magnetometer: bool = True
    use_ahrs: bool = True
    magnetometer_hard_iron_t: tuple[float, float, float] = (0.0, 0.0, 0.0)
    magnetometer_soft_iron: tuple[float, ...] = (1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0)
    magnetometer_heading_sigma_deg: float = 1.0
    magnetometer_full_scale_t: float = 8e-4
    ahrs_lag_s: float = 0.0
    ahrs_lag_uncertainty_s: float = 0.1
    ahrs_variance_floor_rad2: float = 1e-5
    ahrs_error_correlation_time_s: float = 60.0
    moored: bool = False
    moored_position_sigma_horizontal_m: float = 3.0
    moored_position_sigma_vertical_m: float = 1.0
    moored_anchor_time_constant_s: float = 600.0
    moored_update_period_s: float = 1.0
    imu_gyro_bias_rad_s: tuple[float, float, float] = (0.0, 0.0, 0.0)
    imu_accel_bias_mps2: tuple[float, float, float] = (0.0, 0.0, 0.0)
    imu_accel_scale: tuple[float, float, float] = (1.0, 1.0, 1.0)

    realtime_output: bool = True
    output_rate_hz: float = 0.0
    record_innovations: bool = False

    def __post_init__(self):
        for field in dataclasses.fields(self):
            value = getattr(self, field.name)
            object.__setattr__(self, field.name, _coerce(field.name, field.type, value))
        self._validate()

    def _validate(self):
        try:
            check_shared_fields(self)
        except ValueError as error:
            raise ConfigError(str(error)) from None
        for name in (
            "gyro_noise_deg_sqrt_h",
            "gyro_turn_on_bias_deg_s",
            "gyro_bias_instability_deg_h",
            "accel_noise_mps_sqrt_h",
            "accel_turn_on_bias_mg",
            "accel_bias_instability_mg",
            "scale_factor_error_percent",
            "output_rate_hz",
            "max_measurement_delay_s",
        ):
            _require(getattr(self, name) >= 0.0, name, "finite and ≥ 0")
        for name in (
            "gyro_bias_correlation_time_s",
            "accel_bias_correlation_time_s",
            "alignment_window_s",
            "alignment_max_fix_age_s",
            "gnss_position_variance_floor_m2",
            "gnss_velocity_variance_floor_m2s2",
            "gnss_heading_variance_floor_rad2",
            "gnss_baseline_sigma_horizontal_m",
            "gnss_baseline_sigma_vertical_m",
            "gnss_tertiary_length_tolerance_m",
            "coasting_timeout_s",
            "covariance_propagation_interval_s",
            "max_imu_gap_s",
            "max_angular_rate_rad_s",
            "max_specific_force_mps2",
            "max_angular_acceleration_rad_s2",
            "max_jerk_mps3",
            "integrity_attitude_sigma_deg",
            "integrity_velocity_sigma_mps",
            "integrity_realign_s",
            "integrity_recovery_s",
            "magnetometer_heading_sigma_deg",
            "magnetometer_full_scale_t",
            "ahrs_variance_floor_rad2",
            "ahrs_error_correlation_time_s",
            "moored_position_sigma_horizontal_m",
            "moored_position_sigma_vertical_m",
            "moored_anchor_time_constant_s",
            "moored_update_period_s",
        ):
            _require(getattr(self, name) > 0.0, name, "finite and > 0")
        for name in ("ahrs_lag_s", "ahrs_lag_uncertainty_s"):
            _require(getattr(self, name) >= 0.0, name, "finite and ≥ 0")
        _require(len(self.magnetometer_soft_iron) == 9, "magnetometer_soft_iron", "9 numbers")
        _require(
            all(0.5 < scale < 2.0 for scale in self.imu_accel_scale),
            "imu_accel_scale",
            "three scale factors in (0.5, 2)",
        )
        _require(0.0 < self.gate_probability < 1.0, "gate_probability", "in (0, 1)")
        _require(self.gate_reset_count >= 1, "gate_reset_count", "≥ 1")
        _require(self.integrity_rejection_count >= 1, "integrity_rejection_count", "≥ 1")
        _require(self.scale_factor_error_percent < 100.0, "scale_factor_error_percent", "< 100")

    @property
    def baseline_body_m(self) -> tuple[float, float, float]:
        """Primary → secondary antenna vector in ``base_link`` (m)."""
        secondary, primary = self.secondary_antenna_body_m, self.primary_antenna_body_m
        return tuple(s - p for s, p in zip(secondary, primary, strict=True))

    @property
    def tertiary_baseline_body_m(self) -> tuple[float, float, float] | None:
        """Primary → tertiary antenna vector in ``base_link`` (m), None without a third
        antenna."""
        if any(math.isnan(c) for c in self.tertiary_antenna_body_m):
            return None
        tertiary, primary = self.tertiary_antenna_body_m, self.primary_antenna_body_m
        return tuple(t - p for t, p in zip(tertiary, primary, strict=True))

    @property
    def imu_calibration(self):
        """(gyro bias rad/s, accelerometer bias m/s², accelerometer scale) from
        ``calibrate_imu``, None when they are the identity (nothing to apply)."""
        calibration = (self.imu_gyro_bias_rad_s, self.imu_accel_bias_mps2, self.imu_accel_scale)
        if calibration == ((0.0, 0.0, 0.0), (0.0, 0.0, 0.0), (1.0, 1.0, 1.0)):
            return None
        return calibration

    @property
    def has_origin(self) -> bool:
        """True when the ``map`` origin is configured (not taken from the first fix)."""
        return not math.isnan(self.origin_latitude_deg)


def _require(condition: bool, name: str, expectation: str):
    if not condition:
        raise ConfigError(f"{name} must be {expectation}")


def _coerce(name: str, annotation, value):
    """Convert ``value`` to the field's declared type or raise :class:`ConfigError` naming it."""
    if annotation is bool or annotation == "bool":
        if isinstance(value, bool):
            return value
        raise ConfigError(f"{name} must be a boolean, got {value!r}")
    if annotation is int or annotation == "int":
        if (
            isinstance(value, bool)
            or not isinstance(value, int | float)
            or not math.isfinite(value)
            or value != int(value)
        ):
            raise ConfigError(f"{name} must be an integer, got {value!r}")
        return int(value)
    if annotation is float or annotation == "float":
        return _to_float(name, value)
    if annotation is str or annotation == "str":
        if isinstance(value, str):
            return value
        raise ConfigError(f"{name} must be a string, got {value!r}")
    # tuple[float, float, float] or tuple[float, ...] (any length)
    length = None if "..." in str(annotation) else 3
    if (
        isinstance(value, str)
        or not hasattr(value, "__len__")
        or len(value) != (length or len(value))
    ):
        expected = "a sequence of three numbers" if length else "a sequence of numbers"
        raise ConfigError(f"{name} must be {expected}, got {value!r}")
    return tuple(_to_float(name, c) for c in value)


def _to_float(name: str, value) -> float:
    if isinstance(value, bool):
        raise ConfigError(f"{name} must be a number, got {value!r}")
    try:
        number = float(value)
    except (TypeError, ValueError):
        raise ConfigError(f"{name} must be a number, got {value!r}") from None
    if math.isinf(number):
        raise ConfigError(f"{name} must be finite, got {value!r}")
    return number


def fusion_config_from_files(paths) -> FusionConfig:
    """The :class:`FusionConfig` ``fusion_node`` would build from these ROS parameter files
    (sections ``/**`` and ``fusion_node``, later files winning). Raises
    :class:`buoy_common.parameters.ParameterError` naming a bad file or value."""
    check_parameter_files(paths, FUSION_NODE_NAME, fusion_parameter_names())
    values = load_parameter_files(paths, FUSION_NODE_NAME)
    return build_config(
        FusionConfig, values, FUSION_PARAMETER_PREFIX, skip=FUSION_FIELDS_NOT_PARAMETERS
    )


def fusion_parameter_names() -> list[str]:
    """Every parameter ``fusion_node`` declares."""
    names = config_parameters(
        FusionConfig, FUSION_PARAMETER_PREFIX, skip=FUSION_FIELDS_NOT_PARAMETERS
    )
    return [parameter for _, parameter, _ in names]
