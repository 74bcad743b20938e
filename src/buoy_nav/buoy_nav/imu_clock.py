"""The IMU's clock against the aiding sources': steps found and undone.

A driver's clock can step (a time-sync correction, a reset): from one sample to the next the IMU
stamps jump back or ahead while the samples, and the GNSS, go on as before. Left alone, a step
back makes every sample until the old stamps are reached "not increasing" and then runs the
strapdown integration seconds off the GNSS; a step ahead looks like an outage and every later
GNSS measurement arrives "too late". :class:`ImuClock` tells a step from an outage and puts the
IMU stamps back on the aiding sources' clock.

Which samples make a new sequence of the IMU's own (after a step or an outage), rather than a
second stream interleaved with it, is for :mod:`buoy_nav.stream_sequence` to say; the clock is told
of a new sequence once it is the IMU's.
"""

import math

from buoy_nav.stream_sequence import SEQUENCE_INTERVALS, RecentIntervals, follows

MAX_AIDING_INTERVAL_S = 1.0
"""Longest interval between aiding measurements of a running GNSS receiver (s): aiding stamps
this close to the newest IMU stamp say the aiding sources and the IMU ran on together."""


class ImuClock:
    """Re-stamps IMU samples onto the aiding sources' clock after a step of the IMU's clock.

    max_gap_s: an IMU stamp further than this from the previous one is a step or an outage
    (the fusion's ``max_imu_gap_s``).
    """

    def __init__(self, max_gap_s: float):
        self._max_gap_s = max_gap_s
        self._offset_s = 0.0
        self.intervals = RecentIntervals()
        """The IMU's recent in-sequence intervals and its sample interval from them."""
        self.newest_aiding_s = -math.inf
        """The newest aiding stamp seen (s)."""
        self.steps: list[tuple[float, float]] = []
        """(stamp of the first sample after the step on the aiding sources' clock, s; step, s,
        negative when the IMU clock went back)."""

    def aiding_stamp(self, t_s: float) -> None:
        """An aiding measurement stamped ``t_s`` (s) arrived."""
        if t_s > self.newest_aiding_s:
            self.newest_aiding_s = t_s

    @property
    def interval_s(self) -> float:
        """The IMU's sample interval (s; NaN until two samples in sequence were accepted)."""
        return self.intervals.interval_s

    @property
    def offset_s(self) -> float:
        """What :meth:`restamp` adds to an IMU stamp (s)."""
        return self._offset_s

    def restamp(self, t_s: float) -> float:
        """The IMU stamp ``t_s`` (s) on the aiding sources' clock, as the steps so far say."""
        return t_s + self._offset_s

    def follows(self, t_s: float, previous_s: float) -> bool:
        """Whether the (re-stamped) stamp ``t_s`` (s) follows ``previous_s`` at the IMU's rate
        (always, while the rate is not known)."""
        return follows(t_s, previous_s, self.interval_s)

    def new_sequence(self, first_s: float, latest_s: float, newest_aiding_s: float) -> float | None:
        """The step (s) to take off the stamps of a new sequence of the IMU's, whose first
        (re-stamped) stamp is ``first_s``, after the latest accepted one at ``latest_s``, the
        newest aiding stamp being ``newest_aiding_s`` when it came (0: no step); None when the
        sequence cannot be taken (it lies behind the latest on the aiding sources' clock).

        The aiding says which of the two sequences its clock ran with: a step (of the new
        sequence's clock) when its newest stamp is nearer the latest IMU stamp than the new one
        and it was running with the IMU until then (within :data:`MAX_AIDING_INTERVAL_S`). More
        than ``max_gap_s`` ahead without a step, it is an outage. Behind the latest without a
        step, the accepted sequence was off the aiding clock (another stream's, which took over
        where its stamps met the IMU's): the new one cannot go back in time, and is given up
        until its stamps pass the latest. A step is undone so that the first sample follows the
        latest one sample interval later.
        """
        if not (math.isfinite(latest_s) and math.isfinite(self.interval_s)):
            return 0.0
        aiding_ran_with_latest = newest_aiding_s > latest_s - MAX_AIDING_INTERVAL_S and abs(
            newest_aiding_s - latest_s
        ) < abs(newest_aiding_s - first_s)
        if first_s <= latest_s and not aiding_ran_with_latest:
            return None
        if first_s <= latest_s or (first_s > latest_s + self._max_gap_s and aiding_ran_with_latest):
            step = first_s - (latest_s + self.interval_s)
            self._offset_s -= step
            self.steps.append((first_s - step, step))
            return step
        return 0.0

    def accepted(self, t_s: float, latest_s: float) -> None:
        """The sample re-stamped ``t_s`` (s) was accepted after the one at ``latest_s``: the
        interval is one of the recent ones when it is in sequence (or none is known yet)."""
        dt = t_s - latest_s
        if dt <= self._max_gap_s and not dt > SEQUENCE_INTERVALS * self.interval_s:
            self.intervals.add(dt)
