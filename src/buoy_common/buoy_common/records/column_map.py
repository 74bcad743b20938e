"""Column maps: how a logger's records become the contract's quantities.

A column map is a YAML file that says where each quantity sits in a record, in which unit, along
which axes, and which values mark an invalid sample. :func:`load_column_map` reads and checks
one; every problem is a :class:`MapError` whose message names the key.

Units come from an explicit table rather than a general units library: the loggers of this field
write ``g`` for standard gravity (a units library reads gram) and ``deg`` for angles and rates
alike, so each field accepts only the units of its own kind, and a unit outside that short list
is refused, naming the field and the units it takes.
"""

from __future__ import annotations

import datetime as dt
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import yaml

from buoy_common.extrinsics import SHARED_PARAMETERS
from buoy_common.records.screening import Screening, screen

STANDARD_GRAVITY_MPS2 = 9.80665
"""The ``g`` of accelerometer data sheets (CGPM 1901), m/s²."""

# unit as written in a map → (scale, offset) into the SI unit of the kind: si = value·scale + offset
UNITS: dict[str, dict[str, tuple[float, float]]] = {
    "velocity": {
        "m/s": (1.0, 0.0),
        "cm/s": (0.01, 0.0),
        "mm/s": (0.001, 0.0),
        "km/h": (1.0 / 3.6, 0.0),
        "kn": (1852.0 / 3600.0, 0.0),
    },
    "angular_rate": {
        "rad/s": (1.0, 0.0),
        "mrad/s": (1e-3, 0.0),
        "deg/s": (math.pi / 180.0, 0.0),
        "deg/h": (math.pi / 180.0 / 3600.0, 0.0),
    },
    "acceleration": {
        "m/s^2": (1.0, 0.0),
        "m/s2": (1.0, 0.0),
        "cm/s^2": (0.01, 0.0),
        "g": (STANDARD_GRAVITY_MPS2, 0.0),
        "mg": (STANDARD_GRAVITY_MPS2 * 1e-3, 0.0),
    },
    "angle": {"rad": (1.0, 0.0), "mrad": (1e-3, 0.0), "deg": (math.pi / 180.0, 0.0)},
    "temperature": {"degC": (1.0, 0.0), "K": (1.0, -273.15)},
    "time": {"s": (1.0, 0.0), "ms": (1e-3, 0.0), "us": (1e-6, 0.0), "ns": (1e-9, 0.0)},
}
"""Into m/s, rad/s, m/s², rad, °C (the contract's ``sensor_msgs/Temperature`` unit) and s."""

AXIS_DIRECTIONS = {
    "F": (1, 0, 0),
    "B": (-1, 0, 0),
    "L": (0, 1, 0),
    "R": (0, -1, 0),
    "U": (0, 0, 1),
    "D": (0, 0, -1),
}
"""Instrument axis letters as unit vectors of the body's forward-left-up axes (REP-103)."""

AHRS_CONVENTIONS = ("ned_zyx", "enu_zyx")
"""``ned_zyx``: roll, pitch, heading of a forward-right-down body in North-East-Down,
R = Rz(heading)·Ry(pitch)·Rx(roll), heading clockwise from north (aerospace, most motion
packs). ``enu_zyx``: roll, pitch, yaw of a forward-left-up body in East-North-Up, yaw
counter-clockwise from east (REP-103)."""

YAW_REFERENCE = SHARED_PARAMETERS["ahrs.yaw_reference"]
"""The map's ``ahrs.yaw_reference`` is the nodes' parameter of that name: the same choices and
default (a map and the nodes given none agree)."""
START_FROM_MAP = "column map"
START_FROM_COMMAND_LINE = "command line"
START_FROM_TIME_COLUMN = "time column"
"""Where a record's start came from: the map's ``time.start`` or ``time.epoch``, ``--start``,
or a time column of absolute (Unix) stamps."""
FORMATS = ("delimited", "binary")
FIELD_KEYS = frozenset({"column", "columns", "unit", "invalid", "fill", "valid_range"})
"""What a field's (or three fields') entry of a map may say."""
SPEED_OF_SOUND_TO_KELVIN_S2_M2 = 1.0 / 403.0
"""Sonic (virtual) temperature from the speed of sound c: T = c²/403 K (c in m/s; 403 m²/(s²K)
is γ·R_d of dry air, the constant sonic anemometers use)."""


