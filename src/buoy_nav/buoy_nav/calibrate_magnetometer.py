"""``calibrate_magnetometer``: hard and soft iron from a bag of the buoy turning (paper 004's
min/max hard iron, then a least-squares ellipsoid; :mod:`buoy_nav.calibration`).

    calibrate_magnetometer IN_BAG OUT_YAML [--overwrite]

Reads ``imu/mag``, refuses a turn that misses heading sectors or tilt (the message says which),
and writes a parameter file the fusion takes (``fusion.magnetometer_hard_iron_t``,
``fusion.magnetometer_soft_iron``). Prints the residual of the calibrated field magnitude, with
the min/max method's beside it. Exit codes: 0 written; 2 bad bag or coverage, or an output it
cannot write (one line on stderr); 130 interrupted (SIGINT or SIGTERM), nothing written.
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

from buoy_common.bag_io import BagError, BagReader
from buoy_common.cli import INTERRUPTIBLE_EXIT_CODES, command_parser, interruptible
from buoy_common.contract import MAGNETOMETER_TOPIC
from buoy_common.safe_output import staged_file
from buoy_nav.calibration import CalibrationError, calibrate_magnetometer, parameter_yaml

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


def parse_arguments(argv):
    parser = command_parser("calibrate_magnetometer", __doc__, EXIT_CODES)
    parser.add_argument("in_bag", help="bag with imu/mag of the buoy turning")
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
        calibration = calibrate_magnetometer(read_field(arguments.in_bag))
    except (BagError, CalibrationError) as error:
        print(f"calibrate_magnetometer: {error}", file=sys.stderr)
        sys.exit(2)
    values = {
        "fusion.magnetometer_hard_iron_t": calibration.hard_iron_t.tolist(),
        "fusion.magnetometer_soft_iron": calibration.soft_iron.ravel().tolist(),
    }
    comment = (
        f"calibrate_magnetometer {arguments.in_bag}: field {calibration.field_t * 1e6:.2f} uT, "
        f"residual {calibration.residual_t * 1e9:.0f} nT RMS "
        f"(min/max method alone: {calibration.min_max_residual_t * 1e9:.0f} nT)"
    )
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
