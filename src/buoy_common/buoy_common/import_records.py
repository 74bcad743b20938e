"""``import_records``: a logger's record file → a contract bag, driven by a column map.

The column map (YAML, see docs/real-records.md, "Importing logger records") says which column holds
which quantity, in which unit and axes, how the samples are timed and which values mark an
invalid sample. The bag carries the contract's sensor topics: ``anemometer/wind`` and
``anemometer/temperature`` (frame ``anemometer_link``), ``imu/data_raw`` and, when the map gives
the motion pack's attitude, ``imu/data`` (frame ``imu_link``); every row is one sample of each,
invalid samples as NaN, log time = header stamp. What the map and the command line know besides
the samples (the pack's north reference, the site, the sensors, the start and who gave it, how
each field was screened) is stored in the bag as well (:mod:`buoy_common.record_facts`).
"""

from __future__ import annotations

import argparse
import dataclasses
import sys
from pathlib import Path
from typing import NamedTuple

import numpy as np

from buoy_common.bag_io import BagError, BagWriter, jazzy_typestore
from buoy_common.cdr import ImuWriter, Vector3StampedWriter
from buoy_common.cli import INTERRUPTIBLE_EXIT_CODES, ExitCode, command_parser, interruptible
from buoy_common.contract import (
    AHRS_TOPIC,
    ANEMOMETER_FRAME,
    IMU_FRAME,
    IMU_MSGTYPE,
    IMU_RAW_TOPIC,
    SONIC_TEMPERATURE_TOPIC,
    TEMPERATURE_MSGTYPE,
    VECTOR3_MSGTYPE,
    WIND_RAW_TOPIC,
    bag_topic,
    ns_to_stamp,
    seconds_to_iso8601,
)
from buoy_common.record_facts import (
    RECORD_METADATA_NAME,
    RECORD_SENSORS,
    SITE_FROM_COMMAND_LINE,
    SITE_FROM_MAP,
    ImportedRecord,
)
from buoy_common.records.column_map import (
    START_FROM_COMMAND_LINE,
    START_FROM_MAP,
    ColumnMap,
    MapError,
    iso8601_ns,
    load_column_map,
    site_of,
)
from buoy_common.records.decoding import (
    ContractSamples,
    decode,
    plausibility_warnings,
    read_table,
)
from buoy_common.safe_output import OutputError, check_outputs_apart_from_inputs

NO_COVARIANCE = (0.0,) * 9
NO_ORIENTATION_COVARIANCE = (-1.0,) + (0.0,) * 8
IDENTITY_XYZW = (0.0, 0.0, 0.0, 1.0)


WIND_ALL_INVALID_EXIT_CODE = 5
"""Exit code of a record refused because not one of its wind samples is valid."""
EXIT_CODES = (
    *INTERRUPTIBLE_EXIT_CODES,
    ExitCode(
        WIND_ALL_INVALID_EXIT_CODE,
        "refused: every wind sample of the record is invalid (nothing written; "
        "--allow-invalid-wind imports it)",
    ),
)


class AllWindInvalidError(ValueError):
    """Every wind sample of the record is invalid (a failed sonic): nothing is imported unless
    asked to (``allow_invalid_wind``)."""


class ImportResult(NamedTuple):
    """What :func:`import_records` wrote and found."""

    counts: dict[str, int]
    """Messages written per topic."""
    warnings: list[str]
    """What looks physically wrong (:func:`~buoy_common.records.decoding.plausibility_warnings`)."""
    facts: ImportedRecord
    """The record's facts, stored in the bag."""


def _start_argument(text: str) -> int:
    try:
        return iso8601_ns(text, "--start")
    except MapError as error:
        raise argparse.ArgumentTypeError(f"{error} (e.g. 2014-12-18T00:00:00Z)") from None


def _site_argument(text: str) -> tuple[float, float]:
    latitude, _, longitude = text.partition(",")
    try:
        site = {"latitude_deg": float(latitude), "longitude_deg": float(longitude)}
        return site_of(site, "--site")
    except (ValueError, MapError) as error:
        detail = str(error) if isinstance(error, MapError) else "expected LAT,LON in degrees"
        raise argparse.ArgumentTypeError(f"{detail}, got {text!r}") from None


