"""Typed configuration of the wind compensation and the current estimate, live and offline.

:class:`CompensatorConfig` (wind) and :class:`CurrentConfig` (current) are frozen dataclasses
with unit-suffixed field names, so that ``compensation_node`` and ``current_node`` declare one
ROS parameter per field: ``compensation.<field>`` and ``current.<field>``, except the shared
extrinsic ones (interface contract), declared with their own names (``anemometer.position``,
``anemometer.rpy_deg``, ``dvl.position``, ``dvl.rpy_deg``). The offline tools build the same
configurations from the same parameter files (:func:`compensator_config_from_files`,
:func:`current_config_from_files`).
"""

import dataclasses
import math
from dataclasses import dataclass
from pathlib import Path

from buoy_common.contract import ANEMOMETER_FRAME, DEFAULT_PRODUCT_WINDOWS_S, DVL_FRAME, Reason
from buoy_common.extrinsics import check_shared_fields, field_parameter, shared_field
from buoy_common.parameter_declarations import (
    DECLARATION_METADATA_KEY,
    POSITIVE,
    WILDCARD_SECTION_COMMENT,
    Declaration,
    DeclaredParameter,
    FileSection,
    NodeParameters,
    ParameterFile,
    ParameterSets,
    custom_rule,
    declared_parameters,
    parameter,
)
from buoy_common.parameters import build_config, check_parameter_files, load_parameter_files
from wind_comp.compensator import FlowSensor, SigmaLimits
from wind_comp.flux_products import DEFAULT_FLUX_WINDOW_S
from wind_comp.flux_quality import FluxQualityLimits
from wind_comp.fluxes import STANDARD_PRESSURE_PA, FluxError, PlanarFit
from wind_comp.wave_motion_left import DEFAULT_THRESHOLDS, MotionLeftThresholds

COMPENSATION_NODE_NAME = "compensation_node"
"""Node name whose parameter-file sections configure the compensation (live and offline)."""
COMPENSATION_PARAMETER_PREFIX = "compensation."
"""ROS parameter of a :class:`CompensatorConfig` field ``f``: ``compensation.f``, except the
shared ones."""
CURRENT_NODE_NAME = "current_node"
"""Node name whose parameter-file sections configure the current estimate (live and offline)."""
CURRENT_PARAMETER_PREFIX = "current."
"""ROS parameter of a :class:`CurrentConfig` field ``f``: ``current.f``, except the shared
ones."""

NAV_TIMEOUT = DeclaredParameter(
    COMPENSATION_PARAMETER_PREFIX + "nav_timeout_s",
    1.0,
    "latency budget, live only: a sample still without navigation on both sides once the "
    "newest sensor stamp is this much later, and that has waited this long in wall time, is "
    "published invalid",
    unit="s",
    rule=str(POSITIVE),
)
"""Latency budget of the live compensation; offline processing has no wall clock to wait on."""
NAV_TIMEOUT_PARAMETER = NAV_TIMEOUT.name
CURRENT_NAV_TIMEOUT = dataclasses.replace(
    NAV_TIMEOUT, name=CURRENT_PARAMETER_PREFIX + "nav_timeout_s", default=5.0
)
"""Latency budget of the live current estimate, live-only as the compensation's. A current is
an average of minutes: waiting for late navigation costs nothing, giving a sample up costs a
sample."""
CURRENT_NAV_TIMEOUT_PARAMETER = CURRENT_NAV_TIMEOUT.name


class ConfigError(ValueError):
    """A compensator setting is missing or malformed; the message names the field."""


def _plane_or_unset(plane) -> bool:
    finite = [math.isfinite(value) for value in plane]
    return len(plane) == 3 and (all(finite) or not any(finite))


PRODUCT_WINDOWS = custom_rule(
    "positive window lengths", lambda windows: bool(windows) and min(windows) > 0
)
FRAME_NAME = custom_rule(
    "a frame name", lambda frame_id: isinstance(frame_id, str) and bool(frame_id.strip())
)
PLANAR_FIT = custom_rule("three finite numbers or all NaN", _plane_or_unset)
FLUX_QUALITY_DEFAULTS = FluxQualityLimits()
"""The flux tests' thresholds are declared here, their defaults are the core's."""
HEIGHT_OR_UNSET = custom_rule(
    "> 0, or NaN (unknown)",
    lambda height: isinstance(height, float) and (math.isnan(height) or height > 0.0),
)
NOISE_SIGMAS = custom_rule(
    "three positive numbers",
    lambda sigmas: len(sigmas) == 3 and all(math.isfinite(s) and s > 0 for s in sigmas),
)


