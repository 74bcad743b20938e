"""``process_archive``: ``process_bag`` over every bag of a directory tree, in parallel.

    process_archive ARCHIVE OUT [--params-file buoy.yaml ...] [--redo]
                    [--nav-rate-hz HZ | --products-only]
                    [--workers N | --scheduler tcp://HOST:8786]
                    [--namespace NS] [--remap FROM:=TO ...]

Each bag under ARCHIVE (``ARCHIVE/REL``) is processed as ``process_bag ARCHIVE/REL OUT/REL`` would
process it, with the same parameter files, namespace options and ``--nav-rate-hz``; the wind
products of the whole archive go to ``OUT/wind_products.parquet``, one row per window, naming its
bag. With ``--products-only`` no bag is written (no ``nav/*``, ``tf`` or corrected samples): the
products alone, the combined table and each bag's products CSVs. Bags run on N local processes
(default: one per core) or, with ``--scheduler``, on the workers of a Dask distributed scheduler.
Bags done by an earlier run with the same parameters are skipped (all redone with ``--redo``); a bag
that fails is listed at the end with its reason and the others go on. See
:mod:`buoy_processing.archive`.

Exit codes: 0 every bag done; 1 some bags failed (listed on stderr); 2 bad arguments,
parameters, archive or scheduler (one line on stderr); 3 every bag done, but some were cut short
and processed up to their last complete chunk (as ``process_bag``); 130 interrupted (Ctrl-C):
bags in flight abandoned, the next run goes on from there.
"""

from __future__ import annotations

import sys
from pathlib import Path

from tqdm import tqdm

from buoy_common.cli import ExitCode, command_parser
from buoy_common.namespaces import NamespaceError, add_namespace_arguments, parse_remap
from buoy_common.parameters import ParameterError
from buoy_common.safe_output import OutputError
from buoy_nav.config import fusion_config_from_files
from buoy_processing.archive import (
    ArchiveError,
    ArchiveReport,
    BagOutcome,
    plan_archive,
    run_archive,
)
from buoy_processing.archive_pools import DaskPool, LocalPool, default_workers
from buoy_processing.nav_output_rate import add_nav_rate_argument
from wind_comp.config import compensator_config_from_files

EXIT_FAILED_BAGS = 1
EXIT_USAGE = 2
EXIT_TRUNCATED_BAGS = 3
EXIT_INTERRUPTED = 130
EXIT_CODES = (
    ExitCode(0, "every bag done"),
    ExitCode(EXIT_FAILED_BAGS, "some bags failed: they are listed on stderr with their reasons"),
    ExitCode(EXIT_USAGE, "bad arguments, parameters, archive or scheduler: one line on stderr"),
    ExitCode(
        EXIT_TRUNCATED_BAGS,
        "every bag done, but some were cut short and processed up to their last complete "
        "chunk (as process_bag)",
    ),
    ExitCode(
        EXIT_INTERRUPTED,
        "interrupted (Ctrl-C): the bags in flight abandoned; the next run goes on from there",
    ),
)


def parse_arguments(argv):
    parser = command_parser("process_archive", __doc__, EXIT_CODES)
    parser.add_argument("archive", help="directory tree holding the bags")
    parser.add_argument("out", help="output directory (created; mirrors ARCHIVE)")
    parser.add_argument(
        "--params-file",
        action="append",
        default=[],
        help="ROS parameter YAML as given to the nodes (repeatable; later files win)",
    )
    add_namespace_arguments(parser)
    written = parser.add_mutually_exclusive_group()
    add_nav_rate_argument(written)
    written.add_argument(
        "--products-only",
        action="store_true",
        help="write the products alone (the combined table and each bag's products CSVs): no "
        "bags, so no nav/*, tf or corrected samples are made",
    )
    where = parser.add_mutually_exclusive_group()
    where.add_argument(
        "--workers",
        type=int,
        default=None,
        help=f"local worker processes, one bag each at a time (default: {default_workers()}, "
        "the cores available)",
    )
    where.add_argument(
        "--scheduler",
        metavar="ADDRESS",
        help="run the bags on the workers of this Dask distributed scheduler "
        "(e.g. tcp://host:8786) instead of locally",
    )
    parser.add_argument(
        "--redo", action="store_true", help="process every bag, even those already done"
    )
    return parser.parse_args(argv)


