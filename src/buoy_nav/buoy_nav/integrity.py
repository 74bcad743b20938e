"""Integrity of the fusion: does the filter still agree with its aiding?

A filter that has lost its way (an attitude error far beyond its covariance, after an input
fault the screening did not catch) rejects every aiding measurement at the gate: to it, the
sensors are wrong. At gate probability 0.9999 a consistent filter rejects a measurement once in
10,000, so ``integrity_rejection_count`` consecutive rejections of one source (3 by default:
a chance of 10⁻¹² on consistent data) mean the filter, not the sensor, is wrong. The monitor then
declares the navigation **not trusted** and the engine

1. inflates the attitude and velocity covariance by ``integrity_attitude_sigma_deg`` and
   ``integrity_velocity_sigma_mps``: the published covariance tells the truth (the wind
   compensation refuses navigation whose attitude 1σ exceeds its ``max_attitude_sigma_deg``),
   and the gate can accept the aiding again, which pulls a modest error back;
2. if the gate still rejects after ``integrity_realign_s``, starts the alignment again from the
   aiding (levelling from specific force, heading from the antennas, position and velocity from
   GNSS): no solution is emitted until it completes, and the new filter starts from the
   alignment's covariance. A velocity source whose failures started the distrust (or the
   episode of distrust that keeps coming back, :meth:`IntegrityMonitor.episode`) while the
   fixes agreed with the filter is first set against the fixes directly
   (:mod:`buoy_nav.contradictions`): when they contradict it, it is the source that is wrong,
   and it is suspended and left out of the new alignment instead of being adopted by it, so
   that one bad source cannot drive the filter from one realignment to the next.

Trust returns once no measurement has failed the gate for ``integrity_recovery_s``, or with a
new alignment. Each period of distrust is kept as an :class:`IntegrityEvent` (when, why, how it
ended) for the diagnostics and the offline summary.
"""

import math
from dataclasses import dataclass

import numpy as np


@dataclass
class IntegrityEvent:
    """One period in which the navigation was not trusted.

    start_s, end_s: stamps (s) of its start and end (NaN while it lasts). reason: what
    started it (``gate_rejections:<source kind>``). realigned: it ended with a new alignment.
    kinds: the sources whose rejections started it.
    """

    start_s: float
    reason: str
    end_s: float = math.nan
    realigned: bool = False
    kinds: tuple[str, ...] = ()

    @property
    def duration_s(self) -> float:
        """Length (s; NaN while it lasts)."""
        return self.end_s - self.start_s


def distrust_variances(config) -> tuple[float, float]:
    """(attitude rad², velocity m²/s²) added per axis to the covariance while the navigation
    is not trusted, from ``integrity_attitude_sigma_deg`` and ``integrity_velocity_sigma_mps`` of
    a :class:`~buoy_nav.config.FusionConfig`."""
    return (
        math.radians(config.integrity_attitude_sigma_deg) ** 2,
        config.integrity_velocity_sigma_mps**2,
    )


def distrusted_at(t_s, events: list[IntegrityEvent]):
    """Which stamps ``t_s`` (s, an array) fall in one of the periods of distrust ``events``."""
    t_s = np.asarray(t_s, dtype=float)
    inside = np.zeros(t_s.shape, dtype=bool)
    for event in events:
        end_s = math.inf if math.isnan(event.end_s) else event.end_s
        inside |= (t_s >= event.start_s) & (t_s < end_s)
    return inside


class IntegrityMonitor:
    """Trust in the fusion, from the outcome of its innovation gates (see the module docstring).

    rejection_count: consecutive gate rejections of one source that end the trust.
    realign_after_s: distrust for this long with rejections going on asks for a realignment (s).
    recovery_s: trust returns after this long without a gate rejection (s).
    """

    def __init__(self, rejection_count: int, realign_after_s: float, recovery_s: float):
        self._rejection_count = rejection_count
        self._realign_after_s = realign_after_s
        self._recovery_s = recovery_s
        self.events: list[IntegrityEvent] = []
        self._last_rejection_s = -math.inf

    @property
    def trusted(self) -> bool:
        """False while an :class:`IntegrityEvent` lasts."""
        return not self.events or not math.isnan(self.events[-1].end_s)

    def gate_outcomes(self, t_s: float, rejected_kinds: dict[str, int]) -> str | None:
        """The gate outcomes of the measurements of stamp ``t_s`` (s): ``rejected_kinds`` maps
        each source rejected there to its consecutive rejections. Returns the action the
        engine must take: ``"inflate"`` (trust just lost), ``"realign"`` or None."""
        if rejected_kinds:
            self._last_rejection_s = t_s
        if self.trusted:
            persistent = sorted(
                kind for kind, count in rejected_kinds.items() if count >= self._rejection_count
            )
            if not persistent:
                return None
            self.events.append(
                IntegrityEvent(
                    t_s, f"gate_rejections:{'+'.join(persistent)}", kinds=tuple(persistent)
                )
            )
            return "inflate"
        event = self.events[-1]
        if t_s - self._last_rejection_s >= self._recovery_s:
            event.end_s = t_s
            return None
        if rejected_kinds and t_s - event.start_s >= self._realign_after_s:
            return "realign"
        return None

    def episode(self, gap_s: float) -> list[IntegrityEvent]:
        """The current period of distrust and those before it that each ended at most
        ``gap_s`` (s) before the next began, oldest first: distrust that keeps coming back,
        as when one bad source drives the filter from one realignment to the next."""
        episode = [self.events[-1]]
        for event in reversed(self.events[:-1]):
            if episode[0].start_s - event.end_s > gap_s:
                break
            episode.insert(0, event)
        return episode

    def realigned(self, t_s: float) -> None:
        """A new alignment completed at ``t_s`` (s): it ends the distrust."""
        if not self.trusted:
            event = self.events[-1]
            event.end_s = t_s
            event.realigned = True
        self._last_rejection_s = -math.inf
