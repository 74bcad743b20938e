"""What the fusion engine reports about itself: counters per input, innovations, health."""

import math
from dataclasses import dataclass, field

import numpy as np

from buoy_nav.alignment import AlignmentResult, AlignmentState
from buoy_nav.integrity import IntegrityEvent
from buoy_nav.source_health import SourceStatus

IMU = "imu"
"""Counter name of the IMU samples (the aiding sources count under their ``kind``)."""


@dataclass(frozen=True)
class InnovationRecord:
    """One gated measurement (kept when ``record_innovations`` is on).

    t_s: stamp. kind: the aiding source's kind. innovation: measured − predicted.
    innovation_covariance: S = H P H^T + R. nis: ν^T S^{-1} ν. accepted: passed the gate.
    """

    t_s: float
    kind: str
    innovation: np.ndarray
    innovation_covariance: np.ndarray
    nis: float
    accepted: bool


@dataclass
class MeasurementCounters:
    """Counters of one input (the IMU or an aiding source).

    accepted: samples used (IMU) or filter updates applied (aiding sources).
    used_for_alignment: measurements consumed by the alignment.
    superseded: measurements not fused because one of another source with the same stamp
    carries their information and more (a heading with the stamp of a baseline).
    rejected: rejections by reason. resets: state resets after the source's number of
    consecutive gate rejections. nis_sum, nis_count: over accepted updates (mean_nis).
    """

    accepted: int = 0
    used_for_alignment: int = 0
    superseded: int = 0
    rejected: dict[str, int] = field(default_factory=dict)
    resets: int = 0
    nis_sum: float = 0.0
    nis_count: int = 0

    @property
    def mean_nis(self) -> float:
        """Running mean of the NIS of accepted updates (NaN before the first)."""
        return self.nis_sum / self.nis_count if self.nis_count else math.nan

    def reject(self, reason: str):
        reason = str(reason)
        self.rejected[reason] = self.rejected.get(reason, 0) + 1

    def snapshot(self) -> "MeasurementCounters":
        """An independent copy."""
        return MeasurementCounters(
            self.accepted,
            self.used_for_alignment,
            self.superseded,
            dict(self.rejected),
            self.resets,
            self.nis_sum,
            self.nis_count,
        )


@dataclass(frozen=True)
class EngineHealth:
    """Snapshot of the engine's health.

    alignment_state: progress of the alignment. aligned: the filter runs.
    coasting_fix, coasting_velocity, coasting_heading: see :class:`buoy_nav.solution.NavSolution`.
    counters: per input: ``imu``, then each aiding source's kind in the order of the registry
      (``gnss_fix``, ``gnss_velocity``, ``gnss_baseline``, ``gnss_heading``).
    covariance_repairs: times P had to be made positive definite again.
    imu_gaps: IMU gaps longer than ``max_imu_gap_s``. alignments: completed alignments.
    time_s: stamp up to which data was processed (NaN before any).
    alignment: the last alignment result (None before the first).
    imu_clock_steps: steps of the IMU's clock relative to the aiding sources, as (stamp of the
      first sample after the step on the aiding sources' clock, s; step, s, negative when the
      IMU clock went back); the IMU samples are re-stamped by the sum of the steps.
    trusted: the filter agrees with its aiding (see :mod:`buoy_nav.integrity`).
    integrity_events: the periods in which it did not, oldest first.
    realignments: alignments started again because the filter stayed inconsistent.
    sensor_set: the sensor set in use (:meth:`buoy_nav.sensor_sets.SensorSets.label`).
    coasting_sources: kinds of the aiding sources accepted before but not within
      ``coasting_timeout_s`` (their quantities are carried by the inertial solution).
    source_health: per aiding source's kind, whether it is suspended, why, and how often it
      was (:mod:`buoy_nav.source_health`).
    """

    alignment_state: AlignmentState
    aligned: bool
    coasting_fix: bool
    coasting_velocity: bool
    coasting_heading: bool
    counters: dict[str, MeasurementCounters]
    covariance_repairs: int
    imu_gaps: int
    alignments: int
    time_s: float
    alignment: AlignmentResult | None
    imu_clock_steps: tuple[tuple[float, float], ...] = ()
    trusted: bool = True
    integrity_events: tuple[IntegrityEvent, ...] = ()
    realignments: int = 0
    sensor_set: str = ""
    coasting_sources: tuple[str, ...] = ()
    source_health: dict[str, SourceStatus] = field(default_factory=dict)


