"""A stretch of IMU samples between aiding measurements, in one compiled call.

Most IMU samples of an aided run change nothing but the nominal states: the sample enters the
buffer, the prediction ahead steps to it and writes its solution's row
(:mod:`buoy_nav.prediction`), and the filter, ``max_measurement_delay_s`` behind, steps to the
buffered samples its horizon passed (:meth:`~buoy_nav.engine.FusionEngine._process`).
:func:`imu_stretch` does exactly that for consecutive accepted samples, with the engine's own
kernels (the strapdown step, the row writer) and in the engine's order, and stops where the
engine has more to do: a measurement due, the covariance's batch full, a gap, the prediction to
fork afresh, the rows' block full. The engine then takes over at that sample
(:meth:`~buoy_nav.engine.FusionEngine.add_inputs`), so the result is the engine's to the bit;
a test holds the two equal.

The aiding measurements in between are taken too: a motion pack's attitude, which comes with
every IMU sample (:mod:`buoy_nav.aiding.ahrs_attitude`, :mod:`buoy_nav.pack_epoch`), or the GNSS
sources' (:mod:`buoy_nav.stretched_aiding`, :mod:`buoy_nav.aiding_epoch`), one or the other in
a stretch. The stretch queues each as the engine does and, when the filter reaches its stamp,
makes its epoch with the engine's kernels: the step there with the covariance's propagation,
the compiled update (the pack's, or the GNSS sources' models stacked, gated and applied in one
update), the injection of the correction and its carry-over to the prediction. It stops before
an epoch the engine must make itself (a gate that fails, a covariance to repair, a model that
does not hold, another measurement or a constraint due, the prediction forked afresh) and where
the sources' books could change what follows (a source's health moved by a pass, the filter
distrusted, a smoother recording the epochs); the engine then keeps the books of the epochs it
made, in their order.
"""

import itertools
import math
from collections import deque
from typing import NamedTuple

import numba
import numpy as np

from buoy_common.contract import Reason
from buoy_nav.aiding.ahrs_attitude import AhrsAttitudeSource
from buoy_nav.aiding_epoch import (
    BOOK_SIZE,
    QUEUED,
    ROW_SIZE,
    ROW_SLOT,
    ROW_STATUS,
    ROW_T,
    TERMS_SIZE,
    aiding_epoch,
    due_status,
    first_queued,
)
from buoy_nav.error_state_filter import GateResult
from buoy_nav.pack_epoch import (
    ATTITUDE_START,
    EPOCH_INNOVATION,
    EPOCH_NIS,
    EPOCH_S,
    EPOCH_SIZE,
    EPOCH_T,
    PACK_ROW_SIZE,
    PACK_T,
    PACK_TERMS_SIZE,
    RESYNC_AT,
    THRESHOLD,
    pack_epoch,
)
from buoy_nav.sequence_kernels import (
    RING_SIZE,
    SEQUENCE_LATEST,
    SEQUENCE_SIZE,
    queued_in_sequence,
    ring_add,
    ring_interval,
    sequence_of,
)
from buoy_nav.solution_rows import write_row
from buoy_nav.strapdown_kernel import (
    DURATION,
    LATITUDE,
    LONGITUDE,
    strapdown_step,
)
from buoy_nav.strapdown_kernel import STATE_SIZE as STRAPDOWN_STATE_SIZE
from buoy_nav.stream_sequence import SEQUENCE_INTERVALS
from buoy_nav.stretched_aiding import AidingRows, StretchedAiding

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
DISTRUSTED, ATTITUDE_VARIANCE, VELOCITY_VARIANCE, CONSTRAINT_DUE = range(5, 9)
LIMITS_SIZE = 9
# The screening's limits and state (:func:`imu_stretch`'s ``screening`` and ``screened_state``,
# :meth:`~buoy_nav.imu_input.ImuInput.steady_screening`): the clock's offset (s), the largest
# squared rate and force, the largest gap (s), the calibration's gyro biases, accelerometer
# biases and scales (none when CALIBRATED is 0.0), the largest angular acceleration and jerk,
# the rate's and force's noise allowances, the learnt sample interval (s) and the exponent of
# the squares (2.0, handed in so that they are the C library's, as the interpreter's ``** 2``);
# the latest accepted stamp, the sequence's latest stamp, the clock's sample interval (s), the
# last accepted sample (stamp s, gyro, force) and, last, the ring of the clock's recent
# intervals the sample interval is taken from (:mod:`buoy_nav.sequence_kernels`).
(CLOCK_OFFSET, MAX_RATE_SQ, MAX_FORCE_SQ, SCREENING_MAX_GAP, CALIBRATED) = range(5)
GYRO_BIAS, ACCEL_BIAS, ACCEL_SCALE = 5, 8, 11
(MAX_ANGULAR_ACCELERATION, MAX_JERK, RATE_NOISE, FORCE_NOISE, SAMPLE_INTERVAL) = range(14, 19)
SQUARE = 19
SCREENING_SIZE = 20
LATEST, SEQUENCE_LAST, CLOCK_INTERVAL, LAST_SAMPLE, CLOCK_RING = 0, 1, 2, 3, 10
SCREENED_STATE_SIZE = CLOCK_RING + RING_SIZE
# How far a stretch went (``counts``): the IMU samples it took, where the queued attitudes begin
# and end in ``pack_rows`` (those before the first were applied), the epochs applied; where the
# queued aiding measurements begin and end in the aiding rows, and the books of their epochs.
IMU_TAKEN, QUEUE_HEAD, QUEUE_TAIL, EPOCHS, AIDING_HEAD, AIDING_TAIL, AIDING_BOOKS = range(7)
COUNTS_SIZE = 7
# The aiding measurements' arguments (:func:`imu_stretch`'s ``aiding``, laid out in
# :mod:`buoy_nav.aiding_epoch`): their rows, each source's sequence
# (:mod:`buoy_nav.sequence_kernels`), each source's terms, the epochs' books.
AIDING_ROWS, AIDING_SEQUENCES, AIDING_TERMS, AIDING_BOOKS_ROWS = range(4)


