"""A motion-pack hour to NetCDF (tools/bench.py, section ``fdchp_hour``): how fast ``process_bag
--netcdf`` takes one hour of 10 Hz FDCHP-like data (IMU, the pack's own attitude ``imu/data``,
sonic; moored, no GNSS), against the target of 1 000× real time.

Two hours of input, each imported from an FDCHP L0 file through the shipped column map
(``import_records``), as a user's record would be:

- simulated: the simulator playing an FDCHP (``tools/fdchp_simulated.py``, its
  ``sway_6_to_9_s`` sea) for 30 s of settling and an hour, written in the L0 layout; processed
  with ``buoy.yaml``, ``tools/fdchp_simulated_params.yaml`` and the mooring's site;
- the OOI record repeated: the 12 009 rows of ``tests/data/ooi_fdchp/fdchp_test_dp.dat`` three
  times in one file (the column map stamps rows at 10 Hz, so the three copies follow one another
  without a gap: 3 602.7 s; the motion jumps where one copy meets the next, twice in the hour);
  processed with ``ooi_fdchp_params.yaml``.

Each is processed RUNS times in this process two ways, alternately (after a first run that
loads every module and numba's compiled kernels, not counted): with the output bag, as
``process_bag --netcdf``, and to the NetCDF file and the products CSVs alone, as
``process_bag --netcdf --no-bag``. The figure of each way is its fastest run: wall and CPU time
of this process (the processing) and of the process writing the output bag (on a second core),
× real time of the wall time and of this process's CPU time. Start-up is apart: the wall time from
starting ``process_bag --netcdf`` as a command to its first output message, cold (numba's cache
files and the project's bytecode caches removed, as after a change of the sources) and warm
(the caches the cold run wrote). What a user's one command costs beyond the processing is
apart too: ``process_bag --netcdf --no-bag`` started and run to its exit, warm, less the same
processing in a process that has run it before (the fixed cost: the start-up, the compiled code
loaded at its first call, the modules imported where first needed). A cProfile of one run of
each hour says where the time goes.

    python -m tools.bench_fdchp_hour [--runs N]
    python -m tools.bench --only fdchp_hour

Results go to out/bench/fdchp_hour.json, the profiles' top functions with them.
"""

from __future__ import annotations

import contextlib
import cProfile
import hashlib
import io
import os
import pstats
import resource
import shutil
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

from buoy_common.import_records import import_records
from buoy_nav.config import fusion_config_from_files
from buoy_processing.bag_processing import process_bag
from tools import bench_speed, compiled_caches, fdchp_simulated
from tools.bench_command import run_timed_tool
from tools.bench_fdchp import COLUMN_MAP
from tools.bench_fdchp import PARAMS as OOI_PARAMS
from tools.interpreter import describe, interpreter
from wind_comp.config import compensator_config_from_files

REPO = Path(__file__).resolve().parent.parent
OUT_DIR = REPO / "out/bench"
WORK_DIR = OUT_DIR / "runs/fdchp_hour"
CACHE_DIR = OUT_DIR / "cache/fdchp_hour"
OOI_RECORD = REPO / "tests/data/ooi_fdchp/fdchp_test_dp.dat"
OOI_COPIES = 3
SIMULATED_SEA = "sway_6_to_9_s"
HOUR_ROWS = 36000
RUNS = 3
TARGET_REAL_TIME = 1000.0
PROFILE_LINES = 25


def _cache_key(*paths: Path) -> str:
    """Digest of the files (and every source of the simulator) an input hour is made from."""
    digest = hashlib.sha256()
    sources = sorted((REPO / "src/sensor_sim/sensor_sim").rglob("*.py"))
    for path in [*paths, *sources, Path(fdchp_simulated.__file__), COLUMN_MAP]:
        digest.update(path.read_bytes())
    return digest.hexdigest()[:12]


def _import(record_file: Path, bag: Path) -> None:
    with contextlib.redirect_stdout(io.StringIO()):
        import_records(record_file, COLUMN_MAP, bag, overwrite=True)


