"""``fuse_bag``: the fusion of ``fusion_node`` run over a recorded bag, as fast as it goes.

    fuse_bag IN_BAG OUT_BAG [--params-file buoy.yaml] [--params-file fusion.yaml] [--overwrite]
             [--namespace NS] [--remap FROM:=TO ...] [--smooth] [--nav-rate-hz HZ]

Reads the sensor topics (``imu/data_raw`` and at least one heading reference: a GNSS heading or
baseline, ``imu/mag`` or a motion pack's ``imu/data``; GNSS fixes and velocities when present,
which a moored buoy does without) in log-time order, feeds them through the
same conversion and engine as the live node, and writes ``nav/odometry``, ``nav/imu``,
``nav/velocity`` and ``nav/fix`` to a new bag, each with the log time of the IMU message that
produced it. Truth topics (``truth/*``) are copied unchanged, so the output carries its own
answer. With ``--smooth`` ``nav/*`` carry the fixed-interval smoother's solution (every sample
estimated from the whole recording, :mod:`buoy_nav.smoother`) and ``nav/forward/odometry`` the
forward filter's; the run reads the bag twice and keeps its records in a temporary directory
beside OUT_BAG (about 0.35 GB per hour of 100 Hz data, removed at the end). With
``--nav-rate-hz HZ`` the solutions at that rate only are written, a subset of the full-rate
ones with the same stamps and bytes. Parameters come
from the same YAML files the node takes (sections ``/**`` and ``fusion_node``).

A bag recorded under a namespace (``/buoy1/imu/data_raw``) is read in that namespace, and the
outputs go into it (``/buoy1/nav/odometry``); ``--namespace`` picks one of several, ``--remap``
reads single topics from other names. A bag of several buoys, without ``--namespace``, gives one
output bag per namespace: ``OUT_BAG/buoy1``, ``OUT_BAG/buoy2`` (:mod:`buoy_common.namespaces`).

OUT_BAG is written under a temporary name beside it and appears only when complete; it may not
be, contain or lie inside IN_BAG. Exit codes: 0 done; 2 bad arguments, parameters or bags
(one line on stderr); 3 done, but IN_BAG was cut short (a recorder killed or out of power) and
was processed up to its last complete chunk (a warning says how much was read).
"""

from __future__ import annotations

import sys

from buoy_common.bag_io import RECOVERED_BAG_EXIT_CODE, BagError
from buoy_common.cli import INTERRUPTIBLE_EXIT_CODES, RECOVERED_BAG, command_parser, interruptible
from buoy_common.contract import IMU_RAW_TOPIC
from buoy_common.extrinsics import describe_shared_fields
from buoy_common.namespaces import (
    NamespaceError,
    add_namespace_arguments,
    output_for,
    views_of_bag,
)
from buoy_common.parameters import ParameterError
from buoy_common.safe_output import OutputError
from buoy_processing.bag_facts import fusion_config_for_bag
from buoy_processing.bag_fusion import FusedBag, fuse_bag
from buoy_processing.nav_output_rate import add_nav_rate_argument
from buoy_processing.offline_fusion import FUSION_TOPICS_HELP

EXIT_CODES = (*INTERRUPTIBLE_EXIT_CODES, RECOVERED_BAG)


def parse_arguments(argv):
    parser = command_parser("fuse_bag", __doc__, EXIT_CODES)
    parser.add_argument("in_bag", help=f"bag with {FUSION_TOPICS_HELP}")
    parser.add_argument("out_bag", help="bag directory to create with the nav/* topics")
    parser.add_argument(
        "--params-file",
        action="append",
        default=[],
        help="ROS parameter YAML as given to fusion_node (repeatable; later files win)",
    )
    parser.add_argument("--overwrite", action="store_true", help="replace an existing OUT_BAG")
    parser.add_argument(
        "--smooth",
        action="store_true",
        help="write the fixed-interval smoother's solution (nav/*) and the forward filter's "
        "(nav/forward/odometry)",
    )
    add_nav_rate_argument(parser)
    add_namespace_arguments(parser)
    return parser.parse_args(argv)


@interruptible("fuse_bag")
def main(argv=None) -> None:
    arguments = parse_arguments(sys.argv[1:] if argv is None else argv)
    truncated = False
    try:
        config, record_lines = fusion_config_for_bag(arguments.in_bag, arguments.params_file)
        for line in record_lines:
            print(f"record: {line}")
        print(f"extrinsics: {describe_shared_fields(config)}")
        views = views_of_bag(arguments, arguments.in_bag, IMU_RAW_TOPIC)
        for view in views:
            out_bag = output_for(arguments.out_bag, view, several=len(views) > 1)
            if len(views) > 1:
                print(f"namespace {view.label} -> {out_bag}")
            fused = fuse_bag(
                arguments.in_bag,
                out_bag,
                config,
                arguments.overwrite,
                view,
                arguments.smooth,
                arguments.nav_rate_hz,
            )
            print_summary(fused, out_bag)
            if fused.recovery is not None:
                warning = fused.recovery.describe(arguments.in_bag)
                print(f"fuse_bag: warning: {warning}", file=sys.stderr)
                truncated = truncated or fused.recovery.truncated
    except (ParameterError, BagError, OutputError, NamespaceError, OSError) as error:
        print(f"fuse_bag: {error}", file=sys.stderr)
        sys.exit(2)
    if truncated:
        sys.exit(RECOVERED_BAG_EXIT_CODE)


def print_summary(fused: FusedBag, out_bag: str) -> None:
    for line in fused.fusion.summary():
        print(line)
    for topic, count in sorted(fused.topic_counts.items()):
        print(f"{topic:20s} {count:8d}")
    print(
        f"wrote {out_bag}: {fused.duration_s:.1f} s of data in {fused.wall_s:.1f} s "
        f"({fused.duration_s / max(fused.wall_s, 1e-9):.0f}x real time)"
    )
