"""The measurements waiting for the filter, in stamp order.

Measurements of one stamp come out together, in the order of the registry of aiding sources
(:data:`buoy_nav.aiding.AIDING_SOURCES`), then of arrival. The queue keeps the stamps each
source holds, to reject a duplicated stamp and to set aside a measurement whose superseding
source (``superseded_by``) has one of the same stamp.

A measurement that arrived ahead of its source's sequence (:mod:`buoy_nav.stream_sequence`) waits
here like the others, marked: the source's own measurement of its stamp, arriving in sequence,
takes its place (it was another stream's), and at its turn it is used only if its stamp lies on
the sequence's grid (one the source has or could have: a measurement that came early, or the
first after an outage); otherwise it is rejected as ``out_of_sequence``. Until its turn it moves
nothing.
"""

import heapq
from collections.abc import Sequence

from buoy_common.contract import Reason
from buoy_nav.aiding.base import AidingSource
from buoy_nav.health import MeasurementCounters
from buoy_nav.stream_sequence import StreamSequence

# How far measurements may run ahead of the newest IMU sample (s of stamps). More can only be an
# IMU outage (or GNSS before the IMU starts): the filter could use them only for the alignment
# that follows, which needs the last seconds alone, and keeping them all would let an outage
# fill the memory and, when the IMU returns, stall the node on the backlog.
MAX_MEASUREMENT_LEAD_S = 10.0


