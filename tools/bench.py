"""`make bench`: accuracy and speed of the suite on simulated data, beside the source paper.

Source paper (000): Zhang, Zhou, Shao, "Design of wind speed measurement motion compensation
scheme based on dual-antenna GNSS/SINS integrated system". Its Tables 1-3 are reproduced here
as constants and printed beside our figures:

1. attitude (paper Table 1): fuse_bag on static, tilt_table, sea_state, open_ocean; and
   (Table 1b) sea_state and open_ocean again with other seeds;
2. wind tunnel (paper Table 2): process_bag on wind_tunnel at 5, 10, 15 m/s, still reference
   and sway-and-rotation run;
3. vertical wind (paper Table 3): process_bag on vertical_wind at 5 and 15 m/s;
4. sea: process_bag on sea_state and open_ocean, with the share of each Miller term;
5. speed: fuse_bag and process_bag on one hour of open_ocean: wall and CPU time, messages read
   and written per second, × real time (tools/bench_speed.py);
6. live latency and CPU of fusion_node (tools/bench_live.py), and (6b) the same run with
   pass-through stand-ins for both nodes (tools/passthrough_node.py): the floor it is read
   against;
7. consistency: Monte-Carlo normalised errors of the accelerometer bias over many seeds
   (tools/bias_consistency.py);
8. sensor_sets: the sensor sets beyond RTK on sea_state and open_ocean, with outages
   (tools/bench_sensor_sets.py);
9. smoother (paper 002 Table 1, short): process_bag --smooth on sea_state with the paper's
   sensors and with the default ones, and on open_ocean, 300 s each; forward against smoothed
   errors, and the wind corrected with each (tools/bench_smoother.py); smoother_table1: the
   same on the paper's 4000 s (long; 600 s with --quick);
10. antennas (paper 001): heading-only, baseline-vector and three-antenna models side by side on
   a flight-like and two buoy trajectories (tools/bench_antennas.py);
11. smoother_speed (long): wall time and peak memory of fuse_bag/process_bag with and without
   --smooth on one hour of open_ocean; smoother_day (long): the same on 24 hours (the
   simulation and four runs of a day of data take hours).
12. soak (long): 2 simulated hours through the live nodes at 2x (tools/soak.py), on the
    moored set (e) buoy with GNSS outages and a suspended magnetometer: RSS of each node after
    the first hour and at the end (flat: within 10 %), latency percentiles per simulated hour,
    every anemometer sample out once on wind/true and once on wind/true_with_covariance, the
    fusion's suspensions (an hour of wall-clock time; ``--quick``: six simulated minutes).
13. real_record: OOI's FDCHP flux-buoy record, ours beside Edson's processing
    (tools/bench_fdchp.py), and both on simulated FDCHP records against the truth
    (tools/fdchp_simulated.py).
14. archive: process_archive over a tree of the committed bags, one local worker against two
    (tools/bench_archive.py); archive_year (long): a year-shaped tree of hourly simulated
    10 Hz motion-pack files through process_archive --products-only on a Dask LocalCluster,
    a sample spread over the year sized to about 40 minutes (tools/bench_archive_year.py).
15. current (paper 003): process_bag on ship_current and sea_state with its DVL, short runs;
    current_long (long): an hour of ship_current, sea_state and open_ocean
    (tools/bench_current.py).
16. fluxes: u* and w'Ts' of the corrected wind against those of the truth over two 30-min
    windows of open_ocean with a surface layer carrying fluxes (tools/bench_fluxes.py; about
    fifteen minutes; ``--quick``: two 10-min windows), and the named flux tests of the same
    windows for the truth, the corrected wind, a tenfold stress and motion left in
    (tools/bench_flux_quality.py).
17. magnetometer_calibration: which motions of a moored buoy let calibrate_magnetometer
    recover the hard and soft iron from the record, and the fused heading with what it writes
    (tools/bench_magnetometer_calibration.py; twelve 12-min records; ``--quick``: the four of
    the scenario's own sea).
18. io_floor (long): the I/O floor on one hour of open_ocean: the suite's reader reading and
    decoding every input message, its writer writing process_bag's output messages, and
    process_bag against their sum (tools/bench_io_floor.py; about ten minutes).
19. fdchp_hour: a motion-pack hour to NetCDF, process_bag --netcdf on a simulated FDCHP hour
    and on the OOI record repeated to an hour, with the bag and without (--no-bag), against
    1 000× real time, with start-up cold and warm and a profile (tools/bench_fdchp_hour.py);
    then the filter's step of its rows, the engine's against the same kernels composed into one
    compiled call (tools/bench_filter_row.py), and a row's time by stage, without a profiler
    (tools/bench_row_stages.py).
20. event_entry: what one input costs the fusion engine handed the inputs one at a time, as
    the live node hands them, against the compiled stretch driven one input at a time and by
    chunks, on the simulated FDCHP hour's inputs and the first of the speed section's hour
    (tools/bench_event_entry.py; about four minutes).

Simulated bags are cached in out/bench/cache/ under a key of scenario, overrides, seed and a
hash of the simulator's sources and parameter files, so a second run only processes. Figures
go to stdout and out/bench/results.json, progress to stderr.

    python -m tools.bench [--quick] [--only attitude|wind|speed|live|consistency|sensor_sets|
                                            smoother|antennas|smoother_table1|smoother_speed|
                                            smoother_day|soak|real_record|archive|archive_year|
                                            current|current_long|fluxes|
                                            magnetometer_calibration|io_floor|
                                            fdchp_hour|event_entry ...]

Without --only every section runs but the long ones (LONG_SECTIONS: smoother_table1, 4000 s
runs as in paper 002; smoother_speed, one hour; smoother_day, 24 hours; soak, 2
simulated hours through the live nodes, an hour of wall time; current_long, an hour of paper
003's ship and of each buoy with its DVL, tens of minutes; io_floor, process_bag and the
suite's bag reading and writing three times each on one hour; archive_year, about 40 minutes
of a sample of a year of hourly files), which run only when named.

The paper's figures, the targets and the runs are in tools/bench_plan.py, the analyses of the
processed bags in tools/bench_analysis.py, the printed tables in tools/bench_tables.py.
"""

