"""``calibrate_magnetometer``: hard and soft iron from a bag of the buoy's record (paper 004's
min/max hard iron, then a least-squares ellipsoid; :mod:`buoy_nav.calibration`).

    calibrate_magnetometer IN_BAG OUT_YAML [--overwrite]

Reads ``imu/mag`` (and ``imu/data_raw``, when the bag has it, for how far the record swung and
tilted), refuses a record whose motion leaves the iron undetermined (the message says what is
undetermined, how the buoy moved and what a new record needs), and writes a parameter file the
fusion takes (``fusion.magnetometer_hard_iron_t``, ``fusion.magnetometer_soft_iron``). Prints
the residual of the calibrated field magnitude, with the min/max method's beside it, the noise
the record shows and the fit's 1σ. Exit codes: 0 written; 2 bad bag or a record that does not
determine the iron, or an output it cannot write (one line on stderr); 130 interrupted (SIGINT
or SIGTERM), nothing written.
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

from buoy_common.bag_io import BagError, BagReader
from buoy_common.cli import INTERRUPTIBLE_EXIT_CODES, command_parser, interruptible
from buoy_common.contract import IMU_RAW_TOPIC, MAGNETOMETER_TOPIC, header_seconds
from buoy_common.safe_output import staged_file
from buoy_nav.calibration import (
    CalibrationError,
    MagnetometerCalibration,
    RecordMotion,
    calibrate_magnetometer,
    parameter_yaml,
    record_motion,
)

EXIT_CODES = INTERRUPTIBLE_EXIT_CODES


def read_field(bag: str) -> np.ndarray:
    """The bag's ``imu/mag`` samples (N, 3; T)."""
    samples = []
    with BagReader(bag) as reader:
        reader.require(MAGNETOMETER_TOPIC)
        for message in reader.messages([MAGNETOMETER_TOPIC]):
            field = reader.decode(message).magnetic_field
            samples.append((field.x, field.y, field.z))
    return np.array(samples, dtype=float).reshape(-1, 3)


def read_motion(bag: str) -> RecordMotion | None:
    """How the record moved the buoy, from the bag's ``imu/data_raw``; None without it."""
    times, rates, forces = [], [], []
    with BagReader(bag) as reader:
        try:
            reader.require(IMU_RAW_TOPIC)
        except BagError:
            return None
        for message in reader.messages([IMU_RAW_TOPIC]):
            imu = reader.decode(message)
            times.append(header_seconds(imu.header))
            rates.append((imu.angular_velocity.x, imu.angular_velocity.y, imu.angular_velocity.z))
            acceleration = imu.linear_acceleration
            forces.append((acceleration.x, acceleration.y, acceleration.z))
    if len(times) < 2:
        return None
    return record_motion(times, rates, forces)


def summary_lines(bag: str, calibration: MagnetometerCalibration) -> list[str]:
    """What the calibration found and how well the record determines it (ASCII units)."""
    soft_sigma = calibration.soft_iron_sigma
    return [
        f"calibrate_magnetometer {bag}: field {calibration.field_t * 1e6:.2f} uT, "
        f"residual {calibration.residual_t * 1e9:.0f} nT RMS "
        f"(min/max method alone: {calibration.min_max_residual_t * 1e9:.0f} nT), "
        f"sensor noise {calibration.noise_t * 1e9:.0f} nT",
        f"1-sigma of the fit: hard iron (uT) "
        f"{np.round(calibration.hard_iron_sigma_t * 1e6, 3).tolist()}, soft iron "
        f"{soft_sigma[0, 0]:.4f}/{soft_sigma[1, 1]:.4f}/{soft_sigma[2, 2]:.4f} (diagonal), "
        f"{soft_sigma[0, 1]:.4f}/{soft_sigma[0, 2]:.4f}/{soft_sigma[1, 2]:.4f} (xy/xz/yz)",
    ]


def parse_arguments(argv):
    parser = command_parser("calibrate_magnetometer", __doc__, EXIT_CODES)
    parser.add_argument("in_bag", help="bag with imu/mag of the buoy turning and tilting")
    parser.add_argument("out_yaml", help="parameter file to write")
    parser.add_argument("--overwrite", action="store_true", help="replace an existing OUT_YAML")
    return parser.parse_args(argv)


@interruptible("calibrate_magnetometer")
def main(argv=None) -> None:
    arguments = parse_arguments(sys.argv[1:] if argv is None else argv)
    output = Path(arguments.out_yaml)
    try:
        if output.exists() and not arguments.overwrite:
            raise CalibrationError(f"{output} exists (--overwrite replaces it)")
        calibration = calibrate_magnetometer(
            read_field(arguments.in_bag), read_motion(arguments.in_bag)
        )
    except (BagError, CalibrationError) as error:
        print(f"calibrate_magnetometer: {error}", file=sys.stderr)
        sys.exit(2)
    values = {
        "fusion.magnetometer_hard_iron_t": calibration.hard_iron_t.tolist(),
        "fusion.magnetometer_soft_iron": calibration.soft_iron.ravel().tolist(),
    }
    comment = "\n".join(summary_lines(arguments.in_bag, calibration))
    try:
        with staged_file(output) as stream:
            stream.write(parameter_yaml(values, comment))
    except OSError as error:
        print(f"calibrate_magnetometer: cannot write {output}: {error}", file=sys.stderr)
        sys.exit(2)
    print(comment)
    print(f"min/max hard iron (uT): {np.round(calibration.min_max_hard_iron_t * 1e6, 3).tolist()}")
    for name, value in values.items():
        print(f"{name}: {value}")
    print(f"wrote {output}")
