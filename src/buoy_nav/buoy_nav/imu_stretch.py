"""A stretch of IMU samples between aiding measurements, in one compiled call.

Most IMU samples of an aided run change nothing but the nominal states: the sample enters the
buffer, the prediction ahead steps to it and writes its solution's row
(:mod:`buoy_nav.prediction`), and the filter, ``max_measurement_delay_s`` behind, steps to the
buffered samples its horizon passed (:meth:`~buoy_nav.engine.FusionEngine._process`).
:func:`imu_stretch` does exactly that for consecutive accepted samples, with the engine's own
kernels (the strapdown step, the row writer) and in the engine's order, and stops where the
engine has more to do: a measurement due, the covariance's batch full, a gap, the prediction to
fork afresh, the rows' block full. The engine then takes over at that sample
(:meth:`~buoy_nav.engine.FusionEngine.add_imu_samples`), so the result is the engine's to the
bit; a test holds the two equal.
"""

import itertools
import math
from collections import deque
from typing import NamedTuple

import numba
import numpy as np

from buoy_nav.solution_rows import write_row
from buoy_nav.strapdown_kernel import DURATION, strapdown_step
from buoy_nav.strapdown_kernel import STATE_SIZE as STRAPDOWN_STATE_SIZE
from buoy_nav.stream_sequence import SEQUENCE_INTERVALS

DONE = 0
"""Every sample of the stretch taken, the filter caught up to the last one's horizon."""
BEFORE_SAMPLE = 1
"""Stopped before the sample at the count returned: the engine takes it the interpreted way."""
CATCH_UP = 2
"""Stopped after the prediction of the last sample counted: the engine's filtering up to that
sample's horizon (:meth:`~buoy_nav.engine.FusionEngine.catch_up`) is left to do."""

# The state handed in and out (:func:`imu_stretch`'s ``state``): where the (stamp s, gyro,
# force) samples the filter's and the prediction's states are at begin, then the stamp of the
# latest sample predicted (s), the output decimation's next output stamp (s), the rows written.
POINT = 0
AHEAD = 7
SAMPLE_SIZE = 7
LAST_PREDICTED_T = 14
NEXT_OUTPUT_T = 15
ROWS = 16
STATE_SIZE = 17
# The limits handed in (:func:`imu_stretch`'s ``limits``).
DELAY, MAX_GAP, PROPAGATION_INTERVAL, NEXT_MEASUREMENT, OUTPUT_PERIOD = range(5)
DISTRUSTED, ATTITUDE_VARIANCE, VELOCITY_VARIANCE = range(5, 8)
# The screening's limits and state (:func:`imu_stretch`'s ``screening`` and ``screened_state``,
# :meth:`~buoy_nav.imu_input.ImuInput.steady_screening`): the clock's offset (s), the largest
# squared rate and force, the largest gap (s), the calibration's gyro biases, accelerometer
# biases and scales (none when CALIBRATED is 0.0), the largest angular acceleration and jerk,
# the rate's and force's noise allowances, the learnt sample interval (s) and the exponent of
# the squares (2.0, handed in so that they are the C library's, as the interpreter's ``** 2``);
# the latest accepted stamp, the sequence's latest stamp, the clock's sample interval (s) and
# the last accepted sample (stamp s, gyro, force).
(CLOCK_OFFSET, MAX_RATE_SQ, MAX_FORCE_SQ, SCREENING_MAX_GAP, CALIBRATED) = range(5)
GYRO_BIAS, ACCEL_BIAS, ACCEL_SCALE = 5, 8, 11
(MAX_ANGULAR_ACCELERATION, MAX_JERK, RATE_NOISE, FORCE_NOISE, SAMPLE_INTERVAL) = range(14, 19)
SQUARE = 19
SCREENING_SIZE = 20
LATEST, SEQUENCE_LAST, CLOCK_INTERVAL, LAST_SAMPLE = 0, 1, 2, 3
SCREENED_STATE_SIZE = 10


class Taken(NamedTuple):
    """What a stretch took: its samples (stamp s, gyro, force; re-stamped and calibrated),
    whether each one's solution was written, and whether the engine's filtering up to the last
    one's horizon is left to do (:data:`CATCH_UP`)."""

    samples: list[tuple]
    rows_written: list[bool]
    catch_up: bool


