"""``process_bag`` over a directory tree of bags: a buoy fleet's archive, reprocessed.

Every bag found under the archive (a directory holding ``metadata.yaml`` or an MCAP file, as
:class:`~buoy_common.bag_io.BagReader` reads it) is processed by
:func:`buoy_processing.bag_processing.process_bag` into the same relative place under the output
directory, exactly as ``process_bag ARCHIVE/REL OUT/REL`` would write it (the bag and its
products CSV; one output per namespace for a bag of several buoys); with ``products_only``, its
products alone (the CSVs, no bag: no ``nav/*``, ``tf`` or corrected samples are made). The bags
run in parallel, on a local process pool or on the workers of a Dask distributed scheduler.

The run is resumable. Once a bag's outputs are in place, the worker that made them writes its
wind products as a Parquet fragment and then a completion marker (both under
``OUT/.process_archive/``, each renamed into place when complete) holding what the outputs were
made from: the size and modification time of every file of the bag, a digest of the parameters
the bag was processed with and the suite's version. A later run skips a bag whose marker matches;
a changed bag, a changed parameter, another version or a missing output re-does it. A crash or
Ctrl-C loses at most the bags in flight, which leave no partial output behind (``process_bag``
writes each output under a temporary name and renames it when complete).

The combined table of the wind products of every completed bag, one row per averaging window
with the bag's relative path and namespace, is written at the end of each run to
``OUT/wind_products.parquet``, from the fragments, one row group per bag (so its size is not
bounded by memory).
"""

from __future__ import annotations

import contextlib
import dataclasses
import hashlib
import io
import json
import os
import signal
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from importlib import metadata
from pathlib import Path
from types import SimpleNamespace

import pyarrow as pa
import pyarrow.parquet as pq

from buoy_common.bag_io import BagError
from buoy_common.bag_io.common import MCAP_SUFFIX, METADATA_FILE
from buoy_common.contract import WIND_RAW_TOPIC
from buoy_common.namespaces import NamespaceError, output_for, views_of_bag
from buoy_common.parameters import ParameterError
from buoy_common.safe_output import OutputError, check_outputs_apart_from_inputs, staged_file
from buoy_nav.config import FusionConfig
from buoy_processing.bag_processing import process_bag
from wind_comp.config import CompensatorConfig
from wind_comp.products import WindProduct

STATE_DIRECTORY = ".process_archive"
COMBINED_TABLE = "wind_products.parquet"
MARKER_SUFFIX = ".done.json"
FRAGMENT_SUFFIX = ".parquet"
# Columns naming the origin of each row of the combined table, before the product's fields.
BAG_COLUMN = "bag"
NAMESPACE_COLUMN = "namespace"
# Errors a bag can raise that say what is wrong with it; anything else is reported with its type.
BAG_PROBLEMS = (BagError, OutputError, NamespaceError, ParameterError, OSError)


class ArchiveError(Exception):
    """The archive or the output directory cannot be used; the message says why."""


# ---------------------------------------------------------------------------------------------
# What a bag's outputs are made from.


def suite_version() -> str:
    """The installed version of the wind correction (what made the outputs)."""
    return metadata.version("wind_comp")


def bag_identity(bag: Path) -> dict[str, list[int]]:
    """Size (bytes) and modification time (ns) of every file of ``bag``, by name: a bag that is
    rewritten, extended or replaced changes them."""
    identity = {}
    for path in sorted(bag.iterdir()):
        if path.is_file():
            status = path.stat()
            identity[path.name] = [status.st_size, status.st_mtime_ns]
    return identity


def parameters_digest(
    fusion_config: FusionConfig,
    compensator_config: CompensatorConfig,
    namespace: str | None,
    remaps: tuple[str, ...],
    nav_rate_hz: float = 0.0,
    products_only: bool = False,
) -> str:
    """SHA-256 of every setting that decides the outputs: the resolved configurations (frozen
    dataclasses of plain values, so their repr is exact), the namespace options, the rate of
    the written navigation and whether bags are written. A parameter file edited without
    changing a value (a comment, the order) keeps the digest."""
    text = repr((fusion_config, compensator_config, namespace, tuple(remaps)))
    if nav_rate_hz:
        # Every solution written, the default, keeps the digest of the bags done before the
        # rate could be lowered: they need no redoing.
        text += f" nav_rate_hz={float(nav_rate_hz)!r}"
    if products_only:
        # A bag done without its output bag is not done for a run that writes bags.
        text += " products_only"
    return hashlib.sha256(text.encode()).hexdigest()


