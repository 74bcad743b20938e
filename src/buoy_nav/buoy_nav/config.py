"""Typed configuration of the fusion engine.

:class:`FusionConfig` is a frozen dataclass of simple field types (float, int, bool, str, tuple of
floats) with unit-suffixed names, so that a ROS node can declare one parameter per field. The IMU
error fields carry the same names and meanings as the simulator's IMU error configuration, so the
filter can be tuned to a sensor by copying its data sheet (or the simulator's settings) verbatim.
"""

import dataclasses
import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

from buoy_common.extrinsics import check_shared_fields, shared_field
from buoy_common.parameter_declarations import (
    NON_NEGATIVE,
    POSITIVE,
    WILDCARD_SECTION_COMMENT,
    DeclaredParameter,
    FileSection,
    NodeParameters,
    ParameterFile,
    ParameterSets,
    at_least,
    broken_rules,
    custom_rule,
    declared_parameters,
    half_open_interval,
    open_interval,
    parameter,
)
from buoy_common.parameters import build_config, check_parameter_files, load_parameter_files
from buoy_nav.source_health import SourceHealthRule

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
    """Configuration of :class:`buoy_nav.engine.FusionEngine`.

    Each field is declared once, below, with its default, unit, rule and meaning; the parameter
    files and the reference ``docs/parameters.md`` are generated from these declarations
    (:mod:`buoy_common.parameter_docs`). The IMU error fields carry the names and meanings of
    the simulator's IMU error configuration. Validation: the shared parameters' rules
    (:func:`buoy_common.extrinsics.check_shared_fields`), then each field's declared rule.
    """

    primary_antenna_body_m: tuple[float, float, float] = shared_field("gnss.primary_antenna")
    secondary_antenna_body_m: tuple[float, float, float] = shared_field("gnss.secondary_antenna")
    tertiary_antenna_body_m: tuple[float, float, float] = shared_field("gnss.tertiary_antenna")
    origin_latitude_deg: float = shared_field("origin.latitude_deg")
    origin_longitude_deg: float = shared_field("origin.longitude_deg")
    origin_altitude_m: float = shared_field("origin.altitude_m")

    gyro_noise_deg_sqrt_h: float = parameter(
        0.2,
        unit="deg/√h",
        meaning="gyro angle random walk",
        rule=NON_NEGATIVE,
        heading="IMU error model (same names and meanings as the simulator's imu.* parameters)",
    )
    gyro_turn_on_bias_deg_s: float = parameter(
        0.02, unit="deg/s", meaning="1σ gyro bias at switch-on, per axis", rule=NON_NEGATIVE
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
        5.0, unit="mg", meaning="1σ accelerometer bias at switch-on, per axis", rule=NON_NEGATIVE
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
        meaning="1σ scale-factor error of gyros and accelerometers, not estimated: process "
        "noise proportional to the motion",
        rule=half_open_interval(0.0, 100.0),
    )

    alignment_window_s: float = parameter(
        10.0,
        unit="s",
        meaning="levelling window of averaged specific force (roll, pitch)",
        rule=POSITIVE,
        heading="Alignment",
    )
    alignment_max_fix_age_s: float = parameter(
        1.0,
        unit="s",
        meaning="oldest fix and velocity, relative to the heading that completes the alignment, "
        "used to initialise position and velocity",
        rule=POSITIVE,
    )

    gate_probability: float = parameter(
        0.9999,
        meaning="probability of the chi-square innovation gate",
        rule=open_interval(0.0, 1.0),
        heading="Measurements",
    )
    gate_reset_count: int = parameter(
        50,
        meaning="consecutive gate rejections of one kind after which the filter resets the "
        "corresponding states (yaw, velocity or position) to that measurement",
        rule=at_least(1),
    )
    gnss_position_variance_floor_m2: float = parameter(
        1e-4, unit="m²", meaning="smallest GNSS position variance used per ENU axis", rule=POSITIVE
    )
    gnss_velocity_variance_floor_m2s2: float = parameter(
        1e-4,
        unit="m²/s²",
        meaning="smallest GNSS velocity variance used per ENU axis",
        rule=POSITIVE,
    )
    gnss_heading_variance_floor_rad2: float = parameter(
        1e-6, unit="rad²", meaning="smallest dual-antenna heading variance used", rule=POSITIVE
    )
    use_gnss_baseline: bool = parameter(
        True,
        meaning="fuse gnss/baseline (azimuth and tilt); a heading of the same stamp is then "
        "superseded, not fused",
    )
    gnss_baseline_sigma_horizontal_m: float = parameter(
        0.003,
        unit="m",
        meaning="1σ baseline vector error per horizontal ENU axis (receiver's data sheet)",
        rule=POSITIVE,
    )
    gnss_baseline_sigma_vertical_m: float = parameter(
        0.006,
        unit="m",
        meaning="1σ vertical baseline vector error (receiver's data sheet)",
        rule=POSITIVE,
    )
    use_gnss_baseline_tertiary: bool = parameter(
        True, meaning="fuse gnss/baseline_tertiary when gnss.tertiary_antenna is set"
    )
    gnss_tertiary_length_tolerance_m: float = parameter(
        0.05,
        unit="m",
        meaning="a tertiary baseline whose length differs from the configured primary → "
        "tertiary distance by more is rejected (out_of_range)",
        rule=POSITIVE,
    )
    coasting_timeout_s: float = parameter(
        1.0,
        unit="s",
        meaning="a measurement kind not accepted for this long is reported as coasting",
        rule=POSITIVE,
    )

    integrity_rejection_count: int = parameter(
        3,
        meaning="consecutive gate rejections of one source after which the navigation is not "
        "trusted",
        rule=at_least(1),
        heading="Integrity: when the filter stops agreeing with its aiding",
    )
    integrity_attitude_sigma_deg: float = parameter(
        5.0,
        unit="deg",
        meaning="1σ added to each attitude error state, and to the published covariance, "
        "while the trust is lost",
        rule=POSITIVE,
    )
    integrity_velocity_sigma_mps: float = parameter(
        1.0,
        unit="m/s",
        meaning="1σ added to each velocity error state, and to the published covariance, "
        "while the trust is lost",
        rule=POSITIVE,
    )
    integrity_realign_s: float = parameter(
        5.0,
        unit="s",
        meaning="the alignment starts again when the gates still reject this long after the "
        "trust was lost",
        rule=POSITIVE,
    )
    integrity_recovery_s: float = parameter(
        2.0,
        unit="s",
        meaning="the trust returns after this long without a gate rejection",
        rule=POSITIVE,
    )

    source_health_window: int = parameter(
        200,
        meaning="recent gate outcomes of one aiding source judged for its health",
        rule=at_least(1),
        heading="Source health: a source that keeps disagreeing is suspended, not followed",
    )
    source_health_min_samples: int = parameter(
        100,
        meaning="outcomes needed before a source is suspended, and the span judged for its "
        "resumption (at most source_health_window)",
        rule=at_least(1),
    )
    source_health_min_span_s: float = parameter(
        60.0,
        unit="s",
        meaning="a slow source is judged for suspension once its outcomes span this long (with "
        "at least 20 of them), before source_health_min_samples are in",
        rule=POSITIVE,
    )
    source_health_suspend_share: float = parameter(
        0.5,
        meaning="share of failed outcomes in the window that suspends a source",
        rule=custom_rule("in (0, 1]", lambda share: 0.0 < share <= 1.0),
    )
    source_health_resume_share: float = parameter(
        0.05,
        meaning="a suspended source resumes when no larger share of its last "
        "source_health_min_samples outcomes failed (below source_health_suspend_share)",
        rule=half_open_interval(0.0, 1.0),
    )

    max_measurement_delay_s: float = parameter(
        0.3,
        unit="s",
        meaning="how late measurements may arrive after the IMU sample of their stamp; "
        "processing lags the newest IMU stamp by this much",
        rule=NON_NEGATIVE,
        heading="Timing and input validation",
    )
    covariance_propagation_interval_s: float = parameter(
        0.1,
        unit="s",
        meaning="longest span of IMU samples over which the covariance is propagated in one step",
        rule=POSITIVE,
    )
    max_imu_gap_s: float = parameter(
        0.5, unit="s", meaning="a longer IMU gap restarts the alignment", rule=POSITIVE
    )
    max_angular_rate_rad_s: float = parameter(
        35.0,
        unit="rad/s",
        meaning="IMU samples with a larger rate magnitude are rejected",
        rule=POSITIVE,
    )
    max_specific_force_mps2: float = parameter(
        160.0,
        unit="m/s²",
        meaning="IMU samples with a larger specific force are rejected",
        rule=POSITIVE,
    )
    max_angular_acceleration_rad_s2: float = parameter(
        50.0,
        unit="rad/s²",
        meaning="largest angular acceleration of the platform: a larger rate change between "
        "samples (plus the sensor noise) is rejected as implausible_change",
        rule=POSITIVE,
    )
    max_jerk_mps3: float = parameter(
        2000.0,
        unit="m/s³",
        meaning="largest rate of change of the platform's specific force: a larger change "
        "between samples (plus the sensor noise) is rejected as implausible_change",
        rule=POSITIVE,
    )

    site_latitude_deg: float = shared_field("site.latitude_deg")
    site_longitude_deg: float = shared_field("site.longitude_deg")
    magnetic_declination_deg: float = shared_field("magnetic.declination_deg")
    ahrs_yaw_reference: str = shared_field("ahrs.yaw_reference")
    use_magnetometer: bool = parameter(
        True,
        meaning="fuse imu/mag when present",
        heading="Sites without GNSS: magnetometer, motion pack, mooring, IMU calibration",
    )
    use_ahrs: bool = parameter(True, meaning="fuse imu/data when present")
    magnetometer_hard_iron_t: tuple[float, float, float] = parameter(
        (0.0, 0.0, 0.0),
        unit="T",
        meaning="hard-iron offset subtracted from the raw field (calibrate_magnetometer)",
    )
    magnetometer_soft_iron: tuple[float, ...] = parameter(
        (1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0),
        meaning="row-major 3×3 matrix applied after the hard-iron offset (calibrate_magnetometer)",
        rule=custom_rule("9 numbers", lambda matrix: len(matrix) == 9),
    )
    magnetometer_heading_sigma_deg: float = parameter(
        1.0,
        unit="deg",
        meaning="1σ of the magnetic heading beyond the sensor noise: residual calibration, "
        "local fields",
        rule=POSITIVE,
    )
    magnetometer_error_correlation_time_s: float = parameter(
        60.0,
        unit="s",
        meaning="how long the magnetic heading's error beyond the sensor noise stays alike (it "
        "moves with the buoy's heading): closer samples share one error and are weighted so",
        rule=POSITIVE,
    )
    magnetometer_full_scale_t: float = parameter(
        8e-4, unit="T", meaning="a component this large is a saturated sample", rule=POSITIVE
    )
    magnetometer_strength_tolerance: float = parameter(
        0.2,
        meaning="a calibrated field whose strength differs from the World Magnetic Model's by "
        "more than this share is refused (magnetic_field_inconsistent)",
        rule=POSITIVE,
    )
    magnetometer_dip_tolerance_deg: float = parameter(
        10.0,
        unit="deg",
        meaning="a calibrated field whose dip (from the nominal attitude) differs from the World "
        "Magnetic Model's by more is refused (magnetic_field_inconsistent)",
        rule=POSITIVE,
    )
    ahrs_lag_s: float = parameter(
        0.0,
        unit="s",
        meaning="the motion pack's own lag; its attitude is carried forward by it with the gyro",
        rule=NON_NEGATIVE,
    )
    ahrs_lag_uncertainty_s: float = parameter(
        0.1,
        unit="s",
        meaning="what is not known of that lag, added as noise proportional to the body rate",
        rule=NON_NEGATIVE,
    )
    ahrs_variance_floor_rad2: float = parameter(
        1e-5, unit="rad²", meaning="smallest motion-pack attitude variance per axis", rule=POSITIVE
    )
    ahrs_error_correlation_time_s: float = parameter(
        60.0,
        unit="s",
        meaning="how long the pack's attitude error stays alike: closer samples share one error "
        "and are weighted so",
        rule=POSITIVE,
    )
    moored: bool = parameter(
        False,
        meaning="moored buoy: while no fix is accepted, hold the position to its slowly moving "
        "mean (zero mean velocity)",
    )
    moored_position_sigma_horizontal_m: float = parameter(
        3.0, unit="m", meaning="1σ horizontal wave excursion about that mean", rule=POSITIVE
    )
    moored_position_sigma_vertical_m: float = parameter(
        1.0, unit="m", meaning="1σ vertical wave excursion about that mean", rule=POSITIVE
    )
    moored_anchor_time_constant_s: float = parameter(
        600.0, unit="s", meaning="time constant of the moored mean position", rule=POSITIVE
    )
    moored_update_period_s: float = parameter(
        1.0, unit="s", meaning="interval of the moored constraint", rule=POSITIVE
    )
    moored_check_window_s: float = parameter(
        300.0,
        unit="s",
        meaning="the GNSS's mean velocity over this long (once it spans a fifth of it) is held "
        "against the mooring's zero mean: a buoy that drifts has its mooring constraint "
        "suspended",
        rule=POSITIVE,
    )
    moored_sigma_scale_limit: float = parameter(
        3.0,
        meaning="largest factor by which the mooring's own innovations may widen its "
        "horizontal σ (1: never widened)",
        rule=at_least(1),
    )
    moored_gyro_drift_scale_limit: float = parameter(
        50.0,
        meaning="largest factor by which a moored buoy's mean velocity over 30-s blocks may "
        "widen the σ of the gyro's drift, gyro_bias_instability_deg_h (1: never widened)",
        rule=at_least(1),
    )
    moored_velocity_noise_scale_limit: float = parameter(
        200.0,
        meaning="largest factor by which a moored buoy's mean velocity over 10-s blocks may "
        "widen the σ of the velocity's noise, accel_noise_mps_sqrt_h (1: never widened)",
        rule=at_least(1),
    )
    imu_gyro_bias_rad_s: tuple[float, float, float] = parameter(
        (0.0, 0.0, 0.0),
        unit="rad/s",
        meaning="gyro bias of the raw IMU (calibrate_imu): ω = ω_raw − b_g",
    )
    imu_accel_bias_mps2: tuple[float, float, float] = parameter(
        (0.0, 0.0, 0.0),
        unit="m/s²",
        meaning="accelerometer bias of the raw IMU (calibrate_imu): f = (f_raw − b_a) / scale",
    )
    imu_accel_scale: tuple[float, float, float] = parameter(
        (1.0, 1.0, 1.0),
        meaning="accelerometer scale of the raw IMU, per axis (calibrate_imu)",
        rule=custom_rule(
            "three scale factors in (0.5, 2)",
            lambda scales: all(0.5 < scale < 2.0 for scale in scales),
        ),
    )

    realtime_output: bool = parameter(
        True,
        meaning="true: each solution with its IMU sample, predicted from the filter "
        "max_measurement_delay_s behind; false: that late, every measurement applied",
        heading="Output",
    )
    output_rate_hz: float = parameter(
        0.0,
        unit="Hz",
        meaning="rate of navigation solutions; 0: one per IMU sample",
        rule=NON_NEGATIVE,
    )
    record_innovations: bool = parameter(
        False, meaning="keep every innovation in FusionEngine.innovation_log (analysis tools)"
    )

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
        for name, broken in broken_rules(self):
            raise ConfigError(f"{name} must be {broken}")
        try:
            self.source_health_rule  # noqa: B018 (the rule checks its fields together)
        except ValueError as error:
            raise ConfigError(str(error)) from None
        if self.site_latitude_only_deg is not None and math.isnan(self.magnetic_declination_deg):
            raise ConfigError(
                "parameter 'site.longitude_deg': NaN (and no origin.longitude_deg) while "
                "magnetic.declination_deg is NaN too: the World Magnetic Model gives the "
                "declination at the site only with its longitude; give site.longitude_deg, "
                "or magnetic.declination_deg as a number"
            )

    @property
    def site_position_deg(self) -> tuple[float, float] | None:
        """(latitude, longitude), deg, of the site the parameters give: ``site.*``, a
        coordinate not given there taken from ``origin.*``; None when a coordinate is known
        from neither (GNSS fixes then give the position, or nothing does)."""
        latitude, longitude = self.site_latitude_deg, self.site_longitude_deg
        if math.isnan(latitude):
            latitude = self.origin_latitude_deg
        if math.isnan(longitude):
            longitude = self.origin_longitude_deg
        if math.isnan(latitude) or math.isnan(longitude):
            return None
        return float(latitude), float(longitude)

    @property
    def site_latitude_only_deg(self) -> float | None:
        """``site.latitude_deg`` when it is given without any longitude (gravity and Earth
        rate, not a position); None otherwise."""
        if self.site_position_deg is None and math.isfinite(self.site_latitude_deg):
            return float(self.site_latitude_deg)
        return None

    @property
    def source_health_rule(self) -> SourceHealthRule:
        """When an aiding source is suspended and resumed (:mod:`buoy_nav.source_health`)."""
        return SourceHealthRule(
            self.source_health_window,
            self.source_health_min_samples,
            self.source_health_suspend_share,
            self.source_health_resume_share,
            self.source_health_min_span_s,
        )

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