WINDOW = 512
"""Inputs offered to one call at most: a stretch rarely runs longer (a constraint, a fix, the
covariance's batch stop it), and its arrays are made for what it is offered."""


class MeasurementInput(NamedTuple):
    """An aiding source's measurement among the inputs of
    :meth:`~buoy_nav.engine.FusionEngine.add_inputs`: its ``source``, its stamp ``t_s`` (s) and
    the ``measurement`` (or the :class:`~buoy_common.contract.Reason` its message is none)."""

    source: object
    t_s: float
    measurement: object


class Taken(NamedTuple):
    """What a stretch took: how many inputs, the IMU samples among them (stamp s, gyro,
    force; re-stamped and calibrated) with their places among the inputs and whether each
    one's solution was written, and whether the engine's filtering up to the last sample's
    horizon is left to do (:data:`CATCH_UP`)."""

    inputs: int
    samples: list[tuple]
    places: list[int]
    rows_written: list[bool]
    catch_up: bool


class _Run(NamedTuple):
    """The inputs of one call made ready for the stretches: the IMU samples' rows (n × 7), and
    for each input its IMU sample's index there or its pack attitude's in ``pack_rows`` (−1:
    neither, the engine takes it), the pack's validated attitudes and their rows, the terms
    those rows hold with (:meth:`AhrsAttitudeSource.stretch_terms`; None: no pack) at the
    filter's position then (rad), and whether the inputs are IMU samples alone."""

    raw: np.ndarray
    imu_index: np.ndarray
    pack_index: np.ndarray
    measurements: list
    pack_rows: np.ndarray
    pack_terms: tuple | None
    position_rad: tuple[float, float]
    imu_only: bool
    aiding_index: np.ndarray
    """Each input's index among the stretched aiding measurements of ``aiding`` (−1: none)."""
    aiding: AidingRows
    aiding_slots: np.ndarray
    """Each input's aiding source's slot (:mod:`buoy_nav.stretched_aiding`; −1: none)."""
    imu_stamps: np.ndarray
    """Each input's IMU stamp (s; −inf: not an IMU sample's)."""


class _PackArguments(NamedTuple):
    """:func:`imu_stretch`'s arguments for the pack's attitudes, in its order."""

    rows: np.ndarray
    sequence: np.ndarray
    terms: np.ndarray
    noise_terms: np.ndarray
    jacobian: np.ndarray
    epochs: np.ndarray


class _Offer(NamedTuple):
    """What one call of :func:`imu_stretch` is offered: the IMU samples' rows, the inputs'
    ``order``, the pack's arguments, its attitudes (those queued before first, ``queued`` of
    them; none when the stretch takes IMU samples alone)."""

    raw: np.ndarray
    order: np.ndarray
    pack: _PackArguments
    measurements: list
    queued: int
    aiding: tuple
    """:func:`imu_stretch`'s ``aiding`` (:mod:`buoy_nav.stretched_aiding`)."""
    aiding_rows: AidingRows
    """The aiding measurements offered, those queued before first, ``aiding_queued`` of them."""
    aiding_queued: int


_POSITIONS = np.arange(WINDOW, dtype=np.int64)
"""The ``order`` of a stretch of IMU samples alone."""


class EngineParts(NamedTuple):
    """The parts of a :class:`~buoy_nav.engine.FusionEngine` a stretch reads and moves."""

    config: object
    buffer: deque
    point: object
    prediction: object
    output: object
    solutions: object
    queue: object
    imu_input: object
    gates: object
    sequences: dict
    contradictions: object
    integrity: object
    transitions: list
    pseudo: tuple
    pack: AhrsAttitudeSource | None
    """The motion pack's attitude source when enabled: its attitudes are taken in stretches."""
    counters: dict
    sources: tuple
    """Every aiding source, in registry order (:mod:`buoy_nav.stretched_aiding` takes some)."""