from __future__ import annotations

import argparse
import contextlib
import hashlib
import io
import json
import os
import shutil
import sys
import time
from concurrent.futures import ProcessPoolExecutor, as_completed
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from buoy_nav.config import fusion_config_from_files
from buoy_processing.bag_fusion import fuse_bag
from buoy_processing.bag_processing import process_bag
from sensor_sim.scenario import load_scenario
from sensor_sim.simulate_bag import simulate
from tools import bench_antennas, bench_smoother
from tools.bench_analysis import ANALYSES, wrap_deg
from tools.bench_current import CURRENT_ANALYSES, current_cases, current_results, print_current
from tools.bench_plan import (
    ATTITUDE_MAX_ERROR_DEG,
    ATTITUDE_RMS_DEG,
    ATTITUDE_SCENARIOS,
    CONSISTENCY_CHECKPOINTS_S,
    CONSISTENCY_DURATION_S,
    CONSISTENCY_SEEDS,
    CONVERGED_SIGMA_DEG,
    LIVE_DURATION_S,
    PAPER_RESIDUAL_SHARE,
    PAPER_TABLE1_DEG,
    PAPER_TABLE2,
    PAPER_TABLE3,
    PROCESSING_PARAMS,
    QUICK_DURATION_S,
    REPO,
    SEA_MEAN_DIRECTION_ERROR_DEG,
    SEA_MEAN_SPEED_ERROR_MPS,
    SEA_SCENARIOS,
    SEED_SPREAD,
    SEED_SPREAD_SCENARIOS,
    SIMULATION_PARAMS,
    SPEED_DURATION_S,
    STILL_LEVEL,
    TUNNEL_SPEEDS_MPS,
    VERTICAL_RESIDUAL_SHARE_TARGET,
    VERTICAL_SPEED_ERROR_TARGET,
    VERTICAL_SPEEDS_MPS,
)
from tools.bench_speed import print_speed, run_speed
from tools.bench_tables import (
    print_attitude,
    print_live,
    print_sea,
    print_seed_spread,
    print_tunnel,
    print_vertical,
)
from wind_comp.config import compensator_config_from_files, current_config_from_files

OUT_DIR = REPO / "out" / "bench"
CACHE_DIR = OUT_DIR / "cache"
RUNS_DIR = OUT_DIR / "runs"
SIMULATOR_PACKAGE = REPO / "src/sensor_sim/sensor_sim"
# Modules outside sensor_sim whose code decides what simulate_bag writes.
SIMULATION_SHARED_MODULES = ("buoy_common.parameters", "buoy_common.bag_io")
SECTIONS = (
    "attitude",
    "wind",
    "speed",
    "live",
    "consistency",
    "sensor_sets",
    "smoother",
    "antennas",
    "smoother_table1",
    "smoother_speed",
    "smoother_day",
    "soak",
    "real_record",
    "archive",
    "archive_year",
    "current",
    "current_long",
    "fluxes",
    "uncertainty",
    "uncertainty_day",
    "magnetometer_calibration",
    "io_floor",
    "fdchp_hour",
    "event_entry",
)
LONG_SECTIONS = (
    "smoother_table1",
    "smoother_speed",
    "smoother_day",
    "soak",
    "current_long",
    "uncertainty_day",
    "io_floor",
    "archive_year",
)
"""Sections of long runs (simulated and processed only when named with --only)."""
DEFAULT_SECTIONS = tuple(s for s in SECTIONS if s not in LONG_SECTIONS)
SMOOTHER_DAY_S = 86400.0
SOAK_HOURS = {"quick": 0.1, "full": 2.0}
SOAK_RATE_FACTOR = 2.0
WORKERS = max(1, min(2, os.cpu_count() or 1))


