"""Samples out of a sensor stream's accepted sequence: a second stream on its topic.

A second device publishing on a sensor's topic (another buoy's nodes on the same ROS domain)
looks, sample by sample, like a step of the sensor's clock or the end of an outage: its stamps
lie off the sensor's own, back or ahead. What tells it apart is that the sensor's own samples go
on between its samples. So a sample that does not follow the latest one of the accepted
sequence at the stream's rate (within :data:`SEQUENCE_INTERVALS` sample intervals) is held off
it: it moves no clock and gives no output. Held samples that follow each other make a new
sequence; when their stamps span :data:`CONFIRMING_SPAN_S` with no sample of the accepted
sequence in between, the accepted sequence has stopped and the new one is the sensor's (after
a step of its clock, or an outage). A sample of the accepted sequence gives the held ones up:
they were another stream's (or a single stray sample).

Messages arrive in bursts (a recorder or a busy middleware delivers a topic's messages up to a
second late and together), so the span is far longer than a burst: a second stream interleaved
with the sensor's never spans it, and a real step or outage only delays the samples of its first
:data:`CONFIRMING_SPAN_S`. A second stream whose stamps lie
within :data:`SEQUENCE_INTERVALS` sample intervals of the sensor's cannot be told from it.

What becomes of a held sample depends on who waits for it:

- the IMU's samples (:mod:`buoy_nav.imu_input`) are held, given up when the IMU's own go on,
  and, once confirmed, released after a step of the IMU's clock is undone;
- an aiding measurement (screened by a :class:`StreamSequence` per source in
  :class:`buoy_nav.engine.FusionEngine`) may arrive out of order within
  ``max_measurement_delay_s`` and so ahead of its sequence: it waits in the queue like the
  others, moving nothing, and is judged when its turn comes
  (:class:`buoy_nav.measurement_queue.MeasurementQueue`): the source's own measurement of its
  stamp arriving in sequence replaces it, and at its turn it is used only if it lies on the
  sequence's grid (:meth:`StreamSequence.on_grid`: a whole number of sample intervals from it,
  as a measurement that came early or the first after an outage does); the measurements of a
  confirmed new sequence are used whatever their grid;
- a flow sensor's sample (:class:`wind_comp.pipeline.CompensationPipeline`) waits, held, in the
  compensator's queue of samples (the outputs leave in input order), exempt from the live
  latency budget, until the sequence decides: given up, its output is invalid
  (``out_of_sequence``); confirmed, it is corrected like any other.
"""

import bisect
import itertools
import math
from collections import deque
from typing import NamedTuple

CONFIRMING_SPAN_S = 2.0
"""Span of stamps (s) over which held samples must follow each other, with none of the accepted
sequence in between, to be the stream's new sequence."""

SEQUENCE_INTERVALS = 2.5
"""A sample follows the latest one of the sequence when its stamp is later by at most this many
sample intervals (a sample lost in between is still in sequence)."""

GRID_TOLERANCE = 0.01
"""A stamp lies on the stream's grid when it is within this share of a sample interval of a
whole number of intervals from the sequence's latest stamp."""

RATE_MEMORY = 16
"""In-sequence intervals a stream's sequence keeps (:class:`RecentIntervals`)."""


def stream_interval_s(intervals) -> float:
    """The sample interval (s) of a stream whose recent in-sequence intervals (s) are
    ``intervals``: their median, the lower one of an even count; NaN when there is none.

    A sample lost in between makes one interval twice the stream's, a stamp off its grid (a
    driver's jitter) two shorter ones that sum to it. The median holds the stream's rate against
    a few of either. The shortest would follow the jittered one: a stream stamped every 10 ms
    after a stamp 4 ms off would be taken for one sampled every 4 ms, its own samples would no
    longer follow each other within :data:`SEQUENCE_INTERVALS` of that, and after an outage no
    new sequence would ever be confirmed: the stream would be lost for good. The lower median
    of two keeps the shorter, so that a sample lost early does not widen what follows.

    The compiled stretches keep the same interval in their rings
    (:func:`buoy_nav.sequence_kernels.ring_add`); a test holds the two equal."""
    return _lower_median(sorted(intervals))