def diagnostic_values(health: EngineHealth) -> dict:
    """The diagnostics' key-value pairs of ``health``: alignment and coasting, the counters of
    each input, the filter's repairs and alignments, its integrity and the IMU clock's steps."""
    values = {
        "alignment_state": health.alignment_state.value,
        "aligned": health.aligned,
        "coasting_fix": health.coasting_fix,
        "coasting_velocity": health.coasting_velocity,
        "coasting_heading": health.coasting_heading,
        "sensor_set": health.sensor_set,
        "coasting_sources": ",".join(health.coasting_sources),
    }
    for kind, counters in health.counters.items():
        values[f"{kind}.accepted"] = counters.accepted
        for reason, count in sorted(counters.rejected.items()):
            values[f"{kind}.rejected[{reason}]"] = count
        if kind != IMU:  # alignment use, resets and NIS are of measurements only
            values[f"{kind}.used_for_alignment"] = counters.used_for_alignment
            values[f"{kind}.superseded"] = counters.superseded
            values[f"{kind}.resets"] = counters.resets
            values[f"{kind}.mean_nis"] = counters.mean_nis
            status = health.source_health.get(kind)
            if status is not None:
                values[f"{kind}.suspended"] = status.suspended
                values[f"{kind}.suspension_reason"] = status.reason
                values[f"{kind}.suspensions"] = status.suspensions
                values[f"{kind}.warning"] = status.warning
    values.update(
        {
            "covariance_repairs": health.covariance_repairs,
            "imu_gaps": health.imu_gaps,
            "alignments": health.alignments,
            "navigation_trusted": health.trusted,
            "integrity_events": len(health.integrity_events),
            "realignments": health.realignments,
            "untrusted_s": sum(
                (event.end_s if math.isfinite(event.end_s) else health.time_s) - event.start_s
                for event in health.integrity_events
            ),
            "imu_clock_steps": len(health.imu_clock_steps),
            "imu_clock_correction_s": -sum(step for _, step in health.imu_clock_steps),
            # Full precision: a stamp in seconds since the epoch.
            "processed_up_to_s": f"{health.time_s:.6f}",
        }
    )
    return values


def health_status(
    health: EngineHealth, imu_topic: str, imu_samples_since_report: int, solutions_published: int
) -> tuple[str, str]:
    """The diagnostics' level (``ok`` or ``warn``) and message: no IMU samples on ``imu_topic``
    since the last report, aligning, not trusted, a source suspended, coasting, or the solutions
    published."""
    if imu_samples_since_report == 0:
        return "warn", f"no {imu_topic} samples"
    if not health.aligned:
        return "warn", f"aligning ({health.alignment_state.value})"
    coasting = [
        kind
        for kind, flag in (
            ("fix", health.coasting_fix),
            ("velocity", health.coasting_velocity),
            ("heading", health.coasting_heading),
        )
        if flag
    ]
    if not health.trusted:
        reason = health.integrity_events[-1].reason
        return "warn", f"aligned, navigation not trusted ({reason})"
    suspended = [kind for kind, status in health.source_health.items() if status.suspended]
    if suspended:
        return "warn", f"aligned on {health.sensor_set}, suspended: {', '.join(suspended)}"
    if coasting:
        return (
            "warn",
            f"aligned on {health.sensor_set}, coasting without GNSS {', '.join(coasting)}",
        )
    return "ok", f"aligned on {health.sensor_set}, {solutions_published} solutions published"