@dataclass(frozen=True)
class Case:
    """One simulated run and how it is processed and analysed."""

    key: str
    scenario: str
    overrides: tuple[str, ...]
    pipeline: str  # "fuse" (fuse_bag) or "process" (process_bag)
    analysis: str  # "attitude", "tunnel", "vertical", "sea", "paper_current", "buoy_current"
    label: str


def log(text: str) -> None:
    print(text, file=sys.stderr, flush=True)


def duration_overrides(scenario: str, quick: bool) -> tuple[str, ...]:
    duration_s = QUICK_DURATION_S[scenario] if quick else None
    return () if duration_s is None else (f"duration_s={duration_s:g}",)


def plan_cases(sections: set[str], quick: bool) -> list[Case]:
    cases = []
    if "attitude" in sections:
        cases += attitude_cases(quick)
    if "wind" in sections:
        cases += wind_cases(quick)
    for section in ("current", "current_long"):
        if section in sections:
            cases += current_cases(section, quick, Case)
    return cases


def attitude_cases(quick: bool) -> list[Case]:
    """fuse_bag on each attitude scenario (paper Table 1), then on the seed-spread scenarios
    with other seeds (Table 1b)."""
    cases = []
    for scenario in ATTITUDE_SCENARIOS:
        cases.append(
            Case(
                f"attitude/{scenario}",
                scenario,
                duration_overrides(scenario, quick),
                "fuse",
                "attitude",
                scenario,
            )
        )
    for scenario in SEED_SPREAD_SCENARIOS:
        for seed in SEED_SPREAD:
            cases.append(
                Case(
                    f"attitude_seed/{scenario}/{seed}",
                    scenario,
                    (*duration_overrides(scenario, quick), f"seed={seed}"),
                    "fuse",
                    "attitude",
                    f"{scenario} seed {seed}",
                )
            )
    return cases


def wind_cases(quick: bool) -> list[Case]:
    """process_bag on the wind tunnel still and moving at each speed (paper Table 2), on the
    vertical wind (Table 3) and on the sea scenarios (Table 4)."""
    cases = []
    for speed in TUNNEL_SPEEDS_MPS:
        base = (*duration_overrides("wind_tunnel", quick), f"wind.speed_mps={speed}")
        cases.append(
            Case(
                f"tunnel/{speed}/reference",
                "wind_tunnel",
                (*base, *STILL_LEVEL),
                "process",
                "tunnel",
                f"wind tunnel {speed} m/s, still level",
            )
        )
        cases.append(
            Case(
                f"tunnel/{speed}/motion",
                "wind_tunnel",
                base,
                "process",
                "tunnel",
                f"wind tunnel {speed} m/s, sway and rotation",
            )
        )
    for speed in VERTICAL_SPEEDS_MPS:
        cases.append(
            Case(
                f"vertical/{speed}",
                "vertical_wind",
                (*duration_overrides("vertical_wind", quick), f"wind.speed_mps={speed}"),
                "process",
                "vertical",
                f"vertical wind {speed} m/s",
            )
        )
    for scenario in SEA_SCENARIOS:
        cases.append(
            Case(
                f"sea/{scenario}",
                scenario,
                duration_overrides(scenario, quick),
                "process",
                "sea",
                scenario,
            )
        )
    return cases


def speed_overrides(quick: bool) -> tuple[str, ...]:
    return (f"duration_s={SPEED_DURATION_S['quick' if quick else 'full']:g}",)


# ---------------------------------------------------------------------------------------------
# Simulated bags, cached.


def simulator_fingerprint() -> str:
    """Hash of everything that shapes a simulated bag besides scenario, overrides and seed:
    the simulator modules simulate_bag runs on (not the live nodes, whose edits do not change
    a simulated bag), the shipped scenario files and the parameter files."""
    sources = {
        Path(module.__file__)
        for name, module in list(sys.modules.items())
        if (
            name.split(".")[0] == "sensor_sim"
            or any(name == m or name.startswith(m + ".") for m in SIMULATION_SHARED_MODULES)
        )
        and getattr(module, "__file__", None)
    }
    sources |= set((SIMULATOR_PACKAGE / "scenarios").glob("*.yaml"))
    sources |= {Path(p) for p in SIMULATION_PARAMS}
    digest = hashlib.sha256()
    for path in sorted(sources):
        digest.update(str(path.relative_to(REPO)).encode())
        digest.update(path.read_bytes())
    return digest.hexdigest()