def _lower_median(ascending: list[float]) -> float:
    """The lower median of values in ascending order (NaN: none)."""
    return ascending[(len(ascending) - 1) // 2] if ascending else math.nan


class RecentIntervals:
    """A stream's recent in-sequence intervals (s), :data:`RATE_MEMORY` at most, and its sample
    interval from them (:func:`stream_interval_s`)."""

    def __init__(self):
        self._intervals: deque[float] = deque(maxlen=RATE_MEMORY)
        # The same intervals in ascending order: a new one goes in place at each sample, which
        # costs less than sorting them all again.
        self._ascending: list[float] = []
        self.interval_s = math.nan
        """The stream's sample interval (s; NaN until an interval came)."""

    @property
    def values_s(self) -> list[float]:
        """The recent intervals (s), oldest first."""
        return list(self._intervals)

    def add(self, interval_s: float) -> None:
        """An in-sequence interval of ``interval_s`` (s, finite) came."""
        intervals, ascending = self._intervals, self._ascending
        if len(intervals) == RATE_MEMORY:
            del ascending[bisect.bisect_left(ascending, intervals[0])]
        intervals.append(interval_s)
        bisect.insort(ascending, interval_s)
        self.interval_s = _lower_median(ascending)

    def extend(self, intervals_s: list[float]) -> None:
        """In-sequence intervals ``intervals_s`` (s, finite, in order) came: as :meth:`add` of
        each."""
        if intervals_s:
            self._intervals.extend(intervals_s)
            self._reorder()

    def restart(self, intervals_s) -> None:
        """The recent intervals are ``intervals_s`` (s, oldest first, finite) alone."""
        self._intervals.clear()
        self._intervals.extend(intervals_s)
        self._reorder()

    def _reorder(self) -> None:
        """The intervals in order again, and the sample interval from them
        (:func:`stream_interval_s`, sorting them once)."""
        self._ascending = sorted(self._intervals)
        self.interval_s = _lower_median(self._ascending)


def follows(t_s: float, previous_s: float, interval_s: float) -> bool:
    """Whether the stamp ``t_s`` (s) follows ``previous_s`` (s) for a stream sampled every
    ``interval_s`` (s; always, while NaN: the rate not known yet)."""
    return t_s > previous_s and not t_s - previous_s > SEQUENCE_INTERVALS * interval_s


class HeldSequence:
    """Samples (tuples, stamp in s first) out of the accepted sequence, oldest first, that
    follow each other at the stream's rate."""

    def __init__(self):
        self.samples: list[tuple] = []

    def confirmed(self) -> bool:
        """Whether the held samples span :data:`CONFIRMING_SPAN_S`."""
        samples = self.samples
        return bool(samples) and samples[-1][0] - samples[0][0] >= CONFIRMING_SPAN_S

    def take(self) -> list[tuple]:
        """The held samples, leaving none."""
        samples, self.samples = self.samples, []
        return samples


class Screening(NamedTuple):
    """What :meth:`StreamSequence.screen` made of a sample."""

    held: bool
    """The sample is off the accepted sequence and held."""
    taken: list
    """The items to take now, oldest first: the sample's (in sequence, or behind the latest for
    the caller's own order checks), or those of a new sequence once confirmed."""
    given_up: list
    """Held items given up because the accepted sequence went on: a second stream's, or stray
    ones (or, for a stream that may arrive out of order, early ones)."""


class StreamSequence:
    """The accepted sequence of one stream's stamps and the samples held off it (see the module
    docstring)."""

    def __init__(self):
        self.latest_s = -math.inf
        """The latest stamp of the accepted sequence (s)."""
        self._intervals = RecentIntervals()
        self._held = HeldSequence()
        self.second_stream_samples = 0
        """Held samples given up so far: a second stream's."""
        self.second_stream_lead_s = math.nan
        """The last of them less the latest stamp of the sequence then (s): how far the second
        stream runs ahead of the sensor's."""

    @property
    def interval_s(self) -> float:
        """The stream's sample interval (s) from its recent ones in sequence
        (:func:`stream_interval_s`; NaN until two samples in sequence came)."""
        return self._intervals.interval_s

    def screen(self, t_s: float, item) -> Screening:
        """Screen the sample stamped ``t_s`` (s, finite) that the caller knows as ``item``."""
        latest = self.latest_s
        if t_s <= latest:
            return Screening(False, [item], [])
        if follows(t_s, latest, self.interval_s):
            given_up = self._give_up_held()
            if math.isfinite(latest):
                self._intervals.add(t_s - latest)
            self.latest_s = t_s
            return Screening(False, [item], given_up)
        return self._hold(t_s, item)

    @property
    def steady(self) -> bool:
        """Whether no sample is held off the sequence."""
        return not self._held.samples

    @property
    def intervals_s(self) -> list[float]:
        """The recent in-sequence intervals (s), oldest first."""
        return self._intervals.values_s

    def followed(self, stamps_s: list[float]) -> None:
        """Samples stamped ``stamps_s`` (s, in order) followed the sequence, none held: as
        :meth:`screen` takes them one by one (:mod:`buoy_nav.imu_stretch` screened them)."""
        if not stamps_s:
            return
        previous = [self.latest_s, *stamps_s[:-1]]
        self._intervals.extend(
            [
                t - latest
                for t, latest in zip(stamps_s, previous, strict=True)
                if math.isfinite(latest)
            ]
        )
        self.latest_s = stamps_s[-1]

    def on_grid(self, t_s: float) -> bool:
        """Whether the stamp ``t_s`` (s) lies on the sequence's grid: a whole number of sample
        intervals from its latest stamp (within :data:`GRID_TOLERANCE`), a stamp the stream
        itself has or could have (always, while the rate is not known)."""
        interval = self.interval_s
        if not (math.isfinite(interval) and math.isfinite(self.latest_s)):
            return True
        intervals = (t_s - self.latest_s) / interval
        return abs(intervals - round(intervals)) <= GRID_TOLERANCE

    def _hold(self, t_s: float, item) -> Screening:
        held = self._held
        given_up = []
        if held.samples and not follows(t_s, held.samples[-1][0], self.interval_s):
            given_up = self._give_up_held()
        held.samples.append((t_s, item))
        if not held.confirmed():
            return Screening(True, [], given_up)
        samples = held.take()
        stamps = [t for t, _ in samples]
        self._intervals.restart([b - a for a, b in itertools.pairwise(stamps)])
        self.latest_s = stamps[-1]
        return Screening(True, [item for _, item in samples], given_up)

    def _give_up_held(self) -> list:
        samples = self._held.take()
        if samples:
            self.second_stream_samples += len(samples)
            self.second_stream_lead_s = samples[-1][0] - self.latest_s
        return [item for _, item in samples]