class ImuStretches:
    """The engine's ``parts`` handed to :func:`imu_stretch` and set from what it did, and the
    books of the pack's attitudes it applied kept as the engine keeps them."""

    def __init__(self, parts: EngineParts):
        self._parts = parts
        self._aiding = StretchedAiding(parts, parts.sources)
        self._no_aiding = AidingRows([], np.zeros((0, ROW_SIZE)))
        # Writable, as the compiled stretch is loaded for.
        self._jacobian = np.zeros((3, 1)) if parts.pack is None else parts.pack.jacobian.copy()
        self._no_pack = _PackArguments(
            np.zeros((0, PACK_ROW_SIZE)),
            np.zeros(SEQUENCE_SIZE),
            np.zeros(PACK_TERMS_SIZE),
            np.zeros(7),
            self._jacobian,
            np.zeros((0, EPOCH_SIZE)),
        )

    @property
    def pack(self) -> AhrsAttitudeSource | None:
        """The motion pack's attitude source whose attitudes the stretches take (None: none)."""
        return self._parts.pack

    @property
    def aiding_sources(self) -> tuple:
        """The aiding sources whose measurements the stretches take
        (:mod:`buoy_nav.stretched_aiding`)."""
        return self._aiding.sources

    def run_of(self, inputs: list, nav) -> _Run:
        """``inputs`` (IMU samples and :class:`MeasurementInput`) made ready, the pack's true
        north turned at the filter's position of ``nav`` now. An IMU sample that is not three
        numbers each is the engine's to take (:meth:`~buoy_nav.engine.FusionEngine.add_imu`
        says why), as is a measurement that is not valid."""
        pack = self._parts.pack
        n = len(inputs)
        imu_index, pack_index = np.full(n, -1), np.full(n, -1)
        aiding_index, aiding_slots = np.full(n, -1), np.full(n, -1)
        samples, measurements, aiding_items, aiding_rows = [], [], [], []
        for place, item in enumerate(inputs):
            if type(item) is not MeasurementInput:
                imu_index[place] = len(samples)
                samples.append(item)
            elif item.source is pack:
                validated = _valid(item)
                if validated is not None:
                    pack_index[place] = len(measurements)
                    measurements.append(validated)
            elif self._aiding.takes(item.source):
                made = self._aiding.row(*item)
                if made is not None:
                    aiding_index[place], aiding_slots[place] = len(aiding_items), made[1][1]
                    aiding_items.append((item.source, made[0], item.t_s))
                    aiding_rows.append(made[1])
        raw, sample_rows = _imu_rows(samples)
        if len(raw) < len(samples):
            imu_index = np.where(imu_index < 0, -1, np.array([*sample_rows, -1])[imu_index])
        imu_stamps = np.full(n, -math.inf)
        imu_stamps[imu_index >= 0] = raw[imu_index[imu_index >= 0], 0]
        state = nav.integrator.state_vector
        position = (float(state[LATITUDE]), float(state[LONGITUDE]))
        rows = [pack.stretch_row(m, *position) for m in measurements] if measurements else []
        return _Run(
            raw,
            imu_index,
            pack_index,
            measurements,
            np.array(rows, dtype=float).reshape(-1, PACK_ROW_SIZE),
            None if pack is None else pack.stretch_terms(*position, nav.kalman),
            position,
            len(raw) == n,
            aiding_index,
            AidingRows(aiding_items, np.array(aiding_rows).reshape(-1, ROW_SIZE)),
            aiding_slots,
            imu_stamps,
        )

    def take(self, run: _Run, start: int, screening: tuple, nav) -> Taken | None:
        """The inputs of ``run`` from ``start`` through :func:`imu_stretch`, with the IMU
        ``screening``'s limits and state and the aided navigation ``nav``; None when it took
        none (the engine takes the first itself)."""
        parts = self._parts
        if run.imu_only:
            offer = self._imu_offer(run, start)
        else:
            offer = self._measurement_offer(run, start, nav)
        if offer is None:
            return None
        raw = offer.raw
        limits_of_screening, screened_state = screening
        due = self._buffered_within_reach(raw, limits_of_screening[CLOCK_OFFSET])
        ahead = parts.prediction.ahead[0]
        state = self._state()
        screened = np.empty_like(raw)
        rows_written = np.zeros(len(raw), dtype=bool)
        plane_terms, covariance, block_indices, distrusted, distrust = (
            parts.solutions.row_arguments(nav.kalman)
        )
        if offer.measurements or offer.aiding_rows.items:
            covariance = covariance.copy()  # the epochs' covariance, the filter's if they end
        counts = np.array((0, 0, offer.queued, 0, 0, offer.aiding_queued, 0), dtype=np.int64)
        count, stepped, stop = imu_stretch(
            raw,
            offer.order,
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
            parts.solutions.rows.block,
            plane_terms,
            covariance,
            block_indices,
            rows_written,
            *offer.pack,
            offer.aiding,
            counts,
        )
        if self._booked(run, offer, counts, nav):
            nav.kalman.covariance = covariance
            parts.solutions.covariance_changed()
            parts.solutions.biases_changed()
        if count == 0:
            return None
        imu_taken = int(counts[IMU_TAKEN])
        took = [
            (t, (gx, gy, gz), (fx, fy, fz))
            for t, gx, gy, gz, fx, fy, fz in screened[:imu_taken].tolist()
        ]
        if took:
            parts.imu_input.screened_through(screened_state, took[-1])
            self._moved(state, due, took, stepped)
        places = [start + k for k, place in enumerate(offer.order[:count].tolist()) if place >= 0]
        return Taken(count, took, places, rows_written[:imu_taken].tolist(), stop == CATCH_UP)

    def _imu_offer(self, run: _Run, start: int) -> _Offer:
        """What a stretch of IMU samples alone is offered from ``start``."""
        end = min(start + WINDOW, len(run.imu_index))
        return _Offer(
            run.raw[start:end],
            _POSITIONS[: end - start],
            self._no_pack,
            [],
            0,
            self._aiding.arguments(self._no_aiding.rows),
            self._no_aiding,
            0,
        )

    def _measurement_offer(self, run: _Run, start: int, nav) -> _Offer | None:
        """What a stretch is offered from ``start`` with the measurements of the pack or of the
        stretched aiding sources among the IMU samples, when they can be applied in it (their
        queued ones taken out of the queue); None: nothing. A stretch takes the pack's or the
        aiding sources', not both: their books are kept source by source."""
        parts = self._parts
        with_pack = self._pack_ready(nav) and self._pack_present(run, start)
        ready = frozenset() if with_pack else self._aiding.ready(nav)
        if not parts.queue.settled:  # the queue judges some of its measurements at their turn
            with_pack, ready = False, frozenset()
        end = self._window_end(run, start, with_pack, ready)
        if end == start:
            return None
        window = slice(start, end)
        queued = None
        if with_pack and (run.pack_index[window] >= 0).any():
            queued = parts.queue.take_source(parts.pack)
        aiding_queued = self._aiding.queued(ready) if ready else self._no_aiding
        imu = run.imu_index[window]
        raw = run.raw[imu[imu >= 0]]
        order, pack_rows, measurements, aiding = self._order(run, window, queued, aiding_queued)
        pack = _PackArguments(
            pack_rows,
            self._pack_sequence(),
            self._pack_terms(run),
            np.array(nav.noise_terms(), dtype=float),
            self._jacobian,
            np.empty((len(pack_rows), EPOCH_SIZE)),
        )
        return _Offer(
            raw,
            order,
            pack,
            measurements,
            len(queued or ()),
            self._aiding.arguments(aiding.rows),
            aiding,
            len(aiding_queued.items),
        )

    def _pack_present(self, run: _Run, start: int) -> bool:
        """Whether the pack has attitudes queued or among the inputs a stretch from ``start``
        could be offered."""
        pack = self._parts.pack
        return any(entry[3] is pack for entry in self._parts.queue.heap) or bool(
            (run.pack_index[start : start + WINDOW] >= 0).any()
        )

    def _booked(self, run: _Run, offer: _Offer, counts, nav) -> bool:
        """Keep the books of the measurements ``offer`` had (``counts``: what the stretch did);
        whether it applied any."""
        applied = False
        if offer.measurements:
            self._book_pack(run, offer.measurements, offer.queued, counts, offer.pack.epochs, nav)
            applied = bool(counts[EPOCHS])
        if offer.aiding_rows.items:
            books = offer.aiding[AIDING_BOOKS_ROWS][: counts[AIDING_BOOKS]]
            tail = int(counts[AIDING_TAIL])
            applied = self._aiding.book(offer.aiding_rows, offer.aiding_queued, tail, books)
        return applied

    def _buffered_within_reach(self, raw: np.ndarray, clock_offset_s: float) -> list[tuple]:
        """The buffered samples the filter may step to while taking ``raw``: none beyond the
        horizon of its latest stamp (the clock's offset ``clock_offset_s`` stays while a
        stretch runs: a step of the clock has samples held, which stops it)."""
        stamps = raw[:, 0]
        finite = stamps[np.isfinite(stamps)]
        latest_s = finite.max() + clock_offset_s if finite.size else -math.inf
        reach_s = latest_s - self._parts.config.max_measurement_delay_s
        return list(itertools.takewhile(lambda sample: sample[0] <= reach_s, self._parts.buffer))

    def _state(self) -> np.ndarray:
        """:func:`imu_stretch`'s ``state`` from the parts."""
        parts = self._parts
        point, prediction = parts.point, parts.prediction
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
                parts.output.next_output_s,
                parts.solutions.rows.count,
            ),
            dtype=float,
        )

    def _limits(self, distrusted: bool, distrust: tuple[float, float]) -> np.ndarray:
        """:func:`imu_stretch`'s ``limits``, the filter ``distrusted`` or not (``distrust``: the
        attitude and velocity variances then added)."""
        parts = self._parts
        config = parts.config
        heap = parts.queue.heap
        return np.array(
            (
                config.max_measurement_delay_s,
                config.max_imu_gap_s,
                config.covariance_propagation_interval_s,
                heap[0][0] if heap else math.inf,
                parts.output.period_s,
                1.0 if distrusted else 0.0,
                *distrust,
                min((source.next_due_s for source in parts.pseudo), default=math.inf),
            )
        )

    def _moved(self, state: np.ndarray, due: list, took: list, stepped: int) -> None:
        """The parts set from what the stretch did: it ``took`` these samples (into the
        buffer) and stepped the filter to ``stepped`` of the ``due`` buffered samples and
        then of those; ``state`` as it left it."""
        parts = self._parts
        point = parts.point
        buffer = parts.buffer
        buffer.extend(took)
        if stepped:
            walked = [(point.t_s, point.gyro, point.force), *due, *took]
            for _ in range(stepped):
                buffer.popleft()
            point.stepped_through(walked[stepped - 1], walked[stepped])
        parts.prediction.predicted_through(took[-1])
        parts.output.next_output_s = float(state[NEXT_OUTPUT_T])
        parts.solutions.rows.count = int(state[ROWS])

    def _pack_ready(self, nav) -> bool:
        """Whether a stretch may apply the pack's attitudes as the engine would: the pack's
        health unmoved by passing attitudes, its sequence holding none, the filter trusted,
        nothing recorded for a smoother."""
        parts = self._parts
        pack = parts.pack
        return (
            pack is not None
            and parts.gates.unmoved_by_passes(pack.kind)
            and parts.sequences[pack.kind].steady
            and parts.integrity.trusted
            and not nav.records_epochs
        )

    def _window_end(self, run: _Run, start: int, with_pack: bool, ready: frozenset) -> int:
        """Where the inputs from ``start`` a stretch is offered end: at the first the engine
        must take (the pack's too, unless ``with_pack``; the aiding sources' unless ``ready``),
        after the first IMU sample whose filtering reaches the next measurement or constraint
        due (the stretch stops there), :data:`WINDOW` at most."""
        parts = self._parts
        taken = ready | {parts.pack} if with_pack else ready
        heap = parts.queue.heap
        stop_s = min(
            min((entry[0] for entry in heap if entry[3] not in taken), default=math.inf),
            min((source.next_due_s for source in parts.pseudo), default=math.inf),
        )
        stop_s += parts.config.max_measurement_delay_s
        end = min(start + WINDOW, len(run.imu_index))
        allowed = run.imu_index[start:end] >= 0
        if with_pack:
            allowed |= run.pack_index[start:end] >= 0
        if ready:
            allowed |= self._aiding.ready_mask(ready)[run.aiding_slots[start:end]]
        blocked = np.flatnonzero(~allowed)
        if blocked.size:
            end = start + int(blocked[0])
        beyond = np.flatnonzero(run.imu_stamps[start:end] > stop_s)
        return start + int(beyond[0]) + 1 if beyond.size else end

    def _order(self, run: _Run, window: slice, queued: list | None, aiding_queued: AidingRows):
        """:func:`imu_stretch`'s ``order`` for the inputs of the ``window``, the pack's rows and
        attitudes (the ``queued`` ones first, then those of the window) and the aiding rows
        (``aiding_queued`` first, then those of the window)."""
        pack = self._parts.pack
        imu, packs, aids = run.imu_index[window], run.pack_index[window], run.aiding_index[window]
        is_imu = imu >= 0
        is_pack = ~is_imu & (packs >= 0)
        is_aiding = ~is_imu & ~is_pack
        measurements = [measurement for _, measurement in queued or ()]
        rows = [pack.stretch_row(m, *run.position_rad) for m in measurements]
        n_queued = len(measurements)
        pack_places = packs[is_pack]
        measurements += [run.measurements[index] for index in pack_places.tolist()]
        pack_rows = np.concatenate(
            (np.array(rows, dtype=float).reshape(-1, PACK_ROW_SIZE), run.pack_rows[pack_places])
        )
        aiding_places = aids[is_aiding]
        order = np.empty(len(imu), dtype=np.int64)
        order[is_imu] = np.arange(np.count_nonzero(is_imu))
        order[is_pack] = -1 - n_queued - np.arange(len(pack_places))
        order[is_aiding] = (
            -1 - len(measurements) - len(aiding_queued.items) - np.arange(len(aiding_places))
        )
        aiding = AidingRows(
            [*aiding_queued.items, *(run.aiding.items[index] for index in aiding_places.tolist())],
            np.concatenate((aiding_queued.rows, run.aiding.rows[aiding_places])),
        )
        return order, pack_rows, measurements, aiding

    def _pack_sequence(self) -> np.ndarray:
        """:func:`imu_stretch`'s ``pack_sequence`` from the pack's sequence."""
        parts = self._parts
        if parts.pack is None:
            sequence = np.zeros(SEQUENCE_SIZE)
            sequence[SEQUENCE_LATEST] = math.inf
            return sequence
        return sequence_of(parts.sequences[parts.pack.kind])

    def _pack_terms(self, run: _Run) -> np.ndarray:
        """:func:`imu_stretch`'s ``pack_terms``."""
        lag, lag_uncertainty_sq, floor, threshold, *bounds = run.pack_terms or (
            0.0,
            0.0,
            0.0,
            0.0,
            -math.inf,
            math.inf,
            -math.inf,
            math.inf,
        )
        return np.array(
            (
                lag,
                lag_uncertainty_sq,
                floor,
                threshold,
                float(self._parts.pack.states.attitude.start) if self._parts.pack else 0.0,
                self._parts.prediction.resync_at_s,
                *bounds,
            )
        )

    def _book_pack(self, run: _Run, measurements: list, first_new: int, counts, epochs, nav):
        """Keep the books of what the stretch did with the pack's ``measurements`` (those
        queued before it first, the new ones from ``first_new``) as the engine keeps them: its
        sequence and the IMU's clock follow the new ones it queued, each epoch it applied
        (``epochs``) is observed and booked as passed by its gate, and the attitudes still
        queued go back to the queue."""
        parts = self._parts
        pack = parts.pack
        head, tail, applied = int(counts[QUEUE_HEAD]), int(counts[QUEUE_TAIL]), int(counts[EPOCHS])
        for measurement in measurements[first_new:tail]:
            parts.sequences[pack.kind].followed(measurement.t_s)
            parts.imu_input.clock.aiding_stamp(measurement.t_s)
        threshold = run.pack_terms[THRESHOLD]
        for epoch, measurement in zip(epochs[:applied].tolist(), measurements, strict=False):
            t = epoch[EPOCH_T]
            parts.contradictions.observe(t, measurement)
            gate = GateResult(
                True,
                epoch[EPOCH_NIS],
                threshold,
                np.array(epoch[EPOCH_S : EPOCH_S + 9]).reshape(3, 3),
            )
            innovation = np.array(epoch[EPOCH_INNOVATION : EPOCH_INNOVATION + 3])
            fused, outcome = parts.gates.passed(pack, t, innovation, gate)
            if not fused:
                raise RuntimeError(f"{pack.kind}: an attitude the stretch applied was not fused")
            parts.transitions.extend(outcome.transitions)
        for measurement in measurements[head:tail]:
            parts.queue.push(pack, measurement.t_s, measurement)