def cached_bag_path(scenario: str, overrides: tuple[str, ...], fingerprint: str) -> Path:
    seed = load_scenario(scenario, list(overrides), None).seed
    key = json.dumps([scenario, sorted(overrides), seed, fingerprint])
    digest = hashlib.sha256(key.encode()).hexdigest()[:12]
    readable = "_".join(o.split(".")[-1].replace("=", "") for o in sorted(overrides))
    return CACHE_DIR / f"{scenario}{'_' + readable if readable else ''}_seed{seed}_{digest}"


def simulate_to_cache(scenario: str, overrides: tuple[str, ...], bag: str) -> float:
    """Simulate into a temporary name and rename, so an aborted run leaves no usable bag."""
    partial = Path(f"{bag}.partial")
    shutil.rmtree(partial, ignore_errors=True)
    started = time.monotonic()
    with contextlib.redirect_stderr(io.StringIO()):
        simulate(
            argparse.Namespace(
                scenario=scenario,
                output=str(partial),
                overrides=list(overrides),
                seed=None,
                params_file=SIMULATION_PARAMS,
                no_truth=False,
                overwrite=False,
            )
        )
    partial.rename(bag)
    return time.monotonic() - started


def ensure_bags(wanted: dict[Path, tuple[str, tuple[str, ...]]]) -> dict[str, float]:
    """Simulate the bags not in the cache, in parallel; returns wall s per simulated bag."""
    missing = {path: spec for path, spec in wanted.items() if not (path / "metadata.yaml").exists()}
    log(f"bench: {len(wanted) - len(missing)} cached bag(s), {len(missing)} to simulate")
    CACHE_DIR.mkdir(parents=True, exist_ok=True)
    walls = {}
    if not missing:
        return walls
    with ProcessPoolExecutor(WORKERS) as pool:
        futures = {
            pool.submit(simulate_to_cache, scenario, overrides, str(path)): path
            for path, (scenario, overrides) in missing.items()
        }
        for done, future in enumerate(as_completed(futures), 1):
            path = futures[future]
            walls[path.name] = future.result()
            log(f"bench: [{done}/{len(missing)}] simulated {path.name} in {walls[path.name]:.1f} s")
    return walls


def run_case(case: Case, in_bag: str, out_bag: str) -> dict:
    """Process one cached bag and analyse the output (in a worker process)."""
    scenario_duration_s = load_scenario(case.scenario, list(case.overrides), None).duration_s
    with contextlib.redirect_stderr(io.StringIO()):
        if case.pipeline == "fuse":
            config = fusion_config_from_files(PROCESSING_PARAMS)
            wall_s = fuse_bag(in_bag, out_bag, config, overwrite=True).wall_s
        else:
            summary = process_bag(
                in_bag,
                out_bag,
                fusion_config_from_files(PROCESSING_PARAMS),
                compensator_config_from_files(PROCESSING_PARAMS),
                overwrite=True,
                current_config=current_config_from_files(PROCESSING_PARAMS),
            )
            wall_s = summary.wall_s
    started = time.monotonic()
    result = {**ANALYSES, **CURRENT_ANALYSES}[case.analysis](out_bag, scenario_duration_s)
    result["pipeline"] = "fuse_bag" if case.pipeline == "fuse" else "process_bag"
    result["pipeline_wall_s"] = wall_s
    result["analysis_wall_s"] = time.monotonic() - started
    result["overrides"] = list(case.overrides)
    return result


def run_cases(cases: list[Case], bag_of: dict[str, Path]) -> dict[str, dict]:
    RUNS_DIR.mkdir(parents=True, exist_ok=True)
    results = {}
    with ProcessPoolExecutor(WORKERS) as pool:
        futures = {
            pool.submit(
                run_case, case, str(bag_of[case.key]), str(RUNS_DIR / case.key.replace("/", "_"))
            ): case
            for case in cases
        }
        for done, future in enumerate(as_completed(futures), 1):
            case = futures[future]
            results[case.key] = future.result()
            log(
                f"bench: [{done}/{len(cases)}] {results[case.key]['pipeline']} {case.label}: "
                f"{results[case.key]['pipeline_wall_s']:.1f} s"
            )
    return results


# ---------------------------------------------------------------------------------------------


def parse_arguments(argv):
    parser = argparse.ArgumentParser(prog="bench", description=__doc__.split("\n")[0])
    parser.add_argument("--quick", action="store_true", help="short runs, for a smoke test")
    parser.add_argument(
        "--only",
        action="append",
        choices=SECTIONS,
        help="run only this part (repeatable); wind = tables 2, 3 and 4; without it, every "
        f"section but the long ones ({', '.join(LONG_SECTIONS)})",
    )
    return parser.parse_args(argv)


