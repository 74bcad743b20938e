"""Logger records → the contract's quantities, in SI units and the contract's frames.

:func:`read_table` reads a delimited-text or fixed-layout binary file into one float column per
mapped field, refusing a file that does not fit its map; :func:`decode` applies units, axes and
invalid-value codes and returns :class:`ContractSamples`; :func:`plausibility_warnings` says
what looks physically wrong after that (gravity, gyro bias), which is usually a wrong unit or
axis in the map.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

from buoy_common.records.column_map import (
    CALENDAR_PARTS,
    SPEED_OF_SOUND_TO_KELVIN_S2_M2,
    STANDARD_GRAVITY_MPS2,
    ColumnMap,
    Field,
    MapError,
    axes_to_body,
)
from buoy_common.records.screening import FieldCounts

ENU_FROM_NED = np.array([[0.0, 1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, -1.0]])
FRD_FROM_FLU = np.diag([1.0, -1.0, -1.0])


@dataclass
class ContractSamples:
    """One record as the contract carries it. Arrays of N samples; NaN where invalid.

    ``wind_mps`` is in the anemometer's axes made forward-left-up (``anemometer_link``);
    ``angular_rate_rad_s`` and ``specific_force_mps2`` in ``imu_link`` (forward-left-up,
    +9.8 m/s² on z when level and still, REP-145); ``orientation_xyzw`` rotates ``imu_link``
    vectors into East-North-Up, yaw referenced as ``yaw_reference`` says.
    """

    time_ns: np.ndarray
    """int64 header stamps, ns since the Unix epoch."""
    wind_mps: np.ndarray | None
    sonic_temperature_degc: np.ndarray | None
    angular_rate_rad_s: np.ndarray | None
    specific_force_mps2: np.ndarray | None
    orientation_xyzw: np.ndarray | None
    orientation_sigma_rad: tuple[float, float, float]
    yaw_reference: str
    field_counts: dict[str, FieldCounts] = field(default_factory=dict)
    """How each field of the map was screened (:mod:`.screening`), by field name."""
    temperatures_without_wind: int = 0
    """Sonic temperatures set invalid because their sample's wind is invalid."""

    def __len__(self) -> int:
        return self.time_ns.size


def _column_index(field: Field, column_count: int) -> int:
    if field.column > column_count:
        raise MapError(
            f"{field.name}: the map reads column {field.column}, the file has only "
            f"{column_count} columns"
        )
    return field.column - 1


def _read_delimited(path: Path, column_map: ColumnMap) -> tuple[np.ndarray, int]:
    try:
        lines = path.read_text("utf8", errors="replace").splitlines()
    except OSError as error:
        raise MapError(f"record {path}: cannot read: {error.strerror}") from error
    numbered = [
        (number, line)
        for number, line in enumerate(lines, start=1)
        if number > column_map.skip_lines and line.strip()
    ]
    if not numbered:
        raise MapError(f"record {path}: no data rows (empty file)")
    rows = [line.split(column_map.delimiter) for _, line in numbered]
    expected = column_map.column_count or len(rows[0])
    for (number, _), row in zip(numbered, rows, strict=True):
        if len(row) != expected:
            what = "the map says" if column_map.column_count else "the first row has"
            raise MapError(
                f"record {path} line {number}: {len(row)} columns, {what} {expected} "
                f"(column map {column_map.path.name}, delimiter {column_map.delimiter!r})"
            )
    try:
        return np.array(rows, dtype=float), expected
    except ValueError:
        for (number, _), row in zip(numbered, rows, strict=True):
            for index, text in enumerate(row, start=1):
                try:
                    float(text)
                except ValueError:
                    raise MapError(
                        f"record {path} line {number} column {index}: not a number: {text!r}"
                    ) from None
        raise


def _read_binary(path: Path, layout: np.dtype) -> np.ndarray:
    try:
        size = path.stat().st_size
    except OSError as error:
        raise MapError(f"record {path}: cannot read: {error.strerror}") from error
    if size == 0:
        raise MapError(f"record {path}: no records (empty file)")
    if size % layout.itemsize:
        raise MapError(
            f"record {path}: {size} bytes is not a whole number of {layout.itemsize}-byte "
            f"records of the map's record_layout"
        )
    return np.fromfile(path, dtype=layout)


def read_table(path: str | Path, column_map: ColumnMap) -> dict[str, np.ndarray]:
    """The raw values (record units) of every mapped field, by field name. MapError when the
    file is empty, a row has another number of columns, a value is not a number, or the map
    reads a column the file does not have."""
    path = Path(path)
    if column_map.format == "binary":
        records = _read_binary(path, column_map.record_layout)
        names = column_map.record_layout.names
        table = {}
        for field in column_map.fields():
            name = field.column
            if isinstance(name, int):
                name = names[_column_index(field, len(names))]
            table[field.name] = records[name].astype(float)
        return table
    values, column_count = _read_delimited(path, column_map)
    return {
        field.name: values[:, _column_index(field, column_count)] for field in column_map.fields()
    }