def _valid(item: MeasurementInput):
    """The validated measurement of ``item``, or None when it is none (the engine says why)."""
    if isinstance(item.measurement, Reason) or not math.isfinite(item.t_s):
        return None
    validated = item.source.validated(item.measurement)
    return None if isinstance(validated, Reason) else validated


def _imu_rows(samples: list) -> tuple[np.ndarray, list[int]]:
    """The rows (n × 7: stamp s, gyro, force) of the IMU ``samples`` that are three numbers
    each, and each sample's row (−1: not such a sample)."""
    try:
        raw = np.array([(t_s, *gyro, *force) for t_s, gyro, force in samples], dtype=float)
        if raw.shape == (len(samples), SAMPLE_SIZE):
            return raw, list(range(len(samples)))
    except (TypeError, ValueError):
        pass
    rows, sample_rows = [], []
    for t_s, gyro, force in samples:
        try:
            row = np.array((t_s, *gyro, *force), dtype=float)
        except (TypeError, ValueError):
            row = None
        well_formed = row is not None and row.shape == (SAMPLE_SIZE,)
        sample_rows.append(len(rows) if well_formed else -1)
        if well_formed:
            rows.append(row)
    return np.array(rows).reshape(-1, SAMPLE_SIZE), sample_rows


@numba.njit(cache=True)
def imu_stretch(
    raw,
    order,
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
    pack_rows,
    pack_sequence,
    pack_terms,
    noise_terms,
    pack_jacobian,
    epochs,
    aiding,
    counts,
):
    """Take the inputs in ``order`` (an IMU sample's index in ``raw``, or −1 − the index of a
    motion-pack attitude in ``pack_rows``) as the engine's ``add_imu``, ``add_measurement`` and
    ``catch_up`` would, until one needs the engine; the filter may also reach the ``buffered``
    IMU samples ahead of it (k × 7, oldest first).

    Each IMU sample (n × 7: header stamp s, ω_ib body rad/s, specific force body m/s²) is
    screened (``screening``, ``screened_state``; into ``samples``, re-stamped and calibrated),
    predicted ahead with its row (:func:`_predicted`) and the filter stepped to its horizon
    (:func:`_filtered`); each attitude is queued
    (:func:`~buoy_nav.sequence_kernels.queued_in_sequence`) and its epoch made when the filter
    reaches it. The arrays' layouts are this module's
    constants and :mod:`buoy_nav.pack_epoch`'s; ``state``, the strapdown states, ``covariance``
    and ``counts`` are updated in place, ``row_written`` set for each sample whose row was
    written.

    Returns (inputs taken, buffered samples the filter stepped to, :data:`DONE`,
    :data:`BEFORE_SAMPLE` or :data:`CATCH_UP`).
    """
    # Integer bounds: a slice object held globally would be unpickled at each call.
    point = state[POINT : POINT + SAMPLE_SIZE]
    ahead = state[AHEAD : AHEAD + SAMPLE_SIZE]
    stepped = 0
    for item in range(order.shape[0]):
        position = order[item]
        if position < 0:
            if not _queued(-1 - position, pack_rows, pack_sequence, aiding, point, screened_state):
                return item, stepped, BEFORE_SAMPLE
            if -1 - position < pack_rows.shape[0]:
                counts[QUEUE_TAIL] += 1
            else:
                counts[AIDING_TAIL] = -1 - position - pack_rows.shape[0] + 1
            continue
        index = counts[IMU_TAKEN]
        sample = samples[index]
        if not _taken(raw[position], screening, screened_state, sample, state, limits, rows_block):
            return item, stepped, BEFORE_SAMPLE
        counts[IMU_TAKEN] += 1
        row_written[index] = _predicted(
            sample,
            state,
            limits,
            ahead_state,
            ahead_coning,
            ahead_sculling,
            rows_block,
            plane_terms,
            covariance,
            block_indices,
        )
        stepped = _filtered(
            sample[0] - limits[DELAY],
            stepped,
            buffered.shape[0] + index + 1,
            buffered,
            samples,
            point,
            limits,
            filter_state,
            filter_coning,
            filter_sculling,
            covariance,
            pack_rows,
            pack_terms,
            noise_terms,
            pack_jacobian,
            ahead_state,
            ahead[0],
            epochs,
            aiding,
            counts,
        )
        if stepped < 0:
            return item + 1, -1 - stepped, CATCH_UP
    return order.shape[0], stepped, DONE