def fusion_config_from_files(paths, defaults: Mapping[str, Any] | None = None) -> FusionConfig:
    """The :class:`FusionConfig` ``fusion_node`` would build from these ROS parameter files
    (sections ``/**`` and ``fusion_node``, later files winning), over ``defaults`` (parameter
    values by name, such as an imported record's facts; a file's value wins). Raises
    :class:`buoy_common.parameters.ParameterError` naming a bad file or value."""
    check_parameter_files(paths, FUSION_NODE_NAME, fusion_parameter_names())
    values = {**(defaults or {}), **load_parameter_files(paths, FUSION_NODE_NAME)}
    return build_config(
        FusionConfig, values, FUSION_PARAMETER_PREFIX, skip=FUSION_FIELDS_NOT_PARAMETERS
    )


def fusion_parameters() -> list[DeclaredParameter]:
    """Every parameter ``fusion_node`` declares, shared ones included."""
    return declared_parameters(
        FusionConfig, FUSION_PARAMETER_PREFIX, skip=FUSION_FIELDS_NOT_PARAMETERS
    )


def fusion_parameter_names() -> list[str]:
    """The names of :func:`fusion_parameters`."""
    return [declared.name for declared in fusion_parameters()]


FUSION_PARAMETER_FILE_HEADER = (
    "Navigation fusion (fusion_node and offline fuse_bag): every fusion.* parameter with its "
    "default.",
    "Use together with the shared buoy file, which sets gnss.primary_antenna, "
    "gnss.secondary_antenna",
    "and, optionally, origin.latitude_deg, origin.longitude_deg, origin.altitude_m:",
    "  fusion_node --ros-args --params-file buoy.yaml --params-file fusion.yaml",
)


def parameter_sets() -> ParameterSets:
    """The fusion's parameters, for the generated parameter file and reference (entry point of
    :data:`buoy_common.parameter_declarations.ENTRY_POINT_GROUP`)."""
    parameters = tuple(fusion_parameters())
    own = tuple(declared for declared in parameters if not declared.shared)
    section = FileSection("/**", own, WILDCARD_SECTION_COMMENT)
    return ParameterSets(
        "buoy_nav",
        nodes=(
            NodeParameters(
                FUSION_NODE_NAME,
                "navigation fusion (fusion_node, offline fuse_bag and process_bag)",
                parameters,
            ),
        ),
        files=(
            ParameterFile(
                "src/buoy_nav/config/fusion.yaml", FUSION_PARAMETER_FILE_HEADER, (section,)
            ),
        ),
    )
