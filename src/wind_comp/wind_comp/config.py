"""Typed configuration of the wind compensation and the current estimate, live and offline.

:class:`CompensatorConfig` (wind) and :class:`CurrentConfig` (current) are frozen dataclasses
with unit-suffixed field names, so that ``compensation_node`` and ``current_node`` declare one
ROS parameter per field: ``compensation.<field>`` and ``current.<field>``, except the shared
extrinsic ones (interface contract), declared with their own names (``anemometer.position``,
``anemometer.rpy_deg``, ``dvl.position``, ``dvl.rpy_deg``). The offline tools build the same
configurations from the same parameter files (:func:`compensator_config_from_files`,
:func:`current_config_from_files`).
"""

import math
from dataclasses import dataclass

from buoy_common.contract import ANEMOMETER_FRAME, DEFAULT_PRODUCT_WINDOWS_S, DVL_FRAME, Reason
from buoy_common.extrinsics import check_shared_fields, shared_field
from buoy_common.parameters import (
    build_config,
    check_parameter_files,
    config_parameters,
    load_parameter_files,
)
from wind_comp.compensator import FlowSensor
from wind_comp.flux_products import DEFAULT_FLUX_WINDOW_S
from wind_comp.fluxes import STANDARD_PRESSURE_PA, PlanarFit

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

NAV_TIMEOUT_PARAMETER = COMPENSATION_PARAMETER_PREFIX + "nav_timeout_s"
"""Latency budget of the live compensation (s); offline processing has no wall clock to wait
on."""
CURRENT_NAV_TIMEOUT_PARAMETER = CURRENT_PARAMETER_PREFIX + "nav_timeout_s"
"""Latency budget of the live current estimate (s), live-only as the compensation's."""


class ConfigError(ValueError):
    """A compensator setting is missing or malformed; the message names the field."""


@dataclass(frozen=True)
class CompensatorConfig:
    """Settings of the wind compensation.

    Attributes:
        anemometer_position_body_m: anemometer measurement centre in ``base_link``, m
            (Miller's lever arm B; parameter ``anemometer.position``).
        anemometer_rpy_deg: roll, pitch, yaw of ``anemometer_link`` relative to ``base_link``,
            deg, applied as Rz(yaw)·Ry(pitch)·Rx(roll) (parameter ``anemometer.rpy_deg``).
        max_nav_gap_s: largest spacing of the two navigation samples bracketing a wind stamp
            for which the navigation is interpolated, s.
        max_wind_speed_mps: measured wind speeds above this are rejected as absurd, m/s.
        nav_history_s: how far behind the newest navigation sample a wind stamp may lag and
            still be corrected in streaming use, s.
        product_windows_s: lengths of the averaging windows of the wind products, s
            (60 s and 600 s by default, WMO practice).
        gust_window_s: length of the running mean whose maximum is the gust, s (WMO: 3 s).
        anemometer_frame_id: the ``frame_id`` of ``anemometer/wind`` messages; a message in
            another frame is rejected (``wrong_frame``) and its output is NaN. The contract's
            ``anemometer_link`` unless a driver names its frame otherwise.
        max_attitude_sigma_deg: a navigation sample whose attitude 1σ (the largest of the
            three in its pose covariance) exceeds this corrects no wind: the samples it
            brackets are invalid as ``navigation_not_trusted``, deg. The fusion publishes its
            attitude 1σ at least ``fusion.integrity_attitude_sigma_deg`` (5°) while it finds
            itself inconsistent with its aiding, so this is how an untrustworthy navigation
            reaches the wind; the default lies between that and the 1σ a sound filter reports
            in the first second after its alignment (up to about 3°).
        flux_window_s: averaging window of the eddy-covariance fluxes, s (30 min by default).
        flux_planar_fit: the plane w̄ = b0 + b1·ū + b2·v̄ (b0 m/s, b1 and b2 dimensionless)
            to rotate the wind with for the fluxes (planar fit, Wilczak et al. 2001, fitted to
            the mean winds of many windows with :func:`wind_comp.fluxes.fit_plane`); all NaN
            (the default): double rotation, window by window.
        air_pressure_pa: air pressure for the air density of the stress, Pa (the standard
            atmosphere by default: ±30 hPa of weather changes the stress by 3 %).
        flux_despike: take the Vickers–Mahrt spikes out of the fluxes (each spike NaN in its
            own component of the window's rotated wind or sonic temperature; the counts
            ``spikes_*`` are then the samples taken out); False (the default): only count them.
            The corrected wind and its products keep every sample either way.
    """

    anemometer_position_body_m: tuple[float, float, float] = shared_field("anemometer.position")
    anemometer_rpy_deg: tuple[float, float, float] = shared_field("anemometer.rpy_deg")
    max_nav_gap_s: float = 0.1
    max_wind_speed_mps: float = 100.0
    nav_history_s: float = 10.0
    product_windows_s: tuple[float, ...] = DEFAULT_PRODUCT_WINDOWS_S
    gust_window_s: float = 3.0
    anemometer_frame_id: str = ANEMOMETER_FRAME
    max_attitude_sigma_deg: float = 4.0
    flux_window_s: float = DEFAULT_FLUX_WINDOW_S
    flux_planar_fit: tuple[float, float, float] = (math.nan, math.nan, math.nan)
    air_pressure_pa: float = STANDARD_PRESSURE_PA
    flux_despike: bool = False

    def __post_init__(self):
        _check_and_coerce(
            self,
            ("anemometer_position_body_m", "anemometer_rpy_deg"),
            (
                "max_nav_gap_s",
                "max_wind_speed_mps",
                "nav_history_s",
                "gust_window_s",
                "max_attitude_sigma_deg",
                "flux_window_s",
                "air_pressure_pa",
            ),
            "anemometer_frame_id",
        )
        try:
            plane = tuple(float(value) for value in self.flux_planar_fit)
        except (TypeError, ValueError) as error:
            raise ConfigError(
                f"flux_planar_fit must be three numbers, got {self.flux_planar_fit!r}"
            ) from error
        finite = [math.isfinite(value) for value in plane]
        if len(plane) != 3 or (any(finite) and not all(finite)):
            raise ConfigError(
                "flux_planar_fit must be three finite numbers (b0 m/s, b1, b2) or all NaN "
                f"(double rotation), got {self.flux_planar_fit!r}"
            )
        object.__setattr__(self, "flux_planar_fit", plane)
        if self.gust_window_s >= min(self.product_windows_s):
            raise ConfigError(
                f"gust_window_s ({self.gust_window_s}) must be shorter than every product window "
                f"{self.product_windows_s}"
            )

    def planar_fit(self) -> PlanarFit | None:
        """The plane of :attr:`flux_planar_fit`; None for double rotation."""
        if math.isnan(self.flux_planar_fit[0]):
            return None
        return PlanarFit(*self.flux_planar_fit)

    def flow_sensor(self) -> FlowSensor:
        """The anemometer as the correction sees it."""
        return FlowSensor(
            self.anemometer_position_body_m,
            self.anemometer_rpy_deg,
            self.max_wind_speed_mps,
            Reason.INVALID_WIND,
            Reason.WIND_SPEED_OUT_OF_RANGE,
        )