def main(argv=None) -> None:
    arguments = parse_arguments(sys.argv[1:] if argv is None else argv)
    sections = set(arguments.only or DEFAULT_SECTIONS)
    quick = arguments.quick
    started = time.monotonic()
    OUT_DIR.mkdir(parents=True, exist_ok=True)

    cases = plan_cases(sections, quick)
    smoothing_cases = bench_smoother.plan(sections, quick)
    bags = plan_bags(sections, quick, cases, smoothing_cases)
    simulation_walls = ensure_bags(bags.wanted)

    results = {"meta": run_meta(sections, quick, simulation_walls)}
    case_results = run_cases(cases, bags.bag_of) if cases else {}
    run = BenchRun(sections, quick, cases, case_results, smoothing_cases, bags)
    for section_results in SECTION_STEPS:
        results.update(section_results(run))

    results["meta"]["wall_s"] = time.monotonic() - started
    path = OUT_DIR / "results.json"
    merged = merged_results(results, earlier_results(path))
    with open(path, "w") as stream:
        json.dump(merged, stream, indent=2, default=json_default)
    print(f"\nbench: {results['meta']['wall_s']:.0f} s wall; figures in {path.relative_to(REPO)}")


def earlier_results(path: Path) -> dict:
    """The results an earlier run wrote to ``path`` ({} when there are none). A file that is
    not JSON is kept beside it, renamed, and said so, not overwritten."""
    if not path.exists():
        return {}
    try:
        return json.loads(path.read_text())
    except json.JSONDecodeError as error:
        kept = path.with_suffix(".unreadable.json")
        path.replace(kept)
        print(f"bench: {path} is not JSON ({error}); kept as {kept}", file=sys.stderr)
        return {}


def merged_results(run_results: dict, earlier: dict) -> dict:
    """This run's results over ``earlier`` ones: a run of some sections keeps the figures of
    the others. ``meta`` is this run's; ``meta.measured_utc`` says, for every key, when the run
    that measured it started."""
    earlier_meta = earlier.get("meta", {})
    measured = {key: earlier_meta.get("started_utc") for key in earlier if key != "meta"}
    measured.update(earlier_meta.get("measured_utc", {}))
    started = run_results["meta"]["started_utc"]
    measured.update({key: started for key in run_results if key != "meta"})
    merged = {key: value for key, value in earlier.items() if key != "meta"}
    merged.update(run_results)
    merged["meta"] = {**run_results["meta"], "measured_utc": measured}
    return merged


@dataclass
class BagPlan:
    """The simulated bags a run needs: what to simulate into each cache path, the bag of each
    case key, and the bags of the speed sections (an hour of open_ocean) and of smoother_day."""

    wanted: dict[Path, tuple[str, tuple[str, ...]]]
    bag_of: dict[str, Path]
    speed_bag: Path | None = None
    day_bag: Path | None = None


@dataclass(frozen=True)
class BenchRun:
    """What the sections of one run share: the sections asked for, the cases and their
    results, the smoothing cases and the bags."""

    sections: set[str]
    quick: bool
    cases: list[Case]
    case_results: dict[str, dict]
    smoothing_cases: list
    bags: BagPlan


def plan_bags(sections: set[str], quick: bool, cases: list[Case], smoothing_cases) -> BagPlan:
    """The cached bags of ``cases`` and ``smoothing_cases`` and those the speed sections and
    smoother_day simulate."""
    fingerprint = simulator_fingerprint()
    bags = BagPlan({}, {})
    for case in cases:
        path = cached_bag_path(case.scenario, case.overrides, fingerprint)
        bags.wanted[path] = (case.scenario, case.overrides)
        bags.bag_of[case.key] = path
    if sections & {"speed", "smoother_speed", "io_floor", "event_entry"}:
        bags.speed_bag = cached_bag_path("open_ocean", speed_overrides(quick), fingerprint)
        bags.wanted[bags.speed_bag] = ("open_ocean", speed_overrides(quick))
    for case in smoothing_cases:
        path = cached_bag_path(case.scenario, case.overrides, fingerprint)
        bags.wanted[path] = (case.scenario, case.overrides)
        bags.bag_of[case.key] = path
    if "smoother_day" in sections:
        day_overrides = (f"duration_s={SMOOTHER_DAY_S:g}",)
        bags.day_bag = cached_bag_path("open_ocean", day_overrides, fingerprint)
        bags.wanted[bags.day_bag] = ("open_ocean", day_overrides)
    return bags


def run_meta(sections: set[str], quick: bool, simulation_walls: dict[str, float]) -> dict:
    return {
        "quick": quick,
        "sections": sorted(sections),
        "started_utc": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()),
        "cpus": os.cpu_count(),
        "workers": WORKERS,
        "processing_params_files": [str(Path(p).relative_to(REPO)) for p in PROCESSING_PARAMS],
        "simulation_params_files": [str(Path(p).relative_to(REPO)) for p in SIMULATION_PARAMS],
        "simulated_this_run_wall_s": simulation_walls,
    }


