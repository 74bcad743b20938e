"""The mooring's constraint in the compiled stretches (:mod:`buoy_nav.mooring_epoch`): when the
stretches may make its epochs, the kernel's arguments for them, and the books of what a stretch
did, kept as the engine keeps them.

A stretch makes the mooring's epochs when the mooring (:mod:`buoy_nav.aiding.moored`) is the
engine's one constraint and its anchor is set; when no fix can reset the anchor (none accepted
for ``coasting_timeout_s``, and none in the stretch: it takes no GNSS measurement) and the
receiver's motion holds nothing to judge the mooring by; when a pass of its gate cannot move its
health and it is neither suspended nor contradicted; when the filter is trusted and no smoother
records the epochs. Its epochs then move nothing else the engine keeps but what
:meth:`StretchedMooring.booker` books (its innovation watch among them: the books give it the
same innovations, and it widens or narrows the σ as it did in the stretch).
"""

import math
from collections.abc import Callable

import numpy as np

from buoy_nav.aiding.base import AIDED_QUANTITIES, FIX
from buoy_nav.aiding.moored import MooredSource
from buoy_nav.chi_square import chi_square_quantile
from buoy_nav.error_state_filter import GateResult
from buoy_nav.mooring_epoch import (
    ANCHOR,
    ANCHOR_T,
    ATTITUDE_START,
    BOOK_ANCHOR,
    BOOK_INNOVATION,
    BOOK_NIS,
    BOOK_S,
    BOOK_SIZE,
    BOOK_T,
    BOOK_VELOCITY,
    BOOK_VELOCITY_COVARIANCE,
    PERIOD,
    POSITION_START,
    STATE_SIZE,
    TERMS_SIZE,
    THRESHOLD,
    TIME_CONSTANT,
    VELOCITY_START,
    MooringArguments,
    no_mooring,
)


class StretchedMooring:
    """The engine's mooring, when it is its one constraint, with the engine's ``parts``
    (:class:`~buoy_nav.imu_stretches.EngineParts`) its epochs are booked in."""

    def __init__(self, parts):
        self._parts = parts
        pseudo = parts.pseudo
        only = pseudo[0] if len(pseudo) == 1 else None
        self.source: MooredSource | None = only if isinstance(only, MooredSource) else None
        self._none = no_mooring()
        self._threshold = (
            chi_square_quantile(3, self.source.gate_probability) if self.source else math.nan
        )

    @property
    def none(self) -> MooringArguments:
        """The arguments of a stretch that stops at the constraint."""
        return self._none

    def ready(self, nav) -> bool:
        """Whether a stretch that takes no GNSS measurement may make the mooring's epochs now
        (see the module docstring)."""
        source, parts = self.source, self._parts
        if source is None or not source.anchored:
            return False
        kind, gates = source.kind, parts.gates
        fix_age_s = parts.recency.age_s(AIDED_QUANTITIES.index(FIX), parts.point.t_s)
        return (
            parts.integrity.trusted
            and not nav.records_epochs
            and not source.fixes_reset(fix_age_s)
            and parts.contradictions.motion.empty
            and gates.unmoved_by_passes(kind)
            and not gates.suspended(kind)
            and not gates.contradicted(kind)
        )

    def arguments(self, room: int) -> MooringArguments:
        """:func:`~buoy_nav.imu_stretch.imu_stretch`'s ``mooring`` with room for ``room``
        epochs."""
        source = self.source
        stretch = source.stretch(room)
        states = source.states
        terms = np.zeros(TERMS_SIZE)
        terms[TIME_CONSTANT], terms[PERIOD] = stretch.time_constant_s, stretch.period_s
        terms[THRESHOLD] = self._threshold
        terms[POSITION_START] = states.position.start
        terms[VELOCITY_START] = states.velocity.start
        terms[ATTITUDE_START] = states.attitude.start
        state = np.zeros(STATE_SIZE)
        state[ANCHOR : ANCHOR + 3] = stretch.anchor
        state[ANCHOR_T] = stretch.anchor_t_s
        books = np.zeros((room, BOOK_SIZE))
        return MooringArguments(
            terms,
            stretch.covariance_m2,
            state,
            stretch.innovation_watch,
            stretch.velocity_watches,
            books,
        )

    def booker(self, arguments: MooringArguments, epochs: int) -> Callable[[float], bool]:
        """What books the first ``epochs`` of the stretch's mooring epochs (``arguments``) as
        the engine keeps them, in their order: called with a stamp (s), those before it not yet
        booked; whether it booked any."""
        books = arguments.books[:epochs].tolist()
        booked = 0

        def book_before(t_s: float) -> bool:
            nonlocal booked
            first = booked
            while booked < len(books) and books[booked][BOOK_T] < t_s:
                self._book_epoch(books[booked])
                booked += 1
            return booked > first

        return book_before

    def _book_epoch(self, book: list) -> None:
        """The books of one epoch, as the engine keeps them: the mooring's own (its anchor,
        the mean velocity's watches), the receiver's motion, and its gate's pass."""
        parts, source = self._parts, self.source
        t = book[BOOK_T]
        anchor = source.replayed(
            t,
            book[BOOK_VELOCITY : BOOK_VELOCITY + 3],
            np.array(book[BOOK_VELOCITY_COVARIANCE : BOOK_VELOCITY_COVARIANCE + 9]).reshape(3, 3),
            book[BOOK_ANCHOR : BOOK_ANCHOR + 3],
        )
        parts.contradictions.observe(t, anchor)
        gate = GateResult(
            True, book[BOOK_NIS], self._threshold, np.array(book[BOOK_S : BOOK_S + 9]).reshape(3, 3)
        )
        innovation = np.array(book[BOOK_INNOVATION : BOOK_INNOVATION + 3])
        fused, outcome = parts.gates.passed(source, t, innovation, gate)
        if not fused:
            raise RuntimeError(f"{source.kind}: a stretch's constraint was not fused")
        parts.transitions.extend(outcome.transitions)