class ImuStretches:
    """The parts of a :class:`~buoy_nav.engine.FusionEngine` a stretch reads and moves (its
    fusion ``config``, IMU ``buffer`` ahead of the filter, processing ``point``, real-time
    ``prediction``, ``output`` decimation, ``solutions`` and measurement ``queue``, the
    ``imu_input``'s screening), handed to :func:`imu_stretch` and set from what it did."""

    def __init__(
        self, config, buffer: deque, point, prediction, output, solutions, queue, imu_input
    ):
        self._config = config
        self._buffer = buffer
        self._point = point
        self._prediction = prediction
        self._output = output
        self._solutions = solutions
        self._queue = queue
        self._imu_input = imu_input

    def take(self, raw: np.ndarray, screening: tuple, nav) -> Taken | None:
        """The ``raw`` samples (n × 7: stamp s, gyro, force) through :func:`imu_stretch`, with
        the IMU ``screening``'s limits and state and the aided navigation ``nav``; None when it
        took none (the engine takes the first itself)."""
        limits_of_screening, screened_state = screening
        due = self._buffered_within_reach(raw, limits_of_screening[CLOCK_OFFSET])
        ahead = self._prediction.ahead[0]
        state = self._state()
        screened = np.empty_like(raw)
        rows_written = np.zeros(len(raw), dtype=bool)
        plane_terms, covariance, block_indices, distrusted, distrust = (
            self._solutions.row_arguments(nav.kalman)
        )
        count, stepped, stop = imu_stretch(
            raw,
            limits_of_screening,
            screened_state,
            screened,
            np.array([(t, *gyro, *force) for t, gyro, force in due]).reshape(-1, SAMPLE_SIZE),
            state,
            self._limits(distrusted, distrust),
            nav.integrator.state_vector,
            nav.integrator.coning_correction,
            nav.integrator.sculling_correction,
            ahead.state_vector,
            ahead.coning_correction,
            ahead.sculling_correction,
            self._solutions.rows.block,
            plane_terms,
            covariance,
            block_indices,
            rows_written,
        )
        if count == 0:
            return None
        took = [
            (t, (gx, gy, gz), (fx, fy, fz))
            for t, gx, gy, gz, fx, fy, fz in screened[:count].tolist()
        ]
        self._imu_input.screened_through(screened_state, took[-1])
        self._moved(state, due, took, stepped)
        return Taken(took, rows_written[:count].tolist(), stop == CATCH_UP)

    def _buffered_within_reach(self, raw: np.ndarray, clock_offset_s: float) -> list[tuple]:
        """The buffered samples the filter may step to while taking ``raw``: none beyond the
        horizon of its latest stamp (the clock's offset ``clock_offset_s`` stays while a
        stretch runs: a step of the clock has samples held, which stops it)."""
        stamps = raw[:, 0]
        finite = stamps[np.isfinite(stamps)]
        latest_s = finite.max() + clock_offset_s if finite.size else -math.inf
        reach_s = latest_s - self._config.max_measurement_delay_s
        return list(itertools.takewhile(lambda sample: sample[0] <= reach_s, self._buffer))

    def _state(self) -> np.ndarray:
        """:func:`imu_stretch`'s ``state`` from the parts."""
        point, prediction = self._point, self._prediction
        _, ahead_t, ahead_gyro, ahead_force = prediction.ahead
        return np.array(
            (
                point.t_s,
                *point.gyro,
                *point.force,
                ahead_t,
                *ahead_gyro,
                *ahead_force,
                prediction.last_predicted_stamp_s,
                self._output.next_output_s,
                self._solutions.rows.count,
            ),
            dtype=float,
        )

    def _limits(self, distrusted: bool, distrust: tuple[float, float]) -> np.ndarray:
        """:func:`imu_stretch`'s ``limits``, the filter ``distrusted`` or not (``distrust``: the
        attitude and velocity variances then added)."""
        config = self._config
        heap = self._queue.heap
        return np.array(
            (
                config.max_measurement_delay_s,
                config.max_imu_gap_s,
                config.covariance_propagation_interval_s,
                heap[0][0] if heap else math.inf,
                self._output.period_s,
                1.0 if distrusted else 0.0,
                *distrust,
            )
        )

    def _moved(self, state: np.ndarray, due: list, took: list, stepped: int) -> None:
        """The parts set from what the stretch did: it ``took`` these samples (into the
        buffer) and stepped the filter to ``stepped`` of the ``due`` buffered samples and
        then of those; ``state`` as it left it."""
        point = self._point
        buffer = self._buffer
        buffer.extend(took)
        if stepped:
            walked = [(point.t_s, point.gyro, point.force), *due, *took]
            for _ in range(stepped):
                buffer.popleft()
            point.stepped_through(walked[stepped - 1], walked[stepped])
        self._prediction.predicted_through(took[-1])
        self._output.next_output_s = float(state[NEXT_OUTPUT_T])
        self._solutions.rows.count = int(state[ROWS])


