"""A year of hourly motion-pack records through ``process_archive`` on a Dask ``LocalCluster``
(tools/bench.py, section ``archive_year``): files per second and × real time per core, two
workers against one, the whole year's wall time, each worker's peak memory, and every processed
hour's products in the combined table once.

The records are simulated FDCHP hours (``tools/fdchp_simulated.py``: sonic 0.753 m above a
motion pack; IMU, the pack's attitude and the sonic at 10 Hz, as the FDCHP records them, and a
magnetometer at 1 Hz; no GNSS, moored), one file per hour in a year-shaped tree
``YEAR/MM/DD/HH``. A few distinct hours are simulated (DISTINCT_HOURS: the sway and two JONSWAP
seas, and the sway again with another seed, all at one mooring); each hour of the year is a link
to one of them, drawn by its path. Their stamps are those of the simulated hour, not of the
hour the path names: the archive's work, not the calendar, is measured.

A year (8,760 files) takes hours to process on two cores, beyond the hour a bench section may
take. So the distinct hours are first processed once by one worker (the probe: the measured
per-file time, and the compiled kernels cached); from that time, the sample is sized so that
one worker and then two process it within the budget (``--budget-min``), spread evenly over the
year; the whole year's wall time is extrapolated from the sample's rate. ``--hours N`` fixes
the sample; ``--year`` processes the whole tree (hours of wall time).

Each run is ``process_archive --products-only`` (the combined Parquet table and each hour's
products CSVs, no bags) on a fresh ``LocalCluster`` of N single-threaded worker processes, from
planning the archive to writing the table (the cluster's start is not counted). One run per
worker count: on this shared machine the figures are a single sample each.

    python -m tools.bench_archive_year [--hours N | --year] [--budget-min M]
                                       # or: python -m tools.bench --only archive_year

Results go to out/bench/archive_year.json.
"""

from __future__ import annotations

import argparse
import contextlib
import datetime
import io
import json
import os
import resource
import shutil
import sys
import time
import zlib
from collections import Counter
from pathlib import Path

import distributed
import pyarrow.parquet as pq

from buoy_nav.config import fusion_config_from_files
from buoy_processing.archive import BAG_COLUMN, COMBINED_TABLE, plan_archive, run_archive
from buoy_processing.archive_pools import DaskPool
from sensor_sim import simulate_bag
from tools import fdchp_simulated
from tools.bench_plan import REPO
from wind_comp.config import compensator_config_from_files

OUT_DIR = REPO / "out" / "bench"
WORK_DIR = OUT_DIR / "archive_year"
YEAR = 2026
HOUR_S = 3600.0
MOORING_DEG = (35.0, 120.0)
"""The mooring's latitude and longitude, deg: every distinct hour is simulated there."""
DISTINCT_HOURS = {
    "sway": ("sway_6_to_9_s", ()),
    "sway_seed_14": ("sway_6_to_9_s", ("seed=14",)),
    "jonswap_tp_9_s": ("jonswap_tp_9_s", ()),
    "jonswap_tp_2_s": ("jonswap_tp_2_s", ()),
}
"""Name: (sea of ``fdchp_simulated.SEAS``, further overrides) of each distinct simulated hour."""
WORKER_COUNTS = (1, 2)
DEFAULT_BUDGET_MIN = 40.0
TWO_WORKERS_SHARE = 0.55
"""Wall time of two workers as a share of one's, for sizing the sample (1.92× measured by
tools/bench_archive.py, with some margin)."""
KILOBYTES = 1024


def log(text: str) -> None:
    print(f"bench: archive_year: {text}", file=sys.stderr, flush=True)


