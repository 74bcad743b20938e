"""``process_bag``: fusion, wind correction and current over a recorded bag, the offline twin of
the nodes.

    process_bag IN_BAG OUT_BAG [--params-file buoy.yaml] [--params-file compensation.yaml]
                [--params-file current.yaml] [--overwrite] [--namespace NS]
                [--remap FROM:=TO ...] [--smooth] [--nav-rate-hz HZ]
                [--netcdf PATH [--netcdf-attribute NAME=VALUE ...]] [--no-bag]

Runs over the bag's sensor topics, in log-time order, the same core as ``fusion_node`` followed
by ``compensation_node`` and ``current_node`` (:func:`buoy_processing.bag_processing.process_bag`):
every ``anemometer/wind`` sample yields exactly one ``wind/true``, every ``dvl/velocity`` sample
one ``current/velocity`` (NaN when they cannot be computed). The bag needs the fusion's topics
and at least one of the two. The new bag holds ``nav/*``, ``wind/true``, ``current/velocity``,
their products (``wind/mean_<window>``, ``wind/stats_<window>``, ``current/mean_<window>``,
``current/stats_<window>``), the eddy-covariance fluxes of the wind (``wind/fluxes_<window>``,
with the sonic temperature of ``anemometer/temperature`` when the bag has it), the measured
``anemometer/wind``, ``anemometer/temperature`` and ``dvl/velocity`` and any truth topics; the
products are also written to ``<OUT_BAG>_wind_products.csv``,
``<OUT_BAG>_current_products.csv`` and ``<OUT_BAG>_wind_fluxes.csv`` (each window with its
ISO 8601 bounds, coverage and QARTOD quality flag). With ``--netcdf PATH`` the corrected
series, the products, the fluxes, the navigation and their quality flags are also written to
PATH as NetCDF-CF (CF-1.10, ACDD-1.3; :mod:`buoy_processing.netcdf_output`), with the global
attributes given as ``--netcdf-attribute NAME=VALUE`` (``creator_name``, ``institution``,
``license``, ...); an existing PATH is replaced only with ``--overwrite``. For a bag of several
buoys each namespace gets its own file, named after it (``out.nc`` → ``out_buoy1.nc``).
With ``--smooth`` ``nav/*`` carry the fixed-interval smoother's solution, the wind and the
current are computed with the smoothed attitude and velocity, and the forward filter's odometry
is kept as ``nav/forward/odometry`` (the bag is read twice; temporary records beside OUT_BAG,
about 0.35 GB per hour of 100 Hz data). With ``--nav-rate-hz HZ`` ``nav/*``, ``tf`` (and the
NetCDF file's navigation) carry the solutions at that rate only, a subset with the same stamps
and bytes, while the wind and the current are still corrected with every solution; the
processed bag's facts state the rate. With ``--no-bag`` no bag is written: the products CSVs
(and with ``--netcdf`` the NetCDF file, navigation included) alone, named after OUT_BAG as
always, holding the same values; it saves the bag's disk space and about a tenth of the time
for a user who reads only the columnar outputs. Parameters come from the same YAML files the
nodes take.
Namespaces and remappings as for ``fuse_bag``: a bag recorded under one namespace is read and
written in it; a bag of several buoys gives one output per namespace holding an anemometer or a
DVL (``OUT_BAG/buoy1`` and its CSVs ``OUT_BAG/buoy1_wind_products.csv``, ...).

All outputs are written under temporary names beside them and appear only when complete; they
may not be, contain or lie inside IN_BAG. It prints the extrinsics it used first.

Exit codes: 0 done; 2 bad arguments, parameters (an unknown name among them) or bags (one line
on stderr); 3 done, but IN_BAG was cut short (a recorder killed or out of power) and was
processed up to its last complete chunk (a warning says how much was read); 4 done, but most
wind samples or most DVL samples came out invalid (a warning names the main reason, such as a
wrong frame); 130 interrupted (SIGINT or SIGTERM), nothing left under OUT_BAG.
"""