def parse_arguments(argv):
    parser = command_parser("import_records", __doc__, EXIT_CODES)
    parser.add_argument("record", help="the logger's record file (delimited text or binary)")
    parser.add_argument("column_map", help="column map YAML (see docs/real-records.md)")
    parser.add_argument("output", help="bag directory to create")
    parser.add_argument("--overwrite", action="store_true", help="replace an existing bag")
    parser.add_argument(
        "--start",
        type=_start_argument,
        metavar="ISO8601",
        help="when the record starts (its first sample, or the zero of its time column), "
        "e.g. 2014-12-18T00:00:00Z; overrides the map's time.start or time.epoch",
    )
    parser.add_argument(
        "--site",
        type=_site_argument,
        metavar="LAT,LON",
        help="the buoy's latitude and longitude, deg (overrides the map's site)",
    )
    parser.add_argument(
        "--allow-invalid-wind",
        action="store_true",
        help="import a record whose every wind sample is invalid (a failed sonic): every wind "
        "sample as invalid, no sonic temperature",
    )
    return parser.parse_args(argv)


def _temperature_raws(samples: ContractSamples, stamps) -> list[bytes]:
    typestore = jazzy_typestore()
    temperature = typestore.types[TEMPERATURE_MSGTYPE]
    header = typestore.types["std_msgs/msg/Header"]
    time = typestore.types["builtin_interfaces/msg/Time"]
    return [
        typestore.serialize_cdr(
            temperature(
                header=header(stamp=time(sec=sec, nanosec=nanosec), frame_id=ANEMOMETER_FRAME),
                temperature=float(value),
                variance=0.0,
            ),
            TEMPERATURE_MSGTYPE,
        ).tobytes()
        for (sec, nanosec), value in zip(stamps, samples.sonic_temperature_degc, strict=True)
    ]


def _imu_raws(samples: ContractSamples, stamps, orientations, orientation_covariance):
    writer = ImuWriter(IMU_FRAME)
    rows = zip(
        stamps, orientations, samples.angular_rate_rad_s, samples.specific_force_mps2, strict=True
    )
    return [
        writer.write(
            sec,
            nanosec,
            orientation,
            orientation_covariance,
            rate,
            NO_COVARIANCE,
            force,
            NO_COVARIANCE,
        )
        for (sec, nanosec), orientation, rate, force in rows
    ]


def contract_messages(samples: ContractSamples) -> list[tuple[str, str, list[bytes]]]:
    """(topic, message type, CDR bytes of each sample) of every topic the samples fill."""
    stamps = [ns_to_stamp(int(t)) for t in samples.time_ns]
    topics = []
    if samples.wind_mps is not None:
        sec, nanosec = zip(*stamps, strict=True)
        raws = Vector3StampedWriter(ANEMOMETER_FRAME).write_many(sec, nanosec, samples.wind_mps)
        topics.append((WIND_RAW_TOPIC, VECTOR3_MSGTYPE, raws))
    if samples.sonic_temperature_degc is not None:
        topics.append(
            (SONIC_TEMPERATURE_TOPIC, TEMPERATURE_MSGTYPE, _temperature_raws(samples, stamps))
        )
    if samples.angular_rate_rad_s is not None:
        unknown = [IDENTITY_XYZW] * len(samples)
        raws = _imu_raws(samples, stamps, unknown, NO_ORIENTATION_COVARIANCE)
        topics.append((IMU_RAW_TOPIC, IMU_MSGTYPE, raws))
    if samples.orientation_xyzw is not None:
        variance = np.diag(np.square(samples.orientation_sigma_rad)).ravel()
        raws = _imu_raws(samples, stamps, samples.orientation_xyzw, variance)
        topics.append((AHRS_TOPIC, IMU_MSGTYPE, raws))
    return topics


def write_contract_bag(
    samples: ContractSamples, output: str | Path, overwrite: bool, facts: ImportedRecord | None
) -> dict:
    """Write ``samples`` as the contract's sensor topics, sample after sample in time order
    (log time = header stamp), and the record's ``facts`` beside them; returns the messages
    per topic."""
    stamps_ns = samples.time_ns
    topics = contract_messages(samples)
    with BagWriter(output, overwrite=overwrite) as bag:
        for i in np.argsort(stamps_ns, kind="stable"):
            for topic, msgtype, raws in topics:
                bag.write_raw(bag_topic(topic), msgtype, int(stamps_ns[i]), raws[i])
        if facts is not None:
            bag.add_metadata(RECORD_METADATA_NAME, facts.to_metadata())
    return dict(bag.counts)


def with_start(column_map: ColumnMap, start_ns: int | None) -> ColumnMap:
    """``column_map`` with the record's start given on the command line (None: the map's)."""
    if start_ns is None:
        return column_map
    if column_map.time.calendar:
        raise MapError(
            "--start: the record writes each sample's date and time (time.calendar), so its "
            "start is its own"
        )
    time = dataclasses.replace(
        column_map.time, epoch_ns=start_ns, start_source=START_FROM_COMMAND_LINE
    )
    return dataclasses.replace(column_map, time=time)


