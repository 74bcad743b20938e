"""The filter's work for one row of a motion-pack hour, interpreted and compiled.

    python -m tools.bench_filter_row

On the simulated FDCHP hour (``tools/bench_fdchp_hour.py``), every aligned row whose one
measurement is the pack's attitude at the IMU stamp, with no constraint due, makes the same
filter step: integrate to the stamp, propagate the covariance, the pack's attitude model, the
gate, the Joseph update, the injection and the covariance's reset. The engine does it through
some twenty interpreted calls between its compiled kernels. This tool times those rows in the
engine (``FusionEngine._process_sample``, wall per row) and then runs the same step as ONE
compiled call composed of the engine's own kernels (strapdown step, error model, gate, update,
injection, reset, the pack's innovation and covariance), from the state and covariance the
engine had before each row, and compares the result with what the engine had after it. It
measures what a compiled event loop would cost a row of this filter; it is not a second engine
(the composed step lives here, beside the measurement). Writes out/bench/filter_row.json.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import time

import numba
import numpy as np

from buoy_nav import earth
from buoy_nav import kalman_kernel as kalman
from buoy_nav.aiding.ahrs_attitude import (
    AhrsAttitudeSource,
    _attitude_innovation,
    _model_covariance,
)
from buoy_nav.aiding.base import samples_per_correlation_time
from buoy_nav.config import fusion_config_from_files
from buoy_nav.engine import FusionEngine
from buoy_nav.error_state_filter import (
    ERROR_STATES,
    SCALE_FACTOR_CORRELATION_TIME_S,
    ImuErrorModel,
    _fill_error_model,
    chi_square_quantile,
)
from buoy_nav.rotations import rotation_matrix_elements
from buoy_nav.strapdown_kernel import (
    ALTITUDE,
    ATTITUDE,
    DURATION,
    FORCE_DEVIATION_SQ_SUM,
    FORCE_SUM,
    GYRO_BIAS,
    LATITUDE,
    RATE_SQ_SUM,
    ROTATION_SUM,
    VELOCITY,
    inject_error_state,
    strapdown_step,
)
from tools import bench_fdchp_hour

OUT_DIR = bench_fdchp_hour.OUT_DIR
TIMED_PASSES = 3
# The nominal state's part of the state vector: the propagation sums after it are reset by the
# covariance's propagation and compared through the covariance.
NOMINAL_SIZE = DURATION
ATTITUDE_ERROR_START = ERROR_STATES.attitude.start

_radii_of_curvature_m = numba.njit(cache=True)(earth.radii_of_curvature_m)
_normal_gravity_mps2 = numba.njit(cache=True)(earth.normal_gravity_mps2)
_rotation_matrix_elements = numba.njit(cache=True)(rotation_matrix_elements)


@numba.njit(cache=True)
def _propagate(state, covariance, imu, gyro_drift_scale, accel_noise_scale):
    """The covariance ``covariance`` carried over the interval integrated in ``state`` (the
    strapdown kernel's layout; its sums restarted), as ``discrete_error_model`` and
    ``ErrorStateFilter.propagate`` compute it. ``imu``: scale_factor, gyro noise PSD (rad²/s),
    accel noise PSD (m²/s³), gyro Markov σ (rad/s) and τ (s), accel Markov σ (m/s²) and τ (s)."""
    duration = state[DURATION]
    latitude, altitude = state[LATITUDE], state[ALTITUDE]
    meridian, prime_vertical = _radii_of_curvature_m(latitude)
    earth_rate = np.array(
        (0.0, earth.EARTH_RATE_RAD_S * np.cos(latitude), earth.EARTH_RATE_RAD_S * np.sin(latitude))
    )
    east_radius = prime_vertical + altitude
    v_east, v_north = state[VELOCITY], state[VELOCITY + 1]
    transport_rate = np.array(
        (
            -v_north / (meridian + altitude),
            v_east / east_radius,
            v_east * math.tan(latitude) / east_radius,
        )
    )
    transition = np.empty((covariance.shape[0], covariance.shape[0]))
    noise = np.zeros((covariance.shape[0], covariance.shape[0]))
    _fill_error_model(
        transition,
        noise,
        duration,
        earth_rate + transport_rate,
        2.0 * earth_rate + transport_rate,
        state[FORCE_SUM : FORCE_SUM + 3].copy(),
        state[ROTATION_SUM : ROTATION_SUM + 9].reshape(3, 3).copy(),
        meridian + altitude,
        prime_vertical + altitude,
        math.tan(latitude),
        _normal_gravity_mps2(latitude, altitude),
        imu[0] ** 2 * SCALE_FACTOR_CORRELATION_TIME_S,
        state[RATE_SQ_SUM : RATE_SQ_SUM + 3].copy(),
        state[FORCE_DEVIATION_SQ_SUM : FORCE_DEVIATION_SQ_SUM + 3].copy(),
        imu[1] * duration,
        accel_noise_scale**2 * imu[2] * duration,
        2.0 * (gyro_drift_scale * imu[3]) ** 2 * duration / imu[4],
        2.0 * imu[5] ** 2 * duration / imu[6],
        0,
        3,
        6,
        9,
        12,
    )
    state[DURATION:] = 0.0
    return kalman.propagated(covariance, transition, noise)


@numba.njit(cache=True)
def compiled_row(
    state,
    covariance,
    step_s,
    gyro_start,
    gyro_end,
    force_start,
    force_end,
    measured_nb,
    measured_covariance_rad2,
    weight,
    lag_s,
    lag_uncertainty_s,
    floor_rad2,
    gate_threshold,
    jacobian,
    imu,
    gyro_drift_scale,
    accel_noise_scale,
):
    """One filter step of a motion-pack row in place of ``state``: integrate ``step_s`` (s)
    between the raw samples (body rad/s, m/s²), propagate, and fuse the pack's true-north
    attitude ``measured_nb`` (body→ENU) of covariance ``measured_covariance_rad2`` (ENU rad²).
    Returns the covariance after the row, the NIS and whether the gate accepted it."""
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
    if state[DURATION] > 0.0:
        covariance = _propagate(state, covariance, imu, gyro_drift_scale, accel_noise_scale)
    elements = _rotation_matrix_elements(
        state[ATTITUDE], state[ATTITUDE + 1], state[ATTITUDE + 2], state[ATTITUDE + 3]
    )
    rotation_nb = np.empty((3, 3))
    for index in range(9):
        rotation_nb[index // 3, index % 3] = elements[index]
    rate_x = gyro_end[0] - state[GYRO_BIAS]
    rate_y = gyro_end[1] - state[GYRO_BIAS + 1]
    rate_z = gyro_end[2] - state[GYRO_BIAS + 2]
    innovation = np.array(
        _attitude_innovation(measured_nb, rotation_nb, rate_x, rate_y, rate_z, lag_s)
    )
    lag_variance = (rate_x**2 + rate_y**2 + rate_z**2) * lag_uncertainty_s**2
    model_covariance = _model_covariance(measured_covariance_rad2, floor_rad2, lag_variance, weight)
    nis, _ = kalman.innovation_test(covariance, innovation, jacobian, model_covariance)
    if not nis <= gate_threshold:
        return covariance, nis, False
    covariance, correction, _ = kalman.joseph_update(
        covariance, innovation, jacobian, model_covariance
    )
    inject_error_state(state, correction)
    covariance, _ = kalman.attitude_reset(covariance, correction, ATTITUDE_ERROR_START)
    return covariance, nis, True


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
            for source, _ in group:
                source.__dict__.pop("_true_north", None)
            if len(group) == 1 and isinstance(group[0][0], AhrsAttitudeSource):
                source, measurement = group[0]
                rows.append(
                    {
                        **before,
                        "after": _filter_snapshot(engine),
                        "interpolated": seen["samples"],
                        "measured_nb": np.ascontiguousarray(seen["measured_nb"], dtype=float),
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
    """Record the group the row pops, the samples interpolated at its stamp and the pack's
    attitude turned to true north (instance attributes over the methods, removed after the
    row)."""
    seen = {"group": [], "samples": None, "measured_nb": None}
    queue, point = engine._queue, engine._point
    pop_stamp, samples_at = queue.pop_stamp, point.samples_at

    def popped():
        stamp, seen["group"] = pop_stamp()
        for source, _ in seen["group"]:
            if isinstance(source, AhrsAttitudeSource):
                _watch_true_north(source, seen)
        return stamp, seen["group"]

    def interpolated(*arguments):
        seen["samples"] = samples_at(*arguments)
        return seen["samples"]

    queue.pop_stamp, point.samples_at = popped, interpolated
    return seen


def _watch_true_north(source: AhrsAttitudeSource, seen: dict) -> None:
    true_north = source._true_north

    def turned(*arguments):
        seen["measured_nb"] = true_north(*arguments)
        return seen["measured_nb"]

    source._true_north = turned


def row_arguments(row: dict, imu: np.ndarray, jacobian: np.ndarray) -> tuple:
    """The arguments of :func:`compiled_row` for a captured ``row`` (state and covariance
    copied)."""
    source, measurement = row["source"], row["measurement"]
    gyro_end, force_end = row["interpolated"]
    before = row["after"]["t_s"]
    return (
        row["state"].copy(),
        row["covariance"].copy(),
        before - row["t_s"],
        np.array(row["gyro"]),
        np.array(gyro_end, dtype=float),
        np.array(row["force"]),
        np.array(force_end, dtype=float),
        row["measured_nb"],
        np.ascontiguousarray(measurement.covariance_rad2, dtype=float),
        samples_per_correlation_time(measurement.interval_s, source._correlation_s),
        source._lag_s,
        source._lag_uncertainty_s,
        source._floor_rad2,
        chi_square_quantile(3, source.gate_probability),
        jacobian,
        imu,
        *row["scales"],
    )


def imu_parameters(config) -> np.ndarray:
    """The IMU error model's parameters in the order :func:`_propagate` reads them."""
    model = ImuErrorModel.from_config(config)
    return np.array(
        (
            model.scale_factor,
            model.gyro_noise_psd_rad2_s,
            model.accel_noise_psd_m2_s3,
            model.gyro_markov_sigma_rad_s,
            model.gyro_correlation_time_s,
            model.accel_markov_sigma_mps2,
            model.accel_correlation_time_s,
        )
    )


def replay(rows: list[dict], imu: np.ndarray) -> dict:
    """Each captured row through :func:`compiled_row`: how many match the engine to the bit,
    the largest relative difference, and the best wall per row over :data:`TIMED_PASSES`."""
    jacobian = np.zeros((3, ERROR_STATES.dim))
    jacobian[:, ERROR_STATES.attitude] = np.eye(3)
    arguments = [row_arguments(row, imu, jacobian) for row in rows]
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
    result = replay(rows, imu_parameters(config))
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
