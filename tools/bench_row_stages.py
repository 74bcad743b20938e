"""Where a row of a motion-pack hour goes, by stage, without a profiler.

    python -m tools.bench_row_stages

Runs ``process_bag --netcdf --no-bag`` on the simulated FDCHP hour (``tools/bench_fdchp_hour.py``)
with a clock around the entry of each stage of the processing, and prints the wall time of each
per 10 Hz row: the fusion's filter step, the prediction ahead with its solution, the screening
and queueing of the pack's measurements, the solutions held back for the corrections, the
wind's correction (the sonic's samples, the navigation handed over in bulk, which runs inside
them) and the decoding of the chunks. cProfile charges
every call the profiler's own cost and so inflates the interpreter's share; a clock per stage
entry costs about half a microsecond a call, and the stages nest (the filter step runs inside
the message that catches it up), so they do not add up to the row. One run after an untimed one
that loads the compiled code. Results go to out/bench/row_stages.json.
"""

from __future__ import annotations

import argparse
import contextlib
import json
import time
from collections import Counter, defaultdict

from buoy_nav.engine import FusionEngine
from buoy_nav.prediction import RealtimePrediction
from buoy_processing import offline_runner
from buoy_processing.bag_processing import BagCorrections
from buoy_processing.offline_fusion import OfflineFusion
from buoy_processing.solution_columns import HeldBackSolutions
from tools import bench_fdchp_hour, fdchp_simulated

OUT_DIR = bench_fdchp_hour.OUT_DIR
STAGES = (
    ("the filter's step (FusionEngine._process)", FusionEngine, "_process"),
    ("the prediction ahead and its solution", RealtimePrediction, "predict"),
    ("a measurement's screening and queue", FusionEngine, "_screen_measurement"),
    ("the solutions held back for the corrections", BagCorrections, "add_solution_rows"),
    ("the wind's correction: the sonic's samples", BagCorrections, "add_message"),
    ("the wind's correction: the navigation handed over in bulk", HeldBackSolutions, "hand_over"),
    ("decoding the chunks", offline_runner, "chunk_records"),
    ("a message through the fusion, all of the above in it", OfflineFusion, "add_message"),
)
"""(label, owner, attribute) of each stage's entry."""


@contextlib.contextmanager
def stage_clocks(totals_ns: dict[str, int], calls: Counter):
    """Wrap each stage's entry in a clock while the block runs, adding each call's wall time
    (ns) to ``totals_ns`` and counting it in ``calls``, by label."""
    originals = [(owner, name, getattr(owner, name)) for _, owner, name in STAGES]
    for (label, owner, name), (_, _, original) in zip(STAGES, originals, strict=True):
        setattr(owner, name, _clocked(original, label, totals_ns, calls))
    try:
        yield
    finally:
        for owner, name, original in originals:
            setattr(owner, name, original)


def _clocked(function, label: str, totals_ns: dict[str, int], calls: Counter):
    def clocked(*arguments, **keywords):
        start = time.perf_counter_ns()
        try:
            return function(*arguments, **keywords)
        finally:
            totals_ns[label] += time.perf_counter_ns() - start
            calls[label] += 1

    return clocked


def run_row_stages(log=lambda text: None) -> dict:
    bag, params = bench_fdchp_hour.simulated_hour()
    out = bench_fdchp_hour.WORK_DIR / "row_stages"
    out.mkdir(parents=True, exist_ok=True)
    log("bench: row_stages: the NetCDF-only hour, untimed, then with the stage clocks ...")
    bench_fdchp_hour._process(bag, params, out, write_bag=False)
    totals_ns: dict[str, int] = defaultdict(int)
    calls: Counter = Counter()
    with stage_clocks(totals_ns, calls):
        summary = bench_fdchp_hour._process(bag, params, out, write_bag=False)
    rows = summary.duration_s * fdchp_simulated.RATE_HZ
    return {
        "rows": rows,
        "wall_s": summary.wall_s,
        "us_per_row": summary.wall_s / rows * 1e6,
        "stages": [
            {
                "stage": label,
                "us_per_row": totals_ns[label] / 1e3 / rows,
                "calls": calls[label],
            }
            for label, _, _ in STAGES
        ],
    }


def print_row_stages(result: dict) -> None:
    print(
        f"\nWhere a row of the simulated FDCHP hour goes (NetCDF file alone, stage clocks): "
        f"{result['wall_s']:.2f} s, {result['us_per_row']:.0f} µs a row with the clocks"
    )
    for stage in result["stages"]:
        print(f"  {stage['us_per_row']:7.1f} µs a row {stage['calls']:8d} calls  {stage['stage']}")


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(prog="bench_row_stages", description=__doc__.split("\n")[0])
    parser.parse_args(argv)
    result = run_row_stages(lambda text: print(text, flush=True))
    print_row_stages(result)
    OUT_DIR.mkdir(parents=True, exist_ok=True)
    (OUT_DIR / "row_stages.json").write_text(json.dumps(result, indent=2))


if __name__ == "__main__":
    main()