def is_bag(directory: Path) -> bool:
    """Whether ``directory`` is a bag: it holds ``metadata.yaml`` or an MCAP file (a bag whose
    recorder stopped before writing its metadata)."""
    return (directory / METADATA_FILE).is_file() or any(
        path.suffix == MCAP_SUFFIX and path.is_file() for path in directory.iterdir()
    )


def find_bags(archive: Path) -> list[str]:
    """Relative paths (POSIX) of the bags under ``archive``, sorted. Symbolic links to
    directories are followed (a bag linked in twice is two bags of the archive), except a link
    back to a directory above it; a bag's own directory is not searched further."""
    if is_bag(archive):
        raise ArchiveError(f"{archive} is a bag, not a directory of bags; use process_bag")
    found: list[str] = []

    def search(directory: Path, above: frozenset[Path]) -> None:
        real = directory.resolve()
        if real in above:
            return
        if directory != archive and is_bag(directory):
            found.append(directory.relative_to(archive).as_posix())
            return
        for child in sorted(directory.iterdir()):
            if child.is_dir():
                search(child, above | {real})

    search(archive, frozenset())
    return sorted(found)


# ---------------------------------------------------------------------------------------------
# One bag, on a worker.


@dataclass(frozen=True)
class BagJob:
    """Everything a worker needs to process one bag of the archive (sent to it by pickling)."""

    relative: str
    archive: str
    out: str
    fusion_config: FusionConfig
    compensator_config: CompensatorConfig
    namespace: str | None
    remaps: tuple[str, ...]
    digest: str
    version: str
    nav_rate_hz: float = 0.0
    """Rate of the written navigation, Hz (0: every solution), as ``process_bag --nav-rate-hz``."""
    products_only: bool = False
    """Write the bag's products alone: no output bag (:func:`process_bag`'s ``write_bag``)."""

    @property
    def in_bag(self) -> Path:
        return Path(self.archive) / self.relative

    @property
    def out_bag(self) -> Path:
        return Path(self.out) / self.relative

    @property
    def marker(self) -> Path:
        return state_path(Path(self.out), self.relative, MARKER_SUFFIX)

    @property
    def fragment(self) -> Path:
        return state_path(Path(self.out), self.relative, FRAGMENT_SUFFIX)


@dataclass
class BagOutcome:
    """What became of one bag: ``done``, ``skipped`` (done by an earlier run), ``failed`` (with
    the reason) or ``interrupted`` (abandoned on Ctrl-C, nothing written)."""

    relative: str
    status: str
    reason: str = ""
    outputs: list[str] = field(default_factory=list)
    warnings: list[str] = field(default_factory=list)
    truncated: bool = False
    duration_s: float = 0.0
    wall_s: float = 0.0


def state_path(out: Path, relative: str, suffix: str) -> Path:
    """Where the marker or the products fragment of bag ``relative`` is kept."""
    return out / STATE_DIRECTORY / (relative + suffix)


# Set in the processes of the local pool, which share the tool's terminal and process group.
_in_local_pool = False


def prepare_pool_worker() -> None:
    """Start of a local pool's worker. Ctrl-C, which reaches the whole process group, is ignored
    between bags (an idle worker would die with a traceback) and taken by a bag in progress."""
    global _in_local_pool
    _in_local_pool = True
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    # The pool starts its workers with Ctrl-C blocked, so that none dies of it while importing.
    signal.pthread_sigmask(signal.SIG_UNBLOCK, {signal.SIGINT})


