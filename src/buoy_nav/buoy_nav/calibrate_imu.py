"""``calibrate_imu``: accelerometer bias and scale per axis and gyro bias from a bag of still
positions (paper 004's six-position method; :mod:`buoy_nav.calibration`).

    calibrate_imu IN_BAG OUT_YAML [--params-file buoy.yaml] [--overwrite]

Reads ``imu/data_raw``, finds the still positions (at least 10 s each), fits the gravity sphere
and writes a parameter file the fusion takes (``fusion.imu_accel_bias_mps2``,
``fusion.imu_accel_scale``, ``fusion.imu_gyro_bias_rad_s`` and the bias's remaining 1-σ as
``fusion.accel_turn_on_bias_mg``, at least :data:`MIN_CALIBRATED_BIAS_MG`). Gravity is the
normal gravity at ``site.*`` (else ``origin.*``, else 45°) from the parameter files. A bag in
which an axis is never held up or down is refused with a message naming the missing attitudes.
Exit codes: 0 written; 2 bad bag, parameters or coverage, or an output it cannot write (one line
on stderr); 130 interrupted (SIGINT or SIGTERM), nothing written.
"""

from __future__ import annotations

import math
import sys
from pathlib import Path

import numpy as np

from buoy_common.bag_io import BagError, BagReader
from buoy_common.cli import INTERRUPTIBLE_EXIT_CODES, command_parser, interruptible
from buoy_common.contract import IMU_RAW_TOPIC, header_seconds
from buoy_common.parameters import ParameterError
from buoy_common.safe_output import staged_file
from buoy_nav import earth
from buoy_nav.calibration import CalibrationError, calibrate_imu, parameter_yaml
from buoy_nav.config import FusionConfig, fusion_config_from_files

STANDARD_GRAVITY_MPS2 = 9.80665
DEFAULT_LATITUDE_DEG = 45.0
MIN_CALIBRATED_BIAS_MG = 0.5
"""Smallest bias 1-σ written: six positions fix six unknowns exactly, so the fit cannot show
its own error; the positions' noise and the drift until deployment leave about this much."""


EXIT_CODES = INTERRUPTIBLE_EXIT_CODES


def site_latitude_deg(config: FusionConfig) -> float:
    for latitude in (config.site_latitude_deg, config.origin_latitude_deg):
        if not math.isnan(latitude):
            return latitude
    return DEFAULT_LATITUDE_DEG


def read_imu(bag: str):
    """(stamps s, gyro rad/s, specific force m/s²) of the bag's ``imu/data_raw``."""
    stamps, gyro, force = [], [], []
    with BagReader(bag) as reader:
        reader.require(IMU_RAW_TOPIC)
        for message in reader.messages([IMU_RAW_TOPIC]):
            imu = reader.decode(message)
            stamps.append(header_seconds(imu.header))
            gyro.append((imu.angular_velocity.x, imu.angular_velocity.y, imu.angular_velocity.z))
            force.append(
                (imu.linear_acceleration.x, imu.linear_acceleration.y, imu.linear_acceleration.z)
            )
    return np.array(stamps), np.array(gyro), np.array(force)


def parse_arguments(argv):
    parser = command_parser("calibrate_imu", __doc__, EXIT_CODES)
    parser.add_argument("in_bag", help="bag with imu/data_raw of the still positions")
    parser.add_argument("out_yaml", help="parameter file to write")
    parser.add_argument("--params-file", action="append", default=[], help="site parameters")
    parser.add_argument("--overwrite", action="store_true", help="replace an existing OUT_YAML")
    return parser.parse_args(argv)


@interruptible("calibrate_imu")
def main(argv=None) -> None:
    arguments = parse_arguments(sys.argv[1:] if argv is None else argv)
    output = Path(arguments.out_yaml)
    try:
        if output.exists() and not arguments.overwrite:
            raise CalibrationError(f"{output} exists (--overwrite replaces it)")
        config = fusion_config_from_files(arguments.params_file)
        latitude = math.radians(site_latitude_deg(config))
        gravity = earth.normal_gravity_mps2(latitude, 0.0)
        calibration = calibrate_imu(*read_imu(arguments.in_bag), gravity)
    except (ParameterError, BagError, CalibrationError) as error:
        print(f"calibrate_imu: {error}", file=sys.stderr)
        sys.exit(2)
    bias_sigma_mg = float(calibration.accel_bias_sigma_mps2.max()) / STANDARD_GRAVITY_MPS2 * 1e3
    values = {
        "fusion.imu_accel_bias_mps2": calibration.accel_bias_mps2.tolist(),
        "fusion.imu_accel_scale": calibration.accel_scale.tolist(),
        "fusion.imu_gyro_bias_rad_s": calibration.gyro_bias_rad_s.tolist(),
        "fusion.accel_turn_on_bias_mg": max(bias_sigma_mg, MIN_CALIBRATED_BIAS_MG),
    }
    comment = (
        f"calibrate_imu {arguments.in_bag}: {len(calibration.positions)} still positions, "
        f"residual |f| - g {calibration.residual_mps2 * 1e3:.2f} mm/s^2"
    )
    try:
        with staged_file(output) as stream:
            stream.write(parameter_yaml(values, comment))
    except OSError as error:
        print(f"calibrate_imu: cannot write {output}: {error}", file=sys.stderr)
        sys.exit(2)
    print(comment)
    for name, value in values.items():
        print(f"{name}: {value}")
    print(f"wrote {output}")
