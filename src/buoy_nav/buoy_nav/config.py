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
from buoy_common.parameters import build_config, load_parameter_files

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

    Timing and input validation
      max_measurement_delay_s: how long measurements may arrive after the IMU sample of the same
        stamp; processing lags the newest IMU stamp by this much (s) [0.3].
      covariance_propagation_interval_s: longest span of IMU samples over which the covariance is
        propagated in one step (s) [0.1].
      max_imu_gap_s: an IMU gap longer than this restarts the alignment (s) [0.5].
      max_angular_rate_rad_s: IMU samples with a larger rate magnitude are rejected (rad/s) [35].
      max_specific_force_mps2: IMU samples with a larger specific force are rejected (m/s²) [160].

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

    max_measurement_delay_s: float = 0.3
    covariance_propagation_interval_s: float = 0.1
    max_imu_gap_s: float = 0.5
    max_angular_rate_rad_s: float = 35.0
    max_specific_force_mps2: float = 160.0

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
        ):
            _require(getattr(self, name) > 0.0, name, "finite and > 0")
        _require(0.0 < self.gate_probability < 1.0, "gate_probability", "in (0, 1)")
        _require(self.gate_reset_count >= 1, "gate_reset_count", "≥ 1")
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
    # tuple[float, float, float]
    if isinstance(value, str) or not hasattr(value, "__len__") or len(value) != 3:
        raise ConfigError(f"{name} must be a sequence of three numbers, got {value!r}")
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
    values = load_parameter_files(paths, FUSION_NODE_NAME)
    return build_config(
        FusionConfig, values, FUSION_PARAMETER_PREFIX, skip=FUSION_FIELDS_NOT_PARAMETERS
    )
