"""``calibrate_mounting``: the anemometer's mounting angles from a recorded bag.

    calibrate_mounting IN_BAG OUT_YAML [--params-file buoy.yaml ...] [--namespace NS]
                       [--remap FROM:=TO ...] [--window-s 30] [--max-uncertainty-deg 0.1]
                       [--overwrite]

Runs ``process_bag`` over IN_BAG with the parameter files given (the mounting they hold is the
starting point), then finds the mounting that makes the mean vertical wind zero and the
corrected wind free of the buoy's motion (:mod:`buoy_processing.mounting_calibration`), and
writes it as a parameter file the nodes and tools take after the others::

    process_bag IN OUT --params-file buoy.yaml --params-file OUT_YAML

It prints the angles with their 1σ. When the data cannot determine an angle to
``--max-uncertainty-deg`` (1σ), it writes nothing and says why. Exit codes: 0 done; 2 bad
arguments, parameters or bag, or data that do not determine the mounting; 130 interrupted
(SIGINT or SIGTERM), nothing written. It prints the extrinsics it used first.
"""

from __future__ import annotations

import sys
import tempfile
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation, Slerp

from buoy_common.bag_io import BagError, BagReader
from buoy_common.cli import INTERRUPTIBLE_EXIT_CODES, command_parser, interruptible
from buoy_common.contract import NAV_ODOMETRY_TOPIC, WIND_RAW_TOPIC, WIND_TRUE_TOPIC
from buoy_common.extrinsics import describe_shared_fields
from buoy_common.namespaces import (
    NamespaceError,
    TopicView,
    add_namespace_arguments,
    views_of_bag,
)
from buoy_common.parameters import ParameterError
from buoy_common.safe_output import OutputError, check_outputs_apart_from_inputs, staged_file
from buoy_nav.config import fusion_config_from_files
from buoy_processing.bag_processing import process_bag
from buoy_processing.mounting_calibration import (
    DEFAULT_MAX_UNCERTAINTY_DEG,
    DEFAULT_WINDOW_S,
    CalibrationError,
    MountingEstimate,
    estimate_mounting,
)
from buoy_processing.report.data import odometry_series, stamped_vectors, vectors_at_stamps
from wind_comp.config import compensator_config_from_files

EXIT_CODES = INTERRUPTIBLE_EXIT_CODES


def parse_arguments(argv):
    parser = command_parser("calibrate_mounting", __doc__, EXIT_CODES)
    parser.add_argument("in_bag", help="bag with the sensor topics process_bag needs")
    parser.add_argument("out_yaml", help="parameter file to write (anemometer.rpy_deg)")
    parser.add_argument(
        "--params-file",
        action="append",
        default=[],
        help="ROS parameter YAML as given to the nodes (repeatable; later files win); its "
        "anemometer.rpy_deg is the starting point",
    )
    parser.add_argument(
        "--window-s",
        type=float,
        default=DEFAULT_WINDOW_S,
        help=f"window of the horizontal mean wind, s (default {DEFAULT_WINDOW_S:g})",
    )
    parser.add_argument(
        "--max-uncertainty-deg",
        type=float,
        default=DEFAULT_MAX_UNCERTAINTY_DEG,
        help="largest 1-sigma of any angle for the result to be written, deg "
        f"(default {DEFAULT_MAX_UNCERTAINTY_DEG:g})",
    )
    parser.add_argument("--overwrite", action="store_true", help="replace an existing OUT_YAML")
    add_namespace_arguments(parser)
    return parser.parse_args(argv)


def calibration_inputs(processed_bag: Path, namespace: str):
    """(t_s, corrected ENU, measured sensor-axes wind, attitude xyzw) at the anemometer stamps
    of a processed bag."""
    with BagReader(processed_bag, TopicView(namespace)) as reader:
        measured = stamped_vectors(reader, WIND_RAW_TOPIC)
        corrected = vectors_at_stamps(measured.stamps_ns, stamped_vectors(reader, WIND_TRUE_TOPIC))
        odometry = odometry_series(reader, NAV_ODOMETRY_TOPIC)
    if odometry.stamps_ns.size < 2:
        raise CalibrationError("the fusion produced no navigation: the buoy never aligned")
    origin_ns = odometry.stamps_ns[0]
    nav_t_s = (odometry.stamps_ns - origin_ns) * 1e-9
    t_s = (measured.stamps_ns - origin_ns) * 1e-9
    inside = (t_s >= nav_t_s[0]) & (t_s <= nav_t_s[-1])
    attitude = np.full((t_s.size, 4), np.nan)
    attitude[inside] = Slerp(nav_t_s, Rotation.from_quat(odometry.quat_xyzw))(t_s[inside]).as_quat()
    return t_s, corrected, measured.vectors, attitude


