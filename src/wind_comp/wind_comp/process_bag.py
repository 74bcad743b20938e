"""``process_bag``: fusion and wind correction over a recorded bag, the offline twin of the nodes.

    process_bag IN_BAG OUT_BAG [--params-file buoy.yaml] [--params-file compensation.yaml]
                [--overwrite] [--namespace NS] [--remap FROM:=TO ...] [--smooth]

Runs over the bag's sensor topics, in log-time order, the same core as ``fusion_node`` followed
by ``compensation_node`` (:func:`wind_comp.bag_processing.process_bag`): every
``anemometer/wind`` sample yields exactly one ``wind/true`` (NaN when it cannot be corrected).
The new bag holds ``nav/*``, ``wind/true``, the wind products (``wind/mean_<window>``,
``wind/stats_<window>``), the measured ``anemometer/wind`` and any truth topics; the wind
products are also written to ``<OUT_BAG>_wind_products.csv``. With ``--smooth`` ``nav/*`` carry
the fixed-interval smoother's solution, the wind is corrected with the smoothed attitude and
velocity, and the forward filter's odometry is kept as ``nav/forward/odometry`` (the bag is read
twice; temporary records beside OUT_BAG, about 0.35 GB per hour of 100 Hz data). Parameters come
from the same YAML files the nodes take. Namespaces and remappings as for ``fuse_bag``: a bag
recorded under one namespace is read and written in it; a bag of several buoys gives one output
per namespace (``OUT_BAG/buoy1`` and its CSV ``OUT_BAG/buoy1_wind_products.csv``, ...).

Both outputs are written under temporary names beside them and appear only when complete; they
may not be, contain or lie inside IN_BAG. It prints the extrinsics it used first.

Exit codes: 0 done; 2 bad arguments, parameters (an unknown name among them) or bags (one line
on stderr); 3 done, but IN_BAG was cut short (a recorder killed or out of power) and was
processed up to its last complete chunk (a warning says how much was read); 4 done, but most
wind samples came out invalid (a warning names the main reason, such as a wrong frame); 130
interrupted (SIGINT or SIGTERM), nothing left under OUT_BAG.
"""

from __future__ import annotations

import argparse
import sys

from buoy_common.bag_io import RECOVERED_BAG_EXIT_CODE, BagError
from buoy_common.cli import interruptible
from buoy_common.contract import WIND_RAW_TOPIC, seconds_to_stamp, window_label
from buoy_common.extrinsics import describe_shared_fields
from buoy_common.namespaces import (
    NamespaceError,
    add_namespace_arguments,
    output_for,
    views_of_bag,
)
from buoy_common.parameters import ParameterError
from buoy_common.safe_output import OutputError
from buoy_nav.config import fusion_config_from_files
from wind_comp.bag_processing import ProcessSummary, process_bag
from wind_comp.compensator import WindStatus
from wind_comp.config import compensator_config_from_files
from wind_comp.pipeline import mostly_invalid_warning, wrong_frame_message

MOSTLY_INVALID_EXIT_CODE = 4
"""Exit code of a run that completed but whose wind samples came out mostly invalid."""


def parse_arguments(argv):
    parser = argparse.ArgumentParser(prog="process_bag", description=__doc__.split("\n")[0])
    parser.add_argument(
        "in_bag",
        help="bag with imu/data_raw, gnss/fix, gnss/heading, anemometer/wind"
        "[, gnss/vel, gnss/baseline]",
    )
    parser.add_argument("out_bag", help="bag directory to create")
    parser.add_argument(
        "--params-file",
        action="append",
        default=[],
        help="ROS parameter YAML as given to the nodes (repeatable; later files win)",
    )
    parser.add_argument("--overwrite", action="store_true", help="replace an existing OUT_BAG")
    parser.add_argument(
        "--smooth",
        action="store_true",
        help="correct the wind with the fixed-interval smoother's navigation (nav/*); the "
        "forward filter's odometry goes to nav/forward/odometry",
    )
    add_namespace_arguments(parser)
    return parser.parse_args(argv)


def print_summary(summary: ProcessSummary, out_bag: str) -> None:
    for line in summary.fusion_lines:
        print(line)
    counts = summary.wind_status_counts
    invalid = ", ".join(
        f"{status.reason} {n}" for status, n in counts.items() if status != WindStatus.VALID and n
    )
    print(
        f"wind samples: {sum(counts.values())} in, {counts.get(WindStatus.VALID, 0)} corrected, "
        f"invalid: {invalid or 'none'}"
    )
    for reason, n in sorted(summary.rejected_wind_messages.items()):
        print(f"rejected message {WIND_RAW_TOPIC}: {reason}: {n}")
    for product in summary.products:
        if product.window_end_s - product.window_start_s < product.window_s:
            continue
        start_sec, _ = seconds_to_stamp(product.window_start_s)
        print(
            f"{window_label(product.window_s):>6s} window from {start_sec}: "
            f"{product.vector_mean_speed_mps:6.2f} m/s from "
            f"{product.vector_mean_direction_deg:6.1f} deg, gust {product.gust_mps:6.2f} m/s, "
            f"{product.n_valid} valid / {product.n_invalid} invalid"
        )
    for topic, count in sorted(summary.topic_counts.items()):
        print(f"{topic:22s} {count:8d}")
    print(f"wrote {out_bag} and {summary.csv_path}")
    print(
        f"{summary.duration_s:.1f} s of data in {summary.wall_s:.1f} s "
        f"({summary.duration_s / max(summary.wall_s, 1e-9):.0f}x real time)"
    )


@interruptible("process_bag")
def main(argv=None) -> None:
    arguments = parse_arguments(sys.argv[1:] if argv is None else argv)
    truncated = mostly_invalid = False
    try:
        fusion_config = fusion_config_from_files(arguments.params_file)
        compensator_config = compensator_config_from_files(arguments.params_file)
        print(f"extrinsics: {describe_shared_fields(fusion_config)}")
        print(
            f"extrinsics: {describe_shared_fields(compensator_config)}; anemometer/wind "
            f"expected in frame '{compensator_config.anemometer_frame_id}'"
        )
        views = views_of_bag(arguments, arguments.in_bag, WIND_RAW_TOPIC)
        for view in views:
            out_bag = output_for(arguments.out_bag, view, several=len(views) > 1)
            if len(views) > 1:
                print(f"namespace {view.label} -> {out_bag}")
            summary = process_bag(
                arguments.in_bag,
                out_bag,
                fusion_config,
                compensator_config,
                arguments.overwrite,
                view,
                arguments.smooth,
            )
            print_summary(summary, out_bag)
            for frame_id, n in sorted(summary.wrong_wind_frames.items()):
                message = wrong_frame_message(frame_id, compensator_config.anemometer_frame_id)
                print(f"process_bag: error: {n} samples of {message}", file=sys.stderr)
            if summary.recovery is not None:
                warning = summary.recovery.describe(arguments.in_bag)
                print(f"process_bag: warning: {warning}", file=sys.stderr)
                truncated = truncated or summary.recovery.truncated
            warning = mostly_invalid_warning(summary.wind_status_counts)
            if warning is not None:
                print(f"process_bag: warning: {warning}", file=sys.stderr)
                mostly_invalid = True
    except (ParameterError, BagError, OutputError, NamespaceError, OSError) as error:
        print(f"process_bag: {error}", file=sys.stderr)
        sys.exit(2)
    if truncated:
        sys.exit(RECOVERED_BAG_EXIT_CODE)
    if mostly_invalid:
        sys.exit(MOSTLY_INVALID_EXIT_CODE)