def process_archived_bag(job: BagJob) -> BagOutcome:
    """Process one bag into its outputs, its products fragment and its marker, in that order.

    Never raises for a problem of the bag: it is returned as a ``failed`` outcome with the
    reason. Ctrl-C while it works (on a local pool) abandons the bag: ``process_bag`` deletes
    its partial outputs, and the outcome says ``interrupted``.
    """
    started = time.monotonic()
    if _in_local_pool:
        signal.signal(signal.SIGINT, signal.default_int_handler)
    try:
        return _process(job, started)
    except KeyboardInterrupt:
        return BagOutcome(job.relative, "interrupted", "interrupted")
    except BAG_PROBLEMS as error:
        return BagOutcome(job.relative, "failed", str(error), wall_s=time.monotonic() - started)
    except Exception as error:  # a bag the suite cannot handle must not stop the archive
        reason = f"{type(error).__name__}: {error}"
        return BagOutcome(job.relative, "failed", reason, wall_s=time.monotonic() - started)
    finally:
        if _in_local_pool:
            signal.signal(signal.SIGINT, signal.SIG_IGN)


def _process(job: BagJob, started: float) -> BagOutcome:
    in_bag, out_bag = job.in_bag, job.out_bag
    # A marker left by an earlier run no longer describes the outputs once they are replaced.
    job.marker.unlink(missing_ok=True)
    identity = bag_identity(in_bag)
    options = SimpleNamespace(namespace=job.namespace, remap=list(job.remaps))
    views = views_of_bag(options, in_bag, WIND_RAW_TOPIC)
    outcome = BagOutcome(job.relative, "done")
    rows = []
    # process_bag draws a progress bar of its own on a terminal, which in the local pool is the
    # tool's, where the archive has its own bar. (A Dask worker may run bags in threads: there
    # the process-wide stderr stays as it is.)
    quiet = (
        contextlib.redirect_stderr(io.StringIO()) if _in_local_pool else contextlib.nullcontext()
    )
    with quiet:
        for view in views:
            output = output_for(out_bag, view, several=len(views) > 1)
            output.parent.mkdir(parents=True, exist_ok=True)
            # Every core runs a bag of its own: the bag is written in this process.
            summary = process_bag(
                in_bag,
                output,
                job.fusion_config,
                job.compensator_config,
                overwrite=True,
                view=view,
                write_in_background=False,
                nav_rate_hz=job.nav_rate_hz,
                write_bag=not job.products_only,
                say_statements=False,
            )
            # The products table is the wind's; a bag with a DVL also gets its current CSV,
            # one with an anemometer the CSV of its fluxes.
            corrections = [c for c in (summary.wind, summary.current) if c is not None]
            if not job.products_only:
                outcome.outputs.append(str(output))
            outcome.outputs += [str(c.csv_path) for c in corrections]
            outcome.outputs += [
                str(c.fluxes_csv_path) for c in corrections if c.fluxes_csv_path is not None
            ]
            outcome.duration_s += summary.duration_s
            # Kept in the bag's marker; the tool says each once for all the bags that share it.
            outcome.warnings += [s for s in summary.statements if s not in outcome.warnings]
            if summary.recovery is not None:
                outcome.warnings.append(summary.recovery.describe(str(in_bag)))
                outcome.truncated = outcome.truncated or summary.recovery.truncated
            if summary.wind is not None:
                rows += [(view.label, product) for product in summary.wind.products]
    job.fragment.parent.mkdir(parents=True, exist_ok=True)
    write_products_fragment(job.relative, rows, job.fragment)
    outcome.wall_s = time.monotonic() - started
    write_marker(job, identity, outcome)
    return outcome


# ---------------------------------------------------------------------------------------------
# Markers and the products table.


def write_marker(job: BagJob, identity: dict, outcome: BagOutcome) -> None:
    """The completion marker of ``job``'s bag, renamed into place once written."""
    record = {
        "bag": job.relative,
        "bag_files": identity,
        "parameters_sha256": job.digest,
        "suite_version": job.version,
        "outputs": [os.path.relpath(path, job.out) for path in outcome.outputs],
        "warnings": outcome.warnings,
        "truncated": outcome.truncated,
        "data_s": outcome.duration_s,
        "wall_s": outcome.wall_s,
        "finished_utc": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()),
    }
    with staged_file(job.marker) as stream:
        json.dump(record, stream, indent=1)