class MapError(ValueError):
    """A column map is unusable or does not fit the record; the message names the problem."""


@dataclass(frozen=True)
class Field:
    """One scalar quantity of the record: where it is (1-based column number, or a field name
    of a binary layout), its unit as written, and the values that mark it missing (fill
    codes), flagged (invalid codes) or implausible (outside the valid range), all three in the
    record's own unit (:mod:`.screening`)."""

    name: str
    column: int | str
    kind: str
    unit: str
    invalid_values: tuple[float, ...] = ()
    valid_range: tuple[float, float] = (-math.inf, math.inf)
    fill_values: tuple[float, ...] = ()

    def screen(self, values: np.ndarray) -> Screening:
        """Which of ``values`` (record units) are not data, and why."""
        return screen(values, self.fill_values, self.invalid_values, self.valid_range)

    def to_si(self, values: np.ndarray) -> np.ndarray:
        """``values`` in the SI unit of the field's kind; fill codes, invalid codes and values
        outside the valid range as NaN."""
        values = np.asarray(values, dtype=float)
        scale, offset = UNITS[self.kind][self.unit]
        with np.errstate(invalid="ignore"):
            return np.where(self.screen(values).rejected, np.nan, values * scale + offset)


CALENDAR_PARTS = ("year", "month", "day", "hour", "minute", "second", "millisecond")
"""The parts of a stamp written as a calendar date and time of day (UTC), in order: each a
column; ``millisecond`` may be left out, and ``second`` may carry a fraction."""


@dataclass(frozen=True)
class TimeSpec:
    """Sample times: a stamp column (unit, epoch), a calendar date and time in parts, or a
    start time and a rate."""

    stamp: Field | None
    epoch_ns: int | None
    """What the record's time zero stands for, ns since the Unix epoch: the stamp column's
    epoch, or the first sample's time; None: not known yet (a record numbered by its rate
    whose map gives no start needs one on the command line)."""
    rate_hz: float
    start_source: str = START_FROM_MAP
    """Who said when the record starts: ``START_FROM_MAP``, ``START_FROM_COMMAND_LINE`` or
    ``START_FROM_TIME_COLUMN``."""
    calendar: tuple[Field, ...] = ()
    """The columns of the stamp's calendar parts (:data:`CALENDAR_PARTS`, named
    ``time.calendar.<part>``), when the record writes its stamps so."""


@dataclass(frozen=True)
class ColumnMap:
    path: Path
    format: str
    delimiter: str | None
    skip_lines: int
    column_count: int | None
    record_layout: np.dtype | None
    time: TimeSpec
    wind: tuple[Field, Field, Field] | None
    wind_axes: str
    sonic_temperature: Field | None
    speed_of_sound: Field | None
    angular_rate: tuple[Field, Field, Field] | None
    specific_force: tuple[Field, Field, Field] | None
    imu_axes: str
    ahrs_angles: tuple[Field, Field, Field] | None
    ahrs_convention: str
    ahrs_yaw_reference: str
    ahrs_sigma_rad: tuple[float, float, float]
    gravity_tolerance_mps2: float
    max_gyro_bias_rad_s: float
    site_deg: tuple[float, float] | None = None
    """(latitude, longitude) of the buoy, deg, when the map knows it."""
    description: str = ""

    def fields(self) -> list[Field]:
        groups = (self.wind, self.angular_rate, self.specific_force, self.ahrs_angles)
        singles = (self.time.stamp, self.sonic_temperature, self.speed_of_sound)
        return [
            *(f for group in groups if group for f in group),
            *(f for f in singles if f),
            *self.time.calendar,
        ]


