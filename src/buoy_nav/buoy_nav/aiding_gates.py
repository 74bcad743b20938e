"""The innovation gate of each aiding measurement, and the books kept of its outcomes.

Each measurement of a stamp is gated on its own against the predicted covariance (the
chi-square test at its source's ``gate_probability``). What the gate decides is counted by source
and reason, logged (``record_innovations``), kept as the stamp each source and aided quantity was
last accepted (:class:`~buoy_nav.sensor_sets.AidingRecency`, for the sensor set and the coasting
flags) and as each source's run of consecutive rejections: the run that asks the source for a
reset, and that the integrity monitor (:mod:`buoy_nav.integrity`) judges the filter by.

Every outcome also goes to the source's :class:`~buoy_nav.source_health.SourceHealth`: a
source that keeps failing is suspended. Its measurements are still modelled and gated, so its
agreement stays watched, but they are not fused (counted as ``suspended``), do not reset states
and do not witness the integrity: a sensor that is wrong is taken out, not followed, and does
not make the filter realign to it. Evidence from outside the gate
(:mod:`buoy_nav.contradictions`) suspends a source through :meth:`AidingGates.judged`.
"""

import math
from typing import NamedTuple

from buoy_common.contract import Reason
from buoy_nav.aiding.base import AidingSource, LinearisationPoint, MeasurementModel, Verdict
from buoy_nav.error_state_filter import ErrorStateFilter, GateResult
from buoy_nav.health import InnovationRecord, MeasurementCounters
from buoy_nav.sensor_sets import AidingRecency
from buoy_nav.source_health import (
    HealthChange,
    HealthTransition,
    SourceHealth,
    SourceHealthRule,
    SourceStatus,
)


class GateOutcome(NamedTuple):
    """What the gates made of the measurements of one stamp.

    accepted: the models of the accepted measurements, in the order of the group.
    persistent_rejections: (source, measurement, model) of each rejected measurement whose
      source has now been rejected ``reset_after_rejections`` times in a row.
    rejected_kinds: each source rejected there that witnesses the integrity, with its run of
      consecutive rejections.
    transitions: the sources suspended or resumed by these outcomes.
    """

    accepted: list[MeasurementModel]
    persistent_rejections: list[tuple[AidingSource, object, MeasurementModel]]
    rejected_kinds: dict[str, int]
    transitions: list[HealthTransition]


