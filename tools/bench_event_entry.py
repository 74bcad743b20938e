"""One input at a time: what the engine's calls cost the live node's way and through the stretch.

What one input costs the fusion engine when it is handed the inputs one at a time, as the live
node hands them, against the compiled stretch driven one input at a time and by chunks
(tools/bench.py, section ``event_entry``).

The live node gives the engine each message as it arrives, and the engine returns its solutions
as objects (:class:`~buoy_nav.engine.NavSolution`) for the node to publish. An offline run gives
it a chunk's inputs at once with the solutions written as rows, and most inputs then go through
the compiled stretch (:mod:`buoy_nav.imu_stretch`) in one call. A live node built on that
stretch would drive it one input at a time. This tool measures what that costs, beside what the
live node's calls cost today.

The inputs are those the engine is given while processing an hour, recorded once from
:meth:`~buoy_nav.engine.FusionEngine.add_inputs`: the simulated FDCHP hour
(``tools/bench_fdchp_hour.py``: 10 Hz IMU, the pack's attitude, moored) and, in ``make bench``,
the first GNSS_INPUTS inputs of the speed section's hour of ``open_ocean`` (100 Hz IMU, dual-
antenna RTK GNSS, the live bench's sensor set). They are given to new engines four ways,
alternately, RUNS times each after one untimed run of each:

- ``live``: one input a call, solutions as objects: the live node's engine calls;
- ``engine_rows``: one input a call, solutions as rows, the stretch kept out: the engine's own
  path for each input (the compiled kernels it calls one event at a time, the row writer among
  them), which a live node publishing from rows would drive;
- ``stretch_one``: one input a call, solutions as rows: the stretch driven one input at a time;
- ``stretch_chunk``: the chunks as recorded, solutions as rows: the offline run.

The figure of each way is its fastest run's wall time per input, the engine's calls alone: no
decoding, no messages. The ways with rows must write the same rows to the bit, and the live way
the same solutions' stamps; the tool checks this and fails if they differ.

    python -m tools.bench_event_entry [--runs N]   (the FDCHP hour)
    python -m tools.bench --only event_entry       (both hours)

Results go to out/bench/event_entry.json.
"""

from __future__ import annotations

import contextlib
import io
import math
import os
import time
from pathlib import Path

import numpy as np

from buoy_nav.config import fusion_config_from_files
from buoy_nav.engine import FusionEngine
from buoy_nav.imu_stretches import MeasurementInput
from buoy_nav.solution_rows import SolutionRows
from buoy_processing.bag_processing import process_bag
from tools import bench_fdchp_hour
from tools.bench_command import run_timed_tool
from tools.bench_plan import PROCESSING_PARAMS
from tools.interpreter import describe, interpreter
from wind_comp.config import compensator_config_from_files

OUT_DIR = bench_fdchp_hour.OUT_DIR
RUNS = 3
WAYS = ("live", "engine_rows", "stretch_one", "stretch_chunk")
GNSS_INPUTS = 120_000
"""Inputs of the GNSS-aided hour recorded (its first 13 minutes or so): the stretch one input
at a time takes about a minute a run over them."""


class WaysDifferError(RuntimeError):
    """Two ways of giving the engine the same inputs made different solutions."""


@contextlib.contextmanager
def stretches_kept_out(way: str):
    """While the block runs, the engine takes every input its own way when ``way`` is
    ``engine_rows`` (its screening for a stretch says none may start)."""
    screening = FusionEngine._stretch_screening
    if way == "engine_rows":
        FusionEngine._stretch_screening = lambda engine: None
    try:
        yield
    finally:
        FusionEngine._stretch_screening = screening


class Recorded:
    """The inputs an engine was given, a list per call of ``add_inputs``, and its sources (the
    measurements' sources, which another engine's replace)."""

    def __init__(self, limit: float = math.inf):
        self.chunks: list[list] = []
        self.sources: tuple = ()
        self._left = limit

    def add(self, engine: FusionEngine, inputs) -> None:
        if self._left > 0:
            self.sources = engine.sources
            self.chunks.append(list(inputs))
            self._left -= len(inputs)

    def for_engine(self, engine: FusionEngine) -> list[list]:
        """The chunks with each measurement's source that of the new ``engine`` at its
        place."""
        place = {id(source): index for index, source in enumerate(self.sources)}
        sources = engine.sources
        return [
            [
                MeasurementInput(sources[place[id(item.source)]], item.t_s, item.measurement)
                if type(item) is MeasurementInput
                else item
                for item in chunk
            ]
            for chunk in self.chunks
        ]