from __future__ import annotations

import argparse
import shlex
import sys
from pathlib import Path

from buoy_common.bag_io import RECOVERED_BAG_EXIT_CODE, BagError
from buoy_common.cli import (
    INTERRUPTIBLE_EXIT_CODES,
    RECOVERED_BAG,
    ExitCode,
    command_parser,
    interruptible,
)
from buoy_common.contract import (
    DVL_TOPIC,
    SONIC_TEMPERATURE_TOPIC,
    WIND_RAW_TOPIC,
    seconds_to_iso8601,
    window_label,
)
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
from buoy_processing.bag_processing import ProcessSummary, process_bag
from buoy_processing.nav_output_rate import add_nav_rate_argument
from buoy_processing.offline_fusion import FUSION_TOPICS_HELP
from wind_comp.config import (
    COMPENSATION_PARAMETER_PREFIX,
    CURRENT_PARAMETER_PREFIX,
    compensator_config_from_files,
    current_config_from_files,
)
from wind_comp.flux_quality import FLUX_FLAG_TESTS
from wind_comp.pipeline import mostly_invalid_warning, wrong_frame_message
from wind_comp.products import CurrentProduct, QualityFlag, WindProduct

MOSTLY_INVALID_EXIT_CODE = 4
"""Exit code of a run that completed but whose wind or DVL samples came out mostly invalid."""
EXIT_CODES = (
    *INTERRUPTIBLE_EXIT_CODES,
    RECOVERED_BAG,
    ExitCode(
        MOSTLY_INVALID_EXIT_CODE,
        "done, but most wind samples or most DVL samples came out invalid; a warning names the "
        "main reason, such as a wrong frame",
    ),
)


def parse_arguments(argv):
    parser = command_parser("process_bag", __doc__, EXIT_CODES)
    parser.add_argument(
        "in_bag",
        help=f"bag with {FUSION_TOPICS_HELP}, and anemometer/wind (with "
        "anemometer/temperature for the buoyancy flux), dvl/velocity or both",
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
        help="correct the wind and the current with the fixed-interval smoother's navigation "
        "(nav/*); the forward filter's odometry goes to nav/forward/odometry",
    )
    add_nav_rate_argument(parser)
    parser.add_argument(
        "--netcdf",
        metavar="PATH",
        help="also write the corrected series, products, navigation and quality flags as "
        "NetCDF-CF (CF-1.10, ACDD-1.3) to PATH",
    )
    parser.add_argument(
        "--netcdf-attribute",
        action="append",
        default=[],
        metavar="NAME=VALUE",
        type=_attribute,
        help="a global attribute of the NetCDF file (repeatable), such as creator_name=..., "
        "institution=..., license=..., project=...",
    )
    parser.add_argument(
        "--no-bag",
        action="store_true",
        help="write no bag: the products CSVs (and the NetCDF file of --netcdf) alone, named "
        "after OUT_BAG",
    )
    add_namespace_arguments(parser)
    return parser.parse_args(argv)


def _attribute(text: str) -> tuple[str, str]:
    name, separator, value = text.partition("=")
    if not separator or not name.strip().isidentifier():
        raise argparse.ArgumentTypeError(f"expected NAME=VALUE, got {text!r}")
    return name.strip(), value


def netcdf_output_for(netcdf_path: str, view, several: bool) -> Path:
    """The NetCDF file of ``view``: ``netcdf_path`` for a single buoy, else named after the
    namespace beside it (``out.nc`` → ``out_buoy1.nc``, ``out_fleet_buoy2.nc``)."""
    path = Path(netcdf_path)
    if not several:
        return path
    name = "_".join(view.namespace.strip("/").split("/")) if view.namespace else "root"
    return path.with_name(f"{path.stem}_{name}{path.suffix}")