@numba.njit(cache=True)
def _taken(raw_sample, screening, screened_state, sample, state, limits, rows_block) -> bool:
    """Whether the stretch takes ``raw_sample``: screened as :func:`_screened` screens it, not
    beyond a gap from the prediction ahead (``state``'s :data:`AHEAD`), with room in the rows'
    block; the screening then accepts it into ``sample``."""
    if not _screened(raw_sample, screening, screened_state, sample):
        return False
    if sample[0] - state[AHEAD] > limits[MAX_GAP] or state[ROWS] >= rows_block.shape[0]:
        return False
    _accepted(screening, screened_state, sample)
    return True


@numba.njit(cache=True)
def _predicted(
    sample,
    state,
    limits,
    ahead_state,
    coning,
    sculling,
    rows_block,
    plane_terms,
    covariance,
    block_indices,
) -> bool:
    """The prediction ahead (``ahead_state``, at ``state``'s :data:`AHEAD` sample) stepped to
    the accepted IMU ``sample`` and, when the output is due there, its solution's row written;
    whether it was (``state``'s :data:`ROWS`, :data:`LAST_PREDICTED_T` and the decimation's
    next stamp follow)."""
    ahead = state[AHEAD : AHEAD + SAMPLE_SIZE]
    t = sample[0]
    span = t - ahead[0]
    _step(ahead_state, span, ahead, sample, coning, sculling)
    ahead[:] = sample
    written = t > state[LAST_PREDICTED_T] and _due(state, t, span, limits[OUTPUT_PERIOD])
    if written:
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
    state[LAST_PREDICTED_T] = t
    return written