@dataclass(frozen=True)
class _Threshold:
    """A threshold of a flux test, declared as a parameter of the compensation: its default is
    the core's (the attribute ``name`` of the core's defaults), its rule positive."""

    name: str
    meaning: str
    unit: str = ""


MOTION_LEFT_THRESHOLDS = (
    _Threshold(
        "suspect_share",
        '"motion left" flux test: suspect where the corrected w keeps this share of '
        "the platform's vertical velocity over the wave band, with a coherence beyond noise",
    ),
    _Threshold(
        "fail_share",
        '"motion left" flux test: fail from this share on (at least motion_left_suspect_share)',
    ),
    _Threshold(
        "coherence_sigmas",
        '"motion left" flux test: the share counts where the coherence of w with the '
        "platform's vertical velocity over the wave band lies this many standard deviations "
        "above that of unrelated series (motion_left_coherence_threshold)",
    ),
    _Threshold(
        "max_share_standard_error",
        '"motion left" flux test: not evaluated (its figures still published) where '
        "the share's standard error, from the coherence, the band powers of w and of the "
        "platform's vertical velocity and the segment count, exceeds this (a buoy that barely "
        "heaves, at the noise of the navigation's vertical velocity)",
    ),
)
"""``compensation.motion_left_<name>``: the thresholds of the "motion left" test
(:class:`wind_comp.wave_motion_left.MotionLeftThresholds`)."""
FLUX_QC_THRESHOLDS = (
    _Threshold(
        "max_spike_share",
        "spikes test: suspect when the Vickers-Mahrt spikes of a component exceed this "
        "share of the window's samples (Vickers and Mahrt 1997)",
    ),
    _Threshold(
        "stationarity_suspect_percent",
        "stationarity test (Foken and Wichura 1996, 5-min sub-windows): suspect above "
        "this non-stationarity of u'w' (Foken et al. 2004: classes 1-3 below 30 %)",
        unit="%",
    ),
    _Threshold(
        "stationarity_fail_percent",
        "stationarity test: fail above this non-stationarity of u'w' (Foken et al. "
        "2004: classes 7-9 above 100 %)",
        unit="%",
    ),
    _Threshold(
        "itc_suspect_percent",
        "integral turbulence characteristics test: suspect above this deviation of "
        "sigma_w/u* from 1.3(1+2|z/L|)^(1/3), 1.25 when z/L is unknown (Foken et al. 2004)",
        unit="%",
    ),
    _Threshold(
        "itc_fail_percent",
        "integral turbulence characteristics test: fail above this deviation (Foken et al. 2004)",
        unit="%",
    ),
    _Threshold(
        "drag_min_speed_mps",
        "drag coefficient test: not evaluated below this mean speed (u*^2/U^2 then "
        "follows the noise and free convection, not the wind)",
        unit="m/s",
    ),
    _Threshold(
        "drag_suspect_below_factor",
        "drag coefficient test: suspect below this multiple of the COARE 3.5 neutral "
        "10-m drag coefficient at the mean speed (Edson et al. 2013); never fail below",
    ),
    _Threshold(
        "drag_suspect_above_factor",
        "drag coefficient test: suspect above this multiple of the COARE 3.5 neutral "
        "10-m drag coefficient (30-min values scatter by about 2x around it, Edson et al. 2013)",
    ),
    _Threshold(
        "drag_fail_above_factor",
        "drag coefficient test: fail above this multiple of the COARE 3.5 neutral "
        "10-m drag coefficient (beyond the scatter of real windows; a tenfold stress error over "
        "a sea whose drag is 0.7x the bulk relation's still exceeds it)",
    ),
    _Threshold(
        "min_friction_velocity_mps",
        "cross-wind stress test and T*: not evaluated below this u*, where the stress "
        "is its own sampling noise",
        unit="m/s",
    ),
    _Threshold(
        "cross_wind_suspect_ratio",
        "cross-wind stress test: suspect when |v'w'| exceeds this multiple of |u'w'| "
        "(stress more than 45 deg off the mean wind)",
    ),
    _Threshold(
        "cross_wind_fail_ratio",
        "cross-wind stress test: fail when |v'w'| exceeds this multiple of |u'w'| "
        "(more than 63 deg off the mean wind)",
    ),
    _Threshold(
        "w_ts_correlation_suspect",
        "buoyancy flux test: suspect when |w'Ts'|/(sigma_w sigma_T) exceeds this "
        "(surface-layer correlations stay below about 0.6)",
    ),
    _Threshold(
        "w_ts_correlation_fail",
        "buoyancy flux test: fail when |w'Ts'|/(sigma_w sigma_T) exceeds this",
    ),
    _Threshold(
        "temperature_scale_suspect_k",
        "buoyancy flux test: suspect when |T*| = |w'Ts'|/u* exceeds this (marine "
        "surface layers: tenths of a kelvin at most)",
        unit="K",
    ),
    _Threshold(
        "temperature_scale_fail_k",
        "buoyancy flux test: fail when |T*| exceeds this",
        unit="K",
    ),
)
"""``compensation.flux_qc_<name>``: the thresholds of the other flux tests
(:class:`wind_comp.flux_quality.FluxQualityLimits`)."""