def record_sensors(samples: ContractSamples) -> tuple[str, ...]:
    """The sensors of :data:`~buoy_common.record_facts.RECORD_SENSORS` the samples have."""
    present = (
        samples.wind_mps,
        samples.sonic_temperature_degc,
        samples.angular_rate_rad_s,
        samples.orientation_xyzw,
    )
    return tuple(name for name, s in zip(RECORD_SENSORS, present, strict=True) if s is not None)


def record_facts_of(record, column_map: ColumnMap, samples, site_deg) -> ImportedRecord:
    """The facts of an imported record: the map's, the command line's (``site_deg`` None: the
    map's site, if any) and the screening of its samples."""
    site_source = SITE_FROM_COMMAND_LINE if site_deg is not None else SITE_FROM_MAP
    site_deg = site_deg if site_deg is not None else column_map.site_deg
    return ImportedRecord(
        record=Path(record).name,
        column_map=column_map.path.name,
        description=column_map.description,
        start_ns=int(samples.time_ns.min()),
        start_source=column_map.time.start_source,
        sensors=record_sensors(samples),
        yaw_reference=None if samples.orientation_xyzw is None else samples.yaw_reference,
        site_deg=site_deg,
        site_source=None if site_deg is None else site_source,
        field_counts=samples.field_counts,
        temperatures_without_wind=samples.temperatures_without_wind,
    )


def check_wind(samples: ContractSamples) -> None:
    """AllWindInvalidError when the record maps a wind and not one sample of it is valid."""
    wind = samples.wind_mps
    if wind is None or np.isfinite(wind).all(axis=1).any():
        return
    raise AllWindInvalidError(
        f"every one of the {len(samples)} wind samples is invalid (a fill code, an invalid "
        "code or out of range: see the table above); nothing written "
        "(--allow-invalid-wind imports them as invalid samples, without sonic temperature)"
    )


def import_records(
    record,
    column_map_path,
    output,
    overwrite=False,
    *,
    start_ns: int | None = None,
    site_deg: tuple[float, float] | None = None,
    allow_invalid_wind: bool = False,
    on_screened=None,
) -> ImportResult:
    """Import one record file (``start_ns``: its start, ns since the Unix epoch, over the
    map's; ``site_deg``: (latitude, longitude) over the map's). ``on_screened`` is called with
    the record's facts once its samples are screened, before anything is refused or written.
    Raises MapError, AllWindInvalidError (unless ``allow_invalid_wind``), BagError or
    OutputError."""
    check_outputs_apart_from_inputs([record, column_map_path], [output])
    column_map = with_start(load_column_map(column_map_path), start_ns)
    samples = decode(read_table(record, column_map), column_map)
    facts = record_facts_of(record, column_map, samples, site_deg)
    if on_screened is not None:
        on_screened(facts)
    if not allow_invalid_wind:
        check_wind(samples)
    warnings = plausibility_warnings(samples, column_map)
    return ImportResult(write_contract_bag(samples, output, overwrite, facts), warnings, facts)


def print_screening(facts: ImportedRecord) -> None:
    """Per field: samples read, filled, invalid, out of range; and where the start came from."""
    print(f"{'field':28s} {'read':>8s} {'filled':>8s} {'invalid':>8s} {'out of range':>12s}")
    for name, counts in facts.field_counts.items():
        print(
            f"{name:28s} {counts.read:8d} {counts.filled:8d} {counts.invalid:8d} "
            f"{counts.out_of_range:12d}"
        )
    if facts.temperatures_without_wind:
        print(f"sonic temperatures invalid with their wind: {facts.temperatures_without_wind}")
    source = facts.start_source
    if source == START_FROM_MAP:
        source += f" {facts.column_map}"
    print(f"start {seconds_to_iso8601(facts.start_ns / 1e9)} (from the {source})")


@interruptible("import_records")
def main(argv=None) -> None:
    arguments = parse_arguments(sys.argv[1:] if argv is None else argv)
    try:
        result = import_records(
            arguments.record,
            arguments.column_map,
            arguments.output,
            arguments.overwrite,
            start_ns=arguments.start,
            site_deg=arguments.site,
            allow_invalid_wind=arguments.allow_invalid_wind,
            on_screened=print_screening,
        )
    except AllWindInvalidError as error:
        print(f"import_records: {error}", file=sys.stderr)
        sys.exit(WIND_ALL_INVALID_EXIT_CODE)
    except (MapError, BagError, OutputError) as error:
        print(f"import_records: {error}", file=sys.stderr)
        sys.exit(2)
    for warning in result.warnings:
        print(f"import_records: WARNING: {warning}", file=sys.stderr)
    for topic, count in sorted(result.counts.items()):
        print(f"{topic:24s} {count:8d}")
    print(f"wrote {arguments.output}")
