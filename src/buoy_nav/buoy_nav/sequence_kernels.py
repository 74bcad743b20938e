"""A stream's recent intervals in an array, for the compiled stretches (numba, cached on disk).

:mod:`buoy_nav.imu_stretch` and :mod:`buoy_nav.pack_epoch` follow a stream's sequence as
:class:`~buoy_nav.stream_sequence.RecentIntervals` does: its recent in-sequence intervals in a
ring laid out below, the sample interval from them by the one rule the interpreter uses too
(:func:`~buoy_nav.stream_sequence.stream_interval_s`, compiled from its source).
"""

import numba
import numpy as np

from buoy_nav.stream_sequence import RATE_MEMORY, stream_interval_s

# The ring: how many intervals it holds, where the next one goes, then the intervals (s).
RING_COUNT, RING_NEXT, RING_INTERVALS = range(3)
RING_SIZE = RING_INTERVALS + RATE_MEMORY

stream_interval = numba.njit(cache=True)(stream_interval_s)


@numba.njit(cache=True)
def ring_interval(ring) -> float:
    """The stream's sample interval (s) from the intervals of ``ring`` (NaN: none)."""
    return stream_interval(ring[RING_INTERVALS : RING_INTERVALS + int(ring[RING_COUNT])])


@numba.njit(cache=True)
def ring_add(ring, interval_s) -> None:
    """An in-sequence interval of ``interval_s`` (s) into ``ring``, the oldest one out when it
    is full."""
    following = int(ring[RING_NEXT])
    ring[RING_INTERVALS + following] = interval_s
    ring[RING_NEXT] = (following + 1) % RATE_MEMORY
    ring[RING_COUNT] = min(ring[RING_COUNT] + 1.0, float(RATE_MEMORY))


def ring_of(intervals_s: list[float]) -> np.ndarray:
    """The ring of the recent intervals ``intervals_s`` (s, oldest first, RATE_MEMORY at most)."""
    ring = np.zeros(RING_SIZE)
    count = len(intervals_s)
    ring[RING_COUNT] = count
    ring[RING_NEXT] = count % RATE_MEMORY
    ring[RING_INTERVALS : RING_INTERVALS + count] = intervals_s
    return ring


def intervals_of(ring: np.ndarray) -> list[float]:
    """The intervals (s) of ``ring``, oldest first."""
    count, following = int(ring[RING_COUNT]), int(ring[RING_NEXT])
    values = ring[RING_INTERVALS : RING_INTERVALS + count].tolist()
    return values[following:] + values[:following] if count == RATE_MEMORY else values
