"""The aiding sources whose measurements the compiled stretches take (:mod:`buoy_nav.imu_stretch`,
:mod:`buoy_nav.aiding_epoch`): which they are, their measurements made into rows, when the
stretches may take them, and the books of what a stretch did with them, kept as the engine keeps
them.

A source is taken when its measurement function over arrays is one of
:data:`~buoy_nav.aiding_epoch.MODELS` and the source that supersedes it, if registered, is taken
too (the stretch sets a superseded measurement aside as the queue would). Its measurements are
taken while a pass of its gate cannot move its health, nothing of it is held off its sequence,
no contradiction suspends it, the filter is trusted and no smoother records the epochs: the
epochs a stretch makes then move nothing else the engine keeps. A source its gate outcomes
suspended is watched as the engine watches it (its measurements modelled and gated, none
fused) for as many outcomes as cannot resume it
(:meth:`~buoy_nav.source_health.SourceHealth.outcomes_that_cannot_resume`).
"""

import math
from collections.abc import Callable, Iterable
from typing import NamedTuple

import numpy as np

from buoy_common.contract import Reason
from buoy_nav.aiding_epoch import (
    BOOK_DIMENSION,
    BOOK_INNOVATION,
    BOOK_NIS,
    BOOK_ROW,
    BOOK_S,
    BOOK_SIZE,
    BOOK_STATUS,
    MODELS,
    PENDING,
    QUEUED,
    ROW_SIZE,
    ROW_SLOT,
    ROW_STATUS,
    ROW_T,
    ROW_VALUES,
    SUPERSEDED,
    TERM_MODEL,
    TERM_ORDER,
    TERM_SUPERSEDED_BY,
    TERM_THRESHOLDS,
    TERM_VALUES,
    TERMS_SIZE,
    WATCHED,
    WATCHED_NO_GEOMETRY,
    WATCHED_REFUSED,
    AidingArguments,
)
from buoy_nav.chi_square import chi_square_quantile
from buoy_nav.error_state_filter import GateResult
from buoy_nav.sequence_kernels import SEQUENCE_SIZE, sequence_of


class AidingRows(NamedTuple):
    """The stretched aiding measurements of some inputs: each one's (source, validated
    measurement, stamp s), and their rows (:mod:`buoy_nav.aiding_epoch`'s layout)."""

    items: list[tuple]
    rows: np.ndarray