def describe_done(outcome: BagOutcome) -> str:
    multiple = outcome.duration_s / max(outcome.wall_s, 1e-9)
    return (
        f"done {outcome.relative}: {outcome.duration_s:.0f} s of data in {outcome.wall_s:.1f} s "
        f"({multiple:.0f}x real time)"
    )


def print_report(report: ArchiveReport) -> None:
    counts = {status: len(report.with_status(status)) for status in _STATUSES}
    print(
        f"{len(report.outcomes)} bags: {counts['done']} done, {counts['skipped']} done before, "
        f"{counts['failed']} failed, {counts['interrupted']} not finished "
        f"({report.wall_s:.1f} s)"
    )
    if report.table is not None:
        print(f"wrote {report.table}")
    print_warnings(report.outcomes)
    for outcome in report.with_status("failed"):
        print(f"process_archive: failed: {outcome.relative}: {outcome.reason}", file=sys.stderr)
    if report.interrupted:
        print(
            "process_archive: interrupted; the bags not finished are processed by the next run",
            file=sys.stderr,
        )


def print_warnings(outcomes: list[BagOutcome]) -> None:
    """Each bag's warnings on stderr; one that several bags share (what their common sensors
    leave unobserved, said at the start of each) once, with how many bags and the first of
    them: an archive of a year of hourly files would otherwise repeat it 8,760 times. Every
    bag's marker keeps its own."""
    bags_of: dict[str, list[str]] = {}
    for outcome in outcomes:
        for warning in outcome.warnings:
            bags_of.setdefault(warning, []).append(outcome.relative)
    for warning, bags in bags_of.items():
        if len(bags) == 1:
            print(f"process_archive: warning: {bags[0]}: {warning}", file=sys.stderr)
        else:
            print(
                f"process_archive: warning: {len(bags)} bags (the first {bags[0]}): {warning}",
                file=sys.stderr,
            )


_STATUSES = ("done", "skipped", "failed", "interrupted")


def exit_code(report: ArchiveReport) -> int:
    if report.interrupted:
        return EXIT_INTERRUPTED
    if report.with_status("failed"):
        return EXIT_FAILED_BAGS
    if any(outcome.truncated for outcome in report.outcomes):
        return EXIT_TRUNCATED_BAGS
    return 0


def run(arguments) -> int:
    try:
        remaps = tuple(arguments.remap)
        for rule in remaps:
            parse_remap(rule)
        plan = plan_archive(
            arguments.archive,
            arguments.out,
            fusion_config_from_files(arguments.params_file),
            compensator_config_from_files(arguments.params_file),
            arguments.namespace,
            remaps,
            arguments.redo,
            arguments.nav_rate_hz,
            arguments.products_only,
        )
        if arguments.scheduler:
            pool = DaskPool(arguments.scheduler)
        else:
            pool = LocalPool(arguments.workers or default_workers())
    except (ParameterError, ArchiveError, OutputError, NamespaceError, OSError) as error:
        print(f"process_archive: {error}", file=sys.stderr)
        return EXIT_USAGE
    print(
        f"{len(plan.jobs)} bags under {arguments.archive}: {len(plan.to_do)} to process, "
        f"{len(plan.skipped)} done before; {pool.description}"
    )
    with (
        pool,
        tqdm(
            total=len(plan.jobs),
            initial=len(plan.skipped),
            desc="process_archive",
            unit="bag",
            disable=None,
        ) as bar,
    ):

        def on_outcome(outcome: BagOutcome) -> None:
            if outcome.status == "done":
                bar.write(describe_done(outcome), file=sys.stdout)
            elif outcome.status == "failed":
                bar.write(f"failed {outcome.relative}", file=sys.stdout)
            bar.update(1)

        report = run_archive(plan, pool, Path(arguments.out), on_outcome)
    print_report(report)
    return exit_code(report)


def main(argv=None) -> None:
    arguments = parse_arguments(sys.argv[1:] if argv is None else argv)
    try:
        code = run(arguments)
    except KeyboardInterrupt:  # before or after the bags ran: nothing is half-written
        print("process_archive: interrupted", file=sys.stderr)
        code = EXIT_INTERRUPTED
    sys.exit(code)
