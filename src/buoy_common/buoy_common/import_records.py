"""``import_records``: a logger's record file → a contract bag, driven by a column map.

The column map (YAML, see docs/real-records.md, "Importing logger records") says which column holds
which quantity, in which unit and axes, how the samples are timed and which values mark an
invalid sample. The bag carries the contract's sensor topics: ``anemometer/wind`` and
``anemometer/temperature`` (frame ``anemometer_link``), ``imu/data_raw`` and, when the map gives
the motion pack's attitude, ``imu/data`` (frame ``imu_link``); every row is one sample of each,
invalid samples as NaN, log time = header stamp.
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

from buoy_common.bag_io import BagError, BagWriter, jazzy_typestore
from buoy_common.cdr import ImuWriter, Vector3StampedWriter
from buoy_common.cli import BAD_INPUT, DONE, command_parser
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
)
from buoy_common.records.column_map import MapError, load_column_map
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


EXIT_CODES = (DONE, BAD_INPUT)


def parse_arguments(argv):
    parser = command_parser("import_records", __doc__, EXIT_CODES)
    parser.add_argument("record", help="the logger's record file (delimited text or binary)")
    parser.add_argument("column_map", help="column map YAML (see docs/real-records.md)")
    parser.add_argument("output", help="bag directory to create")
    parser.add_argument("--overwrite", action="store_true", help="replace an existing bag")
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


def write_contract_bag(samples: ContractSamples, output: str | Path, overwrite: bool) -> dict:
    """Write ``samples`` as the contract's sensor topics, sample after sample in time order
    (log time = header stamp); returns the messages per topic."""
    stamps_ns = samples.time_ns
    topics = contract_messages(samples)
    with BagWriter(output, overwrite=overwrite) as bag:
        for i in np.argsort(stamps_ns, kind="stable"):
            for topic, msgtype, raws in topics:
                bag.write_raw(bag_topic(topic), msgtype, int(stamps_ns[i]), raws[i])
    return dict(bag.counts)


def import_records(record, column_map_path, output, overwrite=False) -> tuple[dict, list[str]]:
    """Import one record file; returns (messages per topic, plausibility warnings)."""
    check_outputs_apart_from_inputs([record, column_map_path], [output])
    column_map = load_column_map(column_map_path)
    samples = decode(read_table(record, column_map), column_map)
    warnings = plausibility_warnings(samples, column_map)
    return write_contract_bag(samples, output, overwrite), warnings


def main(argv=None) -> None:
    arguments = parse_arguments(sys.argv[1:] if argv is None else argv)
    try:
        counts, warnings = import_records(
            arguments.record, arguments.column_map, arguments.output, arguments.overwrite
        )
    except (MapError, BagError, OutputError) as error:
        print(f"import_records: {error}", file=sys.stderr)
        sys.exit(2)
    for warning in warnings:
        print(f"import_records: WARNING: {warning}", file=sys.stderr)
    for topic, count in sorted(counts.items()):
        print(f"{topic:24s} {count:8d}")
    print(f"wrote {arguments.output}")