def _threshold_fields(prefix: str, core_defaults, thresholds) -> dict[str, dataclasses.Field]:
    """The configuration fields of ``thresholds``, named ``prefix`` + name, each defaulting to
    the attribute of that name of ``core_defaults``."""
    return {
        prefix + threshold.name: parameter(
            getattr(core_defaults, threshold.name),
            unit=threshold.unit,
            meaning=threshold.meaning,
            rule=POSITIVE,
        )
        for threshold in thresholds
    }


def _declared_after(anchor: str, fields: dict[str, dataclasses.Field]):
    """A class decorator applied before ``dataclass``: the float ``fields`` become fields of
    the class right after its field ``anchor``, in their order (the order of the parameter files
    and of ``docs/parameters.md``)."""

    def declare(cls):
        if anchor not in cls.__annotations__:
            raise TypeError(f"{cls.__name__} has no field {anchor} to declare fields after")
        annotations = {}
        for name, annotation in cls.__annotations__.items():
            annotations[name] = annotation
            if name == anchor:
                annotations.update(dict.fromkeys(fields, float))
        cls.__annotations__ = annotations
        for name, field in fields.items():
            setattr(cls, name, field)
        return cls

    return declare


@dataclass(frozen=True)
@_declared_after(
    "flux_measurement_height_m",
    _threshold_fields("flux_qc_", FLUX_QUALITY_DEFAULTS, FLUX_QC_THRESHOLDS),
)
@_declared_after(
    "flux_despike", _threshold_fields("motion_left_", DEFAULT_THRESHOLDS, MOTION_LEFT_THRESHOLDS)
)
class CompensatorConfig:
    """Settings of the wind compensation, each field declared once with its default, unit,
    rule and meaning (the parameter files and ``docs/parameters.md`` are generated from them).

    ``max_attitude_sigma_deg``: the fusion publishes its attitude 1σ at least
    ``fusion.integrity_attitude_sigma_deg`` (5°) while it finds itself inconsistent with its
    aiding, so this is how an untrustworthy navigation reaches the wind; the default lies
    between that and the 1σ a sound filter reports in the first second after its alignment (up
    to about 3°). ``flux_planar_fit`` is fitted to the mean winds of many windows with
    :func:`wind_comp.fluxes.fit_plane` (Wilczak et al. 2001). ``air_pressure_pa``: ±30 hPa of
    weather changes the stress by 3 %.
    """

    anemometer_position_body_m: tuple[float, float, float] = shared_field("anemometer.position")
    anemometer_rpy_deg: tuple[float, float, float] = shared_field("anemometer.rpy_deg")
    max_nav_gap_s: float = parameter(
        0.1,
        unit="s",
        meaning="largest spacing of the two navigation samples around a wind stamp for which "
        "the navigation is interpolated; wider gaps make the sample invalid",
        rule=POSITIVE,
    )
    max_wind_speed_mps: float = parameter(
        100.0,
        unit="m/s",
        meaning="measured wind speeds above this are rejected as absurd",
        rule=POSITIVE,
    )
    nav_history_s: float = parameter(
        10.0,
        unit="s",
        meaning="how far a wind stamp may lag the newest navigation sample and still be "
        "corrected (longer than max_nav_gap_s)",
        rule=POSITIVE,
    )
    product_windows_s: tuple[float, ...] = parameter(
        DEFAULT_PRODUCT_WINDOWS_S,
        unit="s",
        meaning="averaging windows of the wind products: wind/mean_1min, wind/stats_1min, ... "
        "(other lengths W: wind/mean_<W>s)",
        rule=PRODUCT_WINDOWS,
    )
    gust_window_s: float = parameter(
        3.0,
        unit="s",
        meaning="running mean whose maximum over a window is the gust (WMO: 3 s), shorter than "
        "every product window",
        rule=POSITIVE,
    )
    anemometer_frame_id: str = parameter(
        ANEMOMETER_FRAME,
        meaning="frame_id of anemometer/wind messages (samples in another frame are rejected "
        "as wrong_frame)",
        rule=FRAME_NAME,
    )
    max_attitude_sigma_deg: float = parameter(
        4.0,
        unit="deg",
        meaning="navigation samples whose attitude 1σ exceeds this correct no wind (the samples "
        "they bracket are invalid, navigation_not_trusted)",
        rule=POSITIVE,
    )
    flux_window_s: float = parameter(
        DEFAULT_FLUX_WINDOW_S,
        unit="s",
        meaning="averaging window of the eddy-covariance fluxes: wind/fluxes_30min",
        rule=POSITIVE,
    )
    flux_planar_fit: tuple[float, float, float] = parameter(
        (math.nan, math.nan, math.nan),
        meaning="[b0 (m/s), b1, b2] of the plane w = b0 + b1·u + b2·v the fluxes rotate into "
        "(planar fit); NaN: double rotation, window by window",
        rule=PLANAR_FIT,
    )
    air_pressure_pa: float = parameter(
        STANDARD_PRESSURE_PA,
        unit="Pa",
        meaning="air pressure for the air density of the stress (standard atmosphere)",
        rule=POSITIVE,
    )
    flux_despike: bool = parameter(
        False,
        meaning="take the Vickers-Mahrt spikes out of the fluxes (spikes_* then count the "
        "samples taken out); false: only count them",
    )
    flux_measurement_height_m: float = parameter(
        FLUX_QUALITY_DEFAULTS.measurement_height_m,
        unit="m",
        meaning="height of the sonic above the sea, for the stability z/L of the flux tests; "
        "NaN: unknown (the integral-turbulence test takes the neutral model)",
        rule=HEIGHT_OR_UNSET,
        heading="flux quality control: named QARTOD tests per flux window (wind_comp.flux_quality)",
    )
    anemometer_noise_sigma_mps: tuple[float, float, float] = parameter(
        (0.05, 0.05, 0.03),
        unit="m/s",
        meaning="1σ noise of one anemometer sample along its x, y, z axes (a sonic's data "
        "sheet: Gill WindMaster 1.5 % of the speed, 0.01–0.05 m/s)",
        rule=NOISE_SIGMAS,
    )
    max_wind_sigma_horizontal_mps: float = parameter(
        0.5,
        unit="m/s",
        meaning="a corrected wind sample whose horizontal 1σ, √(σ_E²+σ_N²), exceeds this is "
        "invalid, uncertainty_too_large (WMO-No. 8: 0.5 m/s)",
        rule=POSITIVE,
    )
    max_wind_sigma_vertical_mps: float = parameter(
        0.25,
        unit="m/s",
        meaning="a corrected wind sample whose vertical 1σ exceeds this is invalid, "
        "uncertainty_too_large",
        rule=POSITIVE,
    )

    def __post_init__(self):
        _check_and_coerce(self)
        try:
            plane = tuple(float(value) for value in self.flux_planar_fit)
        except (TypeError, ValueError) as error:
            raise ConfigError(
                f"flux_planar_fit must be three numbers, got {self.flux_planar_fit!r}"
            ) from error
        if not PLANAR_FIT.holds(plane):
            raise ConfigError(
                "flux_planar_fit must be three finite numbers (b0 m/s, b1, b2) or all NaN "
                f"(double rotation), got {self.flux_planar_fit!r}"
            )
        object.__setattr__(self, "flux_planar_fit", plane)
        if self.motion_left_fail_share < self.motion_left_suspect_share:
            raise ConfigError(
                f"motion_left_fail_share ({self.motion_left_fail_share}) must be at least "
                f"motion_left_suspect_share ({self.motion_left_suspect_share})"
            )
        height = _finite_or_nan("flux_measurement_height_m", self.flux_measurement_height_m)
        if not HEIGHT_OR_UNSET.holds(height):
            raise ConfigError(f"flux_measurement_height_m must be {HEIGHT_OR_UNSET}, got {height}")
        object.__setattr__(self, "flux_measurement_height_m", height)
        try:
            self.flux_quality_limits()
        except FluxError as error:
            raise ConfigError(str(error)) from None
        if self.gust_window_s >= min(self.product_windows_s):
            raise ConfigError(
                f"gust_window_s ({self.gust_window_s}) must be shorter than every product window "
                f"{self.product_windows_s}"
            )

    def flux_quality_limits(self) -> FluxQualityLimits:
        """The thresholds of the flux tests (:mod:`wind_comp.flux_quality`)."""
        prefix = "flux_qc_"
        limits = {
            field.name.removeprefix(prefix): getattr(self, field.name)
            for field in dataclasses.fields(self)
            if field.name.startswith(prefix)
        }
        return FluxQualityLimits(measurement_height_m=self.flux_measurement_height_m, **limits)

    def planar_fit(self) -> PlanarFit | None:
        """The plane of :attr:`flux_planar_fit`; None for double rotation."""
        if math.isnan(self.flux_planar_fit[0]):
            return None
        return PlanarFit(*self.flux_planar_fit)

    def motion_left_thresholds(self) -> MotionLeftThresholds:
        """Where the fluxes' "motion left" test turns suspect and fail."""
        return MotionLeftThresholds(
            self.motion_left_suspect_share,
            self.motion_left_fail_share,
            self.motion_left_coherence_sigmas,
            self.motion_left_max_share_standard_error,
        )

    def flow_sensor(self) -> FlowSensor:
        """The anemometer as the correction sees it."""
        return FlowSensor(
            self.anemometer_position_body_m,
            self.anemometer_rpy_deg,
            self.max_wind_speed_mps,
            Reason.INVALID_WIND,
            Reason.WIND_SPEED_OUT_OF_RANGE,
            SigmaLimits(self.max_wind_sigma_horizontal_mps, self.max_wind_sigma_vertical_mps),
            tuple(sigma * sigma for sigma in self.anemometer_noise_sigma_mps),
        )