@numba.njit(cache=True)
def _filtered(
    horizon_s,
    stepped,
    reachable,
    buffered,
    samples,
    point,
    limits,
    filter_state,
    coning,
    sculling,
    covariance,
    pack_rows,
    pack_terms,
    noise_terms,
    pack_jacobian,
    ahead_state,
    ahead_t,
    epochs,
    aiding,
    counts,
) -> int:
    """The filter (``filter_state`` at ``point``) stepped through the samples it has not
    reached of the first ``reachable`` (the ``buffered`` ones, then the taken ``samples``) up to
    ``horizon_s`` (s), the epoch of each stamp with queued pack attitudes or aiding measurements
    made there (:func:`_epoch_made`): how many samples
    it has reached in all, or −1 − that when it stopped where the engine must go on (a gap, a
    measurement or constraint due, the covariance's batch full, an epoch it cannot make)."""
    n_buffered = buffered.shape[0]
    while stepped < reachable:
        due = buffered[stepped] if stepped < n_buffered else samples[stepped - n_buffered]
        t_due = due[0]
        if t_due > horizon_s:
            break
        dt = t_due - point[0]
        # A gap, or a sample predicted before (above), the prediction meets first and the
        # engine takes; the stretch still never steps across one.
        if (
            dt > limits[MAX_GAP]
            or limits[NEXT_MEASUREMENT] <= t_due
            or limits[CONSTRAINT_DUE] <= t_due
        ):
            return -1 - stepped
        head = counts[QUEUE_HEAD]
        pack_due = head < counts[QUEUE_TAIL] and pack_rows[head, PACK_T] <= t_due
        rows = aiding[AIDING_ROWS]
        aiding_due = due_status(rows, counts[AIDING_HEAD], counts[AIDING_TAIL], t_due)
        if pack_due or aiding_due:
            if not (
                dt > 0.0
                and _epoch_made(
                    pack_due,
                    aiding_due,
                    point,
                    due,
                    filter_state,
                    coning,
                    sculling,
                    covariance,
                    pack_rows,
                    pack_terms,
                    noise_terms,
                    pack_jacobian,
                    ahead_state,
                    ahead_t,
                    epochs,
                    aiding,
                    counts,
                )
            ):
                return -1 - stepped
        elif dt > 0.0:
            if filter_state[DURATION] + dt >= limits[PROPAGATION_INTERVAL]:
                return -1 - stepped
            _step(filter_state, dt, point, due, coning, sculling)
        point[:] = due
        stepped += 1
    return stepped


