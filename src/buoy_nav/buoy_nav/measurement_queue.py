"""The measurements waiting for the filter, in stamp order.

Measurements of one stamp come out together, in the order of the registry of aiding sources
(:data:`buoy_nav.aiding.AIDING_SOURCES`), then of arrival. The queue keeps the stamps each
source holds, to reject a duplicated stamp and to set aside a measurement whose superseding
source (``superseded_by``) has one of the same stamp.
"""

import heapq
from collections.abc import Sequence

from buoy_common.contract import Reason
from buoy_nav.aiding.base import AidingSource
from buoy_nav.health import MeasurementCounters


class MeasurementQueue:
    """Validated measurements of ``sources`` by stamp; counts into ``counters`` (by kind) what it
    sets aside (superseded) or gives up (``beyond_imu_data``).

    ``heap`` holds (stamp, registry order, arrival sequence, source, measurement); read
    ``heap[0][0]`` for the earliest stamp, change it only through the methods.
    """

    def __init__(self, sources: Sequence[AidingSource], counters: dict[str, MeasurementCounters]):
        self.heap: list = []
        self._counters = counters
        self._order = {source: index for index, source in enumerate(sources)}
        self._sequence = 0
        self._stamps: dict[str, set[float]] = {source.kind: set() for source in sources}
        # (superseded kind, superseding kind), both registered.
        self._supersessions = [
            (source.kind, source.superseded_by)
            for source in sources
            if source.superseded_by in self._stamps
        ]

    def push(self, source: AidingSource, t: float, measurement) -> Reason | None:
        """Queue ``measurement`` of ``source`` stamped ``t``; the reason when it is refused (a
        measurement of that source with that stamp is already queued)."""
        stamps = self._stamps[source.kind]
        if t in stamps:
            return Reason.DUPLICATE_STAMP
        stamps.add(t)
        self._sequence += 1
        heapq.heappush(self.heap, (t, self._order[source], self._sequence, source, measurement))
        return None

    def pop_stamp(self) -> tuple[float, list[tuple[AidingSource, object]]]:
        """The earliest stamp and its (source, measurement) pairs, less the superseded ones."""
        heap = self.heap
        group = [heapq.heappop(heap)]
        t = group[0][0]
        while heap and heap[0][0] == t:
            group.append(heapq.heappop(heap))
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

    def give_up_between(self, after_s: float, before_s: float) -> None:
        """Give up the measurements stamped after ``after_s`` and before ``before_s`` (s)."""
        kept = []
        for entry in self.heap:
            stamp, _, _, source, _ = entry
            if after_s < stamp < before_s:
                self._stamps[source.kind].discard(stamp)
                self._counters[source.kind].reject(Reason.BEYOND_IMU_DATA)
            else:
                kept.append(entry)
        heapq.heapify(kept)
        self.heap[:] = kept

    def give_up_all(self) -> None:
        """Give up every queued measurement."""
        for entry in self.heap:
            self._counters[entry[3].kind].reject(Reason.BEYOND_IMU_DATA)
        self.heap.clear()
        for stamps in self._stamps.values():
            stamps.clear()