@dataclass(frozen=True)
class CurrentConfig:
    """Settings of the current estimate from a DVL in water track, each field declared once
    with its default, unit, rule and meaning. ``max_attitude_sigma_deg`` as for the wind
    (:class:`CompensatorConfig`): an attitude error of 4° turns a 5 m/s water track by 0.35 m/s.
    """

    dvl_position_body_m: tuple[float, float, float] = shared_field("dvl.position")
    dvl_rpy_deg: tuple[float, float, float] = shared_field("dvl.rpy_deg")
    max_nav_gap_s: float = parameter(
        0.1,
        unit="s",
        meaning="largest spacing of the two navigation samples around a DVL stamp for which "
        "the navigation is interpolated; wider gaps make the sample invalid",
        rule=POSITIVE,
    )
    max_dvl_speed_mps: float = parameter(
        20.0,
        unit="m/s",
        meaning="DVL velocities faster than this are rejected as absurd (beyond any DVL's range)",
        rule=POSITIVE,
    )
    nav_history_s: float = parameter(
        10.0,
        unit="s",
        meaning="how far a DVL stamp may lag the newest navigation sample and still be used "
        "(longer than max_nav_gap_s)",
        rule=POSITIVE,
    )
    product_windows_s: tuple[float, ...] = parameter(
        DEFAULT_PRODUCT_WINDOWS_S,
        unit="s",
        meaning="averaging windows of the current products: current/mean_1min, "
        "current/stats_1min, ... (other lengths W: current/mean_<W>s)",
        rule=PRODUCT_WINDOWS,
    )
    dvl_frame_id: str = parameter(
        DVL_FRAME,
        meaning="frame_id of dvl/velocity messages (samples in another frame are rejected as "
        "wrong_frame)",
        rule=FRAME_NAME,
    )
    max_attitude_sigma_deg: float = parameter(
        4.0,
        unit="deg",
        meaning="navigation samples whose attitude 1σ exceeds this correct no DVL sample "
        "(navigation_not_trusted)",
        rule=POSITIVE,
    )
    max_current_sigma_horizontal_mps: float = parameter(
        0.1,
        unit="m/s",
        meaning="a current sample whose horizontal 1σ, √(σ_E²+σ_N²), exceeds this is invalid, "
        "uncertainty_too_large (a tenth of a typical 1 m/s tidal current)",
        rule=POSITIVE,
    )
    max_current_sigma_vertical_mps: float = parameter(
        0.05,
        unit="m/s",
        meaning="a current sample whose vertical 1σ exceeds this is invalid, uncertainty_too_large",
        rule=POSITIVE,
    )

    def __post_init__(self):
        _check_and_coerce(self)

    def flow_sensor(self) -> FlowSensor:
        """The DVL as the correction sees it. The correction takes the water's velocity past
        the DVL, the negative of its reading
        (:func:`wind_comp.compensation_messages.dvl_sample`)."""
        return FlowSensor(
            self.dvl_position_body_m,
            self.dvl_rpy_deg,
            self.max_dvl_speed_mps,
            Reason.INVALID_DVL,
            Reason.DVL_SPEED_OUT_OF_RANGE,
            SigmaLimits(self.max_current_sigma_horizontal_mps, self.max_current_sigma_vertical_mps),
        )