@numba.njit(cache=True)
def _queued(measurement, pack_rows, pack_sequence, aiding, point, screened_state) -> bool:
    """Whether the engine would queue the ``measurement`` th of the stretch's measurements (the
    pack's rows, then the aiding rows) with nothing else to do; its source's sequence then
    follows it and an aiding row is marked queued."""
    n_pack = pack_rows.shape[0]
    if measurement < n_pack:
        t = pack_rows[measurement, PACK_T]
        return queued_in_sequence(t, pack_sequence, point[0], screened_state[LATEST])
    rows = aiding[AIDING_ROWS]
    k = measurement - n_pack
    sequence = aiding[AIDING_SEQUENCES][int(rows[k, ROW_SLOT])]
    if not queued_in_sequence(rows[k, ROW_T], sequence, point[0], screened_state[LATEST]):
        return False
    rows[k, ROW_STATUS] = QUEUED
    return True


@numba.njit(cache=True)
def _epoch_made(
    pack_due,
    aiding_due,
    point,
    due,
    filter_state,
    coning,
    sculling,
    covariance,
    pack_rows,
    pack_terms,
    noise_terms,
    pack_jacobian,
    ahead_state,
    ahead_t,
    epochs,
    aiding,
    counts,
) -> bool:
    """The epoch at the IMU sample ``due`` of the queued pack attitude (``pack_due``) or aiding
    measurements (``aiding_due``, :func:`~buoy_nav.aiding_epoch.due_status`) made with the
    engine's kernels, ``counts`` following it; False, with nothing changed, when the engine is
    to make it (a stamp of both, a stamp between two IMU samples, an epoch the kernels leave
    to it)."""
    t_due = due[0]
    if pack_due and aiding_due:
        return False
    if pack_due:
        head = counts[QUEUE_HEAD]
        if not (
            pack_rows[head, PACK_T] == t_due
            and pack_epoch(
                pack_rows[head],
                point,
                due,
                filter_state,
                coning,
                sculling,
                covariance,
                noise_terms,
                pack_terms,
                pack_jacobian,
                ahead_state,
                ahead_t,
                epochs[counts[EPOCHS]],
            )
        ):
            return False
        counts[QUEUE_HEAD] += 1
        counts[EPOCHS] += 1
        return True
    rows = aiding[AIDING_ROWS]
    if aiding_due != 1:
        return False
    written = aiding_epoch(
        rows,
        counts[AIDING_HEAD],
        counts[AIDING_TAIL],
        point,
        due,
        filter_state,
        coning,
        sculling,
        covariance,
        noise_terms,
        aiding[AIDING_TERMS],
        int(pack_terms[ATTITUDE_START]),
        pack_terms[RESYNC_AT],
        ahead_state,
        ahead_t,
        aiding[AIDING_BOOKS_ROWS],
        counts[AIDING_BOOKS],
    )
    if written < 0:
        return False
    counts[AIDING_BOOKS] += written
    counts[AIDING_HEAD] = first_queued(rows, counts[AIDING_HEAD], counts[AIDING_TAIL])
    return True


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
        ring = screened_state[CLOCK_RING:]
        ring_add(ring, dt)
        screened_state[CLOCK_INTERVAL] = ring_interval(ring)
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
    limits = np.zeros(LIMITS_SIZE)
    limits[[DELAY, MAX_GAP, PROPAGATION_INTERVAL]] = (0.3, 0.5, 0.1)
    limits[[NEXT_MEASUREMENT, CONSTRAINT_DUE]] = math.inf
    strapdown = np.zeros(STRAPDOWN_STATE_SIZE)
    screening = np.zeros(SCREENING_SIZE)
    screening[SAMPLE_INTERVAL] = 0.01
    screening[SQUARE] = 2.0
    screened_state = np.zeros(SCREENED_STATE_SIZE)
    screened_state[LATEST] = -1.0
    imu_stretch(
        np.zeros((1, SAMPLE_SIZE)),
        np.zeros(1, dtype=np.int64),
        screening,
        screened_state,
        np.zeros((1, SAMPLE_SIZE)),
        np.zeros((0, SAMPLE_SIZE)),
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
        np.zeros((0, PACK_ROW_SIZE)),
        np.zeros(SEQUENCE_SIZE),
        np.zeros(PACK_TERMS_SIZE),
        np.zeros(7),
        np.zeros((3, 15)),
        np.zeros((0, EPOCH_SIZE)),
        (
            np.zeros((0, ROW_SIZE)),
            np.zeros((0, SEQUENCE_SIZE)),
            np.zeros((0, TERMS_SIZE)),
            np.zeros((0, BOOK_SIZE)),
        ),
        np.zeros(COUNTS_SIZE, dtype=np.int64),
    )