@numba.njit(cache=True)
def imu_stretch(
    raw,
    screening,
    screened_state,
    samples,
    buffered,
    state,
    limits,
    filter_state,
    filter_coning,
    filter_sculling,
    ahead_state,
    ahead_coning,
    ahead_sculling,
    rows_block,
    plane_terms,
    covariance,
    block_indices,
    row_written,
):
    """Take the ``raw`` IMU samples (n × 7: header stamp s, ω_ib body rad/s, specific force
    body m/s²), after the ``buffered`` ones ahead of the filter that the stretch may reach
    (k × 7, oldest first), as the engine's ``add_imu`` and ``catch_up`` would, until one needs
    the engine: each screened as :meth:`~buoy_nav.imu_input.ImuInput.accept` screens it
    (``screening``, ``screened_state`` updated; into ``samples``, n × 7, re-stamped and
    calibrated), then taken.

    state: :data:`POINT` … :data:`ROWS`, updated; limits: :data:`DELAY` (the fusion's
    ``max_measurement_delay_s``) … :data:`VELOCITY_VARIANCE` (the stamp of the next measurement
    queued, inf: none; the output period, 0: every sample; the distrust, 1.0 or 0.0, and its
    variances); filter_state, ahead_state: the strapdown states, stepped in place, with their
    coning and sculling corrections; rows_block and the row writer's other arguments
    (:func:`~buoy_nav.solution_rows.write_row`); row_written: set for each sample whose
    solution was written.

    Returns (samples taken, buffered samples the filter stepped to, :data:`DONE`,
    :data:`BEFORE_SAMPLE` or :data:`CATCH_UP`); the filter's latest two samples are then the
    last two stepped to (the buffered ones, then the taken ones).
    """
    delay_s = limits[DELAY]
    max_gap_s = limits[MAX_GAP]
    # Integer bounds: a slice object held globally would be unpickled at each call.
    point = state[POINT : POINT + SAMPLE_SIZE]
    ahead = state[AHEAD : AHEAD + SAMPLE_SIZE]
    n_buffered = buffered.shape[0]
    stepped = 0
    for index in range(raw.shape[0]):
        sample = samples[index]
        if not _screened(raw[index], screening, screened_state, sample):
            return index, stepped, BEFORE_SAMPLE
        t = sample[0]
        span = t - ahead[0]
        if span > max_gap_s or state[ROWS] >= rows_block.shape[0]:
            return index, stepped, BEFORE_SAMPLE
        _accepted(screening, screened_state, sample)
        _step(ahead_state, span, ahead, sample, ahead_coning, ahead_sculling)
        ahead[:] = sample
        if t > state[LAST_PREDICTED_T] and _due(state, t, span, limits[OUTPUT_PERIOD]):
            write_row(
                rows_block,
                int(state[ROWS]),
                t,
                ahead_state,
                sample[1],
                sample[2],
                sample[3],
                sample[4],
                sample[5],
                sample[6],
                plane_terms,
                covariance,
                block_indices,
                limits[DISTRUSTED] != 0.0,
                limits[ATTITUDE_VARIANCE],
                limits[VELOCITY_VARIANCE],
            )
            state[ROWS] += 1
            row_written[index] = True
        state[LAST_PREDICTED_T] = t
        horizon = t - delay_s
        while stepped < n_buffered + index + 1:
            due = buffered[stepped] if stepped < n_buffered else samples[stepped - n_buffered]
            t_due = due[0]
            if t_due > horizon:
                break
            dt = t_due - point[0]
            # A gap, or a sample predicted before (above), the prediction meets first and the
            # engine takes; the stretch still never steps across one.
            if (
                t_due - point[0] > max_gap_s
                or limits[NEXT_MEASUREMENT] <= t_due
                or (dt > 0.0 and filter_state[DURATION] + dt >= limits[PROPAGATION_INTERVAL])
            ):
                return index + 1, stepped, CATCH_UP
            if dt > 0.0:
                _step(filter_state, dt, point, due, filter_coning, filter_sculling)
            point[:] = due
            stepped += 1
    return raw.shape[0], stepped, DONE