def print_summary(summary: ProcessSummary, out_bag: str | None, netcdf_path: Path | None) -> None:
    """What the run did and wrote (``out_bag`` None: no bag was written)."""
    for line in summary.fusion_lines:
        print(line)
    if summary.facts is not None:
        print(f"outputs: {summary.facts.north_sentence()}")
        print(f"outputs: sensors used: {summary.facts.sensor_text()}")
        print(f"outputs: {summary.facts.site_text()}")
        if summary.facts.nav_rate_hz > 0:
            print(
                f"outputs: navigation written at {summary.facts.nav_rate_hz:g} Hz; the "
                "corrections used every solution"
            )
    written = [] if out_bag is None else [str(out_bag)]
    for name, topic, correction in (
        ("wind", WIND_RAW_TOPIC, summary.wind),
        ("current", DVL_TOPIC, summary.current),
    ):
        if correction is None:
            continue
        counts = correction.status_counts
        invalid = ", ".join(
            f"{outcome} {n}" for outcome, n in counts.items() if outcome != "valid" and n
        )
        print(
            f"{topic} samples: {sum(counts.values())} in, {counts.get('valid', 0)} {name} "
            f"samples out, invalid: {invalid or 'none'}"
        )
        for reason, n in sorted(correction.rejected_messages.items()):
            print(f"rejected message {topic}: {reason}: {n}")
        for product in correction.products:
            print(
                f"{window_label(product.window_s):>6s} {name} window from "
                f"{seconds_to_iso8601(product.window_start_s)}: {_product_text(product)}"
            )
        for reason, n in sorted(correction.rejected_temperatures.items()):
            print(f"rejected message {SONIC_TEMPERATURE_TOPIC}: {reason}: {n}")
        for flux in correction.fluxes:
            print(
                f"{window_label(flux.window_s):>6s} fluxes from "
                f"{seconds_to_iso8601(flux.window_start_s)}: u* {flux.friction_velocity_mps:.3f} "
                f"m/s, w'Ts' {flux.w_ts_k_mps:.4f} K m/s, tilt {flux.tilt_deg:.1f} deg, "
                f"stationarity {flux.stationarity_u_w_percent:.0f} %, coverage "
                f"{100 * flux.coverage:.0f} %, {QualityFlag(flux.quality_flag).name.lower()}"
                f"{_raised_flux_tests_text(flux)}"
            )
        written.append(str(correction.csv_path))
        if correction.fluxes_csv_path is not None:
            written.append(str(correction.fluxes_csv_path))
    if netcdf_path is not None:
        written.append(str(netcdf_path))
    for topic, count in sorted(summary.topic_counts.items()):
        print(f"{topic:22s} {count:8d}")
    print(f"wrote {', '.join(written)}")
    print(
        f"{summary.duration_s:.1f} s of data in {summary.wall_s:.1f} s "
        f"({summary.duration_s / max(summary.wall_s, 1e-9):.0f}x real time)"
    )


def _raised_flux_tests_text(flux) -> str:
    """The flux tests a window is suspect or bad by, as " (drag_coefficient bad, ...)"."""
    raised = [
        f"{test.name} {QualityFlag(getattr(flux, test.field)).name.lower()}"
        for test in FLUX_FLAG_TESTS
        if getattr(flux, test.field) in (QualityFlag.SUSPECT, QualityFlag.BAD)
    ]
    return f" ({', '.join(raised)})" if raised else ""


def _product_text(product: WindProduct | CurrentProduct) -> str:
    counts = (
        f"{product.n_valid} valid / {product.n_invalid} invalid, coverage "
        f"{100 * product.coverage:.0f} %, {QualityFlag(product.quality_flag).name.lower()}"
    )
    if isinstance(product, CurrentProduct):
        return (
            f"{product.speed_mps:6.3f} m/s toward {product.direction_deg:6.1f} deg, "
            f"std u/v {product.std_u_mps:5.3f}/{product.std_v_mps:5.3f} m/s, {counts}"
        )
    return (
        f"{product.vector_mean_speed_mps:6.2f} m/s from "
        f"{product.vector_mean_direction_deg:6.1f} deg, gust {product.gust_mps:6.2f} m/s, "
        f"{counts}"
    )