def completed_outcome(job: BagJob) -> BagOutcome | None:
    """The outcome recorded by an earlier run, if its marker says the outputs were made from
    this bag as it is now, with the same parameters and version, and they are all there."""
    try:
        record = json.loads(job.marker.read_text())
        identity = bag_identity(job.in_bag)
    except (OSError, ValueError):
        return None
    out = Path(job.out)
    if (
        record.get("bag_files") != identity
        or record.get("parameters_sha256") != job.digest
        or record.get("suite_version") != job.version
        or not job.fragment.is_file()
        or not all((out / path).exists() for path in record.get("outputs", []))
    ):
        return None
    return BagOutcome(
        job.relative,
        "skipped",
        outputs=[str(out / path) for path in record["outputs"]],
        warnings=record.get("warnings", []),
        truncated=bool(record.get("truncated")),
        duration_s=float(record.get("data_s", 0.0)),
    )


def _arrow_type(python_type) -> pa.DataType:
    return pa.int64() if python_type in (int, "int") else pa.float64()


PRODUCT_FIELDS = [f.name for f in dataclasses.fields(WindProduct)]
PRODUCTS_CONVENTIONS = (
    "One row per averaging window of one bag (its path under the archive) and namespace. Units "
    "are in the column names (_s seconds, _mps m/s, _deg degrees). Times are header stamps, "
    "seconds since 1970-01-01 UTC. Wind components are East, North, Up (toward); directions "
    "are where the wind comes FROM, clockwise from true north. coverage is the share of a full "
    "window's samples held valid; quality_flag follows QARTOD (1 good, 2 not evaluated, "
    "3 suspect, 4 bad, 9 missing)."
)


def products_schema() -> pa.Schema:
    """The combined table's columns, with the version of the suite that wrote it and the
    conventions of its columns as schema metadata, so that a file read years later says both."""
    return pa.schema(
        [
            pa.field(BAG_COLUMN, pa.string()),
            pa.field(NAMESPACE_COLUMN, pa.string()),
            *(pa.field(f.name, _arrow_type(f.type)) for f in dataclasses.fields(WindProduct)),
        ],
        metadata={"wind_comp_version": suite_version(), "conventions": PRODUCTS_CONVENTIONS},
    )


def write_products_fragment(relative: str, rows: list[tuple[str, WindProduct]], path: Path) -> None:
    """The products of one bag as a Parquet file of the combined table's schema, renamed into
    place once written."""
    columns = {
        BAG_COLUMN: [relative] * len(rows),
        NAMESPACE_COLUMN: [namespace for namespace, _ in rows],
    }
    for name in PRODUCT_FIELDS:
        columns[name] = [getattr(product, name) for _, product in rows]
    table = pa.Table.from_pydict(columns, schema=products_schema())
    staged = path.with_name(f"{path.name}.partial-{os.getpid()}")
    try:
        pq.write_table(table, staged)
        staged.replace(path)
    finally:
        staged.unlink(missing_ok=True)


def write_combined_table(out: Path, relatives: list[str]) -> Path:
    """``OUT/wind_products.parquet``: the fragments of ``relatives`` (completed bags), in their
    order, one row group each; renamed into place once written."""
    out.mkdir(parents=True, exist_ok=True)
    final = out / COMBINED_TABLE
    staged = final.with_name(f"{final.name}.partial-{os.getpid()}")
    try:
        with pq.ParquetWriter(staged, products_schema()) as writer:
            for relative in relatives:
                writer.write_table(pq.read_table(state_path(out, relative, FRAGMENT_SUFFIX)))
        staged.replace(final)
    finally:
        staged.unlink(missing_ok=True)
    return final


# ---------------------------------------------------------------------------------------------
# The run.


@dataclass
class ArchivePlan:
    """The bags of an archive, split into those to process and those already done."""

    jobs: list[BagJob]
    to_do: list[BagJob]
    skipped: list[BagOutcome]


