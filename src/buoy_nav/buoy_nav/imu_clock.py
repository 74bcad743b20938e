"""The IMU's clock against the aiding sources': steps found and undone.

A driver's clock can step (a time-sync correction, a reset): from one sample to the next the IMU
stamps jump back or ahead while the samples, and the GNSS, go on as before. Left alone, a step
back makes every sample until the old stamps are reached "not increasing" and then runs the
strapdown integration seconds off the GNSS; a step ahead looks like an outage and every later
GNSS measurement arrives "too late". :class:`ImuClock` tells a step from an outage and puts the
IMU stamps back on the aiding sources' clock.
"""

import math

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
        self._interval_s = math.nan
        self._newest_aiding_s = -math.inf
        # A stamp far behind the latest, on the IMU's clock: a step back if the next sample
        # follows it, a stale sample otherwise.
        self._step_back_candidate_s = math.nan
        self.steps: list[tuple[float, float]] = []
        """(stamp of the first sample after the step on the aiding sources' clock, s; step, s,
        negative when the IMU clock went back)."""

    def aiding_stamp(self, t_s: float) -> None:
        """An aiding measurement stamped ``t_s`` (s) arrived."""
        if t_s > self._newest_aiding_s:
            self._newest_aiding_s = t_s

    def restamp(self, t_s: float, latest_s: float) -> float:
        """The IMU stamp ``t_s`` (s) on the aiding sources' clock, given the latest accepted
        (re-stamped) IMU stamp ``latest_s``.

        A stamp more than ``max_gap_s`` before the latest is a sample out of place (it stays
        on its own clock, and is rejected as not increasing); if the next sample follows it one
        sample interval later, the clock went back, and the samples from the second one on are
        re-stamped to continue two sample intervals after the latest. A stamp more than
        ``max_gap_s`` after the latest is an outage if the aiding stamps went on meanwhile, and
        a step if the aiding was running with the IMU until then and did not: its newest stamp is
        still nearer the IMU's latest stamp than this one; the sample is re-stamped to follow
        the latest one sample interval later.
        """
        t_s += self._offset_s
        if not (math.isfinite(latest_s) and math.isfinite(self._interval_s)):
            return t_s
        interval = self._interval_s
        candidate, self._step_back_candidate_s = self._step_back_candidate_s, math.nan
        if abs(t_s - (candidate + interval)) <= 0.5 * interval:
            return self._step(t_s, candidate - (latest_s + interval))
        gap_limit = self._max_gap_s
        if t_s < latest_s - gap_limit:
            self._step_back_candidate_s = t_s
            return t_s
        newest_aiding = self._newest_aiding_s
        if (
            t_s > latest_s + gap_limit
            and newest_aiding > latest_s - MAX_AIDING_INTERVAL_S
            and newest_aiding < 0.5 * (latest_s + t_s)
        ):
            return self._step(t_s, t_s - (latest_s + interval))
        return t_s

    def _step(self, t_s: float, step: float) -> float:
        """Undo a step of ``step`` s of the IMU clock for the sample stamped ``t_s``."""
        self._offset_s -= step
        self.steps.append((t_s - step, step))
        return t_s - step

    def accepted(self, t_s: float, latest_s: float) -> None:
        """The sample re-stamped ``t_s`` (s) was accepted after the one at ``latest_s``: the
        sample interval follows it unless the two are a gap apart."""
        if t_s - latest_s <= self._max_gap_s:
            self._interval_s = t_s - latest_s
