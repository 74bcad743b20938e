"""Archive throughput of ``process_archive`` (tools/bench.py, section ``archive``): the same
archive processed by one local worker and by two, each twice, alternating, in this run.

The archive is a tree of links to the committed bags recorded with the shipped buoy (each bag
under two buoys, so that two workers finish close together); every run processes all of it
anew (``--redo``), from starting the pool to writing the combined table. The figure of each
worker count is its fastest run: on a shared machine the others measure the neighbours too.

    python -m tools.bench_archive      # or: python -m tools.bench --only archive
"""

from __future__ import annotations

import json
import os
import shutil
import sys
import time
from pathlib import Path

from buoy_nav.config import fusion_config_from_files
from buoy_processing.archive import plan_archive, run_archive
from buoy_processing.archive_pools import LocalPool
from tools.bench_plan import PROCESSING_PARAMS, REPO
from wind_comp.config import compensator_config_from_files

ARCHIVE_BAGS = (
    "static",
    "tilt_table",
    "wind_tunnel_10",
    "vertical_wind_5",
    "sea_state",
    "open_ocean",
)
ARCHIVE_BUOYS = ("buoy1", "buoy2")
WORKER_COUNTS = (1, 2)
ARCHIVE_RUNS = 2
ARCHIVE_SPEEDUP_TARGET = 1.7
OUT_DIR = REPO / "out" / "bench"


def linked_archive(root: Path) -> Path:
    """``root/archive/<buoy>/<bag>``: links to the committed bags."""
    archive = root / "archive"
    shutil.rmtree(archive, ignore_errors=True)
    for buoy in ARCHIVE_BUOYS:
        (archive / buoy).mkdir(parents=True)
        for bag in ARCHIVE_BAGS:
            (archive / buoy / bag).symlink_to(REPO / "bags" / bag)
    return archive


def run_archive_throughput(work_dir: Path) -> dict:
    archive = linked_archive(work_dir)
    fusion_config = fusion_config_from_files(PROCESSING_PARAMS)
    compensator_config = compensator_config_from_files(PROCESSING_PARAMS)
    load_before = os.getloadavg()[0]
    walls: dict[int, list[float]] = {workers: [] for workers in WORKER_COUNTS}
    data_s = 0.0
    for run in range(1, ARCHIVE_RUNS + 1):
        for workers in WORKER_COUNTS:
            out = work_dir / f"out_{workers}"
            shutil.rmtree(out, ignore_errors=True)
            os.sync()
            print(
                f"bench: archive: {workers} worker(s), run {run} of {ARCHIVE_RUNS}",
                file=sys.stderr,
                flush=True,
            )
            started = time.monotonic()
            plan = plan_archive(archive, out, fusion_config, compensator_config, redo=True)
            with LocalPool(workers) as pool:
                report = run_archive(plan, pool, out, lambda outcome: None)
            walls[workers].append(time.monotonic() - started)
            failed = report.with_status("failed")
            if failed:
                raise RuntimeError(f"bench: archive: {failed[0].relative}: {failed[0].reason}")
            data_s = sum(outcome.duration_s for outcome in report.outcomes)
    by_workers = {
        str(workers): {
            "runs_wall_s": runs,
            "wall_s": min(runs),
            "real_time_multiple": data_s / min(runs),
        }
        for workers, runs in walls.items()
    }
    speedup = min(walls[1]) / min(walls[2])
    return {
        "bags": len(plan.jobs),
        "data_s": data_s,
        "workers": by_workers,
        "speedup_two_over_one": speedup,
        "target_speedup": ARCHIVE_SPEEDUP_TARGET,
        "pass": bool(speedup >= ARCHIVE_SPEEDUP_TARGET),
        "load_average_1min_before": load_before,
        "load_average_1min_after": os.getloadavg()[0],
        "cpus": os.cpu_count(),
    }


def print_archive(result: dict) -> None:
    print(
        f"\nTable 8 — archive throughput: process_archive over {result['bags']} bags "
        f"({result['data_s']:.0f} s of data), local pool, best of the runs (machine load average "
        f"{result['load_average_1min_before']:.2f} before, "
        f"{result['load_average_1min_after']:.2f} after, {result['cpus']} CPUs)"
    )
    print(f"  {'workers':8s} {'wall s':>8s} {'× real time':>12s}   wall s of each run")
    for workers, figures in result["workers"].items():
        runs = " / ".join(f"{wall:.1f}" for wall in figures["runs_wall_s"])
        multiple = figures["real_time_multiple"]
        print(f"  {workers:8s} {figures['wall_s']:8.1f} {multiple:12.1f}   {runs}")
    verdict = "PASS" if result["pass"] else "MISS"
    print(
        f"  two workers over one: {result['speedup_two_over_one']:.2f}×  "
        f"(target ≥ {result['target_speedup']}×) {verdict}"
    )


def main() -> None:
    result = run_archive_throughput(OUT_DIR / "archive")
    print_archive(result)
    OUT_DIR.mkdir(parents=True, exist_ok=True)
    with open(OUT_DIR / "archive.json", "w") as stream:
        json.dump(result, stream, indent=2)


if __name__ == "__main__":
    main()
