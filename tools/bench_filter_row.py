"""The filter's work for one row of a motion-pack hour, interpreted and compiled.

    python -m tools.bench_filter_row

On the simulated FDCHP hour (``tools/bench_fdchp_hour.py``), every aligned row whose one
measurement is the pack's attitude at the IMU stamp, with no constraint due, makes the same
filter step: integrate to the stamp, propagate the covariance, the pack's attitude model, the
gate, the Joseph update, the injection and the covariance's reset. The engine does it through
interpreted calls between its compiled kernels (the strapdown step, the covariance's
propagation, the pack's compiled update). This tool times those rows in the engine
(``FusionEngine._process_sample``, wall per row) and then runs the same step as ONE compiled
call composed of the same kernels, from the state and covariance the engine had before each
row, and compares the result with what the engine had after it: what a compiled event loop
would cost a row of this filter. Writes out/bench/filter_row.json.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import time

import numba
import numpy as np

from buoy_nav.aiding.ahrs_attitude import AhrsAttitudeSource, attitude_update
from buoy_nav.config import fusion_config_from_files
from buoy_nav.engine import FusionEngine
from buoy_nav.error_dynamics import noise_coefficients, propagated_covariance_kernel
from buoy_nav.error_state_filter import ImuErrorModel
from buoy_nav.strapdown_kernel import (
    DURATION,
    inject_error_state,
    strapdown_step,
)
from tools import bench_fdchp_hour

OUT_DIR = bench_fdchp_hour.OUT_DIR
TIMED_PASSES = 3
# The nominal state's part of the state vector: the propagation sums after it are reset by the
# covariance's propagation and compared through the covariance.
NOMINAL_SIZE = DURATION


@numba.njit(cache=True)
def _integrate(state, step_s, gyro_start, gyro_end, force_start, force_end):
    """The strapdown step of ``step_s`` (s) between the raw samples (body rad/s, m/s²)."""
    strapdown_step(
        state,
        step_s,
        gyro_start[0],
        gyro_start[1],
        gyro_start[2],
        gyro_end[0],
        gyro_end[1],
        gyro_end[2],
        force_start[0],
        force_start[1],
        force_start[2],
        force_end[0],
        force_end[1],
        force_end[2],
        True,
        True,
    )


@numba.njit(cache=True)
def compiled_row(
    state,
    covariance,
    step_s,
    gyro_start,
    gyro_end,
    force_start,
    force_end,
    noise_terms,
    update_arguments,
):
    """One filter step of a motion-pack row in place of ``state``: integrate ``step_s`` (s)
    between the raw samples (body rad/s, m/s²), propagate with the IMU's ``noise_terms``
    (:func:`buoy_nav.error_dynamics.propagated_covariance`'s) and apply the pack's compiled
    update (``update_arguments``: those of its kernel after the covariance and the state).
    Returns the covariance after the row, the NIS and whether the gate accepted it."""
    _integrate(state, step_s, gyro_start, gyro_end, force_start, force_end)
    if state[DURATION] > 0.0:
        _, covariance = propagated_covariance_kernel(state, covariance, noise_terms)
    _, nis, _, accepted, updated, correction, _ = attitude_update(
        covariance, state, *update_arguments
    )
    if accepted:
        inject_error_state(state, correction)
    return updated, nis, accepted


class RowCapture:
    """Wraps ``FusionEngine._process_sample`` while a run lasts: for each row of the pack's
    attitude alone (see the module docstring) the engine's state and covariance before and
    after, the row's inputs and the wall time the engine took for it."""

    def __init__(self):
        self.rows: list[dict] = []
        self._original = FusionEngine._process_sample

    def __enter__(self):
        original, rows = self._original, self.rows

        def process_sample(engine, t, gyro, force):
            nav, queue = engine._nav, engine._queue
            if (
                nav is None
                or not queue.heap
                or queue.heap[0][0] != t
                or any(t >= source.next_due_s for source in engine._registry.pseudo)
            ):
                return original(engine, t, gyro, force)
            before = _filter_snapshot(engine)
            seen = _watch_row(engine)
            accepted = engine._counters[AhrsAttitudeSource.kind].accepted
            start = time.perf_counter()
            result = original(engine, t, gyro, force)
            elapsed_s = time.perf_counter() - start
            del queue.pop_stamp, engine._point.samples_at
            group = seen["group"]
            if len(group) == 1 and isinstance(group[0][0], AhrsAttitudeSource):
                source, measurement = group[0]
                rows.append(
                    {
                        **before,
                        "after": _filter_snapshot(engine),
                        "interpolated": seen["samples"],
                        "gate": nav.kalman,
                        "measurement": measurement,
                        "source": source,
                        "accepted": engine._counters[source.kind].accepted == accepted + 1,
                        "engine_s": elapsed_s,
                    }
                )
            return result

        FusionEngine._process_sample = process_sample
        return self

    def __exit__(self, *exc_info):
        FusionEngine._process_sample = self._original


def _filter_snapshot(engine) -> dict:
    nav, point = engine._nav, engine._point
    return {
        "t_s": point.t_s,
        "gyro": tuple(map(float, point.gyro)),
        "force": tuple(map(float, point.force)),
        "state": nav.integrator.state_vector.copy(),
        "covariance": nav.kalman.covariance.copy(),
        "scales": (nav.gyro_drift_scale, nav.accel_noise_scale),
    }


def _watch_row(engine) -> dict:
    """Record the group the row pops and the samples interpolated at its stamp (instance
    attributes over the methods, removed after the row)."""
    seen = {"group": [], "samples": None}
    queue, point = engine._queue, engine._point
    pop_stamp, samples_at = queue.pop_stamp, point.samples_at

    def popped():
        stamp, seen["group"] = pop_stamp()
        return stamp, seen["group"]

    def interpolated(*arguments):
        seen["samples"] = samples_at(*arguments)
        return seen["samples"]

    queue.pop_stamp, point.samples_at = popped, interpolated
    return seen


def row_arguments(row: dict, noise_terms: tuple[float, ...]) -> tuple:
    """The arguments of :func:`compiled_row` for a captured ``row`` (state and covariance
    copied): the pack's update is linearised where the engine linearised it, at the state
    integrated to the row's stamp."""
    gyro_end, force_end = row["interpolated"]
    step = (
        row["after"]["t_s"] - row["t_s"],
        np.array(row["gyro"]),
        np.array(gyro_end, dtype=float),
        np.array(row["force"]),
        np.array(force_end, dtype=float),
    )
    integrated = row["state"].copy()
    _integrate(integrated, *step)
    update_arguments = row["source"].update_arguments(
        row["measurement"], gyro_end, integrated, row["gate"]
    )
    return (row["state"].copy(), row["covariance"].copy(), *step, noise_terms, update_arguments)


def noise_terms(config, scales: tuple[float, float]) -> tuple[float, ...]:
    """The IMU's noise terms of the covariance's propagation with the sources' ``scales`` of
    the gyro's drift and the accelerometer's noise."""
    return noise_coefficients(ImuErrorModel.from_config(config), *scales)


def replay(rows: list[dict], config) -> dict:
    """Each captured row through :func:`compiled_row`: how many match the engine to the bit,
    the largest relative difference, and the best wall per row over :data:`TIMED_PASSES`."""
    terms = {}
    arguments = []
    for row in rows:
        scales = row["scales"]
        if scales not in terms:
            terms[scales] = noise_terms(config, scales)
        arguments.append(row_arguments(row, terms[scales]))
    identical_state = identical_covariance = same_verdict = 0
    largest = 0.0
    for row, call in zip(rows, arguments, strict=True):
        covariance, _, accepted = compiled_row(*call)
        state, after = call[0], row["after"]
        same_verdict += accepted == row["accepted"]
        identical_state += np.array_equal(state[:NOMINAL_SIZE], after["state"][:NOMINAL_SIZE])
        identical_covariance += np.array_equal(covariance, after["covariance"])
        largest = max(
            largest,
            _largest_relative_difference(state[:NOMINAL_SIZE], after["state"][:NOMINAL_SIZE]),
            _largest_relative_difference(covariance, after["covariance"]),
        )
    best_s = math.inf
    for _ in range(TIMED_PASSES):
        calls = [(call[0].copy(), call[1].copy(), *call[2:]) for call in arguments]
        start = time.perf_counter()
        for call in calls:
            compiled_row(*call)
        best_s = min(best_s, (time.perf_counter() - start) / len(calls))
    return {
        "rows": len(rows),
        "same_gate_verdict": same_verdict,
        "state_identical": identical_state,
        "covariance_identical": identical_covariance,
        "largest_relative_difference": largest,
        "compiled_us_per_row": best_s * 1e6,
    }


def _largest_relative_difference(values: np.ndarray, reference: np.ndarray) -> float:
    differing = values != reference
    if not differing.any():
        return 0.0
    return float(np.max(np.abs(values - reference)[differing] / np.abs(reference[differing])))


def run_filter_row(log=lambda text: None) -> dict:
    bag, params = bench_fdchp_hour.simulated_hour()
    out = bench_fdchp_hour.WORK_DIR / "filter_row"
    out.mkdir(parents=True, exist_ok=True)
    log("bench: filter_row: the engine on the simulated FDCHP hour ...")
    with RowCapture() as capture:
        bench_fdchp_hour._process(bag, params, out)
    rows = capture.rows
    if not rows:
        raise SystemExit("bench_filter_row: no row of the pack's attitude alone was found")
    log(f"bench: filter_row: {len(rows)} rows through the compiled step ...")
    config = fusion_config_from_files([str(path) for path in params])
    result = replay(rows, config)
    engine_s = sorted(row["engine_s"] for row in rows)
    result["engine_us_per_row_median"] = engine_s[len(engine_s) // 2] * 1e6
    result["engine_us_per_row_mean"] = sum(engine_s) / len(engine_s) * 1e6
    result["ratio_median"] = result["engine_us_per_row_median"] / result["compiled_us_per_row"]
    return result


def print_filter_row(result: dict) -> None:
    print(
        "\nThe filter's step of a motion-pack row (integrate, propagate, the pack's attitude, "
        "gate, update, injection, reset) on the simulated FDCHP hour"
    )
    print(
        f"  rows {result['rows']}: the engine {result['engine_us_per_row_median']:.1f} µs a row "
        f"(median; mean {result['engine_us_per_row_mean']:.1f}), one compiled call "
        f"{result['compiled_us_per_row']:.1f} µs (best of {TIMED_PASSES} passes): "
        f"{result['ratio_median']:.1f}×"
    )
    print(
        f"  against the engine: gate verdict the same in {result['same_gate_verdict']}, "
        f"state identical in {result['state_identical']}, covariance identical in "
        f"{result['covariance_identical']}; largest relative difference "
        f"{result['largest_relative_difference']:.2g}"
    )


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(prog="bench_filter_row", description=__doc__.split("\n")[0])
    parser.parse_args(argv)
    result = run_filter_row(lambda text: print(text, file=sys.stderr, flush=True))
    print_filter_row(result)
    OUT_DIR.mkdir(parents=True, exist_ok=True)
    (OUT_DIR / "filter_row.json").write_text(json.dumps(result, indent=2))


if __name__ == "__main__":
    main()