def _check_and_coerce(config):
    """The checks both configurations share: finite 3-vectors and the rules of the shared
    parameters, then the declared rules (positive numbers, product windows, the sensor's frame
    name), and a navigation history longer than the gap."""
    fields = dataclasses.fields(config)
    for field in fields:
        if field_parameter(field) is not None:
            value = _finite_tuple(field.name, getattr(config, field.name), length=3)
            object.__setattr__(config, field.name, value)
    try:
        check_shared_fields(config)
    except ValueError as error:
        raise ConfigError(str(error)) from None
    for field in fields:
        declared_rule = field.metadata.get(DECLARATION_METADATA_KEY, Declaration("")).rule
        name, value = field.name, getattr(config, field.name)
        if declared_rule is POSITIVE:
            object.__setattr__(config, name, _positive_float(name, value))
        elif declared_rule is PRODUCT_WINDOWS:
            windows = _finite_tuple(name, value, length=None)
            if not PRODUCT_WINDOWS.holds(windows):
                raise ConfigError(f"{name} must be {PRODUCT_WINDOWS}, got {windows}")
            object.__setattr__(config, name, windows)
        elif declared_rule is NOISE_SIGMAS:
            sigmas = _finite_tuple(name, value, length=3)
            if not NOISE_SIGMAS.holds(sigmas):
                raise ConfigError(f"{name} must be {NOISE_SIGMAS}, got {sigmas}")
            object.__setattr__(config, name, sigmas)
        elif declared_rule is FRAME_NAME and not FRAME_NAME.holds(value):
            raise ConfigError(f"{name} must be {FRAME_NAME}, got {value!r}")
    if config.nav_history_s <= config.max_nav_gap_s:
        raise ConfigError(
            f"nav_history_s ({config.nav_history_s}) must exceed max_nav_gap_s "
            f"({config.max_nav_gap_s})"
        )