@numba.njit(cache=True)
def _screened(raw_sample, screening, screened_state, sample) -> bool:
    """Whether :meth:`~buoy_nav.imu_input.ImuInput.accept` would accept ``raw_sample`` as the
    next sample of the sequence with nothing else to do (nothing held, refused, restarted or
    learnt); ``sample`` then holds it re-stamped and calibrated. Nothing else is changed."""
    t = raw_sample[0]
    stamp = t + screening[CLOCK_OFFSET]
    latest = screened_state[LATEST]
    sequence_last = screened_state[SEQUENCE_LAST]
    if not (
        stamp > latest
        and (
            stamp == sequence_last
            or (
                stamp > sequence_last
                and not stamp - sequence_last > SEQUENCE_INTERVALS * screened_state[CLOCK_INTERVAL]
            )
        )
    ):
        return False
    gx, gy, gz, fx, fy, fz = raw_sample[1:7]
    if not (math.isfinite(t) and math.isfinite(gx + gy + gz) and math.isfinite(fx + fy + fz)):
        return False
    if screening[CALIBRATED] != 0.0:
        gx = gx - screening[GYRO_BIAS]
        gy = gy - screening[GYRO_BIAS + 1]
        gz = gz - screening[GYRO_BIAS + 2]
        fx = (fx - screening[ACCEL_BIAS]) / screening[ACCEL_SCALE]
        fy = (fy - screening[ACCEL_BIAS + 1]) / screening[ACCEL_SCALE + 1]
        fz = (fz - screening[ACCEL_BIAS + 2]) / screening[ACCEL_SCALE + 2]
    if (
        gx * gx + gy * gy + gz * gz > screening[MAX_RATE_SQ]
        or fx * fx + fy * fy + fz * fz > screening[MAX_FORCE_SQ]
    ):
        return False
    if stamp - latest > screening[SCREENING_MAX_GAP]:
        return False
    last = screened_state[LAST_SAMPLE : LAST_SAMPLE + SAMPLE_SIZE]
    dt = stamp - last[0]
    if dt > 0.0 and dt < screening[SAMPLE_INTERVAL]:
        return False
    square = screening[SQUARE]
    rate_bound = screening[MAX_ANGULAR_ACCELERATION] * dt + screening[RATE_NOISE]
    force_bound = screening[MAX_JERK] * dt + screening[FORCE_NOISE]
    if (
        math.pow(gx - last[1], square)
        + math.pow(gy - last[2], square)
        + math.pow(gz - last[3], square)
        > rate_bound * rate_bound
        or math.pow(fx - last[4], square)
        + math.pow(fy - last[5], square)
        + math.pow(fz - last[6], square)
        > force_bound * force_bound
    ):
        return False
    sample[0] = stamp
    sample[1] = gx
    sample[2] = gy
    sample[3] = gz
    sample[4] = fx
    sample[5] = fy
    sample[6] = fz
    return True


@numba.njit(cache=True)
def _accepted(screening, screened_state, sample) -> None:
    """The screened ``sample`` accepted: the screening's state follows it (the sequence, the
    clock's sample interval, the last accepted sample)."""
    stamp = sample[0]
    dt = stamp - screened_state[LATEST]
    if dt <= screening[SCREENING_MAX_GAP] and not dt > (
        SEQUENCE_INTERVALS * screened_state[CLOCK_INTERVAL]
    ):
        screened_state[CLOCK_INTERVAL] = dt
    screened_state[LATEST] = stamp
    screened_state[SEQUENCE_LAST] = stamp
    screened_state[LAST_SAMPLE : LAST_SAMPLE + SAMPLE_SIZE] = sample


@numba.njit(cache=True)
def _step(state, dt_s, start, end, coning, sculling):
    """The strapdown step of ``state`` over ``dt_s`` (s) from the (stamp, gyro, force) sample
    ``start`` to ``end``, with the ``coning`` and ``sculling`` corrections or not."""
    strapdown_step(
        state,
        dt_s,
        start[1],
        start[2],
        start[3],
        end[1],
        end[2],
        end[3],
        start[4],
        start[5],
        start[6],
        end[4],
        end[5],
        end[6],
        coning,
        sculling,
    )


@numba.njit(cache=True)
def _due(state, t, span, period_s):
    """:meth:`~buoy_nav.solution.OutputDecimation.due` on the decimation's next output stamp
    in ``state``."""
    if period_s == 0.0:
        return True
    if t + 0.5 * span < state[NEXT_OUTPUT_T]:
        return False
    following = state[NEXT_OUTPUT_T] + period_s
    state[NEXT_OUTPUT_T] = following if following > t else t + period_s
    return True


def load_compiled_imu_stretch() -> None:
    """Compile the stretch, or load it from the cache, now (see
    :func:`buoy_nav.mechanization.load_compiled_kernels`)."""
    state = np.zeros(STATE_SIZE)
    state[AHEAD] = -1.0
    state[LAST_PREDICTED_T] = -math.inf
    limits = np.array([0.3, 0.5, 0.1, math.inf, 0.0, 0.0, 0.0, 0.0])
    strapdown = np.zeros(STRAPDOWN_STATE_SIZE)
    screening = np.zeros(SCREENING_SIZE)
    screening[SAMPLE_INTERVAL] = 0.01
    screening[SQUARE] = 2.0
    screened_state = np.zeros(SCREENED_STATE_SIZE)
    screened_state[LATEST] = -1.0
    imu_stretch(
        np.zeros((1, 7)),
        screening,
        screened_state,
        np.zeros((1, 7)),
        np.zeros((0, 7)),
        state,
        limits,
        strapdown,
        True,
        True,
        strapdown.copy(),
        True,
        True,
        np.zeros((4, 56)),
        np.zeros(12),
        np.eye(15),
        np.arange(36, dtype=np.int64).reshape(4, 3, 3),
        np.zeros(1, dtype=np.bool_),
    )
