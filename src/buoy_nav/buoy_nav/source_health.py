"""Whether an aiding source agrees with the filter, judged over its recent gate outcomes.

A chi-square gate stops one bad measurement. A source that fails it again and again is evidence
against the source (an uncalibrated magnetometer, a GNSS velocity off by a multipath bias, a
motion pack whose covariance claims more than it delivers), not a reason to realign the filter:
following it would pull the filter off, and rejecting it one sample at a time leaves the
source free to pull whenever a sample slips through the gate (an uncalibrated magnetometer
passes it at some headings and fails it at others). As PX4's EKF2 judges each source by its
test ratios over a window, :class:`SourceHealth` keeps the last ``window`` outcomes of one
source and

- **suspends** the source when at least ``min_samples`` outcomes are known (or, for a slow
  source, when its outcomes span ``min_span_s`` with at least :data:`MIN_OUTCOMES_OVER_SPAN` of
  them: a magnetometer at 1 Hz is judged after a minute, not after a hundred seconds; the
  minute is longer than the filter's reset after ``gate_reset_count`` consecutive rejections
  of a 1-Hz source, so that its reset still comes first) and the
  share that failed the gate reaches ``suspend_share``: its measurements are still modelled and
  gated against the filter, so that its agreement stays watched, but none is fused;
- **resumes** it when, of the last ``min_samples`` outcomes, no more than ``resume_share``
  failed: it agrees with the filter again.

The filter's own errors do not suspend a good source first: a source that fails every sample
resets the states it observes after ``gate_reset_count`` consecutive rejections
(:meth:`buoy_nav.aiding.base.AidingSource.reset`), well before ``min_samples`` outcomes are in,
and then agrees again. Suspension is for a source that keeps disagreeing *after* that.

Evidence from outside the gate suspends a source too (:mod:`buoy_nav.contradictions`):
measurements of other sources that contradict it without the filter in between (a GNSS velocity
against the fixes), or an assumption that the measurements show to be wrong (a mooring on a buoy
the GNSS sees drifting): :meth:`SourceHealth.contradict`. A source that is wrong can still pass
its gate (a constraint the filter follows, a velocity after a realignment that left it out), so
only the evidence that suspended it lifts the suspension
(:meth:`SourceHealth.no_longer_contradicted`).
"""

from __future__ import annotations

import itertools
import math
from collections import deque
from collections.abc import Sequence
from dataclasses import dataclass
from enum import Enum
from typing import NamedTuple


class HealthChange(Enum):
    """What an outcome changed about a source."""

    NONE = "none"
    SUSPENDED = "suspended"
    RESUMED = "resumed"
    WARNED = "warned"
    """Not suspended: its innovations say a parameter is stated too small."""


class HealthTransition(NamedTuple):
    """A source suspended or resumed at stamp ``t_s`` (s); ``message`` says why, and what to
    check."""

    t_s: float
    kind: str
    change: HealthChange
    message: str


class SourceStatus(NamedTuple):
    """The health of one source: suspended or not, why (empty when not), how often it was
    suspended so far, and what its innovations warn of."""

    suspended: bool
    reason: str
    suspensions: int
    warning: str = ""
    """The source's latest innovation warning while it holds (empty when none)."""


MIN_OUTCOMES_OVER_SPAN = 20
"""Outcomes a slow source's ``min_span_s`` must hold before it is judged: at a 0.9999 gate a
consistent source fails half of twenty with a chance of about 10⁻³⁵."""


@dataclass(frozen=True)
class SourceHealthRule:
    """When a source is suspended and resumed (see the module docstring).

    window: number of recent gate outcomes judged. min_samples: outcomes needed before a source
    is suspended, and the span judged for its resumption. suspend_share, resume_share: shares of
    failed outcomes (0 to 1). min_span_s: time (s) over which fewer outcomes suffice to suspend
    a slow source (at least :data:`MIN_OUTCOMES_OVER_SPAN`).
    """

    window: int = 200
    min_samples: int = 100
    suspend_share: float = 0.5
    resume_share: float = 0.05
    min_span_s: float = 60.0

    def __post_init__(self) -> None:
        if not 1 <= self.min_samples <= self.window:
            raise ValueError(
                f"source health: min_samples must be 1 to window ({self.window}), "
                f"got {self.min_samples}"
            )
        if not 0.0 <= self.resume_share < self.suspend_share <= 1.0:
            raise ValueError(
                "source health: shares must satisfy 0 <= resume_share < suspend_share <= 1, "
                f"got {self.resume_share} and {self.suspend_share}"
            )