def simulated_hour() -> tuple[Path, list[Path]]:
    """The simulated FDCHP hour's bag (cached) and its parameter files."""
    scenario, site_deg, overrides = fdchp_simulated.SEAS[SIMULATED_SEA]
    work = CACHE_DIR / f"simulated_{_cache_key(fdchp_simulated.PARAMS)}"
    work.mkdir(parents=True, exist_ok=True)
    params = [
        fdchp_simulated.BUOY_PARAMS,
        fdchp_simulated.PARAMS,
        fdchp_simulated.site_params(work, site_deg),
    ]
    bag = work / "fdchp"
    if not (bag / "metadata.yaml").exists():
        simulated = work / "simulated"
        rows = fdchp_simulated.SETTLE_ROWS + HOUR_ROWS
        fdchp_simulated.simulate(simulated, scenario, overrides, rows)
        record, _, _ = fdchp_simulated.fdchp_record(simulated)
        record_file = work / "fdchp_simulated.dat"
        np.savetxt(record_file, record[fdchp_simulated.SETTLE_ROWS :], delimiter=",", fmt="%.10g")
        _import(record_file, bag)
        shutil.rmtree(simulated)
    return bag, params


def repeated_ooi_hour() -> tuple[Path, list[Path]]:
    """The OOI record's rows OOI_COPIES times over, imported (cached), and its parameters."""
    work = CACHE_DIR / f"ooi_repeated_{_cache_key(OOI_RECORD)}"
    work.mkdir(parents=True, exist_ok=True)
    bag = work / "fdchp"
    if not (bag / "metadata.yaml").exists():
        record_file = work / "fdchp_repeated.dat"
        record_file.write_text(OOI_RECORD.read_text() * OOI_COPIES)
        _import(record_file, bag)
    return bag, [OOI_PARAMS]


def _children_cpu_s() -> float:
    children = resource.getrusage(resource.RUSAGE_CHILDREN)
    return children.ru_utime + children.ru_stime


OUTPUTS = {"with_bag": True, "netcdf_only": False}
"""The two ways an hour is timed, by name: whether the output bag is written."""


def _process(bag: Path, params: list[Path], out: Path, write_bag: bool = True):
    files = [str(path) for path in params]
    with contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(io.StringIO()):
        return process_bag(
            bag,
            out / "processed",
            fusion_config_from_files(files),
            compensator_config_from_files(files),
            overwrite=True,
            netcdf_path=out / "processed.nc",
            write_bag=write_bag,
        )


def timed_runs(bag: Path, params: list[Path], out: Path, runs: int) -> dict:
    """``runs`` timed runs of each way of :data:`OUTPUTS`, alternating, after one untimed: by
    way, the fastest wall and every run."""
    _process(bag, params, out)
    figures = {name: [] for name in OUTPUTS}
    for _ in range(runs):
        for name, write_bag in OUTPUTS.items():
            os.sync()
            cpu_s, writer_cpu_s = time.process_time(), _children_cpu_s()
            summary = _process(bag, params, out, write_bag)
            figures[name].append(
                {
                    "wall_s": summary.wall_s,
                    "cpu_s": time.process_time() - cpu_s,
                    "writer_cpu_s": _children_cpu_s() - writer_cpu_s,
                }
            )
    return {name: _fastest(timed, summary.duration_s) for name, timed in figures.items()}


def _fastest(figures: list[dict], data_s: float) -> dict:
    """The fastest of the timed ``figures`` of an hour of ``data_s`` s, and every run."""
    best = min(figures, key=lambda run: run["wall_s"])
    return {
        "data_s": data_s,
        **best,
        "cpu_s": min(run["cpu_s"] for run in figures),
        "real_time_multiple": data_s / best["wall_s"],
        "cpu_real_time_multiple": data_s / min(run["cpu_s"] for run in figures),
        "us_per_sample": best["wall_s"] / (data_s * fdchp_simulated.RATE_HZ) * 1e6,
        "runs": figures,
        "pass": bool(data_s / best["wall_s"] >= TARGET_REAL_TIME),
    }


