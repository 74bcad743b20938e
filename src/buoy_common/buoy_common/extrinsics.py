"""The parameters every node shares (interface contract): where the sensors sit and the map origin.

Each shared parameter is declared once here, with its default and one validity rule. The
configuration dataclasses of the simulator, the filter and the compensation take their fields
from here with :func:`shared_field` and call :func:`check_shared_fields` after their own
coercion, so a value that one node accepts every node accepts, and the error names the parameter.

Rules that relate two parameters (the antenna separation, the origin given all or not at all)
are part of the rule of the second one and apply when a configuration holds both.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

MIN_ANTENNA_SEPARATION_M = 0.1
"""Closest two GNSS antennas may be: a few mm of carrier-phase baseline noise on a shorter
baseline is more than a degree of attitude."""
MIN_TERTIARY_BASELINE_ANGLE_DEG = 10.0
"""Smallest angle between the primary → secondary and primary → tertiary baselines for the third
antenna to be used: below it the two baselines observe nearly the same direction and the
rotation about it, the reason for a third antenna, is lost in their noise (at 10° a rotation
about the first baseline moves the second by a sixth of what it would at 90°)."""
MAX_LEVER_ARM_M = 100.0
"""Farthest a sensor may sit from ``base_link``: anything larger is a unit or sign mistake."""

PARAMETER_METADATA_KEY = "parameter"


@dataclass(frozen=True)
class SharedParameter:
    """One shared parameter: its ROS name, default, unit, meaning and validity rule.

    ``check(value)`` returns None for a valid value, or the expectation it misses ("three
    finite numbers within 100 m"); ``rule`` says the same for the reader.
    """

    name: str
    default: Any
    meaning: str
    check: Callable[[Any], str | None]
    unit: str = ""
    rule: str = ""


def _position_in_body(value) -> str | None:
    if len(value) != 3 or not all(math.isfinite(c) for c in value):
        return "three finite numbers (m)"
    if math.hypot(*value) > MAX_LEVER_ARM_M:
        return f"within {MAX_LEVER_ARM_M:g} m of base_link"
    return None


def _optional_position_in_body(value) -> str | None:
    if len(value) == 3 and all(math.isnan(c) for c in value):
        return None
    problem = _position_in_body(value)
    return None if problem is None else f"{problem}, or three NaN (no such antenna)"


def _mounting_angles(value) -> str | None:
    if len(value) != 3 or not all(math.isfinite(c) for c in value):
        return "three finite numbers (deg)"
    roll, pitch, yaw = value
    if abs(roll) > 180.0 or abs(pitch) > 90.0 or abs(yaw) > 180.0:
        return "roll and yaw within ±180°, pitch within ±90°"
    return None


def _latitude(value) -> str | None:
    return None if math.isnan(value) or abs(value) < 90.0 else "in (−90, 90) or NaN"


def _longitude(value) -> str | None:
    return None if math.isnan(value) or abs(value) <= 180.0 else "in [−180, 180] or NaN"


def _altitude(value) -> str | None:
    return None if math.isnan(value) or abs(value) < 1.0e5 else "within ±100 km or NaN"


def _declination(value) -> str | None:
    return None if math.isnan(value) or abs(value) <= 180.0 else "within ±180° or NaN"


YAW_REFERENCES = ("true_north", "magnetic_north")
"""What the yaw of ``imu/data`` may be referenced to (parameter ``ahrs.yaw_reference``)."""


def _yaw_reference(value) -> str | None:
    return None if value in YAW_REFERENCES else f"one of {', '.join(YAW_REFERENCES)}"


_NAN = math.nan

_WITHIN_LEVER_ARM = f"three finite numbers within {MAX_LEVER_ARM_M:g} m of base_link"
_MOUNTING_ANGLES = "roll and yaw within ±180°, pitch within ±90°"

SHARED_PARAMETERS: dict[str, SharedParameter] = {
    parameter.name: parameter
    for parameter in (
        SharedParameter(
            "gnss.primary_antenna",
            (-0.75, 0.0, 1.0),
            "primary antenna phase centre in base_link",
            _position_in_body,
            unit="m",
            rule=_WITHIN_LEVER_ARM,
        ),
        SharedParameter(
            "gnss.secondary_antenna",
            (0.75, 0.0, 1.0),
            "secondary antenna phase centre in base_link",
            _position_in_body,
            unit="m",
            rule=_WITHIN_LEVER_ARM + f", at least {MIN_ANTENNA_SEPARATION_M:g} m from the primary",
        ),
        SharedParameter(
            "gnss.tertiary_antenna",
            (_NAN, _NAN, _NAN),
            "third antenna phase centre in base_link (with gnss/baseline_tertiary); NaN: none",
            _optional_position_in_body,
            unit="m",
            rule=_WITHIN_LEVER_ARM
            + f", at least {MIN_ANTENNA_SEPARATION_M:g} m from the other two; or NaN",
        ),
        SharedParameter(
            "anemometer.position",
            (0.0, 0.0, 3.0),
            "anemometer measurement centre in base_link (Miller's lever arm B)",
            _position_in_body,
            unit="m",
            rule=_WITHIN_LEVER_ARM,
        ),
        SharedParameter(
            "anemometer.rpy_deg",
            (0.0, 0.0, 0.0),
            "roll, pitch, yaw of anemometer_link in base_link, R = Rz(yaw)·Ry(pitch)·Rx(roll)",
            _mounting_angles,
            unit="deg",
            rule=_MOUNTING_ANGLES,
        ),
        SharedParameter(
            "dvl.position",
            (0.0, 0.0, -2.0),
            "DVL measurement centre in base_link",
            _position_in_body,
            unit="m",
            rule=_WITHIN_LEVER_ARM,
        ),
        SharedParameter(
            "dvl.rpy_deg",
            (0.0, 0.0, 0.0),
            "roll, pitch, yaw of dvl_link in base_link, R = Rz(yaw)·Ry(pitch)·Rx(roll)",
            _mounting_angles,
            unit="deg",
            rule=_MOUNTING_ANGLES,
        ),
        SharedParameter(
            "origin.latitude_deg",
            _NAN,
            "latitude of the map origin; NaN: first fix",
            _latitude,
            unit="deg",
            rule="in (−90, 90) or NaN; the three origin.* all set or all NaN",
        ),
        SharedParameter(
            "origin.longitude_deg",
            _NAN,
            "longitude of the map origin; NaN: first fix",
            _longitude,
            unit="deg",
            rule="in [−180, 180] or NaN",
        ),
        SharedParameter(
            "origin.altitude_m",
            _NAN,
            "ellipsoidal altitude of the map origin; NaN: first fix",
            _altitude,
            unit="m",
            rule="within ±100 km or NaN",
        ),
        SharedParameter(
            "ahrs.yaw_reference",
            "true_north",
            "what the yaw of imu/data is referenced to",
            _yaw_reference,
            unit="",
            rule=f"one of {', '.join(YAW_REFERENCES)}",
        ),
        SharedParameter(
            "magnetic.declination_deg",
            _NAN,
            "magnetic declination at the site, east positive; NaN: geomagnetic model",
            _declination,
            unit="deg",
            rule="within ±180° or NaN",
        ),
        SharedParameter(
            "site.latitude_deg",
            _NAN,
            "latitude of the site when there is no GNSS fix (gravity, Earth rate, declination); "
            "NaN: origin.latitude_deg",
            _latitude,
            unit="deg",
            rule="in (−90, 90) or NaN; set whenever site.longitude_deg is",
        ),
        SharedParameter(
            "site.longitude_deg",
            _NAN,
            "longitude of the site when there is no GNSS fix; NaN: origin.longitude_deg, else "
            "unknown (site.latitude_deg alone serves gravity and Earth rate, and then "
            "magnetic.declination_deg must be a number)",
            _longitude,
            unit="deg",
            rule="in [−180, 180] or NaN",
        ),
    )
}
"""Every shared parameter, by ROS name."""

ORIGIN_PARAMETERS = ("origin.latitude_deg", "origin.longitude_deg", "origin.altitude_m")
SITE_PARAMETERS = ("site.latitude_deg", "site.longitude_deg")


def shared_field(parameter: str) -> Any:
    """A dataclass field backed by the shared ``parameter``, with its default."""
    default = SHARED_PARAMETERS[parameter].default
    return dataclasses.field(default=default, metadata={PARAMETER_METADATA_KEY: parameter})


def field_parameter(field: dataclasses.Field) -> str | None:
    """The shared parameter behind a configuration field, None for a field of its own."""
    return field.metadata.get(PARAMETER_METADATA_KEY)


def describe_shared_fields(config) -> str:
    """The shared parameters a configuration holds, as ``name=value`` pairs for the line every
    tool prints at start (the lever arms and mounting actually used)."""
    pairs = []
    for field in dataclasses.fields(config):
        parameter = field_parameter(field)
        if parameter is None:
            continue
        value = getattr(config, field.name)
        shown = f"[{', '.join(f'{c:g}' for c in value)}]" if isinstance(value, tuple) else value
        pairs.append(f"{parameter}={shown}")
    return ", ".join(pairs)


def check_shared_fields(config) -> None:
    """Apply the rule of every shared parameter a configuration holds; ValueError naming the
    first parameter whose value breaks its rule."""
    values = {
        parameter: getattr(config, field.name)
        for field in dataclasses.fields(config)
        if (parameter := field_parameter(field)) is not None
    }
    for parameter, value in values.items():
        expectation = SHARED_PARAMETERS[parameter].check(value)
        if expectation is not None:
            raise ValueError(f"parameter '{parameter}' must be {expectation}, got {value!r}")
    _check_antenna_separation(values)
    _check_tertiary_antenna_separation(values)
    _check_origin_complete(values)
    _check_site_complete(values)


def _check_antenna_separation(values: dict[str, Any]) -> None:
    if "gnss.primary_antenna" not in values or "gnss.secondary_antenna" not in values:
        return
    separation = math.dist(values["gnss.primary_antenna"], values["gnss.secondary_antenna"])
    if separation < MIN_ANTENNA_SEPARATION_M:
        raise ValueError(
            f"parameter 'gnss.secondary_antenna' must be at least {MIN_ANTENNA_SEPARATION_M} m "
            f"from 'gnss.primary_antenna', got {separation:.3f} m"
        )


def tertiary_baseline_angle_deg(primary, secondary, tertiary) -> float:
    """Angle (deg, 0 to 90) between the primary → secondary and primary → tertiary baselines.

    Below :data:`MIN_TERTIARY_BASELINE_ANGLE_DEG` the layout is near-collinear: the fusion does
    not use the third antenna (a valid configuration, reported, not an error)."""
    first = [s - p for s, p in zip(secondary, primary, strict=True)]
    second = [t - p for t, p in zip(tertiary, primary, strict=True)]
    cross = (
        first[1] * second[2] - first[2] * second[1],
        first[2] * second[0] - first[0] * second[2],
        first[0] * second[1] - first[1] * second[0],
    )
    sine = math.hypot(*cross) / (math.hypot(*first) * math.hypot(*second))
    return math.degrees(math.asin(min(1.0, sine)))


def _check_tertiary_antenna_separation(values: dict[str, Any]) -> None:
    tertiary = values.get("gnss.tertiary_antenna")
    if tertiary is None or any(math.isnan(c) for c in tertiary):
        return
    for name in ("gnss.primary_antenna", "gnss.secondary_antenna"):
        if name not in values:
            continue
        separation = math.dist(tertiary, values[name])
        if separation < MIN_ANTENNA_SEPARATION_M:
            raise ValueError(
                f"parameter 'gnss.tertiary_antenna' must be at least {MIN_ANTENNA_SEPARATION_M} "
                f"m from '{name}', got {separation:.3f} m"
            )


def _check_origin_complete(values: dict[str, Any]) -> None:
    given = [name for name in ORIGIN_PARAMETERS if name in values]
    unset = [name for name in given if math.isnan(values[name])]
    if unset and len(unset) != len(given):
        raise ValueError(
            f"parameter '{unset[0]}': origin.latitude_deg, origin.longitude_deg and "
            "origin.altitude_m must be all set or all NaN"
        )


def _check_site_complete(values: dict[str, Any]) -> None:
    """A site's latitude alone is a fact (gravity and Earth rate need no more); its longitude
    alone is none."""
    latitude, longitude = (values.get(name, math.nan) for name in SITE_PARAMETERS)
    if math.isnan(latitude) and not math.isnan(longitude):
        raise ValueError(
            "parameter 'site.latitude_deg': NaN while site.longitude_deg is set; a site's "
            "longitude needs its latitude"
        )