class MeasurementQueue:
    """Validated measurements of ``sources`` by stamp; counts into ``counters`` (by kind) what it
    sets aside (superseded) or gives up (``beyond_imu_data``, ``out_of_sequence``), judging the
    measurements that arrived ahead of their sources' ``sequences`` (by kind).

    ``heap`` holds (stamp, registry order, arrival sequence, source, measurement); read
    ``heap[0][0]`` for the earliest stamp, change it only through the methods.
    """

    def __init__(
        self,
        sources: Sequence[AidingSource],
        counters: dict[str, MeasurementCounters],
        sequences: dict[str, StreamSequence],
    ):
        self.heap: list = []
        self._counters = counters
        self._sequences = sequences
        self._order = {source: index for index, source in enumerate(sources)}
        self._sequence = 0
        self._stamps: dict[str, set[float]] = {source.kind: set() for source in sources}
        # By kind: stamp → arrival sequence of the measurement there that arrived ahead.
        self._ahead: dict[str, dict[float, int]] = {source.kind: {} for source in sources}
        # Arrival sequences of the measurements whose place another took.
        self._replaced: set[int] = set()
        self.out_of_sequence: list[AidingSource] = []
        """The sources of the measurements rejected as ``out_of_sequence``, in order (for the
        caller to log; emptied by it)."""
        # (superseded kind, superseding kind), both registered.
        self._supersessions = [
            (source.kind, source.superseded_by)
            for source in sources
            if source.superseded_by in self._stamps
        ]

    def push(self, source: AidingSource, t: float, measurement, ahead: bool = False):
        """Queue ``measurement`` of ``source`` stamped ``t``, ``ahead`` of the source's sequence
        or in it; the reason when it is refused (a measurement of that source with that stamp is
        already queued, and it did not arrive ahead while this one is in sequence)."""
        stamps = self._stamps[source.kind]
        ahead_of_kind = self._ahead[source.kind]
        if t in stamps:
            if ahead or t not in ahead_of_kind:
                return Reason.DUPLICATE_STAMP
            self._replaced.add(ahead_of_kind.pop(t))
            self._reject_out_of_sequence(source)
        stamps.add(t)
        self._sequence += 1
        if ahead:
            ahead_of_kind[t] = self._sequence
        heapq.heappush(self.heap, (t, self._order[source], self._sequence, source, measurement))
        return None

    def settle(self, source: AidingSource, stamps: Sequence[float]) -> None:
        """The measurements of ``source`` at ``stamps`` (s) that arrived ahead are of its
        sequence after all (they started its new one): no longer judged at their turn."""
        ahead_of_kind = self._ahead[source.kind]
        for t in stamps:
            ahead_of_kind.pop(t, None)

    def _reject_out_of_sequence(self, source: AidingSource) -> None:
        self._counters[source.kind].reject(Reason.OUT_OF_SEQUENCE)
        self.out_of_sequence.append(source)

    def _judged(self, entry) -> bool:
        """Whether the popped ``entry`` is to be used: not replaced, and if it arrived ahead,
        on its source's grid (else rejected as ``out_of_sequence``)."""
        t, _, arrival, source, _ = entry
        if arrival in self._replaced:
            self._replaced.discard(arrival)
            return False
        ahead_of_kind = self._ahead[source.kind]
        if ahead_of_kind.get(t) == arrival:
            del ahead_of_kind[t]
            if not self._sequences[source.kind].on_grid(t):
                self._stamps[source.kind].discard(t)
                self._reject_out_of_sequence(source)
                return False
        return True

    def pop_stamp(self) -> tuple[float, list[tuple[AidingSource, object]]]:
        """The earliest stamp and its (source, measurement) pairs, less the superseded ones."""
        heap = self.heap
        group = [heapq.heappop(heap)]
        t = group[0][0]
        while heap and heap[0][0] == t:
            group.append(heapq.heappop(heap))
        group = [entry for entry in group if self._judged(entry)]
        stamps = self._stamps
        superseded = {kind for kind, by in self._supersessions if t in stamps[by]}
        kept = []
        for _, _, _, source, measurement in group:
            stamps[source.kind].discard(t)
            if source.kind in superseded:
                self._counters[source.kind].superseded += 1
            else:
                kept.append((source, measurement))
        return t, kept

    @property
    def settled(self) -> bool:
        """Whether no queued measurement arrived ahead of its sequence or was replaced: none is
        left for the queue to judge at its turn, and :meth:`take_source` takes."""
        return not (self._replaced or any(self._ahead.values()))

    def take_source(self, source: AidingSource) -> list[tuple[float, object]] | None:
        """Take out the queued measurements of ``source`` as (stamp s, measurement), oldest
        first, to be applied elsewhere (:mod:`buoy_nav.imu_stretch`) or queued again with
        :meth:`push`; None, with nothing taken, when the queue is not :attr:`settled` (it
        judges some at their turn)."""
        if not self.settled:
            return None
        kind = source.kind
        taken = sorted(
            (entry[0], entry[2], entry[4]) for entry in self.heap if entry[3].kind == kind
        )
        if taken:
            kept = [entry for entry in self.heap if entry[3].kind != kind]
            heapq.heapify(kept)
            self.heap[:] = kept
            self._stamps[kind].clear()
        return [(stamp, measurement) for stamp, _, measurement in taken]

    def give_up_between(self, after_s: float, before_s: float) -> None:
        """Give up the measurements stamped after ``after_s`` and before ``before_s`` (s)."""
        kept = []
        for entry in self.heap:
            stamp, _, arrival, source, _ = entry
            if not after_s < stamp < before_s:
                kept.append(entry)
            elif arrival in self._replaced:
                self._replaced.discard(arrival)
            else:
                self._stamps[source.kind].discard(stamp)
                self._ahead[source.kind].pop(stamp, None)
                self._counters[source.kind].reject(Reason.BEYOND_IMU_DATA)
        heapq.heapify(kept)
        self.heap[:] = kept

    def give_up_all(self) -> None:
        """Give up every queued measurement."""
        for entry in self.heap:
            if entry[2] not in self._replaced:
                self._counters[entry[3].kind].reject(Reason.BEYOND_IMU_DATA)
        self.heap.clear()
        self._replaced.clear()
        for stamps in self._stamps.values():
            stamps.clear()
        for ahead_of_kind in self._ahead.values():
            ahead_of_kind.clear()