def axes_to_body(axes: str, key: str) -> np.ndarray:
    """3×3 matrix taking a vector's components along an instrument's axes ``axes`` (three
    letters of F/B, L/R, U/D, e.g. ``FRD``) to forward-left-up components. Refuses a repeated
    direction or a left-handed set (MapError naming ``key``)."""
    if not isinstance(axes, str) or len(axes) != 3 or any(a not in AXIS_DIRECTIONS for a in axes):
        raise MapError(f"{key}: axes must be three letters of F, B, L, R, U, D, got {axes!r}")
    rows = np.array([AXIS_DIRECTIONS[a] for a in axes], dtype=float)
    determinant = np.linalg.det(rows)
    if abs(determinant) < 0.5:
        raise MapError(f"{key}: axes {axes!r} name one direction twice")
    if determinant < 0:
        raise MapError(f"{key}: axes {axes!r} are left-handed; a sensor's axes are right-handed")
    return rows.T


def _require_mapping(value, key: str) -> dict:
    if not isinstance(value, dict):
        raise MapError(f"{key}: expected a mapping, got {value!r}")
    return value


def _number(value, key: str) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise MapError(f"{key}: expected a number, got {value!r}")
    return float(value)


def _column(value, key: str, binary: bool) -> int | str:
    if isinstance(value, bool):
        raise MapError(f"{key}: a column is a number from 1 or a field name, got {value!r}")
    if isinstance(value, int) and value >= 1:
        return value
    if binary and isinstance(value, str) and value:
        return value
    raise MapError(f"{key}: a column is a number from 1 or a field name, got {value!r}")


def _field(spec, key: str, kind: str, binary: bool, column=None) -> Field:
    spec = _require_mapping(spec, key)
    unit = spec.get("unit")
    if unit not in UNITS[kind]:
        raise MapError(
            f"{key}: unit {unit!r} is not a unit of {kind.replace('_', ' ')} this map reader knows "
            f"(one of {', '.join(UNITS[kind])})"
        )
    if kind != "time":
        unknown = sorted(set(spec) - FIELD_KEYS)
        if unknown:
            raise MapError(f"{key}: unknown keys {', '.join(map(str, unknown))}")
    return Field(
        name=key,
        column=_column(spec.get("column") if column is None else column, f"{key}.column", binary),
        kind=kind,
        unit=unit,
        invalid_values=_codes(spec, "invalid", key),
        fill_values=_codes(spec, "fill", key),
        valid_range=_valid_range(spec, key),
    )


def _valid_range(spec: dict, key: str) -> tuple[float, float]:
    valid_range = spec.get("valid_range", [-math.inf, math.inf])
    if not isinstance(valid_range, list) or len(valid_range) != 2:
        raise MapError(f"{key}.valid_range: expected [low, high], got {valid_range!r}")
    low, high = (_number(bound, f"{key}.valid_range") for bound in valid_range)
    if not low < high:
        raise MapError(f"{key}.valid_range: low must be below high, got {valid_range!r}")
    return low, high


def _codes(spec: dict, name: str, key: str) -> tuple[float, ...]:
    """The codes (numbers, record units) under ``name`` of a field's spec: a list or one."""
    codes = spec.get(name, [])
    if not isinstance(codes, list):
        codes = [codes]
    return tuple(_number(code, f"{key}.{name}") for code in codes)


def _vector(spec, key: str, kind: str, binary: bool, labels=("x", "y", "z")) -> tuple:
    spec = _require_mapping(spec, key)
    columns = spec.get("columns")
    if not isinstance(columns, list) or len(columns) != 3:
        raise MapError(f"{key}.columns: expected three columns, got {columns!r}")
    return tuple(
        _field(spec, f"{key}.{label}", kind, binary, column)
        for label, column in zip(labels, columns, strict=True)
    )