def _finite_tuple(name: str, value, length: int | None) -> tuple[float, ...]:
    try:
        numbers = tuple(float(item) for item in value)
    except (TypeError, ValueError) as error:
        raise ConfigError(f"{name} must be a sequence of numbers, got {value!r}") from error
    if length is not None and len(numbers) != length:
        raise ConfigError(f"{name} must have {length} values, got {len(numbers)}: {value!r}")
    if not all(math.isfinite(number) for number in numbers):
        raise ConfigError(f"{name} must be finite, got {value!r}")
    return numbers


def _finite_or_nan(name: str, value) -> float:
    """A number, NaN allowed (unset); ConfigError for anything else."""
    if isinstance(value, bool):
        raise ConfigError(f"{name} must be a number, got {value!r}")
    try:
        return float(value)
    except (TypeError, ValueError) as error:
        raise ConfigError(f"{name} must be a number, got {value!r}") from error


def _positive_float(name: str, value) -> float:
    if isinstance(value, bool):
        raise ConfigError(f"{name} must be a number, got {value!r}")
    try:
        number = float(value)
    except (TypeError, ValueError) as error:
        raise ConfigError(f"{name} must be a number, got {value!r}") from error
    if not (math.isfinite(number) and number > 0):
        raise ConfigError(f"{name} must be positive and finite, got {value!r}")
    return number


