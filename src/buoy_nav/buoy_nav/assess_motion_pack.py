"""``assess_motion_pack``: a motion pack's gyro bias wander and the sea's heave, from a bag, as
the parameters a moored buoy without GNSS must state (:mod:`buoy_nav.motion_pack_assessment`).

    assess_motion_pack IN_BAG [OUT_YAML] [--overwrite]

Reads ``imu/data_raw`` and the pack's own attitude ``imu/data`` (at least 300 s of both), prints
the wander of the raw rates against the rates of the pack's attitude below 0.005, 0.01 and
0.02 Hz (deg/h, x, y, z), its correlation time and the 1-sigma heave over 0.05-2 Hz, and the
parameters they suggest: ``fusion.gyro_bias_instability_deg_h``,
``fusion.gyro_bias_correlation_time_s`` and ``fusion.moored_position_sigma_horizontal_m``.
With OUT_YAML it writes them as a parameter file the fusion takes.
Exit codes: 0 done; 2 a bad bag, too short a record or an output it cannot write (one line on
stderr); 130 interrupted (SIGINT or SIGTERM), nothing written.
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

from buoy_common.bag_io import BagError, BagReader
from buoy_common.cli import INTERRUPTIBLE_EXIT_CODES, command_parser, interruptible
from buoy_common.contract import AHRS_TOPIC, IMU_RAW_TOPIC, header_seconds
from buoy_common.safe_output import staged_file
from buoy_nav.calibration import parameter_yaml
from buoy_nav.motion_pack_assessment import (
    AssessmentError,
    MotionPackAssessment,
    MotionPackRecord,
    assess_motion_pack,
)

EXIT_CODES = INTERRUPTIBLE_EXIT_CODES


def xyz(vector) -> tuple[float, float, float]:
    return vector.x, vector.y, vector.z


def read_motion_pack(bag: str) -> MotionPackRecord:
    """The bag's raw IMU and pack attitude, each sorted by header stamp."""
    with BagReader(bag) as reader:
        reader.require(IMU_RAW_TOPIC)
        reader.require(AHRS_TOPIC)
        raw = [
            (header_seconds(imu.header), *xyz(imu.angular_velocity), *xyz(imu.linear_acceleration))
            for imu in map(reader.decode, reader.messages([IMU_RAW_TOPIC]))
        ]
        attitude = [
            (header_seconds(imu.header), *xyz(imu.orientation), imu.orientation.w)
            for imu in map(reader.decode, reader.messages([AHRS_TOPIC]))
        ]
    raw = np.array(sorted(raw))
    attitude = np.array(sorted(attitude))
    if len(raw) < 2 or len(attitude) < 2:
        raise AssessmentError(f"{bag}: fewer than two samples of {IMU_RAW_TOPIC} or {AHRS_TOPIC}")
    norms = np.linalg.norm(attitude[:, 1:], axis=1)
    unit = np.abs(norms - 1.0) < 1e-3
    if not unit.all():
        print(f"assess_motion_pack: {np.count_nonzero(~unit)} non-unit quaternions left out")
    attitude = attitude[unit]
    return MotionPackRecord(
        raw[:, 0], raw[:, 1:4], raw[:, 4:7], attitude[:, 0], Rotation.from_quat(attitude[:, 1:])
    )


def suggested_parameters(assessment: MotionPackAssessment) -> dict[str, float]:
    return {
        "fusion.gyro_bias_instability_deg_h": round(assessment.gyro_bias_instability_deg_h, 1),
        "fusion.gyro_bias_correlation_time_s": round(assessment.correlation_time_s, 0),
        "fusion.moored_position_sigma_horizontal_m": round(assessment.heave_sigma_m, 3),
    }


def report_lines(bag: str, assessment: MotionPackAssessment) -> list[str]:
    lines = [f"assess_motion_pack {bag}: {assessment.duration_s:.0f} s"]
    for cutoff, wander in assessment.wander_deg_h.items():
        x, y, z = wander
        lines.append(
            f"gyro rates minus the pack's attitude rates below {cutoff} Hz, 1 sigma: "
            f"x {x:.0f}, y {y:.0f}, z {z:.0f} deg/h"
        )
    lines.append(f"their correlation time (x, y): {assessment.correlation_time_s:.0f} s")
    lines.append(f"heave over 0.05-2 Hz, 1 sigma: {assessment.heave_sigma_m:.3f} m")
    return lines


def parse_arguments(argv):
    parser = command_parser("assess_motion_pack", __doc__, EXIT_CODES)
    parser.add_argument("in_bag", help="bag with imu/data_raw and imu/data")
    parser.add_argument("out_yaml", nargs="?", help="parameter file to write")
    parser.add_argument("--overwrite", action="store_true", help="replace an existing OUT_YAML")
    return parser.parse_args(argv)


def write_parameters(output: Path, values: dict, comment: str) -> None:
    try:
        with staged_file(output) as stream:
            stream.write(parameter_yaml(values, comment))
    except OSError as error:
        print(f"assess_motion_pack: cannot write {output}: {error}", file=sys.stderr)
        sys.exit(2)


@interruptible("assess_motion_pack")
def main(argv=None) -> None:
    arguments = parse_arguments(sys.argv[1:] if argv is None else argv)
    output = Path(arguments.out_yaml) if arguments.out_yaml else None
    try:
        if output is not None and output.exists() and not arguments.overwrite:
            raise AssessmentError(f"{output} exists (--overwrite replaces it)")
        assessment = assess_motion_pack(read_motion_pack(arguments.in_bag))
    except (BagError, AssessmentError) as error:
        print(f"assess_motion_pack: {error}", file=sys.stderr)
        sys.exit(2)
    lines = report_lines(arguments.in_bag, assessment)
    values = suggested_parameters(assessment)
    print("\n".join(lines))
    for name, value in values.items():
        print(f"{name}: {value:g}")
    if output is not None:
        write_parameters(output, values, "\n".join(lines))
        print(f"wrote {output}")