class StretchedAiding:
    """The stretched aiding sources among the engine's ``sources`` (in registry order), with the
    engine's ``parts`` (:class:`~buoy_nav.imu_stretches.EngineParts`) they are booked in."""

    def __init__(self, parts, sources):
        self._parts = parts
        registered = {source.kind for source in sources}
        stretchable = [
            source
            for source in sources
            if source.enabled and getattr(source, "stretch_model", None) in MODELS
        ]
        stretched_kinds = {source.kind for source in stretchable}
        self.sources = tuple(
            source
            for source in stretchable
            if source.superseded_by not in registered or source.superseded_by in stretched_kinds
        )
        self._slot = {source: slot for slot, source in enumerate(self.sources)}
        self._watch: dict = {}
        """The outcomes each suspended source may have watched, as :meth:`ready` found them."""
        self._attitude_start = sources[0].states.attitude.start
        self._none = AidingArguments(
            np.zeros((0, ROW_SIZE)),
            np.zeros((0, SEQUENCE_SIZE)),
            np.zeros((0, TERMS_SIZE)),
            np.zeros((0, BOOK_SIZE)),
            self._attitude_start,
            np.zeros(0),
        )
        # (kind, stamp s) → row, of the measurements a stretch queued again.
        self._rows_of_queued: dict[tuple[str, float], np.ndarray] = {}
        order = {source: place for place, source in enumerate(sources)}
        self._terms = np.zeros((len(self.sources), TERMS_SIZE))
        for slot, source in enumerate(self.sources):
            self._terms[slot] = self._terms_of(source, order[source])

    def _terms_of(self, source, registry_order: int) -> np.ndarray:
        """The row of ``aiding_terms`` of ``source``."""
        terms = np.zeros(TERMS_SIZE)
        terms[TERM_MODEL] = MODELS.index(source.stretch_model)
        terms[TERM_ORDER] = registry_order
        by = [slot for slot, other in enumerate(self.sources) if other.kind == source.superseded_by]
        terms[TERM_SUPERSEDED_BY] = by[0] if by else -1.0
        for dimension in (1, 2, 3):
            threshold = chi_square_quantile(dimension, source.gate_probability)
            terms[TERM_THRESHOLDS + dimension - 1] = threshold
        own = source.stretch_terms()
        terms[TERM_VALUES : TERM_VALUES + own.size] = own
        return terms

    def takes(self, source) -> bool:
        """Whether the stretches may take measurements of ``source``."""
        return source in self._slot

    def rows(self, inputs: list, position_rad: tuple) -> list[tuple | None]:
        """The (validated measurement, row) of each of ``inputs`` (a stretched source's
        :class:`~buoy_nav.imu_stretches.MeasurementInput`), made with the filter at
        ``position_rad`` (latitude, longitude), or None when the engine is to take it (not
        valid, not a finite stamp). A source's measurements are made into rows together."""
        made: list[tuple | None] = [None] * len(inputs)
        places_of: dict = {}
        for place, (source, t_s, measurement) in enumerate(inputs):
            if not isinstance(measurement, Reason) and math.isfinite(t_s):
                places_of.setdefault(source, []).append(place)
        for source, places in places_of.items():
            validated, values = stretch_values_of(
                source, [inputs[place].measurement for place in places], position_rad
            )
            rows = np.zeros((len(places), ROW_SIZE))
            rows[:, ROW_T] = [inputs[place].t_s for place in places]
            rows[:, ROW_SLOT], rows[:, ROW_STATUS] = self._slot[source], PENDING
            rows[:, ROW_VALUES : ROW_VALUES + values.shape[1]] = values
            for index, place in enumerate(places):
                if not isinstance(validated[index], Reason):
                    made[place] = validated[index], rows[index]
        return made

    def _row_of_validated(self, source, t_s: float, validated, position_rad: tuple) -> np.ndarray:
        """The row of the ``validated`` measurement of ``source`` stamped ``t_s`` (s), made with
        the filter at ``position_rad`` (latitude, longitude). A measurement is validated once:
        a magnetometer's validation calibrates its field."""
        row = np.zeros(ROW_SIZE)
        values = source.stretch_values(validated, position_rad)
        row[ROW_T], row[ROW_SLOT], row[ROW_STATUS] = t_s, self._slot[source], PENDING
        row[ROW_VALUES : ROW_VALUES + len(values)] = values
        return row

    def ready_mask(self, ready: frozenset) -> np.ndarray:
        """Whether each slot's source is among ``ready``, and last False (for the slot −1 of an
        input that is no stretched source's)."""
        return np.array([*(source in ready for source in self.sources), False])

    def ready(self, nav) -> frozenset:
        """The sources whose measurements a stretch may take now (see the module docstring);
        the outcomes each suspended one may have watched are kept for :meth:`arguments`."""
        parts = self._parts
        self._watch = {}
        if not self.sources or not parts.integrity.trusted or nav.records_epochs:
            return frozenset()
        gates = parts.gates
        ready = []
        for source in self.sources:
            kind = source.kind
            if not parts.sequences[kind].steady or gates.contradicted(kind):
                continue
            if gates.unmoved_by_passes(kind):
                ready.append(source)
                continue
            watched = gates.outcomes_while_suspended(kind)
            if watched > 0:
                self._watch[source] = watched
                ready.append(source)
        return frozenset(ready)

    def queued(self, ready: frozenset, position_rad: tuple) -> AidingRows:
        """The queued measurements of the ``ready`` sources taken out of the engine's queue as
        rows (those not made before made with the filter at ``position_rad``), stamp by stamp
        (the queue :attr:`settled`: it takes them)."""
        queue = self._parts.queue
        rows_of_queued, self._rows_of_queued = self._rows_of_queued, {}
        items = []
        for source in self.sources:
            if source in ready:
                taken = queue.take_source(source) or ()
                items.extend((source, measurement, t) for t, measurement in taken)
        items.sort(key=lambda item: (item[2], self._slot[item[0]]))
        rows = np.zeros((len(items), ROW_SIZE))
        for index, (source, measurement, t) in enumerate(items):
            row = rows_of_queued.get((source.kind, t))
            if row is None:
                row = self._row_of_validated(source, t, measurement, position_rad)
            rows[index] = row
        rows[:, ROW_STATUS] = QUEUED
        return AidingRows(items, rows)

    @property
    def none(self) -> AidingArguments:
        """The arguments of a stretch that takes no aiding measurement."""
        return self._none

    def arguments(self, rows: np.ndarray, ready: frozenset) -> AidingArguments:
        """:func:`~buoy_nav.imu_stretch.imu_stretch`'s ``aiding`` for ``rows`` of the
        ``ready`` sources: the rows, each source's sequence, the terms, room for the books and
        the outcomes of each suspended source the stretch may watch."""
        sequences = np.zeros((len(self.sources), SEQUENCE_SIZE))
        watch = np.zeros(len(self.sources))
        for slot, source in enumerate(self.sources):
            sequences[slot] = sequence_of(self._parts.sequences[source.kind])
            if source in ready:
                watch[slot] = self._watch.get(source, 0)
        return AidingArguments(
            rows,
            sequences,
            self._terms,
            np.zeros((len(rows), BOOK_SIZE)),
            self._attitude_start,
            watch,
        )

    def book(
        self,
        aiding: AidingRows,
        first_new: int,
        tail: int,
        books: np.ndarray,
        book_before: Callable[[float], object],
    ) -> bool:
        """Keep the books of what a stretch did with ``aiding`` (those before ``first_new``
        queued before it) as the engine keeps them: the sequences and the IMU's clock follow
        the new ones it queued (up to ``tail``), each epoch's measurements set aside are counted
        superseded and those applied observed and booked as passed by their gates, in the
        engine's order (after ``book_before`` the epoch's stamp, which books the other epochs
        stamped before it), and those still queued go back to the queue. Whether an epoch was
        applied."""
        parts = self._parts
        queued = aiding.items[first_new:tail]
        for source in self.sources:
            parts.sequences[source.kind].followed([t for s, _, t in queued if s is source])
        for _, _, t in queued:
            parts.imu_input.clock.aiding_stamp(t)
        passes = _Passes(
            source for source in self.sources if parts.gates.books_passes_at_once(source)
        )
        epoch: list = []
        for book in books.tolist():
            item = aiding.items[int(book[BOOK_ROW])]
            if epoch and item[2] != epoch[0][1][2]:
                self._book_epoch(epoch, book_before, passes)
                epoch = []
            epoch.append((book, item))
        if epoch:
            self._book_epoch(epoch, book_before, passes)
        passes.book(parts.gates)
        for index in np.flatnonzero(aiding.rows[:, ROW_STATUS] == QUEUED).tolist():
            source, measurement, t = aiding.items[index]
            self._parts.queue.push(source, t, measurement)
            # Taken out again by the next stretch, most likely: its row need not be made again.
            self._rows_of_queued[(source.kind, t)] = aiding.rows[index]
        return bool(epoch)

    def _book_epoch(
        self, epoch: list, book_before: Callable[[float], object], passes: "_Passes"
    ) -> None:
        """The books of one epoch's (book row, item) pairs, as the queue and the engine keep
        them, after ``book_before`` its stamp: the superseded counted, then each other one
        observed, then each booked as passed by its gate (applied; kept in ``passes`` for its
        source's books at once, where they may be) or as a suspended source's outcome
        (watched)."""
        parts = self._parts
        book_before(epoch[0][1][2])
        taken = []
        for book, (source, measurement, t) in epoch:
            if book[BOOK_STATUS] == SUPERSEDED:
                parts.counters[source.kind].superseded += 1
                continue
            parts.contradictions.observe(t, measurement)
            taken.append((book, source, t))
        for book, source, t in taken:
            status = book[BOOK_STATUS]
            if status == WATCHED_NO_GEOMETRY:
                outcome = parts.gates.watched(source, t, None)
            elif status == WATCHED_REFUSED:
                outcome = parts.gates.watched(source, t, source.stretch_refusal)
            elif status != WATCHED and passes.keep(source, t, book[BOOK_NIS]):
                continue
            else:
                outcome = self._gated(book, source, t, watched=status == WATCHED)
            parts.transitions.extend(outcome.transitions)

    def _gated(self, book, source, t: float, watched: bool):
        """The gate's books of a measurement of ``source`` at ``t`` (s) the stretch applied or
        (``watched``) gated alone, as its ``book`` says: the gates' outcome."""
        dimension = int(book[BOOK_DIMENSION])
        threshold = self._terms[self._slot[source], TERM_THRESHOLDS + dimension - 1]
        nis = book[BOOK_NIS]
        gate = GateResult(
            nis <= threshold,
            nis,
            threshold,
            np.array(book[BOOK_S : BOOK_S + dimension * dimension]).reshape(dimension, dimension),
        )
        innovation = np.array(book[BOOK_INNOVATION : BOOK_INNOVATION + dimension])
        if watched:
            return self._parts.gates.watched(source, t, None, innovation, gate)
        fused, outcome = self._parts.gates.passed(source, t, innovation, gate)
        if not fused:
            raise RuntimeError(f"{source.kind}: a stretch's measurement was not fused")
        return outcome


