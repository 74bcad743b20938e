"""The engine's parts handed to the compiled stretch (:func:`buoy_nav.imu_stretch.imu_stretch`)
and set from what it did.

:meth:`~buoy_nav.engine.FusionEngine.add_inputs` is given an offline run's IMU samples and the
measurements among them (:class:`MeasurementInput`). :class:`ImuStretches` makes them ready
once (:meth:`ImuStretches.run_of`: the IMU samples' rows, the measurements validated and made
into rows), offers each stretch the inputs it may take from where the engine stands (up to the
first the engine must take; the stretched aiding sources' measurements with those already queued
taken out of the queue, when their books allow; the mooring's constraint when it may be made
there), calls the kernel, and then sets the engine's parts from what it did (the prediction ahead
too, forked afresh by the stretch or to be) and keeps the books of the epochs it made, as the
engine keeps them, in their order (:mod:`buoy_nav.stretched_aiding`,
:mod:`buoy_nav.stretched_mooring`).
"""

import math
from collections import deque
from typing import NamedTuple

import numpy as np

from buoy_nav.aiding_epoch import ROW_SIZE, ROW_SLOT, AidingArguments
from buoy_nav.imu_stretch import (
    AIDING_BOOKS,
    AIDING_TAIL,
    CATCH_UP,
    COUNTS_SIZE,
    FORK_DUE,
    FORKED_AT,
    IMU_TAKEN,
    MOORING_EPOCHS,
    NEXT_OUTPUT_T,
    ROWS,
    WINDOW_END,
    imu_stretch,
)
from buoy_nav.mooring_epoch import MooringArguments
from buoy_nav.strapdown_kernel import LATITUDE, LONGITUDE
from buoy_nav.stretch_screening import SAMPLE_SIZE
from buoy_nav.stretched_aiding import AidingRows, StretchedAiding
from buoy_nav.stretched_mooring import StretchedMooring

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
    """The inputs of one call made ready for the stretches: the IMU samples' rows (n × 7), for
    each input its IMU sample's index there (−1: none), the filter's position (rad) the
    measurements' rows were made at, and whether the inputs are IMU samples alone."""

    raw: np.ndarray
    imu_index: np.ndarray
    position_rad: tuple[float, float]
    imu_only: bool
    aiding_index: np.ndarray
    """Each input's index among the stretched aiding measurements of ``aiding`` (−1: none)."""
    aiding: AidingRows
    aiding_slots: np.ndarray
    """Each input's aiding source's slot (:mod:`buoy_nav.stretched_aiding`; −1: none)."""
    imu_stamps: np.ndarray
    """Each input's IMU stamp (s; −inf: not an IMU sample's)."""


class _Offer(NamedTuple):
    """What one call of :func:`imu_stretch` is offered: the IMU samples' rows, the inputs'
    ``order``, the process noise's terms (:meth:`AidedNavigation.noise_terms`), the aiding
    measurements' arguments and rows (those queued before first, ``aiding_queued`` of them), and
    the mooring's arguments (:mod:`buoy_nav.stretched_mooring`; without room for its epochs when
    the stretch is to stop at the constraint); no measurement when the stretch takes IMU samples
    alone."""

    raw: np.ndarray
    order: np.ndarray
    noise_terms: np.ndarray
    aiding: AidingArguments
    aiding_rows: AidingRows
    aiding_queued: int
    mooring: MooringArguments


_POSITIONS = np.arange(WINDOW, dtype=np.int64)
"""The ``order`` of a stretch of IMU samples alone."""
_NO_NOISE_TERMS = np.zeros(7)
"""The ``noise_terms`` of a stretch of IMU samples alone (no epoch: none read)."""


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
    counters: dict
    sources: tuple
    """Every aiding source, in registry order (:mod:`buoy_nav.stretched_aiding` takes some)."""
    recency: object
    """When each quantity was last aided (:class:`~buoy_nav.sensor_sets.AidingRecency`)."""