def _vector_si(table, fields, axes: str, key: str) -> np.ndarray:
    """(N, 3) SI values of three fields, turned from the instrument's axes into forward-left-up;
    a sample with any invalid component is NaN in all three (the contract's invalid sample)."""
    vector = np.column_stack([field.to_si(table[field.name]) for field in fields])
    vector = vector @ axes_to_body(axes, key).T
    vector[~np.all(np.isfinite(vector), axis=1)] = np.nan
    return vector


def orientation_enu_flu(angles_rad: np.ndarray, convention: str) -> np.ndarray:
    """(N, 4) quaternions (x, y, z, w) rotating forward-left-up body vectors into East-North-Up,
    from (N, 3) Euler angles (roll, pitch, heading or yaw; rad) of ``convention``; NaN rows
    where an angle is invalid."""
    valid = np.all(np.isfinite(angles_rad), axis=1)
    quaternions = np.full((angles_rad.shape[0], 4), np.nan)
    if not valid.any():
        return quaternions
    # scipy's intrinsic "ZYX" with (yaw, pitch, roll) is R = Rz(yaw)·Ry(pitch)·Rx(roll)
    zyx = Rotation.from_euler("ZYX", angles_rad[valid][:, ::-1])
    if convention == "ned_zyx":
        rotation = Rotation.from_matrix(ENU_FROM_NED) * zyx * Rotation.from_matrix(FRD_FROM_FLU)
    else:
        rotation = zyx
    quaternions[valid] = rotation.as_quat()
    return quaternions


def sample_times_ns(table, column_map: ColumnMap, count: int) -> np.ndarray:
    """Nanoseconds since the Unix epoch of each sample (integers: float seconds since 1970
    resolve only a quarter of a microsecond)."""
    spec = column_map.time
    if spec.epoch_ns is None:
        raise MapError(
            "time: the record carries no time and the map gives no start: give the record's "
            "start, e.g. --start 2014-12-18T00:00:00Z"
        )
    if spec.calendar:
        return spec.epoch_ns + calendar_times_ns(table, spec.calendar)
    if spec.stamp is not None:
        offsets_s = spec.stamp.to_si(table[spec.stamp.name])
    else:
        offsets_s = np.arange(count) / spec.rate_hz
    if not np.isfinite(offsets_s).all():
        raise MapError(
            f"time: {np.count_nonzero(~np.isfinite(offsets_s))} samples have no valid time"
        )
    return spec.epoch_ns + np.round(offsets_s * 1e9).astype(np.int64)


def calendar_times_ns(table, parts) -> np.ndarray:
    """Nanoseconds since the Unix epoch of stamps written as a calendar date and time of day,
    UTC (``parts``: the fields of :data:`~.column_map.CALENDAR_PARTS` the map gives). MapError
    naming the first sample whose parts are no date and time (a month 13, a 31 April, a
    fractional day)."""
    values = {field.name.rsplit(".", 1)[1]: table[field.name] for field in parts}
    year, month, day, hour, minute, second = (values[part] for part in CALENDAR_PARTS[:-1])
    millisecond = values.get("millisecond", np.zeros_like(second))
    whole = np.stack([year, month, day, hour, minute])
    with np.errstate(invalid="ignore"):
        valid = (
            np.all(np.isfinite(whole) & (whole == np.round(whole)), axis=0)
            & (month >= 1) & (month <= 12) & (day >= 1) & (day <= 31)
            & (hour >= 0) & (hour < 24) & (minute >= 0) & (minute < 60)
            & (second >= 0) & (second < 61) & (millisecond >= 0) & (millisecond < 1000)
        )  # fmt: skip
    months = np.full(year.shape, np.datetime64("NaT", "M"))
    since_1970 = (year[valid] - 1970) * 12 + month[valid] - 1
    months[valid] = since_1970.astype(np.int64).astype("datetime64[M]")
    days = months.astype("datetime64[D]") + np.where(valid, day - 1, 0).astype(np.int64)
    valid &= days.astype("datetime64[M]") == months
    if not valid.all():
        first = int(np.flatnonzero(~valid)[0])
        raise MapError(
            f"time: {np.count_nonzero(~valid)} samples have no valid calendar time, the first "
            f"sample {first + 1} ({', '.join(f'{p} {values[p][first]:g}' for p in values)})"
        )
    seconds = hour * 3600.0 + minute * 60.0 + second
    return days.astype("datetime64[ns]").astype(np.int64) + np.round(
        seconds * 1e9 + millisecond * 1e6
    ).astype(np.int64)