def stretch_values_of(source, measurements: list, position_rad: tuple) -> tuple[list, np.ndarray]:
    """Each of ``measurements`` of ``source`` validated (or the :class:`Reason` it is not
    valid) and the rows of the numbers its model over arrays reads, made with the filter at
    ``position_rad``: at once where the source can (its ``stretch_values_of``), else one by one.
    A measurement is validated once: a magnetometer's validation calibrates its field."""
    at_once = getattr(source, "stretch_values_of", None)
    made = None if at_once is None else at_once(measurements, position_rad)
    if made is not None:
        return made
    validated = [source.validated(measurement) for measurement in measurements]
    values = [
        None
        if isinstance(measurement, Reason)
        else source.stretch_values(measurement, position_rad)
        for measurement in validated
    ]
    width = max((len(row) for row in values if row is not None), default=0)
    array = np.zeros((len(values), width))
    for index, row in enumerate(values):
        if row is not None:
            array[index] = row
    return validated, array


class _Passes:
    """The applied measurements of a stretch whose sources book their passes at once
    (:meth:`~buoy_nav.aiding_gates.AidingGates.books_passes_at_once`): each one's stamps and
    normalised innovation squares, in their order, booked after the stretch's other books."""

    def __init__(self, sources: Iterable):
        self._kept = {source: ([], []) for source in sources}

    def keep(self, source, t_s: float, nis: float) -> bool:
        """Keep the pass of ``source`` at ``t_s`` (s) with ``nis``; whether it was kept (False:
        its source books each pass where it comes)."""
        kept = self._kept.get(source)
        if kept is None:
            return False
        kept[0].append(t_s)
        kept[1].append(nis)
        return True

    def book(self, gates) -> None:
        """Book the kept passes of each source at once in ``gates``."""
        for source, (stamps_s, nis) in self._kept.items():
            if stamps_s:
                gates.passed_at_once(source, stamps_s, nis)
