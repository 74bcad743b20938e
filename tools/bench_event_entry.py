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

The inputs are those the engine is given while processing the simulated FDCHP hour
(``tools/bench_fdchp_hour.py``: 10 Hz IMU, the pack's attitude, moored). They are recorded once
from :meth:`~buoy_nav.engine.FusionEngine.add_inputs`, then given to new engines three ways,
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

    python -m tools.bench_event_entry [--runs N]
    python -m tools.bench --only event_entry

Results go to out/bench/event_entry.json.
"""

from __future__ import annotations

import contextlib
import os
import time

import numpy as np

from buoy_nav.config import fusion_config_from_files
from buoy_nav.engine import FusionEngine
from buoy_nav.imu_stretches import MeasurementInput
from buoy_nav.solution_rows import SolutionRows
from tools import bench_fdchp_hour
from tools.bench_command import run_timed_tool
from tools.interpreter import describe, interpreter

OUT_DIR = bench_fdchp_hour.OUT_DIR
RUNS = 3
WAYS = ("live", "engine_rows", "stretch_one", "stretch_chunk")


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


@contextlib.contextmanager
def recorded_inputs(chunks: list[list]):
    """While the block runs, append to ``chunks`` the inputs of each call of
    :meth:`FusionEngine.add_inputs`, and fail where the engine is given inputs any other way
    (they would be missing from the record)."""
    add_inputs, add_imu, add_measurement = (
        FusionEngine.add_inputs,
        FusionEngine.add_imu,
        FusionEngine.add_measurement,
    )
    inside = [0]

    def recording_add_inputs(engine, inputs):
        chunks.append(list(inputs))
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


def hour_inputs() -> tuple[list[list], object]:
    """The chunks of inputs the engine is given on the simulated FDCHP hour, and the fusion's
    configuration."""
    bag, params = bench_fdchp_hour.simulated_hour()
    out = bench_fdchp_hour.WORK_DIR / "event_entry"
    out.mkdir(parents=True, exist_ok=True)
    chunks: list[list] = []
    with recorded_inputs(chunks):
        bench_fdchp_hour._process(bag, params, out, write_bag=False)
    return chunks, fusion_config_from_files([str(path) for path in params])


def _for_engine(chunks: list[list], engine: FusionEngine) -> list[list]:
    """The recorded ``chunks`` with each measurement's source the new ``engine``'s own."""
    sources = {type(source): source for source in engine.sources}
    return [
        [
            MeasurementInput(sources[type(item.source)], item.t_s, item.measurement)
            if type(item) is MeasurementInput
            else item
            for item in chunk
        ]
        for chunk in chunks
    ]


def run_way(way: str, chunks: list[list], config) -> tuple[float, list[float], np.ndarray]:
    """The recorded ``chunks`` given to a new engine of ``config`` the ``way`` named: the wall
    time (s) of the engine's calls, the stamps (s) of the solutions in order, and the rows
    written (none for ``live``)."""
    rows = None if way == "live" else SolutionRows()
    engine = FusionEngine(config, solution_rows=rows)
    given = _for_engine(chunks, engine)
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


def run_event_entry(runs: int = RUNS, log=lambda text: None) -> dict:
    log("bench: event_entry: recording the simulated FDCHP hour's inputs ...")
    chunks, config = hour_inputs()
    inputs = sum(len(chunk) for chunk in chunks)
    results = {"cpus": os.cpu_count(), "interpreter": interpreter(), "inputs": inputs}
    results["load_average_1min_before"] = os.getloadavg()[0]
    walls: dict[str, list[float]] = {way: [] for way in WAYS}
    for timed in range(runs + 1):
        last = {}
        for way in WAYS:
            log(f"bench: event_entry: {way}, run {timed + 1} of {runs + 1} ...")
            last[way] = run_way(way, chunks, config)
            if timed:
                walls[way].append(last[way][0])
        _check_same(last)
    results["load_average_1min_after"] = os.getloadavg()[0]
    results["solutions"] = len(last["live"][1])
    results["ways"] = {
        way: {
            "wall_s": min(walls[way]),
            "us_per_input": min(walls[way]) / inputs * 1e6,
            "runs_s": walls[way],
        }
        for way in WAYS
    }
    return results


def print_event_entry(result: dict) -> None:
    print(
        f"\nWhat one input costs the fusion engine: the simulated FDCHP hour's {result['inputs']} "
        f"inputs (10 Hz IMU and the pack's attitude), {result['solutions']} solutions, the same "
        f"in every way (best of the runs; load average {result['load_average_1min_before']:.2f} "
        f"before, {result['load_average_1min_after']:.2f} after, {result['cpus']} CPUs)"
    )
    print(f"  on {describe(result['interpreter'])}")
    live_us = result["ways"]["live"]["us_per_input"]
    print(f"  {'way':14s} {'wall s':>7s} {'µs an input':>11s} {'× live':>7s}  runs s")
    for way, figures in result["ways"].items():
        runs = ", ".join(f"{wall:.2f}" for wall in figures["runs_s"])
        print(
            f"  {way:14s} {figures['wall_s']:7.2f} {figures['us_per_input']:11.1f} "
            f"{figures['us_per_input'] / live_us:7.2f}  {runs}"
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