def parameter_yaml(estimate: MountingEstimate, in_bag: str) -> str:
    roll, pitch, yaw = estimate.rpy_deg
    sigma = estimate.sigma_rpy_deg
    return (
        f"# Anemometer mounting estimated by calibrate_mounting from {in_bag}:\n"
        f"# {estimate.samples} wind samples in {estimate.windows} windows; 1-sigma roll "
        f"{sigma[0]:.3f} deg, pitch {sigma[1]:.3f} deg, yaw {sigma[2]:.3f} deg.\n"
        f"# Mean vertical wind {estimate.mean_vertical_before_mps:+.4f} m/s before, "
        f"{estimate.mean_vertical_after_mps:+.4f} m/s after.\n"
        "# Give it to the nodes after the shared buoy file: --params-file buoy.yaml "
        "--params-file THIS_FILE\n"
        "/**:\n"
        "  ros__parameters:\n"
        "    anemometer:\n"
        f"      rpy_deg: [{roll:.4f}, {pitch:.4f}, {yaw:.4f}]\n"
    )


def calibrate(arguments) -> MountingEstimate:
    out_yaml = Path(arguments.out_yaml)
    check_outputs_apart_from_inputs([arguments.in_bag, *arguments.params_file], [out_yaml])
    if out_yaml.exists() and not arguments.overwrite:
        raise OutputError(f"{out_yaml} exists; give --overwrite to replace it")
    views = views_of_bag(arguments, arguments.in_bag, WIND_RAW_TOPIC)
    if len(views) > 1:
        names = ", ".join(view.label for view in views)
        raise NamespaceError(
            f"bag {arguments.in_bag} holds several buoys ({names}): choose one with --namespace"
        )
    (view,) = views
    compensator = compensator_config_from_files(arguments.params_file)
    print(f"extrinsics: {describe_shared_fields(compensator)}")
    with tempfile.TemporaryDirectory(prefix="calibrate_mounting-") as folder:
        processed = Path(folder) / "processed"
        process_bag(
            arguments.in_bag,
            processed,
            fusion_config_from_files(arguments.params_file),
            compensator,
            view=view,
        )
        inputs = calibration_inputs(processed, view.namespace)
    estimate = estimate_mounting(
        *inputs,
        compensator.anemometer_rpy_deg,
        window_s=arguments.window_s,
        max_uncertainty_deg=arguments.max_uncertainty_deg,
    )
    with staged_file(out_yaml) as stream:
        stream.write(parameter_yaml(estimate, arguments.in_bag))
    return estimate


@interruptible("calibrate_mounting")
def main(argv=None) -> None:
    arguments = parse_arguments(sys.argv[1:] if argv is None else argv)
    try:
        estimate = calibrate(arguments)
    except (
        ParameterError,
        BagError,
        OutputError,
        NamespaceError,
        CalibrationError,
        OSError,
    ) as error:
        print(f"calibrate_mounting: {error}", file=sys.stderr)
        sys.exit(2)
    for name, angle, sigma in zip(
        ("roll", "pitch", "yaw"), estimate.rpy_deg, estimate.sigma_rpy_deg, strict=True
    ):
        print(f"{name:5s} {angle:+8.3f} deg  ±{sigma:.3f} (1 sigma)")
    print(
        f"rotation applied to the given mounting (sonic axes): "
        f"{', '.join(f'{c:+.3f}' for c in estimate.change_deg)} deg"
    )
    print(
        f"mean vertical wind {estimate.mean_vertical_before_mps:+.4f} m/s before, "
        f"{estimate.mean_vertical_after_mps:+.4f} m/s after; {estimate.samples} samples"
    )
    print(f"wrote {arguments.out_yaml}")