def startup(bag: Path, params: list[Path], out: Path, runs: int) -> dict:
    """Wall s from starting ``process_bag --netcdf`` to its first output message, cold and warm,
    the fastest of ``runs`` each."""
    arguments = ["--netcdf", str(out / "startup.nc")]
    cold, warm = [], []
    for _ in range(runs):
        compiled_caches.remove()
        cold.append(
            bench_speed.first_output_s("process_bag", bag, out / "startup", params, arguments)
        )
        warm.append(
            bench_speed.first_output_s("process_bag", bag, out / "startup", params, arguments)
        )
    compiled_caches.rebuild()
    return {"cold_s": min(cold), "warm_s": min(warm), "runs_cold_s": cold, "runs_warm_s": warm}


def whole_command(bag: Path, params: list[Path], out: Path, runs: int, warm_s: float) -> dict:
    """Wall s of ``process_bag --netcdf --no-bag`` as one command on the hour, start to exit
    (the compiled caches warm), the fastest of ``runs``; and its fixed cost: that less
    ``warm_s``, the same processing in a process that has run it before (the start-up, the
    compiled code loaded at its first call, the modules imported where first needed)."""
    command = [
        sys.executable,
        "-c",
        "import sys; from buoy_processing.process_bag import main; sys.exit(main())",
        *bench_speed.tool_arguments(
            bag, out / "command", params, ["--no-bag", "--netcdf", str(out / "command.nc")]
        ),
    ]
    walls = []
    for _ in range(runs):
        started_s = time.monotonic()
        completed = subprocess.run(command, capture_output=True, text=True)
        walls.append(time.monotonic() - started_s)
        if completed.returncode not in DONE_EXIT_CODES:
            raise RuntimeError(
                f"process_bag exited {completed.returncode}: {completed.stderr[-500:]}"
            )
    return {"wall_s": min(walls), "fixed_s": min(walls) - warm_s, "runs_wall_s": walls}


DONE_EXIT_CODES = (0, 4)
"""process_bag's exit codes of a run that wrote its outputs (4: most wind samples invalid, as
on the OOI record, whose mooring is stated too tight for its motion)."""


AREAS = (
    ("fusion (buoy_nav)", ("/buoy_nav/",)),
    ("wind correction (wind_comp)", ("/wind_comp/",)),
    ("offline tools, NetCDF (buoy_processing)", ("/buoy_processing/",)),
    ("bag reading and writing, contract (buoy_common)", ("/buoy_common/",)),
    ("numpy", ("/numpy/",)),
    ("rosbags (decoding)", ("/rosbags/",)),
    ("xarray, netCDF4, pandas", ("/xarray/", "/netCDF4/", "/pandas/")),
)
"""Where a function's own time is counted: the first area whose path it lies under (the rest,
builtins included, is "other")."""


def profile(bag: Path, params: list[Path], out: Path) -> dict:
    """One run under cProfile: own time by area (:data:`AREAS`) and the functions of most own
    time, with their cumulative time."""
    profiler = cProfile.Profile()
    profiler.runcall(_process, bag, params, out)
    stats = pstats.Stats(profiler).stats
    areas = dict.fromkeys([name for name, _ in AREAS] + ["other"], 0.0)
    for (file, _, _), (_, _, own, _, _) in stats.items():
        area = next((name for name, parts in AREAS if any(p in file for p in parts)), "other")
        areas[area] += own
    rows = [
        {
            "function": f"{Path(file).name}:{line}({name})",
            "calls": calls,
            "own_s": own,
            "cumulative_s": cumulative,
        }
        for (file, line, name), (_, calls, own, cumulative, _) in stats.items()
    ]
    total_s = sum(row["own_s"] for row in rows)
    rows.sort(key=lambda row: -row["own_s"])
    return {
        "total_s": total_s,
        "areas_s": areas,
        "functions": [{**row, "share": row["own_s"] / total_s} for row in rows[:PROFILE_LINES]],
    }


