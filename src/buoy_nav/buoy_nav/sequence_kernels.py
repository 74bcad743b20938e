"""A stream's sequence in an array, for the compiled stretches (numba, cached on disk).

:mod:`buoy_nav.imu_stretch` follows the IMU's sequence and those of the aiding sources whose
measurements it takes as :class:`~buoy_nav.stream_sequence.StreamSequence` and
:class:`~buoy_nav.stream_sequence.RecentIntervals` do: the recent in-sequence intervals in a
ring, the sample interval from them by the one rule the interpreter uses too
(:func:`~buoy_nav.stream_sequence.stream_interval_s`, compiled from its source), and a
measurement queued as :meth:`~buoy_nav.engine.FusionEngine.add_measurement` queues one with
nothing else to do (:func:`queued_in_sequence`). The arrays are laid out below.
"""

import math

import numba
import numpy as np

from buoy_nav.measurement_queue import MAX_MEASUREMENT_LEAD_S
from buoy_nav.stream_sequence import (
    RATE_MEMORY,
    SEQUENCE_INTERVALS,
    StreamSequence,
    stream_interval_s,
)

# The ring: how many intervals it holds, where the next one goes, the sample interval from them
# (:func:`~buoy_nav.stream_sequence.stream_interval_s`, NaN while there is none), then the
# intervals (s).
RING_COUNT, RING_NEXT, RING_INTERVAL, RING_INTERVALS = range(4)
RING_SIZE = RING_INTERVALS + RATE_MEMORY
# An aiding source's sequence: its latest stamp (s), then the ring of its intervals.
SEQUENCE_LATEST, SEQUENCE_RING = 0, 1
SEQUENCE_SIZE = SEQUENCE_RING + RING_SIZE


@numba.njit(cache=True)
def ring_interval(ring) -> float:
    """The stream's sample interval (s) from the intervals of ``ring`` (NaN: none)."""
    return ring[RING_INTERVAL]


@numba.njit(cache=True)
def ring_add(ring, interval_s) -> None:
    """An in-sequence interval of ``interval_s`` (s, finite) into ``ring``, the oldest one out
    when it is full, and the sample interval from them."""
    following = int(ring[RING_NEXT])
    ring[RING_INTERVALS + following] = interval_s
    ring[RING_NEXT] = (following + 1) % RATE_MEMORY
    count = min(int(ring[RING_COUNT]) + 1, RATE_MEMORY)
    ring[RING_COUNT] = count
    ring[RING_INTERVAL] = _lower_median(ring[RING_INTERVALS : RING_INTERVALS + count])


@numba.njit(cache=True)
def _lower_median(values) -> float:
    """The lower median of the finite ``values`` (at least one): the value
    :func:`~buoy_nav.stream_sequence.stream_interval_s` reads off them in order, found without
    sorting them (at each IMU sample, sorting allocated more than this compares)."""
    rank = (values.shape[0] - 1) // 2
    for candidate in values:
        below = equal = 0
        for other in values:
            if other < candidate:
                below += 1
            elif other == candidate:
                equal += 1
        if below <= rank < below + equal:
            return candidate
    return math.nan


def ring_of(intervals_s: list[float]) -> np.ndarray:
    """The ring of the recent intervals ``intervals_s`` (s, oldest first, RATE_MEMORY at most)."""
    ring = np.zeros(RING_SIZE)
    count = len(intervals_s)
    ring[RING_COUNT] = count
    ring[RING_NEXT] = count % RATE_MEMORY
    ring[RING_INTERVAL] = stream_interval_s(intervals_s)
    ring[RING_INTERVALS : RING_INTERVALS + count] = intervals_s
    return ring


def intervals_of(ring: np.ndarray) -> list[float]:
    """The intervals (s) of ``ring``, oldest first."""
    count, following = int(ring[RING_COUNT]), int(ring[RING_NEXT])
    values = ring[RING_INTERVALS : RING_INTERVALS + count].tolist()
    return values[following:] + values[:following] if count == RATE_MEMORY else values


def sequence_of(stream: StreamSequence) -> np.ndarray:
    """The array of a source's sequence ``stream`` (its latest stamp, its intervals' ring)."""
    sequence = np.empty(SEQUENCE_SIZE)
    sequence[SEQUENCE_LATEST] = stream.latest_s
    sequence[SEQUENCE_RING:] = ring_of(stream.intervals_s)
    return sequence


@numba.njit(cache=True)
def queued_in_sequence(t, sequence, last_imu_stamp_s, newest_imu_stamp_s) -> bool:
    """Whether the engine would queue an aiding measurement stamped ``t`` (s) with nothing else
    to do: following its source's ``sequence``, after the latest IMU stamp the filter processed
    (``last_imu_stamp_s``) and not beyond the newest IMU stamp (``newest_imu_stamp_s``) by
    more than :data:`~buoy_nav.measurement_queue.MAX_MEASUREMENT_LEAD_S`; the sequence then
    follows it. Nothing is changed otherwise."""
    latest = sequence[SEQUENCE_LATEST]
    ring = sequence[SEQUENCE_RING:]
    if not (
        math.isfinite(t)
        and t > latest
        and not t - latest > SEQUENCE_INTERVALS * ring_interval(ring)
        and t > last_imu_stamp_s
        and not t - newest_imu_stamp_s > MAX_MEASUREMENT_LEAD_S
    ):
        return False
    if math.isfinite(latest):
        ring_add(ring, t - latest)
    sequence[SEQUENCE_LATEST] = t
    return True