def iso8601_ns(value, key: str) -> int:
    """An ISO 8601 time (UTC unless it says otherwise) as nanoseconds since the Unix epoch."""
    if isinstance(value, dt.datetime):
        when = value
    else:
        try:
            when = dt.datetime.fromisoformat(str(value).replace("Z", "+00:00"))
        except ValueError as error:
            raise MapError(f"{key}: not an ISO 8601 time: {value!r}") from error
    if when.tzinfo is None:
        when = when.replace(tzinfo=dt.UTC)
    since_epoch = when - dt.datetime(1970, 1, 1, tzinfo=dt.UTC)
    return (since_epoch // dt.timedelta(microseconds=1)) * 1000


def _calendar(spec, binary: bool) -> tuple[Field, ...]:
    """The columns of a stamp's calendar parts (MapError naming a missing or unknown part)."""
    spec = _require_mapping(spec, "time.calendar")
    unknown = sorted(set(spec) - set(CALENDAR_PARTS))
    if unknown:
        raise MapError(
            f"time.calendar: unknown parts {', '.join(map(str, unknown))} (the parts are "
            f"{', '.join(CALENDAR_PARTS)})"
        )
    missing = [part for part in CALENDAR_PARTS[:-1] if part not in spec]
    if missing:
        raise MapError(f"time.calendar: give the column of {', '.join(missing)}")
    return tuple(
        Field(
            f"time.calendar.{part}",
            _column(spec[part], f"time.calendar.{part}", binary),
            "calendar",
            "",
        )
        for part in CALENDAR_PARTS
        if part in spec
    )


def _time(spec, binary: bool) -> TimeSpec:
    spec = _require_mapping(spec, "time")
    if "calendar" in spec:
        # Absolute stamps, as a time column of Unix stamps: its epoch is 1970.
        return TimeSpec(
            None, 0, math.nan, START_FROM_TIME_COLUMN, _calendar(spec["calendar"], binary)
        )
    if "column" in spec:
        stamp = _field(spec, "time", "time", binary)
        if "epoch" not in spec:
            return TimeSpec(stamp, 0, math.nan, START_FROM_TIME_COLUMN)
        return TimeSpec(stamp, iso8601_ns(spec["epoch"], "time.epoch"), math.nan, START_FROM_MAP)
    if "rate_hz" not in spec:
        raise MapError(
            "time: give a column (with unit and epoch), the calendar parts' columns, or rate_hz "
            "(and start)"
        )
    rate_hz = _number(spec["rate_hz"], "time.rate_hz")
    if not rate_hz > 0:
        raise MapError(f"time.rate_hz: must be positive, got {rate_hz}")
    start = iso8601_ns(spec["start"], "time.start") if "start" in spec else None
    return TimeSpec(stamp=None, epoch_ns=start, rate_hz=rate_hz)


def site_of(spec, key: str) -> tuple[float, float] | None:
    """(latitude, longitude), deg, of a ``{latitude_deg, longitude_deg}`` mapping, held to the
    rules of the nodes' ``site.*`` parameters; None for None. MapError naming ``key``."""
    if spec is None:
        return None
    spec = _require_mapping(spec, key)
    if set(spec) != {"latitude_deg", "longitude_deg"}:
        raise MapError(f"{key}: give latitude_deg and longitude_deg, got {sorted(spec)}")
    site = []
    for name in ("latitude_deg", "longitude_deg"):
        value = _number(spec[name], f"{key}.{name}")
        rule = SHARED_PARAMETERS[f"site.{name}"]
        if math.isnan(value) or rule.check(value) is not None:
            raise MapError(f"{key}.{name}: {rule.rule.split(' or NaN')[0]}, got {value!r}")
        site.append(value)
    return site[0], site[1]


def _layout(spec) -> np.dtype:
    if not isinstance(spec, list) or not spec:
        raise MapError("record_layout: expected a list of [name, type] pairs")
    try:
        return np.dtype([(str(name), str(kind)) for name, kind in spec])
    except (TypeError, ValueError) as error:
        raise MapError(f"record_layout: not a record layout: {error}") from error


def load_column_map(path: str | Path) -> ColumnMap:
    """Read and check a column map (YAML); MapError naming the key of the first problem."""
    path = Path(path)
    document = _read_document(path)
    file_format, layout, column_count = _record_format(document)
    binary = file_format == "binary"
    anemometer = _anemometer_fields(document, binary)
    imu = _imu_fields(document, binary)
    ahrs = _ahrs_fields(document, binary)
    checks = _require_mapping(document.get("checks", {}), "checks")
    column_map = ColumnMap(
        path=path,
        format=file_format,
        delimiter=document.get("delimiter"),
        skip_lines=int(document.get("skip_lines", 0)),
        column_count=column_count,
        record_layout=layout,
        time=_time(document.get("time"), binary),
        **anemometer,
        **imu,
        **ahrs,
        **_check_limits(checks),
        site_deg=site_of(document.get("site"), "site"),
        description=str(document.get("description", "")),
    )
    _check_consistency(column_map)
    return column_map


def _read_document(path: Path) -> dict:
    """The column map's YAML document, with no key the map does not know."""
    try:
        document = yaml.safe_load(path.read_text("utf8"))
    except OSError as error:
        raise MapError(f"column map {path}: cannot read: {error.strerror}") from error
    except yaml.YAMLError as error:
        raise MapError(f"column map {path}: not YAML: {str(error).splitlines()[0]}") from error
    document = _require_mapping(document, f"column map {path}")
    known = {"format", "delimiter", "skip_lines", "columns", "record_layout", "time"}
    known |= {"anemometer", "imu", "ahrs", "checks", "description", "site"}
    unknown = sorted(set(document) - known)
    if unknown:
        raise MapError(f"column map {path}: unknown keys {', '.join(unknown)}")
    return document


def _record_format(document: dict) -> tuple[str, np.dtype | None, int | None]:
    """(format, binary record layout or None, number of columns of every row or None)."""
    file_format = document.get("format", "delimited")
    if file_format not in FORMATS:
        raise MapError(f"format: one of {', '.join(FORMATS)}, got {file_format!r}")
    layout = _layout(document.get("record_layout")) if file_format == "binary" else None
    column_count = document.get("columns")
    if column_count is not None and (not isinstance(column_count, int) or column_count < 1):
        raise MapError(f"columns: the number of columns of every row, got {column_count!r}")
    return file_format, layout, column_count


def _anemometer_fields(document: dict, binary: bool) -> dict:
    """The anemometer's fields of :class:`ColumnMap`: wind, its axes, sonic temperature or
    speed of sound."""
    anemometer = _require_mapping(document.get("anemometer", {}), "anemometer")
    wind = None
    if "u" in anemometer:
        wind = tuple(
            _field(anemometer[c], f"anemometer.{c}", "velocity", binary) for c in ("u", "v", "w")
        )
    wind_axes = anemometer.get("axes", "FLU")
    axes_to_body(wind_axes, "anemometer.axes")
    temperature = speed_of_sound = None
    if "temperature" in anemometer:
        temperature = _field(
            anemometer["temperature"], "anemometer.temperature", "temperature", binary
        )
    if "speed_of_sound" in anemometer:
        speed_of_sound = _field(
            anemometer["speed_of_sound"], "anemometer.speed_of_sound", "velocity", binary
        )
    return {
        "wind": wind,
        "wind_axes": wind_axes,
        "sonic_temperature": temperature,
        "speed_of_sound": speed_of_sound,
    }


def _imu_fields(document: dict, binary: bool) -> dict:
    """The IMU's fields of :class:`ColumnMap`: angular rate, specific force, their axes."""
    imu = _require_mapping(document.get("imu", {}), "imu")
    rate = (
        _vector(imu["angular_rate"], "imu.angular_rate", "angular_rate", binary)
        if "angular_rate" in imu
        else None
    )
    force = (
        _vector(imu["specific_force"], "imu.specific_force", "acceleration", binary)
        if "specific_force" in imu
        else None
    )
    imu_axes = imu.get("axes", "FLU")
    axes_to_body(imu_axes, "imu.axes")
    return {"angular_rate": rate, "specific_force": force, "imu_axes": imu_axes}


def _ahrs_fields(document: dict, binary: bool) -> dict:
    """The motion pack's fields of :class:`ColumnMap`: its angles, their convention and yaw
    reference, and their standard deviations (rad)."""
    ahrs = _require_mapping(document.get("ahrs", {}), "ahrs")
    angles = None
    if "roll" in ahrs:
        angles = tuple(
            _field(ahrs.get(a), f"ahrs.{a}", "angle", binary) for a in ("roll", "pitch", "heading")
        )
    convention = ahrs.get("convention", "ned_zyx")
    if convention not in AHRS_CONVENTIONS:
        raise MapError(f"ahrs.convention: one of {', '.join(AHRS_CONVENTIONS)}, got {convention!r}")
    yaw_reference = ahrs.get("yaw_reference", YAW_REFERENCE.default)
    if YAW_REFERENCE.check(yaw_reference) is not None:
        raise MapError(f"ahrs.yaw_reference: {YAW_REFERENCE.rule}, got {yaw_reference!r}")
    sigma = ahrs.get("sigma_deg", [1.0, 1.0, 5.0])
    if not isinstance(sigma, list) or len(sigma) != 3:
        raise MapError(f"ahrs.sigma_deg: expected [roll, pitch, yaw] in deg, got {sigma!r}")
    sigma_rad = tuple(math.radians(_number(s, "ahrs.sigma_deg")) for s in sigma)
    if not all(s > 0 for s in sigma_rad):
        raise MapError(f"ahrs.sigma_deg: must be positive, got {sigma!r}")
    return {
        "ahrs_angles": angles,
        "ahrs_convention": convention,
        "ahrs_yaw_reference": yaw_reference,
        "ahrs_sigma_rad": sigma_rad,
    }


def _check_limits(checks: dict) -> dict:
    """The limits of the record's checks, of :class:`ColumnMap` (SI units)."""
    return {
        "gravity_tolerance_mps2": _number(
            checks.get("gravity_tolerance_mps2", 0.5), "checks.gravity_tolerance_mps2"
        ),
        "max_gyro_bias_rad_s": math.radians(
            _number(checks.get("max_gyro_bias_deg_s", 1.0), "checks.max_gyro_bias_deg_s")
        ),
    }


def _check_consistency(column_map: ColumnMap) -> None:
    """MapError when the map's parts do not go together."""
    wind, rate = column_map.wind, column_map.angular_rate
    if wind is None and rate is None:
        raise MapError(f"column map {column_map.path}: maps neither the anemometer nor the IMU")
    if (rate is None) != (column_map.specific_force is None):
        raise MapError("imu: give both angular_rate and specific_force")
    if column_map.ahrs_angles is not None and rate is None:
        raise MapError("ahrs: the motion pack's attitude needs imu.angular_rate and specific_force")
    if column_map.sonic_temperature is not None and column_map.speed_of_sound is not None:
        raise MapError("anemometer: give temperature or speed_of_sound, not both")
    if column_map.record_layout is not None:
        names = set(column_map.record_layout.names)
        for field in column_map.fields():
            if isinstance(field.column, str) and field.column not in names:
                raise MapError(f"{field.name}: field {field.column!r} is not in record_layout")