def compensator_config_from_files(paths) -> CompensatorConfig:
    """The :class:`CompensatorConfig` ``compensation_node`` would build from these ROS parameter
    files (sections ``/**`` and ``compensation_node``, later files winning). Raises
    :class:`buoy_common.parameters.ParameterError` naming a bad file or value."""
    check_parameter_files(paths, COMPENSATION_NODE_NAME, compensation_parameter_names())
    values = load_parameter_files(paths, COMPENSATION_NODE_NAME)
    return build_config(CompensatorConfig, values, prefix=COMPENSATION_PARAMETER_PREFIX)


def current_config_from_files(paths) -> CurrentConfig:
    """The :class:`CurrentConfig` ``current_node`` would build from these ROS parameter files
    (sections ``/**`` and ``current_node``, later files winning). Raises
    :class:`buoy_common.parameters.ParameterError` naming a bad file or value (an unknown
    parameter name among them)."""
    check_parameter_files(paths, CURRENT_NODE_NAME, current_parameter_names())
    values = load_parameter_files(paths, CURRENT_NODE_NAME)
    return build_config(CurrentConfig, values, prefix=CURRENT_PARAMETER_PREFIX)


def compensation_parameters() -> list[DeclaredParameter]:
    """Every parameter ``compensation_node`` declares, the live-only one included."""
    declared = declared_parameters(CompensatorConfig, COMPENSATION_PARAMETER_PREFIX)
    return [*declared, NAV_TIMEOUT]


def current_parameters() -> list[DeclaredParameter]:
    """Every parameter ``current_node`` declares, the live-only one included."""
    return [*declared_parameters(CurrentConfig, CURRENT_PARAMETER_PREFIX), CURRENT_NAV_TIMEOUT]


def compensation_parameter_names() -> list[str]:
    """The names of :func:`compensation_parameters`."""
    return [declared.name for declared in compensation_parameters()]


def current_parameter_names() -> list[str]:
    """The names of :func:`current_parameters`."""
    return [declared.name for declared in current_parameters()]


def _node_file(path: str, node: str, what: str, shared: str, parameters) -> ParameterFile:
    header = (
        f"{what} ({node} and offline processing): every parameter with its default.",
        f"Use together with the shared buoy file, which sets {shared}:",
        f"  {node} --ros-args --params-file buoy.yaml --params-file {Path(path).name}",
    )
    own = tuple(declared for declared in parameters if not declared.shared)
    return ParameterFile(path, header, (FileSection("/**", own, WILDCARD_SECTION_COMMENT),))


def parameter_sets() -> ParameterSets:
    """The compensation's and the current's parameters, for the generated parameter files and
    reference (entry point of :data:`buoy_common.parameter_declarations.ENTRY_POINT_GROUP`)."""
    compensation, current = tuple(compensation_parameters()), tuple(current_parameters())
    return ParameterSets(
        "wind_comp",
        nodes=(
            NodeParameters(
                COMPENSATION_NODE_NAME,
                "wind compensation (compensation_node, offline process_bag)",
                compensation,
            ),
            NodeParameters(
                CURRENT_NODE_NAME,
                "current estimate from a DVL (current_node, offline process_bag)",
                current,
            ),
        ),
        files=(
            _node_file(
                "src/wind_comp/config/compensation.yaml",
                COMPENSATION_NODE_NAME,
                "Wind compensation",
                "anemometer.position and anemometer.rpy_deg",
                compensation,
            ),
            _node_file(
                "src/wind_comp/config/current.yaml",
                CURRENT_NODE_NAME,
                "Current estimate from a DVL",
                "dvl.position and dvl.rpy_deg",
                current,
            ),
        ),
    )