def sensor_sets_section(run: BenchRun) -> dict:
    """Sensor sets beyond RTK, the outage test and the motion pack's lag: their own tool,
    which writes out/bench/sensor_sets.json."""
    if "sensor_sets" not in run.sections:
        return {}
    from tools import bench_sensor_sets

    for scenario in ("sea_state", "open_ocean"):
        bench_sensor_sets.main(
            ["--scenario", scenario, "--outages", *(["--quick"] if run.quick else [])]
        )
        shutil.copy(OUT_DIR / "sensor_sets.json", OUT_DIR / f"sensor_sets_{scenario}.json")
    return {}


def real_record_section(run: BenchRun) -> dict:
    """OOI's FDCHP record beside Edson's processing, and both on simulated FDCHP records held
    to the truth: their own tools, out/bench/fdchp.json and fdchp_simulated.json."""
    if "real_record" not in run.sections:
        return {}
    from tools import bench_fdchp, fdchp_simulated

    bench_fdchp.main([])
    fdchp_simulated.main([])
    return {}


def attitude_section(run: BenchRun) -> dict:
    """Paper Table 1 and the other seeds (Table 1b)."""
    if "attitude" not in run.sections:
        return {}
    case_results = run.case_results
    attitude = {c.scenario: case_results[c.key] for c in run.cases if c.key.startswith("attitude/")}
    other_seeds = {
        scenario: {seed: case_results[f"attitude_seed/{scenario}/{seed}"] for seed in SEED_SPREAD}
        for scenario in SEED_SPREAD_SCENARIOS
    }
    results = {
        "attitude": {
            "targets": {
                "max_abs_error_deg": ATTITUDE_MAX_ERROR_DEG,
                "rms_deg": ATTITUDE_RMS_DEG,
                "convergence_sigma_enu_deg": CONVERGED_SIGMA_DEG,
            },
            "paper_table1_deg": PAPER_TABLE1_DEG,
            "scenarios": attitude,
            "other_seeds": other_seeds,
        }
    }
    print_attitude(attitude, run.quick)
    print_seed_spread(attitude, other_seeds)
    return results


def wind_section(run: BenchRun) -> dict:
    """Paper Tables 2 and 3 (wind tunnel, vertical wind) and the sea (Table 4)."""
    if "wind" not in run.sections:
        return {}
    tunnel = {k: v for k, v in run.case_results.items() if k.startswith("tunnel/")}
    vertical = {k: v for k, v in run.case_results.items() if k.startswith("vertical/")}
    sea = {k: v for k, v in run.case_results.items() if k.startswith("sea/")}
    results = {
        "wind_tunnel": {
            "paper_table2": {str(k): v for k, v in PAPER_TABLE2.items()},
            "runs": {f"{speed}_mps": tunnel_run(tunnel, speed) for speed in TUNNEL_SPEEDS_MPS},
        },
        "vertical_wind": {
            "paper_table3": {str(k): v for k, v in PAPER_TABLE3.items()},
            "paper_residual_share": PAPER_RESIDUAL_SHARE,
            "targets": {
                "residual_share": VERTICAL_RESIDUAL_SHARE_TARGET,
                "speed_error_fraction": VERTICAL_SPEED_ERROR_TARGET,
            },
            "runs": {f"{k.split('/')[1]}_mps": v for k, v in vertical.items()},
        },
        "sea": {
            "targets": {
                "mean_speed_error_mps": SEA_MEAN_SPEED_ERROR_MPS,
                "mean_direction_error_deg": SEA_MEAN_DIRECTION_ERROR_DEG,
            },
            "scenarios": {k.split("/")[1]: v for k, v in sea.items()},
        },
    }
    print_tunnel(tunnel)
    print_vertical(vertical)
    print_sea(sea)
    return results


def tunnel_run(tunnel: dict, speed_mps) -> dict:
    """The still reference and the moving run at ``speed_mps`` (m/s), and the moving run's
    corrected mean speed (m/s) and direction (°) less the reference's."""
    reference = tunnel[f"tunnel/{speed_mps}/reference"]
    motion = tunnel[f"tunnel/{speed_mps}/motion"]
    return {
        "reference": reference,
        "motion": motion,
        "speed_error_mps": motion["corrected"]["mean_speed_mps"]
        - reference["corrected"]["mean_speed_mps"],
        "direction_error_deg": float(
            wrap_deg(motion["corrected"]["direction_deg"] - reference["corrected"]["direction_deg"])
        ),
    }


def speed_section(run: BenchRun) -> dict:
    if "speed" not in run.sections:
        return {}
    speed = run_speed(run.bags.speed_bag, RUNS_DIR / "speed", log)
    print_speed(speed, run.quick)
    return {"speed": speed}