@contextlib.contextmanager
def recording(recorded: Recorded):
    """While the block runs, add to ``recorded`` the inputs of each call of
    :meth:`FusionEngine.add_inputs`, and fail where the engine is given inputs any other way
    (they would be missing from the record)."""
    add_inputs, add_imu, add_measurement = (
        FusionEngine.add_inputs,
        FusionEngine.add_imu,
        FusionEngine.add_measurement,
    )
    inside = [0]

    def recording_add_inputs(engine, inputs):
        recorded.add(engine, inputs)
        inside[0] += 1
        try:
            return add_inputs(engine, inputs)
        finally:
            inside[0] -= 1

    def guarded(method):
        def call(engine, *arguments):
            if not inside[0]:
                raise RuntimeError(f"the engine was given an input by {method.__name__}")
            return method(engine, *arguments)

        return call

    FusionEngine.add_inputs = recording_add_inputs
    FusionEngine.add_imu = guarded(add_imu)
    FusionEngine.add_measurement = guarded(add_measurement)
    try:
        yield
    finally:
        FusionEngine.add_inputs = add_inputs
        FusionEngine.add_imu = add_imu
        FusionEngine.add_measurement = add_measurement


def fdchp_inputs() -> tuple[Recorded, object]:
    """The inputs the engine is given on the simulated FDCHP hour, and the fusion's
    configuration."""
    bag, params = bench_fdchp_hour.simulated_hour()
    out = bench_fdchp_hour.WORK_DIR / "event_entry"
    out.mkdir(parents=True, exist_ok=True)
    recorded = Recorded()
    with recording(recorded):
        bench_fdchp_hour._process(bag, params, out, write_bag=False)
    return recorded, fusion_config_from_files([str(path) for path in params])


def gnss_inputs(bag: Path, work_dir: Path) -> tuple[Recorded, object]:
    """The first :data:`GNSS_INPUTS` inputs the engine is given on ``bag`` (the speed
    section's hour), processed with the bench's parameters, and the fusion's configuration."""
    work_dir.mkdir(parents=True, exist_ok=True)
    config = fusion_config_from_files(PROCESSING_PARAMS)
    recorded = Recorded(GNSS_INPUTS)
    with recording(recorded), contextlib.redirect_stdout(io.StringIO()):
        process_bag(
            str(bag),
            str(work_dir / "processed"),
            config,
            compensator_config_from_files(PROCESSING_PARAMS),
            overwrite=True,
            netcdf_path=work_dir / "processed.nc",
            write_bag=False,
        )
    return recorded, config


def run_way(way: str, recorded: Recorded, config) -> tuple[float, list[float], np.ndarray]:
    """The ``recorded`` inputs given to a new engine of ``config`` the ``way`` named: the wall
    time (s) of the engine's calls, the stamps (s) of the solutions in order, and the rows
    written (none for ``live``)."""
    rows = None if way == "live" else SolutionRows()
    engine = FusionEngine(config, solution_rows=rows)
    given = recorded.for_engine(engine)
    solutions: list = []
    taken: list[np.ndarray] = []
    with stretches_kept_out(way):
        start = time.perf_counter()
        for chunk in given:
            if way == "stretch_chunk":
                outcomes = engine.add_inputs(chunk)
            else:
                outcomes = [engine.add_inputs([item])[0] for item in chunk]
            for emitted, _ in outcomes:
                solutions += emitted
            if rows is not None:
                taken.append(rows.take(rows.count))
        solutions += engine.flush()
        wall_s = time.perf_counter() - start
    if rows is not None:
        taken.append(rows.take(rows.count))
    stamps = [solution if rows is not None else solution.t_s for solution in solutions]
    return wall_s, stamps, np.concatenate(taken) if taken else np.zeros((0, 0))


