"""The compiled ring of a stream's recent intervals against the interpreter's."""

import math

import numpy as np
import pytest

from buoy_nav.sequence_kernels import intervals_of, ring_add, ring_interval, ring_of
from buoy_nav.stream_sequence import RATE_MEMORY, RecentIntervals


@pytest.mark.parametrize("repeated", [False, True], ids=["distinct", "repeated"])
@pytest.mark.parametrize("count", [1, 2, 3, RATE_MEMORY, RATE_MEMORY + 5, 3 * RATE_MEMORY + 7])
def test_the_ring_follows_the_recent_intervals_and_resumes_from_them(count, repeated):
    """Interval by interval, the ring holds the recent intervals in their order and gives the
    same sample interval (``repeated``: intervals of a few values, many equal); a ring made
    from them goes on as they do."""
    rng = np.random.default_rng(count)
    if repeated:
        intervals = rng.choice([0.004, 0.006, 0.01, 0.02], count).tolist()
    else:
        intervals = rng.uniform(0.001, 0.02, count).tolist()
    recent, ring = RecentIntervals(), ring_of([])
    for interval in intervals:
        recent.add(interval)
        ring_add(ring, interval)
        assert intervals_of(ring) == recent.values_s
        assert ring_interval(ring) == recent.interval_s
    resumed = ring_of(recent.values_s)
    for interval in (0.5, 0.25):
        recent.add(interval)
        ring_add(resumed, interval)
    assert intervals_of(resumed) == recent.values_s
    assert ring_interval(resumed) == recent.interval_s


def test_no_interval_gives_no_sample_interval():
    assert math.isnan(ring_interval(ring_of([])))
    assert math.isnan(RecentIntervals().interval_s)