def live_section(run: BenchRun) -> dict:
    """Table 6, the live nodes, and 6b, the same run with stand-ins that compute nothing: what
    the middleware, the executor and this machine cost on the same path, to read 6 against."""
    if "live" not in run.sections:
        return {}
    from tools import bench_live

    live_duration_s = LIVE_DURATION_S["quick" if run.quick else "full"]
    live = bench_live.run_live(live_duration_s, OUT_DIR / "live_logs")
    print_live(
        live, "Table 6 — live: run_scenario sea_state with fusion_node and compensation_node"
    )
    passthrough = bench_live.run_live(
        live_duration_s, OUT_DIR / "live_logs_passthrough", passthrough=True
    )
    print_live(
        passthrough,
        "Table 6b — the floor: the same run with pass-through stand-ins for both nodes "
        "(tools/passthrough_node.py)",
    )
    return {"live": live, "live_passthrough": passthrough}


def current_sections(run: BenchRun) -> dict:
    results = {}
    for section in ("current", "current_long"):
        if section in run.sections:
            paper, buoys = current_results(section, run.case_results)
            results[section] = {"paper_003": paper, "buoys": buoys}
            print_current(section, paper, buoys, run.quick)
    return results


def fluxes_section(run: BenchRun) -> dict:
    """The fluxes of the corrected wind against the truth (tools/bench_fluxes.py) and the named
    flux tests of the same windows (tools/bench_flux_quality.py): two 30-min windows of
    open_ocean with a surface layer (two 10-min windows with --quick), simulated once."""
    if "fluxes" not in run.sections:
        return {}
    from tools import bench_flux_quality, bench_fluxes

    window_s = 600.0 if run.quick else 1800.0
    results = bench_flux_quality.run(2 * window_s, window_s)
    print(bench_fluxes.table(results["fluxes"], window_s))
    print(bench_flux_quality.table(results["flux_quality"], window_s))
    return {
        "fluxes": {"window_s": window_s, "windows": results["fluxes"]},
        "flux_quality": {"window_s": window_s, "windows": results["flux_quality"]},
    }


def consistency_section(run: BenchRun) -> dict:
    if "consistency" not in run.sections:
        return {}
    from tools import bias_consistency

    consistency = bias_consistency.run_consistency(
        CONSISTENCY_SEEDS["quick" if run.quick else "full"],
        CONSISTENCY_DURATION_S,
        CONSISTENCY_CHECKPOINTS_S,
    )
    bias_consistency.print_table(consistency["table"])
    return {"consistency": consistency}


def soak_section(run: BenchRun) -> dict:
    if "soak" not in run.sections:
        return {}
    from tools import soak

    result = soak.soak(
        SOAK_HOURS["quick" if run.quick else "full"],
        SOAK_RATE_FACTOR,
        rss_period_s=10.0,
        log_dir=OUT_DIR / "soak_logs",
    )
    soak.print_table(result)
    return {"soak": result}


def smoother_sections(run: BenchRun) -> dict:
    """Paper 002 Table 1: smoother and smoother_table1."""
    if not run.smoothing_cases:
        return {}
    runs = bench_smoother.run_cases(run.smoothing_cases, run.bags.bag_of, RUNS_DIR, WORKERS)
    return bench_smoother.table1_results(run.sections, runs)


def antennas_section(run: BenchRun) -> dict:
    if "antennas" not in run.sections:
        return {}
    antennas = bench_antennas.run_antennas(run.quick)
    bench_antennas.print_antennas(antennas)
    return {"antennas": antennas}


def smoother_speed_sections(run: BenchRun) -> dict:
    """smoother_speed (an hour of open_ocean) and smoother_day (24 hours)."""
    results = {}
    for section, bags in (
        ("smoother_speed", {"1 h": run.bags.speed_bag} if "smoother_speed" in run.sections else {}),
        ("smoother_day", {"24 h": run.bags.day_bag} if "smoother_day" in run.sections else {}),
    ):
        if bags:
            results[section] = bench_smoother.run_smoother_speed(bags, RUNS_DIR / section)
            bench_smoother.print_smoother_speed(results[section])
    return results


def archive_section(run: BenchRun) -> dict:
    if "archive" not in run.sections:
        return {}
    from tools import bench_archive

    archive = bench_archive.run_archive_throughput(OUT_DIR / "archive")
    bench_archive.print_archive(archive)
    return {"archive": archive}


def archive_year_section(run: BenchRun) -> dict:
    """A sample of a year of hourly motion-pack files through process_archive on a Dask
    LocalCluster (its own tool, which writes out/bench/archive_year.json; about 40 minutes,
    a few with --quick)."""
    if "archive_year" not in run.sections:
        return {}
    from tools import bench_archive_year

    bench_archive_year.main(["--hours", "8"] if run.quick else [])
    return {"archive_year": json.loads((OUT_DIR / "archive_year.json").read_text())}