def plan_archive(
    archive: Path,
    out: Path,
    fusion_config: FusionConfig,
    compensator_config: CompensatorConfig,
    namespace: str | None = None,
    remaps: tuple[str, ...] = (),
    redo: bool = False,
    nav_rate_hz: float = 0.0,
    products_only: bool = False,
) -> ArchivePlan:
    """Find the bags of ``archive`` and decide which need processing (all with ``redo``);
    ``nav_rate_hz``: the rate of their written navigation, Hz (0: every solution);
    ``products_only``: write their products alone, no output bags.
    Raises ArchiveError for a missing archive and OutputError for an output directory that
    overlaps it."""
    archive, out = Path(archive), Path(out)
    if not archive.is_dir():
        raise ArchiveError(f"archive {archive} is not a directory")
    check_outputs_apart_from_inputs([archive], [out])
    if out.exists() and not out.is_dir():
        raise ArchiveError(f"output {out} exists and is not a directory")
    digest = parameters_digest(
        fusion_config, compensator_config, namespace, remaps, nav_rate_hz, products_only
    )
    version = suite_version()
    jobs = [
        BagJob(
            relative,
            str(archive.resolve()),
            str(out.resolve()),
            fusion_config,
            compensator_config,
            namespace,
            tuple(remaps),
            digest,
            version,
            nav_rate_hz,
            products_only,
        )
        for relative in find_bags(archive)
    ]
    if not jobs:
        raise ArchiveError(f"archive {archive} holds no bag (a directory with {METADATA_FILE})")
    to_do, skipped = [], []
    for job in jobs:
        done = None if redo else completed_outcome(job)
        if done is None:
            to_do.append(job)
        else:
            skipped.append(done)
    # Largest first: the workers then finish close together, not with one long bag at the end.
    to_do.sort(key=lambda job: -sum(size for size, _ in bag_identity(job.in_bag).values()))
    return ArchivePlan(jobs, to_do, skipped)


@dataclass
class ArchiveReport:
    """The outcome of every bag of the archive, and where the combined table is."""

    outcomes: list[BagOutcome]
    table: Path | None
    interrupted: bool
    wall_s: float

    def with_status(self, status: str) -> list[BagOutcome]:
        return [outcome for outcome in self.outcomes if outcome.status == status]


def completed_bags(plan: ArchivePlan, outcomes: list[BagOutcome]) -> list[str]:
    """Relative paths of the bags whose outputs are complete, in the archive's order."""
    finished = {o.relative for o in outcomes if o.status in ("done", "skipped")}
    return [job.relative for job in plan.jobs if job.relative in finished]


def run_archive(
    plan: ArchivePlan, pool, out: Path, on_outcome: Callable[[BagOutcome], None]
) -> ArchiveReport:
    """Process the bags of ``plan`` still to do on ``pool`` (:mod:`buoy_processing.archive_pools`),
    calling ``on_outcome`` as each finishes, then write the combined table of every completed
    bag. On Ctrl-C, the bags in flight are abandoned, the rest reported as not done, and the
    table is left as it was (the next run writes it)."""
    started = time.monotonic()
    outcomes = list(plan.skipped)
    interrupted = False
    try:
        for outcome in pool.run(process_archived_bag, plan.to_do):
            outcomes.append(outcome)
            on_outcome(outcome)
    except KeyboardInterrupt:
        interrupted = True
        for outcome in pool.abandon():
            outcomes.append(outcome)
            on_outcome(outcome)
    reported = {outcome.relative for outcome in outcomes}
    outcomes += [
        BagOutcome(job.relative, "interrupted", "not finished")
        for job in plan.to_do
        if job.relative not in reported
    ]
    interrupted = interrupted or any(o.status == "interrupted" for o in outcomes)
    table = None if interrupted else write_combined_table(out, completed_bags(plan, outcomes))
    order = {job.relative: index for index, job in enumerate(plan.jobs)}
    outcomes.sort(key=lambda outcome: order[outcome.relative])
    return ArchiveReport(outcomes, table, interrupted, time.monotonic() - started)