def decode(table: dict[str, np.ndarray], column_map: ColumnMap) -> ContractSamples:
    """Units, axes, conventions and invalid codes applied: the record as the contract has it."""
    count = len(next(iter(table.values())))
    wind = rate = force = orientation = None
    if column_map.wind is not None:
        wind = _vector_si(table, column_map.wind, column_map.wind_axes, "anemometer.axes")
    temperature = sonic_temperature_degc(table, column_map)
    temperatures_without_wind = 0
    if temperature is not None and wind is not None:
        # One sonic measurement gives both from the same transit times: a sample whose wind
        # the sonic did not deliver has no temperature either.
        without_wind = np.isnan(wind[:, 0]) & np.isfinite(temperature)
        temperatures_without_wind = int(np.count_nonzero(without_wind))
        temperature[without_wind] = np.nan
    if column_map.angular_rate is not None:
        rate = _vector_si(table, column_map.angular_rate, column_map.imu_axes, "imu.axes")
        force = _vector_si(table, column_map.specific_force, column_map.imu_axes, "imu.axes")
        invalid = ~(np.isfinite(rate[:, 0]) & np.isfinite(force[:, 0]))
        rate[invalid] = np.nan
        force[invalid] = np.nan
    if column_map.ahrs_angles is not None:
        angles = np.column_stack([f.to_si(table[f.name]) for f in column_map.ahrs_angles])
        orientation = orientation_enu_flu(angles, column_map.ahrs_convention)
    return ContractSamples(
        time_ns=sample_times_ns(table, column_map, count),
        wind_mps=wind,
        sonic_temperature_degc=temperature,
        angular_rate_rad_s=rate,
        specific_force_mps2=force,
        orientation_xyzw=orientation,
        orientation_sigma_rad=column_map.ahrs_sigma_rad,
        yaw_reference=column_map.ahrs_yaw_reference,
        field_counts={f.name: f.screen(table[f.name]).counts() for f in column_map.fields()},
        temperatures_without_wind=temperatures_without_wind,
    )


def sonic_temperature_degc(table, column_map: ColumnMap) -> np.ndarray | None:
    """The sonic temperature, °C, from the map's temperature or speed-of-sound field (None when
    it maps neither)."""
    if column_map.sonic_temperature is not None:
        temperature_field = column_map.sonic_temperature
        return temperature_field.to_si(table[temperature_field.name])
    if column_map.speed_of_sound is not None:
        speed_field = column_map.speed_of_sound
        speed_mps = speed_field.to_si(table[speed_field.name])
        return speed_mps**2 * SPEED_OF_SOUND_TO_KELVIN_S2_M2 - 273.15
    return None


def plausibility_warnings(samples: ContractSamples, column_map: ColumnMap) -> list[str]:
    """What looks physically wrong in the decoded record, one sentence each (empty: nothing).

    Gravity: the mean specific force of a buoy is gravity, so its magnitude must be near
    9.8 m/s² and it must point up (+z) in forward-left-up axes; otherwise the accelerometer's
    unit or axes in the map are likely wrong. Gyro bias: the mean rate of a buoy that does not
    spin is its bias; a mean above the map's threshold is a wrong unit, an offset the logger
    did not remove, or a buoy turning steadily.
    """
    warnings = []
    not_increasing = np.count_nonzero(~(np.diff(samples.time_ns) > 0))
    if not_increasing:
        warnings.append(
            f"{not_increasing} samples are not later than the sample before them: check the "
            "time column (the nodes count them as duplicates or out of order)"
        )
    if samples.specific_force_mps2 is not None and np.isfinite(samples.specific_force_mps2).any():
        mean_force = np.nanmean(samples.specific_force_mps2, axis=0)
        magnitude = float(np.linalg.norm(mean_force))
        if abs(magnitude - STANDARD_GRAVITY_MPS2) > column_map.gravity_tolerance_mps2:
            warnings.append(
                f"mean specific force is {magnitude:.2f} m/s², not near gravity (9.8 m/s²): "
                "check the accelerometer's unit in the map"
            )
        elif mean_force[2] < 0.5 * magnitude:
            warnings.append(
                f"mean specific force points along {np.round(mean_force / magnitude, 2)} in "
                "forward-left-up axes, not up (+z, REP-145): check imu.axes in the map"
            )
    if samples.angular_rate_rad_s is not None and np.isfinite(samples.angular_rate_rad_s).any():
        mean_rate = np.nanmean(samples.angular_rate_rad_s, axis=0)
        if np.max(np.abs(mean_rate)) > column_map.max_gyro_bias_rad_s:
            warnings.append(
                f"mean angular rate {np.round(np.degrees(mean_rate), 3)} deg/s exceeds the "
                f"gyro bias threshold of {np.degrees(column_map.max_gyro_bias_rad_s):.2f} deg/s: "
                "check the gyro's unit in the map"
            )
    return warnings