class AidingGates:
    """Gates measurements and keeps their books: ``counters`` (by kind), ``recency`` (quantities
    indexed by ``aided_index`` of each source), each source's health judged by
    ``health_rule`` and, unless None, ``innovation_log``."""

    def __init__(
        self,
        counters: dict[str, MeasurementCounters],
        recency: AidingRecency,
        aided_index: dict[AidingSource, int],
        innovation_log: list[InnovationRecord] | None,
        health_rule: SourceHealthRule,
    ):
        self._counters = counters
        self._recency = recency
        self._aided_index = aided_index
        self._innovation_log = innovation_log
        self._consecutive_rejections = dict.fromkeys((source.kind for source in aided_index), 0)
        self._run_start_s = dict.fromkeys((source.kind for source in aided_index), math.nan)
        self._health = {source.kind: SourceHealth(health_rule) for source in aided_index}
        self._warnings = dict.fromkeys((source.kind for source in aided_index), "")

    def suspended(self, kind: str) -> bool:
        """Whether the source of ``kind`` is suspended."""
        return self._health[kind].suspended

    def unmoved_by_passes(self, kind: str) -> bool:
        """Whether measurements of ``kind`` that pass the gate leave its health as it is
        (:attr:`SourceHealth.unmoved_by_passes`)."""
        return self._health[kind].unmoved_by_passes

    def run_start_s(self, kind: str) -> float:
        """Stamp (s) of the first of the current run of gate rejections of ``kind``."""
        return self._run_start_s[kind]

    def judged(self, source: AidingSource, t_s: float, verdict: Verdict) -> list[HealthTransition]:
        """Suspend ``source`` at stamp ``t_s`` (s) while ``verdict`` contradicts its
        assumption, and lift that when it no longer does. The transition, if any."""
        health = self._health[source.kind]
        if verdict.contradicted:
            change = health.contradict(verdict.reason)
        else:
            change = health.no_longer_contradicted()
        if change is HealthChange.NONE:
            return []
        self._consecutive_rejections[source.kind] = 0
        message = f"{source.kind} {change.value}: {verdict.reason}"
        if change is HealthChange.SUSPENDED:
            message += f"; {source.suspension_hint}"
        return [HealthTransition(t_s, source.kind, change, message)]

    def contradicted(self, kind: str) -> bool:
        """Whether a contradiction suspends the source of ``kind`` (:meth:`judged`)."""
        return self._health[kind].contradicted

    def status(self) -> dict[str, SourceStatus]:
        """The health of each source, by kind."""
        return {
            kind: SourceStatus(
                health.suspended, health.reason, health.suspensions, self._warnings[kind]
            )
            for kind, health in self._health.items()
        }

    def gate(
        self,
        t_s: float,
        group: list[tuple[AidingSource, object]],
        point: LinearisationPoint,
        kalman: ErrorStateFilter,
    ) -> GateOutcome:
        """Gate each (source, measurement) pair of stamp ``t_s`` (s) linearised at ``point``
        against the covariance of ``kalman``, and book the outcomes."""
        outcome = GateOutcome([], [], {}, [])
        for source, measurement in group:
            model = source.model(measurement, point)
            if model is None or isinstance(model, Reason):
                self._book_unmodelled(source, t_s, model, outcome)
                continue
            gate = kalman.gate(
                model.innovation, model.jacobian, model.gated_covariance, source.gate_probability
            )
            if self._book_gated(source, t_s, measurement, model, model.innovation, gate, outcome):
                outcome.accepted.append(model)
        return outcome

    def watched(
        self,
        source: AidingSource,
        t_s: float,
        refusal: Reason | None,
        innovation=None,
        gate: GateResult | None = None,
    ) -> GateOutcome:
        """Book a measurement of the suspended ``source`` at stamp ``t_s`` (s) modelled and
        gated elsewhere (a compiled stretch) as :meth:`gate` books it: its ``innovation`` and
        ``gate``, or, without a model, the ``refusal`` (None: for want of geometry). Nothing of
        it is fused: its outcome must leave the source suspended."""
        if not self.suspended(source.kind):
            raise RuntimeError(f"{source.kind}: a measurement watched of a source not suspended")
        outcome = GateOutcome([], [], {}, [])
        if gate is None:
            self._book_unmodelled(source, t_s, refusal, outcome)
        elif self._book_gated(source, t_s, None, None, innovation, gate, outcome):
            raise RuntimeError(f"{source.kind}: a watched measurement resumed its source")
        return outcome

    def outcomes_while_suspended(self, kind: str) -> int:
        """How many more gate outcomes of the source of ``kind``, suspended by its gate
        outcomes and not by a contradiction, cannot resume it whatever they are (0: not such a
        source)."""
        if self.contradicted(kind) or not self.suspended(kind):
            return 0
        return self._health[kind].outcomes_that_cannot_resume()

    def _book_unmodelled(
        self, source: AidingSource, t_s: float, refusal: Reason | None, outcome: GateOutcome
    ) -> None:
        """Book a measurement of ``source`` at ``t_s`` (s) that has no model: for want of
        geometry (``refusal`` None), or refused for ``refusal``, a failed outcome."""
        if refusal is None:
            self._counters[source.kind].reject(Reason.GEOMETRY)
            return
        self._counters[source.kind].reject(refusal)
        self._judge(source, t_s, True, outcome)

    def _book_gated(
        self,
        source: AidingSource,
        t_s: float,
        measurement,
        model: MeasurementModel | None,
        innovation,
        gate: GateResult,
        outcome: GateOutcome,
    ) -> bool:
        """Book the ``gate`` of the ``measurement`` of ``source`` at ``t_s`` (s), its
        ``model`` and ``innovation``: whether it is to be fused (a source whose failure leaves
        it suspended needs neither the measurement nor the model)."""
        if gate.accepted:
            return self._book_passed(source, t_s, innovation, gate, outcome)
        self._log_innovation(source, t_s, innovation, gate)
        self._watch_innovations(source, t_s, innovation, gate, outcome)
        if self._judge(source, t_s, True, outcome):
            self._counters[source.kind].reject(Reason.SUSPENDED)
        else:
            self._book_rejection(source, t_s, measurement, model, gate.nis, outcome)
        return False

    def passed(
        self, source: AidingSource, t_s: float, innovation, gate: GateResult
    ) -> tuple[bool, GateOutcome]:
        """Book a measurement of ``source`` at stamp ``t_s`` (s) that passed its ``gate``
        elsewhere (a source's compiled update) as :meth:`gate` books it: whether it is to be
        fused (False: the source is suspended), and the outcome."""
        outcome = GateOutcome([], [], {}, [])
        return self._book_passed(source, t_s, innovation, gate, outcome), outcome

    def books_passes_at_once(self, source: AidingSource) -> bool:
        """Whether the passes of ``source`` may be booked at once (:meth:`passed_at_once`):
        they move nothing of it but its books, whatever comes between (its health cannot move,
        no innovation is logged and the source watches none)."""
        return (
            self._innovation_log is None
            and not source.watches_innovations
            and self._health[source.kind].unmoved_by_passes
        )

    def passed_at_once(self, source: AidingSource, stamps_s: list[float], nis: list[float]) -> None:
        """Book measurements of ``source`` stamped ``stamps_s`` (s, in order) that passed their
        gates elsewhere (a compiled stretch) with normalised innovation squares ``nis``, as
        :meth:`passed` books each, for a source that :meth:`books_passes_at_once`."""
        if not self.books_passes_at_once(source):
            raise RuntimeError(f"{source.kind}: passes booked at once that could move it")
        kind = source.kind
        self._health[kind].record_passes(stamps_s)
        counters = self._counters[kind]
        counters.accepted += len(nis)
        # Summed in the order and the precision of one at a time: the same mean NIS to the bit.
        nis_sum = counters.nis_sum
        for value in nis:
            nis_sum += value
        counters.nis_sum = nis_sum
        counters.nis_count += len(nis)
        self._recency.accepted(kind, self._aided_index[source], stamps_s[-1])
        self._consecutive_rejections[kind] = 0

    def _book_passed(
        self, source: AidingSource, t_s: float, innovation, gate: GateResult, outcome: GateOutcome
    ) -> bool:
        self._log_innovation(source, t_s, innovation, gate)
        self._watch_innovations(source, t_s, innovation, gate, outcome)
        if self._judge(source, t_s, False, outcome):
            self._counters[source.kind].reject(Reason.SUSPENDED)
            return False
        self._book_acceptance(source, t_s, gate.nis)
        return True

    def _log_innovation(self, source: AidingSource, t_s: float, innovation, gate) -> None:
        if self._innovation_log is not None:
            self._innovation_log.append(
                InnovationRecord(
                    t_s,
                    source.kind,
                    innovation,
                    gate.innovation_covariance,
                    gate.nis,
                    gate.accepted,
                )
            )

    def _watch_innovations(
        self, source: AidingSource, t_s: float, innovation, gate, outcome: GateOutcome
    ) -> None:
        """Keep the source's innovation warning (:meth:`AidingSource.innovation_warning`) and
        report a new one as a transition; it never changes what is fused."""
        if not math.isfinite(gate.nis):
            return
        warning = source.innovation_warning(t_s, innovation, gate.innovation_covariance)
        if warning is None:
            return
        self._warnings[source.kind] = warning
        if warning:
            outcome.transitions.append(
                HealthTransition(t_s, source.kind, HealthChange.WARNED, warning)
            )

    def _judge(self, source: AidingSource, t_s: float, failed: bool, outcome: GateOutcome) -> bool:
        """Record one outcome of ``source`` at stamp ``t_s`` (s) in its health; returns whether
        the source is suspended now."""
        health = self._health[source.kind]
        change = health.record(failed, t_s)
        if change is HealthChange.SUSPENDED:
            # Its run of rejections is over: a suspended source asks for no reset.
            self._consecutive_rejections[source.kind] = 0
            message = f"{source.kind} suspended: {health.reason}; {source.suspension_hint}"
            outcome.transitions.append(HealthTransition(t_s, source.kind, change, message))
        elif change is HealthChange.RESUMED:
            message = (
                f"{source.kind} resumed: no more than "
                f"{health.rule.resume_share * 100:.0f} % of its last "
                f"{health.rule.min_samples} samples failed the gate"
            )
            outcome.transitions.append(HealthTransition(t_s, source.kind, change, message))
        return health.suspended

    def _book_acceptance(self, source: AidingSource, t_s: float, nis: float) -> None:
        counters = self._counters[source.kind]
        counters.accepted += 1
        counters.nis_sum += nis
        counters.nis_count += 1
        self._recency.accepted(source.kind, self._aided_index[source], t_s)
        self._consecutive_rejections[source.kind] = 0

    def _book_rejection(
        self,
        source: AidingSource,
        t_s: float,
        measurement,
        model: MeasurementModel,
        nis: float,
        outcome: GateOutcome,
    ) -> None:
        kind = source.kind
        self._counters[kind].reject(Reason.GATE if math.isfinite(nis) else Reason.SINGULAR)
        self._consecutive_rejections[kind] += 1
        run = self._consecutive_rejections[kind]
        if run == 1:
            self._run_start_s[kind] = t_s
        if source.witnesses_integrity:
            outcome.rejected_kinds[kind] = run
        if run >= source.reset_after_rejections:
            outcome.persistent_rejections.append((source, measurement, model))

    def source_reset(self, source: AidingSource, t_s: float) -> None:
        """The states ``source`` observes were reset from its measurement at ``t_s`` (s)."""
        self._counters[source.kind].resets += 1
        self._consecutive_rejections[source.kind] = 0
        self._recency.aided(self._aided_index[source], t_s)

    def aligned(self, t_s: float, forget_health: bool = True) -> None:
        """A new alignment completed at ``t_s`` (s): every run of rejections ends and, with
        ``forget_health``, the sources' health is judged afresh."""
        for kind in self._consecutive_rejections:
            self._consecutive_rejections[kind] = 0
        if forget_health:
            for health in self._health.values():
                health.forget()
        self._recency.aligned(t_s)