@dataclass(frozen=True)
class CurrentConfig:
    """Settings of the current estimate from a DVL in water track.

    Attributes:
        dvl_position_body_m: DVL measurement centre in ``base_link``, m (parameter
            ``dvl.position``).
        dvl_rpy_deg: roll, pitch, yaw of ``dvl_link`` relative to ``base_link``, deg, applied as
            Rz(yaw)·Ry(pitch)·Rx(roll) (parameter ``dvl.rpy_deg``).
        max_nav_gap_s: largest spacing of the two navigation samples bracketing a DVL stamp for
            which the navigation is interpolated, s.
        max_dvl_speed_mps: DVL velocities faster than this are rejected as absurd, m/s (beyond
            the velocity range of any DVL).
        nav_history_s: how far behind the newest navigation sample a DVL stamp may lag and still
            be corrected in streaming use, s.
        product_windows_s: lengths of the averaging windows of the current products, s (60 s
            and 600 s by default).
        dvl_frame_id: the ``frame_id`` of ``dvl/velocity`` messages; a message in another frame
            is rejected (``wrong_frame``) and its output is NaN. The contract's ``dvl_link``
            unless a driver names its frame otherwise.
        max_attitude_sigma_deg: a navigation sample whose attitude 1σ exceeds this corrects no
            DVL sample (``navigation_not_trusted``), deg: as for the wind
            (:class:`CompensatorConfig`); an attitude error of 4° turns a 5 m/s water track
            by 0.35 m/s.
    """

    dvl_position_body_m: tuple[float, float, float] = shared_field("dvl.position")
    dvl_rpy_deg: tuple[float, float, float] = shared_field("dvl.rpy_deg")
    max_nav_gap_s: float = 0.1
    max_dvl_speed_mps: float = 20.0
    nav_history_s: float = 10.0
    product_windows_s: tuple[float, ...] = DEFAULT_PRODUCT_WINDOWS_S
    dvl_frame_id: str = DVL_FRAME
    max_attitude_sigma_deg: float = 4.0

    def __post_init__(self):
        _check_and_coerce(
            self,
            ("dvl_position_body_m", "dvl_rpy_deg"),
            ("max_nav_gap_s", "max_dvl_speed_mps", "nav_history_s", "max_attitude_sigma_deg"),
            "dvl_frame_id",
        )

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
        )


def _check_and_coerce(
    config, vector_fields: tuple[str, ...], positive_fields: tuple[str, ...], frame_field: str
):
    """The checks both configurations share: finite 3-vectors, the shared parameters' rules,
    positive numbers, product windows, the sensor's frame name, and a navigation history
    longer than the gap."""
    for name in vector_fields:
        object.__setattr__(config, name, _finite_tuple(name, getattr(config, name), length=3))
    try:
        check_shared_fields(config)
    except ValueError as error:
        raise ConfigError(str(error)) from None
    for name in positive_fields:
        object.__setattr__(config, name, _positive_float(name, getattr(config, name)))
    windows = _finite_tuple("product_windows_s", config.product_windows_s, length=None)
    if not windows or min(windows) <= 0:
        raise ConfigError(f"product_windows_s must be positive window lengths, got {windows}")
    object.__setattr__(config, "product_windows_s", windows)
    frame_id = getattr(config, frame_field)
    if not isinstance(frame_id, str) or not frame_id.strip():
        raise ConfigError(f"{frame_field} must be a frame name, got {frame_id!r}")
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


def compensation_parameter_names() -> list[str]:
    """Every parameter ``compensation_node`` declares, the live-only one included."""
    names = config_parameters(CompensatorConfig, COMPENSATION_PARAMETER_PREFIX)
    return [parameter for _, parameter, _ in names] + [NAV_TIMEOUT_PARAMETER]


def current_parameter_names() -> list[str]:
    """Every parameter ``current_node`` declares, the live-only one included."""
    names = config_parameters(CurrentConfig, CURRENT_PARAMETER_PREFIX)
    return [parameter for _, parameter, _ in names] + [CURRENT_NAV_TIMEOUT_PARAMETER]