def simulate_hour(bag: Path, name: str, duration_s: float = HOUR_S) -> None:
    """One distinct hour (``duration_s``) of DISTINCT_HOURS as a bag, at MOORING_DEG."""
    sea, extra = DISTINCT_HOURS[name]
    scenario, _, overrides = fdchp_simulated.SEAS[sea]
    latitude, longitude = MOORING_DEG
    arguments = [scenario, str(bag), "--set", f"duration_s={duration_s}"]
    for override in (
        *overrides,
        *extra,
        # The FDCHP records the pack's attitude with every row, not once a second.
        "sensors.ahrs.sample_every=1",
        f"origin_latitude_deg={latitude}",
        f"origin_longitude_deg={longitude}",
    ):
        arguments += ["--set", override]
    for parameters in (fdchp_simulated.BUOY_PARAMS, fdchp_simulated.PARAMS):
        arguments += ["--params-file", str(parameters)]
    with contextlib.redirect_stdout(io.StringIO()):
        simulate_bag.main([*arguments, "--overwrite"])


def simulate_distinct_hours(directory: Path, duration_s: float = HOUR_S) -> list[Path]:
    """Every hour of DISTINCT_HOURS simulated into ``directory``."""
    bags = []
    for name in DISTINCT_HOURS:
        simulate_hour(directory / name, name, duration_s)
        bags.append(directory / name)
    return bags


def hours_of_year(year: int) -> list[str]:
    """``YYYY/MM/DD/HH`` of every hour of ``year`` (UTC), in order."""
    start = datetime.datetime(year, 1, 1, tzinfo=datetime.UTC)
    count = (datetime.datetime(year + 1, 1, 1, tzinfo=datetime.UTC) - start).days * 24
    return [
        (start + datetime.timedelta(hours=index)).strftime("%Y/%m/%d/%H") for index in range(count)
    ]


def source_of(relative: str, sources: list[Path]) -> Path:
    """The distinct hour an hour of the tree links to: drawn by its path (the same every
    run), so that a sample at any spacing holds every sea."""
    return sources[zlib.crc32(relative.encode()) % len(sources)]


def link_tree(root: Path, relatives: list[str], sources: list[Path]) -> Path:
    """``root/REL`` for each of ``relatives``: a link to its distinct hour (``root`` made
    anew)."""
    shutil.rmtree(root, ignore_errors=True)
    for relative in relatives:
        link = root / relative
        link.parent.mkdir(parents=True, exist_ok=True)
        link.symlink_to(source_of(relative, sources).resolve())
    return root