class SourceHealth:
    """The recent gate outcomes of one aiding source and whether it is suspended."""

    def __init__(self, rule: SourceHealthRule):
        self.rule = rule
        self._failed = deque(maxlen=rule.window)
        self._failed_count = 0  # of the outcomes in _failed, kept with them
        self._stamps_s = deque(maxlen=rule.window)
        self._gate_suspended = False
        self._gate_reason = ""
        self._contradiction = ""
        self.suspensions = 0
        """How often the source was suspended so far."""

    @property
    def suspended(self) -> bool:
        """Whether the source is suspended, by its gate outcomes or by a contradiction."""
        return self._gate_suspended or bool(self._contradiction)

    @property
    def contradicted(self) -> bool:
        """Whether a contradiction suspends the source (:meth:`contradict`)."""
        return bool(self._contradiction)

    @property
    def reason(self) -> str:
        """Why the source is suspended (empty while it is not), e.g. ``62 % of the last 200
        samples failed the gate``; a contradiction first."""
        return self._contradiction or (self._gate_reason if self._gate_suspended else "")

    @property
    def unmoved_by_passes(self) -> bool:
        """Whether outcomes that pass the gate can neither suspend nor resume the source: it
        is not suspended, and either none of its outcomes failed or it holds ``min_samples``
        (a pass then only lowers the share failed)."""
        return not self.suspended and (
            self._failed_count == 0 or len(self._failed) >= self.rule.min_samples
        )

    def outcomes_that_cannot_resume(self) -> int:
        """How many more outcomes of a source suspended by its outcomes cannot resume it,
        whatever they are: those before the first after which, had they all passed, no more
        than ``resume_share`` of the last ``min_samples`` would have failed."""
        rule = self.rule
        older = list(self._failed)
        failures_since = [0]  # failures among the last k kept outcomes, k = 0, 1, ...
        for failed in reversed(older):
            failures_since.append(failures_since[-1] + failed)
        for outcomes in range(1, rule.min_samples):
            if len(older) + outcomes < rule.min_samples:
                continue
            kept = min(rule.min_samples - outcomes, len(older))
            if failures_since[kept] / rule.min_samples <= rule.resume_share:
                return outcomes - 1
        return rule.min_samples - 1

    def record(self, failed_gate: bool, t_s: float = math.nan) -> HealthChange:
        """Add one gate outcome (True: the measurement failed the gate) of the measurement of
        stamp ``t_s`` (s; NaN: judged by the count of outcomes alone) and return what it
        changed."""
        was_suspended = self.suspended
        failed = bool(failed_gate)
        if len(self._failed) == self._failed.maxlen:
            self._failed_count -= self._failed[0]
        self._failed.append(failed)
        self._failed_count += failed
        self._stamps_s.append(t_s)
        if self._gate_suspended:
            self._maybe_resume()
        else:
            self._maybe_suspend()
        return self._change_since(was_suspended)

    def record_passes(self, stamps_s: Sequence[float]) -> None:
        """Add outcomes that passed the gate, of the measurements stamped ``stamps_s`` (s, in
        order), as :meth:`record` adds each, to a source they cannot move
        (:attr:`unmoved_by_passes`: each would return :attr:`HealthChange.NONE`)."""
        if not self.unmoved_by_passes:
            raise ValueError("source health: passes recorded at once where one could move it")
        kept = len(self._failed)
        dropped = min(kept, max(0, kept + len(stamps_s) - self.rule.window))
        self._failed_count -= sum(itertools.islice(self._failed, dropped))
        self._failed.extend(itertools.repeat(False, len(stamps_s)))
        self._stamps_s.extend(stamps_s)

    def contradict(self, reason: str) -> HealthChange:
        """Suspend the source for ``reason``, whatever its gate outcomes, until
        :meth:`no_longer_contradicted`."""
        was_suspended = self.suspended
        self._contradiction = reason
        return self._change_since(was_suspended)

    def no_longer_contradicted(self) -> HealthChange:
        """The evidence behind :meth:`contradict` is gone; its gate outcomes judge it again."""
        was_suspended = self.suspended
        self._contradiction = ""
        return self._change_since(was_suspended)

    def failed_share(self, last: int | None = None) -> float:
        """Share of the last ``last`` outcomes (all kept ones when None) that failed the gate;
        NaN before any outcome."""
        if not last or last >= len(self._failed):
            # All kept: the running count, which equals their sum.
            if not self._failed:
                return float("nan")
            return self._failed_count / len(self._failed)
        outcomes = list(self._failed)[-last:]
        return sum(outcomes) / len(outcomes)

    def forget(self) -> None:
        """Drop the outcomes and resume (a new alignment starts the judgement again); a
        contradiction stays, since it was not judged against the filter."""
        self._clear()
        self._gate_suspended = False
        self._gate_reason = ""

    def _change_since(self, was_suspended: bool) -> HealthChange:
        if self.suspended == was_suspended:
            return HealthChange.NONE
        if self.suspended:
            self.suspensions += 1
            return HealthChange.SUSPENDED
        return HealthChange.RESUMED

    def _clear(self) -> None:
        self._failed.clear()
        self._failed_count = 0
        self._stamps_s.clear()

    def _enough_to_suspend(self) -> bool:
        """``min_samples`` outcomes, or (a slow source) ``min_span_s`` of them."""
        count = len(self._failed)
        if count >= self.rule.min_samples:
            return True
        if count < MIN_OUTCOMES_OVER_SPAN:
            return False
        return self._stamps_s[-1] - self._stamps_s[0] >= self.rule.min_span_s

    def _maybe_suspend(self) -> None:
        if not self._enough_to_suspend():
            return
        share = self.failed_share()
        if share < self.rule.suspend_share:
            return
        self._gate_suspended = True
        self._gate_reason = (
            f"{share * 100:.0f} % of the last {len(self._failed)} samples failed the gate"
        )
        # Resumption is judged on outcomes seen while suspended only.
        self._clear()

    def _maybe_resume(self) -> None:
        if len(self._failed) < self.rule.min_samples:
            return
        if self.failed_share(self.rule.min_samples) > self.rule.resume_share:
            return
        self._gate_suspended = False
        self._gate_reason = ""
        self._clear()
