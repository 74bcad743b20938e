"""Typed configuration of the wind compensation, live and offline.

:class:`CompensatorConfig` is a frozen dataclass with unit-suffixed field names, so that
``compensation_node`` declares one ROS parameter per field: ``compensation.<field>``, except the
shared extrinsic ones (interface contract), declared with their own names
(``anemometer.position``, ``anemometer.rpy_deg``). The offline tools build the same
configuration from the same parameter files (:func:`compensator_config_from_files`).
"""

import math
from dataclasses import dataclass

from buoy_common.contract import DEFAULT_PRODUCT_WINDOWS_S
from buoy_common.extrinsics import check_shared_fields, shared_field
from buoy_common.parameters import build_config, load_parameter_files

COMPENSATION_NODE_NAME = "compensation_node"
"""Node name whose parameter-file sections configure the compensation (live and offline)."""
COMPENSATION_PARAMETER_PREFIX = "compensation."
"""ROS parameter of a :class:`CompensatorConfig` field ``f``: ``compensation.f``, except the
shared ones."""


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
        max_attitude_sigma_deg: a navigation sample whose attitude 1σ (the largest of the
            three in its pose covariance) exceeds this corrects no wind: the samples it
            brackets are invalid as ``navigation_not_trusted``, deg. The fusion publishes its
            attitude 1σ at least ``fusion.integrity_attitude_sigma_deg`` (5°) while it finds
            itself inconsistent with its aiding, so this is how an untrustworthy navigation
            reaches the wind; the default lies between that and the 1σ a sound filter reports
            in the first second after its alignment (up to about 3°).
    """

    anemometer_position_body_m: tuple[float, float, float] = shared_field("anemometer.position")
    anemometer_rpy_deg: tuple[float, float, float] = shared_field("anemometer.rpy_deg")
    max_nav_gap_s: float = 0.1
    max_wind_speed_mps: float = 100.0
    nav_history_s: float = 10.0
    product_windows_s: tuple[float, ...] = DEFAULT_PRODUCT_WINDOWS_S
    gust_window_s: float = 3.0
    max_attitude_sigma_deg: float = 4.0

    def __post_init__(self):
        for name in ("anemometer_position_body_m", "anemometer_rpy_deg"):
            object.__setattr__(self, name, _finite_tuple(name, getattr(self, name), length=3))
        try:
            check_shared_fields(self)
        except ValueError as error:
            raise ConfigError(str(error)) from None
        for name in (
            "max_nav_gap_s",
            "max_wind_speed_mps",
            "nav_history_s",
            "gust_window_s",
            "max_attitude_sigma_deg",
        ):
            object.__setattr__(self, name, _positive_float(name, getattr(self, name)))
        windows = _finite_tuple("product_windows_s", self.product_windows_s, length=None)
        if not windows or min(windows) <= 0:
            raise ConfigError(f"product_windows_s must be positive window lengths, got {windows}")
        object.__setattr__(self, "product_windows_s", windows)
        if self.nav_history_s <= self.max_nav_gap_s:
            raise ConfigError(
                f"nav_history_s ({self.nav_history_s}) must exceed max_nav_gap_s "
                f"({self.max_nav_gap_s})"
            )
        if self.gust_window_s >= min(windows):
            raise ConfigError(
                f"gust_window_s ({self.gust_window_s}) must be shorter than every product window "
                f"{windows}"
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
    values = load_parameter_files(paths, COMPENSATION_NODE_NAME)
    return build_config(CompensatorConfig, values, prefix=COMPENSATION_PARAMETER_PREFIX)