def spread_sample(relatives: list[str], count: int) -> list[str]:
    """``count`` of ``relatives``, evenly spaced: the middle one of each of ``count`` equal
    shares (all of them when ``count`` is not smaller)."""
    total = len(relatives)
    if count >= total:
        return list(relatives)
    return [relatives[(2 * index + 1) * total // (2 * count)] for index in range(count)]


def processing_parameters(directory: Path) -> list[str]:
    """The parameter files every hour is processed with: the shipped buoy, the FDCHP's
    geometry and rates, and the mooring's place (no GNSS tells it)."""
    directory.mkdir(parents=True, exist_ok=True)
    site = fdchp_simulated.site_params(directory, MOORING_DEG)
    return [str(fdchp_simulated.BUOY_PARAMS), str(fdchp_simulated.PARAMS), str(site)]


def _peak_rss_mb() -> float:
    """This process's peak resident memory, MB (run on each Dask worker)."""
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / KILOBYTES


def process_tree(tree: Path, out: Path, parameter_files: list[str], workers: int) -> dict:
    """``process_archive --products-only --redo`` of ``tree`` into ``out`` on a new
    ``LocalCluster`` of ``workers`` single-threaded processes: the wall time from planning to
    the combined table, the data processed, each worker's peak memory and how many bags carry
    each warning."""
    shutil.rmtree(out, ignore_errors=True)
    fusion_config = fusion_config_from_files(parameter_files)
    compensator_config = compensator_config_from_files(parameter_files)
    with distributed.LocalCluster(
        n_workers=workers,
        threads_per_worker=1,
        processes=True,
        dashboard_address=None,
        worker_dashboard_address=None,
    ) as cluster:
        started = time.monotonic()
        plan = plan_archive(
            tree, out, fusion_config, compensator_config, redo=True, products_only=True
        )
        with DaskPool(cluster.scheduler_address) as pool:
            report = run_archive(plan, pool, out, lambda outcome: None)
        wall_s = time.monotonic() - started
        with distributed.Client(cluster) as client:
            peak_rss_mb = sorted(client.run(_peak_rss_mb).values())
    failed = report.with_status("failed")
    if failed:
        raise RuntimeError(f"{failed[0].relative}: {failed[0].reason}")
    return {
        "workers": workers,
        "files": len(report.outcomes),
        "wall_s": wall_s,
        "data_s": sum(outcome.duration_s for outcome in report.outcomes),
        "peak_rss_mb_per_worker": peak_rss_mb,
        "warnings": dict(Counter(w for outcome in report.outcomes for w in outcome.warnings)),
    }


def coverage(out: Path, relatives: list[str], sources: list[Path]) -> dict:
    """Whether the combined table holds every processed hour once: each hour's rows are there,
    as many as every other hour of its distinct source has, and no window twice."""
    table = pq.read_table(out / COMBINED_TABLE, columns=[BAG_COLUMN, "window_s", "window_start_s"])
    rows = table.to_pydict()
    per_hour = Counter(rows[BAG_COLUMN])
    windows = Counter(zip(rows[BAG_COLUMN], rows["window_s"], rows["window_start_s"], strict=True))
    rows_by_source: dict[str, set[int]] = {}
    for relative in relatives:
        rows_by_source.setdefault(source_of(relative, sources).name, set()).add(per_hour[relative])
    missing = sorted(set(relatives) - set(per_hour))
    return {
        "hours": len(relatives),
        "hours_in_table": len(per_hour),
        "missing": missing,
        "foreign": sorted(set(per_hour) - set(relatives)),
        "windows_twice": sum(1 for count in windows.values() if count > 1),
        "rows": table.num_rows,
        "rows_per_hour_by_source": {name: sorted(n) for name, n in rows_by_source.items()},
        "complete": not missing
        and set(per_hour) == set(relatives)
        and all(count == 1 for count in windows.values())
        and all(len(counts) == 1 and 0 not in counts for counts in rows_by_source.values()),
    }


def rates(run: dict, year_files: int) -> dict:
    """Files per second and × real time, overall and per worker; the year's wall time at that
    rate."""
    files_per_s = run["files"] / run["wall_s"]
    return {
        "files_per_s": files_per_s,
        "files_per_s_per_core": files_per_s / run["workers"],
        "real_time_multiple": run["data_s"] / run["wall_s"],
        "real_time_multiple_per_core": run["data_s"] / run["wall_s"] / run["workers"],
        "year_wall_h": year_files / files_per_s / 3600.0,
    }


def sample_size(per_file_s: float, budget_s: float, year_files: int) -> int:
    """Files one worker and then two process within ``budget_s`` at ``per_file_s`` each."""
    fitting = int(budget_s / (per_file_s * (1.0 + TWO_WORKERS_SHARE)))
    return max(len(WORKER_COUNTS), min(year_files, fitting))


def run_archive_year(hours: int | None, whole_year: bool, budget_min: float) -> dict:
    started = time.monotonic()
    load_before = os.getloadavg()[0]
    log("simulating the distinct hours")
    sources = simulate_distinct_hours(WORK_DIR / "distinct")
    parameter_files = processing_parameters(WORK_DIR / "params")
    year = hours_of_year(YEAR)
    year_tree = link_tree(WORK_DIR / "year", year, sources)
    log(f"probe: one worker over the {len(sources)} distinct hours")
    probe_tree = link_tree(WORK_DIR / "probe", [source.name for source in sources], sources)
    probe = process_tree(probe_tree, WORK_DIR / "out_probe", parameter_files, 1)
    per_file_s = probe["wall_s"] / probe["files"]
    if whole_year:
        sample, tree = year, year_tree
    else:
        budget_s = budget_min * 60.0 - (time.monotonic() - started)
        count = hours if hours is not None else sample_size(per_file_s, budget_s, len(year))
        sample = spread_sample(year, count)
        tree = link_tree(WORK_DIR / "sample", sample, sources)
    runs = {}
    for workers in WORKER_COUNTS:
        log(f"{len(sample)} hours on {workers} worker(s)")
        out = WORK_DIR / f"out_{workers}"
        run = process_tree(tree, out, parameter_files, workers)
        run |= rates(run, len(year))
        run["coverage"] = coverage(out, sample, sources)
        runs[str(workers)] = run
    return {
        "year": YEAR,
        "year_files": len(year),
        "distinct_hours": list(DISTINCT_HOURS),
        "probe": probe | {"per_file_s": per_file_s},
        "sample_files": len(sample),
        "whole_year": whole_year,
        "sample_first": sample[0],
        "sample_last": sample[-1],
        "runs": runs,
        "two_over_one": runs["1"]["wall_s"] / runs["2"]["wall_s"],
        "complete": all(run["coverage"]["complete"] for run in runs.values()),
        "load_average_1min_before": load_before,
        "load_average_1min_after": os.getloadavg()[0],
        "cpus": os.cpu_count(),
        "bench_wall_s": time.monotonic() - started,
    }


def print_archive_year(result: dict) -> None:
    what = "the whole year" if result["whole_year"] else "a sample spread over the year"
    print(
        f"\nArchive year: process_archive --products-only on a Dask LocalCluster, "
        f"{result['sample_files']} of {result['year_files']} hourly 10 Hz motion-pack files "
        f"({what}, {result['sample_first']} … {result['sample_last']}); probe "
        f"{result['probe']['per_file_s']:.1f} s per file on one worker; "
        f"machine load average {result['load_average_1min_before']:.2f} before, "
        f"{result['load_average_1min_after']:.2f} after, {result['cpus']} CPUs"
    )
    print(
        f"  {'workers':8s} {'wall s':>8s} {'files/s':>8s} {'/core':>7s} {'× real':>8s} "
        f"{'×/core':>7s} {'year h':>7s} {'peak RSS MB per worker':>24s}  products"
    )
    for workers, run in result["runs"].items():
        rss = " / ".join(f"{mb:.0f}" for mb in run["peak_rss_mb_per_worker"])
        cover = run["coverage"]
        products = (
            f"every hour once ({cover['rows']} rows)"
            if cover["complete"]
            else f"INCOMPLETE: {len(cover['missing'])} hours missing, "
            f"{cover['windows_twice']} windows twice"
        )
        print(
            f"  {workers:8s} {run['wall_s']:8.1f} {run['files_per_s']:8.3f} "
            f"{run['files_per_s_per_core']:7.3f} {run['real_time_multiple']:8.0f} "
            f"{run['real_time_multiple_per_core']:7.0f} {run['year_wall_h']:7.1f} {rss:>24s}  "
            f"{products}"
        )
    extrapolated = "measured" if result["whole_year"] else "extrapolated from the sample"
    print(f"  two workers over one: {result['two_over_one']:.2f}×; year h: {extrapolated}")


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    size = parser.add_mutually_exclusive_group()
    size.add_argument("--hours", type=int, help="process this many hours, spread over the year")
    size.add_argument(
        "--year", action="store_true", help="process all 8,760 hours (hours of wall time)"
    )
    parser.add_argument(
        "--budget-min",
        type=float,
        default=DEFAULT_BUDGET_MIN,
        help="wall time the sample is sized for, both worker counts and the simulation "
        f"included, min (default {DEFAULT_BUDGET_MIN:g})",
    )
    arguments = parser.parse_args(argv)
    if arguments.hours is not None and arguments.hours < len(WORKER_COUNTS):
        parser.error(f"--hours: at least {len(WORKER_COUNTS)}")
    result = run_archive_year(arguments.hours, arguments.year, arguments.budget_min)
    print_archive_year(result)
    OUT_DIR.mkdir(parents=True, exist_ok=True)
    (OUT_DIR / "archive_year.json").write_text(json.dumps(result, indent=2))


if __name__ == "__main__":
    main()