def uncertainty_sections(run: BenchRun) -> dict:
    """Every sensor set's valid wind against its stated uncertainty (tools/bench_uncertainty.py,
    15-min runs, 5 with --quick; about 3 min on two cores), and with --only uncertainty_day a
    simulated day through process_bag with its memory (tools/bench_uncertainty_day.py, about
    30 min; 2 h with --quick). Their own tools write out/bench/uncertainty*.json."""
    results = {}
    if "uncertainty" in run.sections:
        from tools import bench_uncertainty

        bench_uncertainty.main(["--quick"] if run.quick else [])
        results["uncertainty"] = json.loads((OUT_DIR / "uncertainty.json").read_text())
    if "uncertainty_day" in run.sections:
        from tools import bench_uncertainty_day

        bench_uncertainty_day.main(["--hours", "2" if run.quick else "24"])
        results["uncertainty_day"] = json.loads((OUT_DIR / "uncertainty_day.json").read_text())
    return results


def io_floor_section(run: BenchRun) -> dict:
    """The I/O floor against process_bag on the speed section's hour of open_ocean (its own
    tool, which writes out/bench/io_floor.json)."""
    if "io_floor" not in run.sections:
        return {}
    from tools import bench_io_floor

    result = bench_io_floor.run_io_floor(run.bags.speed_bag, RUNS_DIR / "io_floor", log=log)
    bench_io_floor.print_io_floor(result)
    (OUT_DIR / "io_floor.json").write_text(json.dumps(result, indent=2))
    return {"io_floor": result}


def magnetometer_calibration_section(run: BenchRun) -> dict:
    """calibrate_magnetometer on moored records of every motion, and the heading it gives
    (tools/bench_magnetometer_calibration.py, which writes
    out/bench/magnetometer_calibration.json)."""
    if "magnetometer_calibration" not in run.sections:
        return {}
    from tools import bench_magnetometer_calibration

    bench_magnetometer_calibration.main(["--quick"] if run.quick else [])
    return {
        "magnetometer_calibration": json.loads(
            (OUT_DIR / "magnetometer_calibration.json").read_text()
        )
    }


def fdchp_hour_section(run: BenchRun) -> dict:
    """A motion-pack hour to NetCDF against 1 000× real time, the filter's step of its rows
    interpreted and compiled, and a row's time by stage (their own tools, which write
    out/bench/fdchp_hour.json, out/bench/filter_row.json and out/bench/row_stages.json)."""
    if "fdchp_hour" not in run.sections:
        return {}
    from tools import bench_fdchp_hour, bench_filter_row, bench_row_stages

    result = bench_fdchp_hour.run_fdchp_hour(log=log)
    bench_fdchp_hour.print_fdchp_hour(result)
    (OUT_DIR / "fdchp_hour.json").write_text(json.dumps(result, indent=2))
    filter_row = bench_filter_row.run_filter_row(log=log)
    bench_filter_row.print_filter_row(filter_row)
    (OUT_DIR / "filter_row.json").write_text(json.dumps(filter_row, indent=2))
    row_stages = bench_row_stages.run_row_stages(log=log)
    bench_row_stages.print_row_stages(row_stages)
    (OUT_DIR / "row_stages.json").write_text(json.dumps(row_stages, indent=2))
    return {"fdchp_hour": result, "filter_row": filter_row, "row_stages": row_stages}


def event_entry_section(run: BenchRun) -> dict:
    """What one input costs the engine handed the inputs one at a time, the live node's way
    and through the stretch, on the FDCHP hour and the speed section's (its own tool, which
    writes out/bench/event_entry.json)."""
    if "event_entry" not in run.sections:
        return {}
    from tools import bench_event_entry

    result = bench_event_entry.run_event_entry(log=log, gnss_bag=run.bags.speed_bag)
    bench_event_entry.print_event_entry(result)
    (OUT_DIR / "event_entry.json").write_text(json.dumps(result, indent=2))
    return {"event_entry": result}


SECTION_STEPS = (
    sensor_sets_section,
    real_record_section,
    attitude_section,
    wind_section,
    speed_section,
    live_section,
    current_sections,
    fluxes_section,
    uncertainty_sections,
    magnetometer_calibration_section,
    consistency_section,
    soak_section,
    smoother_sections,
    antennas_section,
    smoother_speed_sections,
    archive_section,
    archive_year_section,
    io_floor_section,
    fdchp_hour_section,
    event_entry_section,
)
"""The sections after the cases, in the order they run and print; each returns its results."""


def json_default(value):
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, np.ndarray):
        return value.tolist()
    raise TypeError(f"not JSON serialisable: {type(value).__name__}")


if __name__ == "__main__":
    main()