def _check_same(results: dict) -> None:
    """Fail unless every way made the same solutions' stamps and the ways with rows the same
    rows to the bit as the offline run."""
    stamps = {way: result[1] for way, result in results.items()}
    if len({tuple(found) for found in stamps.values()}) != 1:
        counts = {way: len(found) for way, found in stamps.items()}
        raise WaysDifferError(f"the ways' solutions differ: {counts} solutions")
    offline = results["stretch_chunk"][2]
    for way in ("engine_rows", "stretch_one"):
        rows = results[way][2]
        if rows.shape != offline.shape or rows.tobytes() != offline.tobytes():
            raise WaysDifferError(f"{way} wrote other rows than the offline run")


def run_event_entry(runs: int = RUNS, log=lambda text: None, gnss_bag: Path | None = None) -> dict:
    """Both hours' figures (the GNSS-aided one when ``gnss_bag``, the speed section's hour, is
    given)."""
    results = {"cpus": os.cpu_count(), "interpreter": interpreter(), "hours": {}}
    results["load_average_1min_before"] = os.getloadavg()[0]
    log("bench: event_entry: recording the simulated FDCHP hour's inputs ...")
    results["hours"]["fdchp"] = timed_ways(*fdchp_inputs(), runs, log)
    if gnss_bag is not None:
        log(f"bench: event_entry: recording the first {GNSS_INPUTS} inputs of {gnss_bag} ...")
        work_dir = bench_fdchp_hour.OUT_DIR / "runs/event_entry"
        results["hours"]["gnss"] = timed_ways(*gnss_inputs(gnss_bag, work_dir), runs, log)
    results["load_average_1min_after"] = os.getloadavg()[0]
    return results


def timed_ways(recorded: Recorded, config, runs: int, log) -> dict:
    """The ``recorded`` inputs given each way, alternately, ``runs`` times after an untimed
    run: by way, the fastest wall time and every run's; every run's outcomes checked the same
    (:func:`_check_same`)."""
    inputs = sum(len(chunk) for chunk in recorded.chunks)
    walls: dict[str, list[float]] = {way: [] for way in WAYS}
    for timed in range(runs + 1):
        last = {}
        for way in WAYS:
            log(f"bench: event_entry: {way}, run {timed + 1} of {runs + 1} ...")
            last[way] = run_way(way, recorded, config)
            if timed:
                walls[way].append(last[way][0])
        _check_same(last)
    return {
        "inputs": inputs,
        "solutions": len(last["live"][1]),
        "ways": {
            way: {
                "wall_s": min(walls[way]),
                "us_per_input": min(walls[way]) / inputs * 1e6,
                "runs_s": walls[way],
            }
            for way in WAYS
        },
    }


HOUR_LABELS = {
    "fdchp": "the simulated FDCHP hour (10 Hz IMU and the pack's attitude)",
    "gnss": "open_ocean's first inputs (100 Hz IMU, dual-antenna RTK GNSS)",
}


def print_event_entry(result: dict) -> None:
    print(
        "\nWhat one input costs the fusion engine, handed the inputs one at a time and by chunks "
        f"(best of the runs; load average {result['load_average_1min_before']:.2f} before, "
        f"{result['load_average_1min_after']:.2f} after, {result['cpus']} CPUs)"
    )
    print(f"  on {describe(result['interpreter'])}")
    for hour, figures in result["hours"].items():
        print(
            f"  {HOUR_LABELS[hour]}: {figures['inputs']} inputs, {figures['solutions']} "
            "solutions, the same in every way"
        )
        live_us = figures["ways"]["live"]["us_per_input"]
        print(f"    {'way':14s} {'wall s':>7s} {'µs an input':>11s} {'× live':>7s}  runs s")
        for way, way_figures in figures["ways"].items():
            runs = ", ".join(f"{wall:.2f}" for wall in way_figures["runs_s"])
            print(
                f"    {way:14s} {way_figures['wall_s']:7.2f} {way_figures['us_per_input']:11.1f} "
                f"{way_figures['us_per_input'] / live_us:7.2f}  {runs}"
            )
    print(
        "  live: one input a call, solutions as objects (the live node's engine calls); "
        "engine_rows: one input a call, solutions as rows, the stretch kept out; "
        "stretch_one: one input a call through the compiled stretch, solutions as rows; "
        "stretch_chunk: the chunks as an offline run gives them"
    )


def main(argv=None) -> None:
    run_timed_tool(argv, "event_entry", __doc__, RUNS, run_event_entry, print_event_entry)


if __name__ == "__main__":
    main()