class ImuStretches:
    """The engine's ``parts`` handed to :func:`imu_stretch` and set from what it did, and the
    books of the epochs it made kept as the engine keeps them."""

    def __init__(self, parts: EngineParts):
        self._parts = parts
        self._aiding = StretchedAiding(parts, parts.sources)
        self._no_aiding = AidingRows([], np.zeros((0, ROW_SIZE)))
        self._mooring = StretchedMooring(parts)

    @property
    def aiding_sources(self) -> tuple:
        """The aiding sources whose measurements the stretches take
        (:mod:`buoy_nav.stretched_aiding`)."""
        return self._aiding.sources

    def run_of(self, inputs: list, nav) -> _Run:
        """``inputs`` (IMU samples and :class:`MeasurementInput`) made ready, the measurements'
        rows made at the filter's position of ``nav`` now. An IMU sample that is not three
        numbers each is the engine's to take (:meth:`~buoy_nav.engine.FusionEngine.add_imu`
        says why), as is a measurement that is not valid."""
        state = nav.integrator.state_vector
        position = (float(state[LATITUDE]), float(state[LONGITUDE]))
        n = len(inputs)
        imu_index = np.full(n, -1)
        aiding_index, aiding_slots = np.full(n, -1), np.full(n, -1)
        samples, aiding_items, aiding_rows = [], [], []
        takes = self._aiding.takes
        stretched = [
            item for item in inputs if type(item) is MeasurementInput and takes(item.source)
        ]
        made_of_stretched = iter(self._aiding.rows(stretched, position))
        for place, item in enumerate(inputs):
            if type(item) is not MeasurementInput:
                imu_index[place] = len(samples)
                samples.append(item)
            elif takes(item.source):
                made = next(made_of_stretched)
                if made is not None:
                    aiding_index[place], aiding_slots[place] = len(aiding_items), made[1][ROW_SLOT]
                    aiding_items.append((item.source, made[0], item.t_s))
                    aiding_rows.append(made[1])
        raw, sample_rows = _imu_rows(samples)
        if len(raw) < len(samples):
            imu_index = np.where(imu_index < 0, -1, np.array([*sample_rows, -1])[imu_index])
        imu_stamps = np.full(n, -math.inf)
        imu_stamps[imu_index >= 0] = raw[imu_index[imu_index >= 0], 0]
        return _Run(
            raw,
            imu_index,
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
            offer = self._imu_offer(run, start, nav)
        else:
            offer = self._measurement_offer(run, start, nav)
        if offer is None:
            return None
        raw = offer.raw
        limits_of_screening, screened_state = screening
        due = list(parts.buffer)
        ahead, ahead_sample = self._ahead(nav)
        state = self._state(ahead_sample)
        screened = np.empty_like(raw)
        rows_written = np.zeros(len(raw), dtype=bool)
        plane_terms, covariance, block_indices, distrusted, distrust = (
            parts.solutions.row_arguments(nav.kalman)
        )
        if offer.aiding_rows.items or offer.mooring.books.size:
            covariance = covariance.copy()  # the epochs' covariance, the filter's if they end
        counts = np.zeros(COUNTS_SIZE, dtype=np.int64)
        counts[AIDING_TAIL] = offer.aiding_queued
        counts[WINDOW_END] = offer.mooring.watch.stamps.size - offer.mooring.books.shape[0]
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
            offer.noise_terms,
            offer.aiding,
            offer.mooring,
            counts,
        )
        if self._booked(offer, counts):
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
            self._moved(state, due, took, stepped, ahead)
        places = [start + k for k, place in enumerate(offer.order[:count].tolist()) if place >= 0]
        return Taken(count, took, places, rows_written[:imu_taken].tolist(), stop == CATCH_UP)

    def _imu_offer(self, run: _Run, start: int, nav) -> _Offer:
        """What a stretch of IMU samples alone is offered from ``start`` (with the mooring's
        epochs when they may be made, :meth:`StretchedMooring.ready`)."""
        end = min(start + WINDOW, len(run.imu_index))
        with_mooring = self._mooring.ready(nav)
        return _Offer(
            run.raw[start:end],
            _POSITIONS[: end - start],
            np.array(nav.noise_terms(), dtype=float) if with_mooring else _NO_NOISE_TERMS,
            self._aiding.none,
            self._no_aiding,
            0,
            self._mooring_arguments(with_mooring, end - start),
        )

    def _measurement_offer(self, run: _Run, start: int, nav) -> _Offer | None:
        """What a stretch is offered from ``start`` with the measurements of the stretched
        aiding sources among the IMU samples, when they can be applied in it (their queued ones
        taken out of the queue), and the mooring's epochs when they may be made; None:
        nothing."""
        parts = self._parts
        ready = self._aiding.ready(nav)
        if not parts.queue.settled:  # the queue judges some of its measurements at their turn
            ready = frozenset()
        if ready and not self._aiding_present(run, start, ready):
            ready = frozenset()
        with_mooring = self._mooring.ready(nav)
        end = self._window_end(run, start, ready, with_mooring)
        if end == start:
            return None
        window = slice(start, end)
        aiding_queued = self._aiding.queued(ready, run.position_rad) if ready else self._no_aiding
        imu = run.imu_index[window]
        raw = run.raw[imu[imu >= 0]]
        order, aiding = self._order(run, window, aiding_queued)
        return _Offer(
            raw,
            order,
            np.array(nav.noise_terms(), dtype=float),
            self._aiding.arguments(aiding.rows, ready) if aiding.items else self._aiding.none,
            aiding,
            len(aiding_queued.items),
            self._mooring_arguments(with_mooring, len(raw)),
        )

    def _mooring_arguments(self, with_mooring: bool, samples: int) -> MooringArguments:
        """The mooring's arguments of a stretch offered ``samples`` IMU samples: room for an
        epoch at each sample the filter may reach (the buffered ones too), ``with_mooring``."""
        if not with_mooring:
            return self._mooring.none
        return self._mooring.arguments(samples + len(self._parts.buffer))

    def _aiding_present(self, run: _Run, start: int, ready: frozenset) -> bool:
        """Whether the ``ready`` aiding sources have measurements queued or among the inputs a
        stretch from ``start`` could be offered."""
        if any(entry[3] in ready for entry in self._parts.queue.heap):
            return True
        slots = run.aiding_slots[start : start + WINDOW]
        return bool(self._aiding.ready_mask(ready)[slots].any())

    def _booked(self, offer: _Offer, counts) -> bool:
        """Keep the books of the epochs ``offer`` had (``counts``: what the stretch did), in
        their order; whether it made any."""
        book_mooring = self._mooring.booker(offer.mooring, int(counts[MOORING_EPOCHS]))
        applied = False
        if offer.aiding_rows.items:
            books = offer.aiding.books[: counts[AIDING_BOOKS]]
            tail = int(counts[AIDING_TAIL])
            applied = self._aiding.book(
                offer.aiding_rows, offer.aiding_queued, tail, books, book_mooring
            )
        return book_mooring(math.inf) or applied

    def ready(self) -> bool:
        """Whether the prediction ahead lets a stretch go on: forked, or to be forked afresh
        at the next sample as the stretch forks it (:meth:`RealtimePrediction.quiet_fork`)."""
        parts = self._parts
        prediction = parts.prediction
        if prediction.ahead is not None:
            return True
        point = parts.point
        return prediction.quiet_fork((point.t_s, point.gyro, point.force), parts.buffer) is not None

    def _ahead(self, nav) -> tuple:
        """The copy ahead the stretch steps (an integrator; a new fork of the filter's ``nav``
        when it is to be forked afresh) and the (stamp s, gyro, force) sample it is at (the
        newest it would be forked through, then)."""
        parts = self._parts
        prediction = parts.prediction
        if prediction.ahead is not None:
            integrator, *sample = prediction.ahead
            return integrator, sample
        point = parts.point
        newest = prediction.quiet_fork((point.t_s, point.gyro, point.force), parts.buffer)
        return nav.integrator.fork(), newest

    def _state(self, ahead_sample: tuple) -> np.ndarray:
        """:func:`imu_stretch`'s ``state`` from the parts, the prediction at ``ahead_sample``
        (stamp s, gyro, force)."""
        parts = self._parts
        point, prediction = parts.point, parts.prediction
        ahead_t, ahead_gyro, ahead_force = ahead_sample
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
                prediction.forked_at_s,
                0.0 if prediction.ahead is not None else 1.0,
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

    def _moved(self, state: np.ndarray, due: list, took: list, stepped: int, ahead) -> None:
        """The parts set from what the stretch did: it ``took`` these samples (into the
        buffer), stepped the filter to ``stepped`` of the ``due`` buffered samples and then of
        those and the prediction ``ahead`` (an integrator) to the last; ``state`` as it left
        it."""
        parts = self._parts
        point = parts.point
        buffer = parts.buffer
        buffer.extend(took)
        if stepped:
            walked = [(point.t_s, point.gyro, point.force), *due, *took]
            for _ in range(stepped):
                buffer.popleft()
            point.stepped_through(walked[stepped - 1], walked[stepped])
        parts.prediction.predicted_through(
            ahead, took[-1], float(state[FORKED_AT]), state[FORK_DUE] != 0.0
        )
        parts.output.next_output_s = float(state[NEXT_OUTPUT_T])
        parts.solutions.rows.count = int(state[ROWS])

    def _window_end(self, run: _Run, start: int, ready: frozenset, with_mooring: bool) -> int:
        """Where the inputs from ``start`` a stretch is offered end: at the first the engine
        must take (the aiding sources' unless ``ready``), after the first IMU sample whose
        filtering reaches the next measurement or constraint due (unless ``with_mooring``; the
        stretch stops there), :data:`WINDOW` at most."""
        parts = self._parts
        heap = parts.queue.heap
        stop_s = min((entry[0] for entry in heap if entry[3] not in ready), default=math.inf)
        if not with_mooring:
            stop_s = min(stop_s, min((s.next_due_s for s in parts.pseudo), default=math.inf))
        stop_s += parts.config.max_measurement_delay_s
        end = min(start + WINDOW, len(run.imu_index))
        allowed = run.imu_index[start:end] >= 0
        if ready:
            allowed |= self._aiding.ready_mask(ready)[run.aiding_slots[start:end]]
        blocked = np.flatnonzero(~allowed)
        if blocked.size:
            end = start + int(blocked[0])
        beyond = np.flatnonzero(run.imu_stamps[start:end] > stop_s)
        return start + int(beyond[0]) + 1 if beyond.size else end

    def _order(self, run: _Run, window: slice, aiding_queued: AidingRows):
        """:func:`imu_stretch`'s ``order`` for the inputs of the ``window`` and the aiding rows
        (``aiding_queued`` first, then those of the window)."""
        imu, aids = run.imu_index[window], run.aiding_index[window]
        is_imu = imu >= 0
        aiding_places = aids[~is_imu]
        order = np.empty(len(imu), dtype=np.int64)
        order[is_imu] = np.arange(np.count_nonzero(is_imu))
        order[~is_imu] = -1 - len(aiding_queued.items) - np.arange(len(aiding_places))
        aiding = AidingRows(
            [*aiding_queued.items, *(run.aiding.items[index] for index in aiding_places.tolist())],
            np.concatenate((aiding_queued.rows, run.aiding.rows[aiding_places])),
        )
        return order, aiding


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