def run_fdchp_hour(runs: int = RUNS, log=lambda text: None) -> dict:
    results = {
        "target_real_time_multiple": TARGET_REAL_TIME,
        "cpus": os.cpu_count(),
        "interpreter": interpreter(),
    }
    results["load_average_1min_before"] = os.getloadavg()[0]
    for name, make in (("simulated", simulated_hour), ("ooi_repeated", repeated_ooi_hour)):
        log(f"bench: fdchp_hour: {name} ...")
        bag, params = make()
        out = WORK_DIR / name
        out.mkdir(parents=True, exist_ok=True)
        timed = timed_runs(bag, params, out, runs)
        results[name] = {
            **timed,
            "startup": startup(bag, params, out, runs),
            "command": whole_command(bag, params, out, runs, timed["netcdf_only"]["wall_s"]),
            "profile": profile(bag, params, out),
        }
    results["load_average_1min_after"] = os.getloadavg()[0]
    return results


def print_fdchp_hour(result: dict) -> None:
    print(
        "\nA motion-pack hour to NetCDF: process_bag --netcdf on one hour of 10 Hz FDCHP data "
        f"(best of the runs; load average {result['load_average_1min_before']:.2f} before, "
        f"{result['load_average_1min_after']:.2f} after, {result['cpus']} CPUs)"
    )
    print(f"  on {describe(result['interpreter'])}")
    print(
        f"  {'hour':14s} {'outputs':12s} {'data s':>7s} {'wall s':>7s} {'× real time':>11s} "
        f"{'target ≥ 1000×':14s} {'CPU s':>6s} {'× per CPU s':>11s} {'writer CPU s':>12s} "
        f"{'µs/sample':>9s}"
    )
    for name in ("simulated", "ooi_repeated"):
        for outputs in OUTPUTS:
            s = result[name][outputs]
            verdict = "PASS" if s["pass"] else "MISS"
            print(
                f"  {name:14s} {outputs:12s} {s['data_s']:7.0f} {s['wall_s']:7.2f} "
                f"{s['real_time_multiple']:11.0f} {verdict:14s} {s['cpu_s']:6.2f} "
                f"{s['cpu_real_time_multiple']:11.0f} {s['writer_cpu_s']:12.2f} "
                f"{s['us_per_sample']:9.0f}"
            )
    for name in ("simulated", "ooi_repeated"):
        startup_s, command = result[name]["startup"], result[name]["command"]
        data_s = result[name]["netcdf_only"]["data_s"]
        print(
            f"  {name}: start-up cold {startup_s['cold_s']:.2f} s, "
            f"warm {startup_s['warm_s']:.2f} s; "
            f"one command --no-bag, start to exit {command['wall_s']:.2f} s "
            f"({data_s / command['wall_s']:.0f}× real time), fixed cost {command['fixed_s']:.2f} s"
        )
    print(
        "  outputs: with_bag, process_bag --netcdf; netcdf_only, with --no-bag (the NetCDF file "
        "and the CSVs). start-up: wall s from starting the command to its first output message "
        "(cold: numba's and the bytecode caches removed); one command: process_bag --netcdf "
        "--no-bag started and run to its exit, warm; fixed cost: that less netcdf_only's wall s "
        "(the start-up, the compiled code loaded at its first call, the modules imported where "
        "first needed); µs/sample: wall per 10 Hz row"
    )
    for name in ("simulated", "ooi_repeated"):
        profiled = result[name]["profile"]
        print(
            f"\n  Where the time of {name} goes (cProfile, own time; the profiler slows it: "
            f"{profiled['total_s']:.1f} s in all):"
        )
        for area, own_s in profiled["areas_s"].items():
            print(f"    {own_s / profiled['total_s']:6.1%} {own_s:6.2f} s  {area}")
        print("  the functions of most own time:")
        for row in profiled["functions"]:
            print(
                f"    {row['share']:6.1%} {row['own_s']:6.2f} s {row['calls']:8d} calls  "
                f"{row['function']}"
            )


def main(argv=None) -> None:
    run_timed_tool(argv, "fdchp_hour", __doc__, RUNS, run_fdchp_hour, print_fdchp_hour)


if __name__ == "__main__":
    main()