@interruptible("process_bag")
def main(argv=None) -> None:
    argv = sys.argv[1:] if argv is None else argv
    arguments = parse_arguments(argv)
    truncated = mostly_invalid = False
    try:
        fusion_config, record_lines = fusion_config_for_bag(arguments.in_bag, arguments.params_file)
        for line in record_lines:
            print(f"record: {line}")
        compensator_config = compensator_config_from_files(arguments.params_file)
        current_config = current_config_from_files(arguments.params_file)
        print(f"extrinsics: {describe_shared_fields(fusion_config)}")
        print(
            f"extrinsics: {describe_shared_fields(compensator_config)}; {WIND_RAW_TOPIC} "
            f"expected in frame '{compensator_config.anemometer_frame_id}'"
        )
        print(
            f"extrinsics: {describe_shared_fields(current_config)}; {DVL_TOPIC} "
            f"expected in frame '{current_config.dvl_frame_id}'"
        )
        views = views_of_bag(arguments, arguments.in_bag, WIND_RAW_TOPIC, DVL_TOPIC)
        for view in views:
            out_bag = output_for(arguments.out_bag, view, several=len(views) > 1)
            netcdf_path = (
                None
                if arguments.netcdf is None
                else netcdf_output_for(arguments.netcdf, view, several=len(views) > 1)
            )
            if len(views) > 1:
                print(f"namespace {view.label} -> {out_bag}")
            summary = process_bag(
                arguments.in_bag,
                out_bag,
                fusion_config,
                compensator_config,
                arguments.overwrite,
                current_config,
                view,
                arguments.smooth,
                netcdf_path=netcdf_path,
                history=shlex.join(["process_bag", *argv]),
                netcdf_attributes=dict(arguments.netcdf_attribute),
                nav_rate_hz=arguments.nav_rate_hz,
                write_bag=not arguments.no_bag,
            )
            print_summary(summary, None if arguments.no_bag else out_bag, netcdf_path)
            for correction, topic, expected_frame_id, parameter, samples_name in (
                (
                    summary.wind,
                    WIND_RAW_TOPIC,
                    compensator_config.anemometer_frame_id,
                    COMPENSATION_PARAMETER_PREFIX + "anemometer_frame_id",
                    "wind",
                ),
                (
                    summary.current,
                    DVL_TOPIC,
                    current_config.dvl_frame_id,
                    CURRENT_PARAMETER_PREFIX + "dvl_frame_id",
                    "DVL",
                ),
            ):
                if correction is None:
                    continue
                for frame_id, n in sorted(correction.wrong_frames.items()):
                    message = wrong_frame_message(topic, frame_id, expected_frame_id, parameter)
                    print(f"process_bag: error: {n} samples of {message}", file=sys.stderr)
                warning = mostly_invalid_warning(correction.status_counts, samples_name)
                if warning is not None:
                    print(f"process_bag: warning: {warning}", file=sys.stderr)
                    mostly_invalid = True
            if summary.recovery is not None:
                warning = summary.recovery.describe(arguments.in_bag)
                print(f"process_bag: warning: {warning}", file=sys.stderr)
                truncated = truncated or summary.recovery.truncated
    except (ParameterError, BagError, OutputError, NamespaceError, OSError) as error:
        print(f"process_bag: {error}", file=sys.stderr)
        sys.exit(2)
    if truncated:
        sys.exit(RECOVERED_BAG_EXIT_CODE)
    if mostly_invalid:
        sys.exit(MOSTLY_INVALID_EXIT_CODE)
