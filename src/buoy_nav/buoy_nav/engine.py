"""Fusion engine: the one entry point of the navigation core for live nodes and offline tools.

The engine is the clock of the fusion. It buffers IMU samples and the measurements of the
aiding sources (:mod:`buoy_nav.aiding`: GNSS position, velocity, dual-antenna heading and
baseline vector, each a module that owns its conversion, validation, model, gate, reset and
role in the alignment) and processes them strictly in stamp order,
``max_measurement_delay_s`` behind the newest IMU stamp, so measurements that arrive out of
order within that delay give exactly the result of in-order arrival. A measurement whose stamp
falls between two IMU samples is applied at its own stamp: the state is integrated to it with
IMU samples interpolated there (:mod:`buoy_nav.processing_point`), updated, and integrated on to
the next sample. Measurements sharing a stamp are gated one by one and the accepted ones applied in
one stacked update, in the order of the registry (:data:`buoy_nav.aiding.AIDING_SOURCES`). When
their sources' models are compiled (``has_compiled_model``), the gates and the update are one
compiled call with the same arithmetic, and the interpreted way takes over for a stamp with a
rejection; a stamp of the motion pack's attitude alone goes through its compiled update.

A source may be superseded by another (``superseded_by``): the dual antennas give either the
full baseline vector (which observes the baseline's azimuth and tilt) or only its azimuth. Both
come from the same carrier-phase solution, so fusing both of one epoch would count it twice: a
heading with the stamp of a baseline is set aside and counted as superseded; headings of epochs
without a baseline (a receiver that sends none, or sends them at a lower rate) are fused.

With ``realtime_output`` (the default) a solution leaves with its IMU sample, not
``max_measurement_delay_s`` later: :mod:`buoy_nav.prediction` integrates a copy of the filter's
nominal state ahead to the newest sample and carries each correction over to it. The solution
of a sample is predicted before the filter catches up with that sample's horizon
(:meth:`FusionEngine.catch_up`), so a node publishes it before the updates and covariance
propagation it triggers, and corrections reach the prediction one IMU sample later. Its
covariances are the filter's, from up to ``max_measurement_delay_s`` earlier.

An offline run hands the engine the IMU samples between two other sensor messages together,
with the motion pack's attitudes among them (:meth:`FusionEngine.add_inputs`): each stretch of
them with nothing else to do is taken in one compiled call (:mod:`buoy_nav.imu_stretch`), with
the same arithmetic in the same order as one input at a time, which a live node does.

Before alignment the IMU samples and the measurements feed :class:`InMotionAligner`; once
aligned, :class:`~buoy_nav.aided_navigation.AidedNavigation` carries the nominal state and
corrects it after every accepted measurement, its covariance propagated in batches of at most
``covariance_propagation_interval_s``: the covariances in a :class:`NavSolution` are at most
that interval old. The engine's parts: :mod:`buoy_nav.source_registry` (the sources),
:mod:`buoy_nav.measurement_queue` (their measurements in stamp order),
:mod:`buoy_nav.aiding_gates` (the gate of each and its books), :mod:`buoy_nav.integrity`,
:mod:`buoy_nav.sensor_sets` (what is in use), :mod:`buoy_nav.solution` and
:mod:`buoy_nav.prediction` (the solutions).

Invalid input (non-finite values, absurd magnitudes, non-positive variances, IMU stamps not
increasing, duplicated measurement stamps, measurements older than what was already processed)
is rejected and counted by input and reason; it never reaches the state. Measurements more than
``MAX_MEASUREMENT_LEAD_S`` ahead of the newest IMU sample (an IMU outage) are given up as
``beyond_imu_data``, oldest first, so an outage cannot fill the memory. An IMU sample whose
change from the last accepted one no platform can make is rejected as ``implausible_change``
(:mod:`buoy_nav.imu_screening`); a step of the IMU's clock is undone by re-stamping
(:mod:`buoy_nav.imu_clock`); a sample out of the accepted sequence (a second IMU stream on the
topic) never moves the filter's time (:mod:`buoy_nav.stream_sequence`, ``out_of_sequence``);
:mod:`buoy_nav.imu_input` holds that screening of the IMU samples. An aiding measurement ahead
of its source's sequence (a second receiver on the topic, or one that came early) waits in the
queue, moving nothing, and is judged when its turn comes (:mod:`buoy_nav.measurement_queue`).
When the gates keep
rejecting the aiding, the filter no longer agrees with it: the integrity monitor
(:mod:`buoy_nav.integrity`) has the covariance inflated, published inflated while the trust is
not back, and the alignment started again if that does not bring the aiding back into the gates.
When one source keeps failing its gate while the others agree, the source is wrong, not the
filter: it is suspended
(:mod:`buoy_nav.source_health`), its measurements gated but not fused, until it agrees again.
What the GNSS receiver measured of the buoy's motion is also set against the sources directly,
without the filter (:mod:`buoy_nav.contradictions`): a velocity that the fixes contradict is
suspended rather than adopted by a realignment or a reset, and a constraint whose assumption
the measurements disprove (a mooring on a buoy that drifts) is suspended while they do.
"""

import dataclasses
import math
from collections import deque
from collections.abc import Iterable

import numpy as np

from buoy_common.contract import Reason
from buoy_nav import earth
from buoy_nav.aided_navigation import AidedNavigation
from buoy_nav.aiding import AIDING_SOURCES
from buoy_nav.aiding.base import (
    AIDED_QUANTITIES,
    FIX,
    POSITION_REFERENCE,
    VELOCITY_REFERENCE,
    AidingSource,
    MeasurementModel,
    as_floats,
)
from buoy_nav.aiding.model_kernels import load_compiled_model_kernels
from buoy_nav.aiding_gates import AidingGates
from buoy_nav.alignment import AlignmentResult, AlignmentState, InMotionAligner
from buoy_nav.config import FusionConfig
from buoy_nav.contradictions import VELOCITY_CHECK_SPAN_S, Contradictions
from buoy_nav.epoch_recorder import EpochRecorder
from buoy_nav.error_state_filter import ERROR_STATES, ImuErrorModel, NavState
from buoy_nav.health import IMU, EngineHealth, InnovationRecord, MeasurementCounters
from buoy_nav.imu_input import ImuInput
from buoy_nav.imu_stretch import load_compiled_imu_stretch
from buoy_nav.imu_stretches import EngineParts, ImuStretches, MeasurementInput
from buoy_nav.integrity import IntegrityMonitor, distrust_variances
from buoy_nav.measurement_queue import MAX_MEASUREMENT_LEAD_S, MeasurementQueue
from buoy_nav.mechanization import StrapdownIntegrator, load_compiled_kernels
from buoy_nav.nav_numbers import load_compiled_nav_numbers
from buoy_nav.prediction import RealtimePrediction, load_compiled_carry_over
from buoy_nav.processing_point import ProcessingPoint
from buoy_nav.sensor_sets import AidingRecency, SensorSets
from buoy_nav.solution import (
    Emitted,
    NavSolution,
    OutputDecimation,
    SolutionBuilder,
)
from buoy_nav.solution_rows import SolutionRows, load_compiled_solution_rows
from buoy_nav.solution_vector import load_compiled_solution_vector
from buoy_nav.source_health import HealthTransition
from buoy_nav.source_registry import SourceRegistry
from buoy_nav.stream_sequence import StreamSequence

__all__ = ["IMU", "MAX_MEASUREMENT_LEAD_S", "EngineHealth", "FusionEngine", "NavSolution"]


class FusionEngine:
    """Strapdown INS aided by the sources of ``sources`` (see the module docstring).

    sources: the aiding-source classes to run, in the order measurements of one stamp are
    applied (default :data:`buoy_nav.aiding.AIDING_SOURCES`). solution_rows: where an offline
    run has the solutions written, a row each (:mod:`buoy_nav.solution_rows`); the methods that
    return solutions then return their stamps (s) (None: they return :class:`NavSolution`).
    """

    def __init__(
        self,
        config: FusionConfig,
        sources: Iterable[type[AidingSource]] = AIDING_SOURCES,
        solution_rows: SolutionRows | None = None,
    ):
        self.config = config
        self.states = ERROR_STATES
        """Names of the error states (rows and columns of :attr:`covariance`)."""
        self._registry = SourceRegistry(config, self.states, sources)
        # Here, not at the first IMU sample or measurement of a live stream.
        load_compiled_kernels(
            load_compiled_carry_over,
            load_compiled_nav_numbers,
            load_compiled_solution_vector,
            load_compiled_solution_rows,
            load_compiled_model_kernels,
            # The stretches are for solutions written as rows, an offline run's.
            *(() if solution_rows is None else (load_compiled_imu_stretch,)),
            *(source.load_compiled_code for source in self._registry.sources),
        )
        self.sources: tuple[AidingSource, ...] = self._registry.sources
        """The aiding sources, one instance per class, in the order of application."""
        self.recorder = EpochRecorder()
        """Told of every covariance epoch, correction and reset (for a smoother)."""
        self.innovation_log: list[InnovationRecord] | None = (
            [] if config.record_innovations else None
        )
        self.last_input_rejection: str | None = None
        """Why the latest input call rejected its input (None: accepted)."""
        self.imu_given_up: tuple[Reason, ...] = ()
        """Why each held IMU sample that the latest :meth:`add_imu` (or :meth:`flush`) gave up
        was rejected: samples out of the IMU's sequence, rejected once it went on."""

        self._imu_model = ImuErrorModel.from_config(config)
        self._aligner = InMotionAligner(config, self._imu_model, self.states)
        self._nav: AidedNavigation | None = None
        self._alignment: AlignmentResult | None = None
        self._alignments = 0
        self._imu_gaps = 0
        self._realignments = 0
        self._keep_source_health = False

        self._imu_buffer: deque = deque()
        self._imu_input = ImuInput(config)
        self._point = ProcessingPoint(config.max_imu_gap_s)
        # Processing horizon that add_imu left for catch_up (None: nothing deferred).
        self._deferred_horizon: float | None = None

        kinds = self._registry.kinds
        self._sequences = {kind: StreamSequence() for kind in kinds}
        self._counters = {kind: MeasurementCounters() for kind in (IMU, *kinds)}
        self._queue = MeasurementQueue(self.sources, self._counters, self._sequences)
        self._recency = AidingRecency(kinds, len(AIDED_QUANTITIES), config.coasting_timeout_s)
        self._sensor_sets = SensorSets(self.sources)
        self._gates = AidingGates(
            self._counters,
            self._recency,
            self._registry.aided_index,
            self.innovation_log,
            config.source_health_rule,
        )
        self._source_transitions: list[HealthTransition] = []
        self._contradictions = Contradictions(config)
        self._next_velocity_judgement_s = -math.inf
        self._distrust_variances = distrust_variances(config)
        self._integrity = IntegrityMonitor(
            config.integrity_rejection_count,
            config.integrity_realign_s,
            config.integrity_recovery_s,
        )
        self._solutions = SolutionBuilder(_configured_map_plane(config), solution_rows)
        self._output = OutputDecimation(config.output_rate_hz)
        self._prediction = RealtimePrediction(config.max_imu_gap_s, self._solutions, self._output)
        self._stretches = ImuStretches(
            EngineParts(
                config,
                self._imu_buffer,
                self._point,
                self._prediction,
                self._output,
                self._solutions,
                self._queue,
                self._imu_input,
                self._gates,
                self._sequences,
                self._contradictions,
                self._integrity,
                self._source_transitions,
                self._registry.pseudo,
                self._counters,
                tuple(self.sources),
                self._recency,
            )
        )

    # ------------------------------------------------------------------ input
    def add_imu(self, t_s: float, gyro_rad_s, specific_force_mps2) -> list[Emitted]:
        """Add an IMU sample (stamp s; ω_ib body rad/s; specific force body m/s²).

        Returns the new solutions: with ``realtime_output`` the new sample's prediction (after an
        alignment also those of the samples buffered since), the filtering it makes due left to
        :meth:`catch_up`; otherwise those of the samples that became processable (stamp ≤ newest
        IMU stamp − ``max_measurement_delay_s``).
        """
        self.catch_up()
        self.last_input_rejection = None
        imu_input = self._imu_input
        samples = imu_input.accept(t_s, gyro_rad_s, specific_force_mps2)
        self._count_given_up_imu_samples()
        if isinstance(samples, Reason):
            self.reject_input(IMU, samples)
            return []
        solutions = []
        for sample in samples:
            solutions.extend(self._take_imu_sample(sample))
        return solutions

    def add_inputs(self, inputs: list) -> list[tuple[list[Emitted], str | None]]:
        """:meth:`add_imu` of each IMU sample (stamp s, ω_ib body rad/s, specific force body
        m/s²) and :meth:`add_measurement` of each :class:`MeasurementInput` among ``inputs``,
        in order, nothing else given between them: the solutions of each and the reason it was
        rejected (None: accepted); :attr:`imu_given_up` is the last IMU sample's.

        Each stretch of them with nothing else to do is screened and taken in one compiled call
        (:mod:`buoy_nav.imu_stretch`); the engine takes the others, and catches up, as
        :meth:`add_imu` does: the same as one call each.
        """
        self.catch_up()
        run = None  # the inputs made ready, when a stretch first applies
        outcomes: list = [None] * len(inputs)
        position = 0
        while position < len(inputs):
            screening = self._stretch_screening()
            if screening is not None:
                if run is None:
                    run = self._stretches.run_of(inputs, self._nav)
                position += self._take_stretch(run, position, screening, outcomes)
                if position == len(inputs):
                    break
            outcomes[position] = self._take_input(inputs[position])
            position += 1
        return outcomes

    def _take_input(self, item) -> tuple[list[Emitted], str | None]:
        """:meth:`add_imu` of an IMU sample and a catch-up, or :meth:`add_measurement` of a
        :class:`MeasurementInput` (its :class:`Reason` counted when its message is none); its
        solutions and rejection."""
        if type(item) is MeasurementInput:
            source, t_s, measurement = item
            if isinstance(measurement, Reason):
                self.reject_input(source.kind, measurement)
                return [], measurement
            self.add_measurement(t_s, measurement)
            return [], self.last_input_rejection
        solutions = self.add_imu(*item)
        rejection = self.last_input_rejection
        self.catch_up()
        return solutions, rejection

    def _stretch_screening(self) -> tuple[np.ndarray, np.ndarray] | None:
        """The IMU screening's limits and state for :mod:`buoy_nav.imu_stretch`
        (:meth:`~buoy_nav.imu_input.ImuInput.steady_screening`) when the next samples may go
        through it: aligned, with solutions written as rows and predicted ahead from a copy
        the stretch may step (:meth:`~buoy_nav.imu_stretches.ImuStretches.ready`), and the
        screening in its steady course; else None."""
        if (
            self._nav is None
            or not self.config.realtime_output
            or self._solutions.rows is None
            or not self._stretches.ready()
        ):
            return None
        return self._imu_input.steady_screening()

    def _take_stretch(self, run, position: int, screening: tuple, outcomes: list[tuple]) -> int:
        """The inputs of ``run`` from ``position`` on through
        :func:`~buoy_nav.imu_stretch.imu_stretch` with the IMU ``screening``'s limits and
        state, their solutions' stamps in their ``outcomes``; how many it took (0: the engine
        takes the next one itself)."""
        taken = self._stretches.take(run, position, screening, self._nav)
        if taken is None:
            return 0
        for place in range(position, position + taken.inputs):
            outcomes[place] = ([], None)
        self.last_input_rejection = None
        if taken.samples:
            self.imu_given_up = ()
            self._counters[IMU].accepted += len(taken.samples)
            for place, sample, written in zip(
                taken.places, taken.samples, taken.rows_written, strict=True
            ):
                outcomes[place] = ([sample[0]], None) if written else ([], None)
        if taken.catch_up:
            self._deferred_horizon = taken.samples[-1][0] - self.config.max_measurement_delay_s
            self.catch_up()
        return taken.inputs

    def _count_given_up_imu_samples(self) -> None:
        """Count the held IMU samples given up by the latest call
        (:mod:`buoy_nav.stream_sequence`)."""
        self.imu_given_up = tuple(self._imu_input.take_given_up())
        for reason in self.imu_given_up:
            self._counters[IMU].reject(reason)

    def _take_imu_sample(self, sample: tuple) -> list[Emitted]:
        """Take an accepted IMU sample (stamp s, ω_ib body rad/s, specific force body m/s²);
        the solutions :meth:`add_imu` returns for it."""
        self.catch_up()
        self._counters[IMU].accepted += 1
        self._imu_buffer.append(sample)
        config = self.config
        horizon = sample[0] - config.max_measurement_delay_s
        if not config.realtime_output:
            return self._process(horizon)
        self._deferred_horizon = horizon
        if self._nav is None:
            return []
        return self._prediction.predict(
            self._nav.kalman,
            self._nav.integrator,
            (self._point.t_s, self._point.gyro, self._point.force),
            self._imu_buffer,
            sample,
            self._recency.coasting_flags(self._point.t_s),
        )

    def catch_up(self) -> None:
        """Do the filtering that :meth:`add_imu` left for later: with ``realtime_output`` it
        returns the new sample's predicted solution first and defers the processing of the
        buffer up to the new horizon (updates, covariance propagation) to this call, so a node
        can publish before the heavy work. Every other public method catches up first, so the
        results do not depend on whether, or when, it is called."""
        horizon = self._deferred_horizon
        if horizon is not None:
            self._deferred_horizon = None
            self._process(horizon)

    def add_measurement(self, t_s: float, measurement) -> None:
        """Add a measurement stamped ``t_s`` (s) of the aiding source whose ``measurement_type``
        it is (e.g. :class:`buoy_nav.aiding.GnssFix`); the source validates it.

        Raises TypeError for a measurement no registered source takes (a programming error).
        """
        source = self._registry.of_measurement(measurement)
        self.catch_up()
        self.last_input_rejection = None
        refusal = self._screen_measurement(source, t_s, measurement)
        if refusal is not None:
            self.reject_input(source.kind, refusal)

    def _screen_measurement(self, source: AidingSource, t_s: float, measurement) -> Reason | None:
        """Validate ``measurement`` of ``source`` stamped ``t_s`` (s) and queue it, marked when
        it arrived ahead of the source's sequence (:mod:`buoy_nav.stream_sequence`, judged at
        its turn by :class:`~buoy_nav.measurement_queue.MeasurementQueue`); the reason it is
        refused (None: queued)."""
        if not source.enabled:
            return Reason.DISABLED
        stamp = as_floats(t_s)
        if isinstance(stamp, Reason):
            return stamp
        (t,) = stamp
        # Measurements with bad values are still the sensor's: its sequence goes on through them.
        screening = self._sequences[source.kind].screen(t, t)
        if screening.held and screening.taken:
            self._queue.settle(source, screening.taken)
        validated = source.validated(measurement)
        if isinstance(validated, Reason):
            return validated
        ahead = screening.held and not screening.taken
        if ahead and t - self._imu_input.newest_stamp_s > MAX_MEASUREMENT_LEAD_S:
            return Reason.OUT_OF_SEQUENCE
        return self._queue_measurement(source, t, validated, ahead)

    def _queue_measurement(
        self, source: AidingSource, t: float, validated, ahead: bool
    ) -> Reason | None:
        """Queue the ``validated`` measurement of ``source`` stamped ``t`` (s), ``ahead`` of
        its sequence or not; the reason it is refused (None: queued)."""
        if t <= self._point.last_imu_stamp_s:
            return Reason.TOO_LATE
        refused = self._queue.push(source, t, validated, ahead)
        if refused is not None or ahead:
            # A measurement ahead of its sequence tells the IMU's clock nothing until its turn.
            return refused
        self._imu_input.clock.aiding_stamp(t)
        latest_imu_stamp = self._imu_input.latest_stamp_s
        if t - self._imu_input.newest_stamp_s > MAX_MEASUREMENT_LEAD_S:
            # An IMU outage: only the last seconds can serve the realignment that follows.
            self._queue.give_up_between(latest_imu_stamp, t - MAX_MEASUREMENT_LEAD_S)
        return None

    def reject_input(self, kind: str, reason: str) -> None:
        """Count an input of ``kind`` (``imu`` or a source's kind) rejected for ``reason``, also
        when the rejection happened before the input reached the engine (message conversion)."""
        self._counters[kind].reject(reason)
        self.last_input_rejection = reason

    def take_source_transitions(self) -> list[HealthTransition]:
        """The sources suspended or resumed since the last call, oldest first (for the node's
        log and the offline summary)."""
        self.catch_up()
        transitions, self._source_transitions = self._source_transitions, []
        return transitions

    @property
    def imu_clock_steps(self) -> list[tuple[float, float]]:
        """The steps of the IMU's clock undone so far, as (stamp of the first sample after the
        step on the aiding sources' clock, s; step, s), the engine's own list: it grows as
        steps are found (read it, do not change it)."""
        return self._imu_input.clock.steps

    @property
    def stretched_sources(self) -> tuple[AidingSource, ...]:
        """The aiding sources whose measurements :meth:`add_inputs` may take in its compiled
        stretches besides the IMU's samples (the motion pack's attitude, the magnetometer's
        fields and the GNSS sources' measurements, :mod:`buoy_nav.stretched_aiding`)."""
        return self._stretches.aiding_sources

    def source_of_topic(self, topic: str) -> AidingSource:
        """The aiding source that reads ``topic`` (ValueError naming it when none does)."""
        return self._registry.of_topic(topic)

    def flush(self) -> list[Emitted]:
        """End of data: process every buffered IMU sample and every applicable measurement.

        Measurements stamped after the last IMU sample cannot be reached and are rejected. With
        ``realtime_output`` every sample already had its solution, so none is returned.
        """
        self.catch_up()
        self._imu_input.give_up()
        self._count_given_up_imu_samples()
        solutions = self._process(math.inf)
        self._queue.give_up_all()
        self.recorder.end_segment(None if self._nav is None else self._nav.kalman.covariance)
        return solutions

    # ------------------------------------------------------------------ status
    @property
    def aligned(self) -> bool:
        """True once the filter runs (after alignment)."""
        self.catch_up()
        return self._nav is not None

    def health(self) -> EngineHealth:
        """Counters, alignment and coasting state (a snapshot)."""
        self.catch_up()
        t_s = self._point.t_s
        coasting = self._recency.coasting_flags(t_s)
        active, lapsed = self._recency.sources(t_s)
        return EngineHealth(
            alignment_state=AlignmentState.ALIGNED if self.aligned else self._aligner.state,
            aligned=self.aligned,
            coasting_fix=coasting[0],
            coasting_velocity=coasting[1],
            coasting_heading=coasting[2],
            counters={kind: c.snapshot() for kind, c in self._counters.items()},
            covariance_repairs=self._nav.kalman.covariance_repairs if self._nav else 0,
            imu_gaps=self._imu_gaps,
            alignments=self._alignments,
            time_s=t_s if math.isfinite(t_s) else math.nan,
            alignment=self._alignment,
            imu_clock_steps=tuple(self._imu_input.clock.steps),
            trusted=self._integrity.trusted,
            integrity_events=tuple(dataclasses.replace(e) for e in self._integrity.events),
            realignments=self._realignments,
            sensor_set=self._sensor_sets.label(active, lapsed) if self.aligned else "",
            coasting_sources=tuple(sorted(lapsed)),
            source_health=self._gates.status(),
        )

    def take_out_of_sequence(self) -> list[AidingSource]:
        """The sources of the measurements rejected as ``out_of_sequence`` since the last call,
        in order (a second stream's, rejected when their turn came or when the source's own
        measurement of their stamp arrived)."""
        rejected, self._queue.out_of_sequence = self._queue.out_of_sequence, []
        return rejected

    @property
    def second_streams(self) -> dict[str, tuple[int, float]]:
        """By input (``imu`` or a source's kind): (samples of a second stream on its topic
        rejected so far, how far the last ran ahead of the input's own in s, negative behind;
        NaN where not known: a measurement's, rejected at its turn). Not caught up: a count as
        of the filtering done."""
        imu_input = self._imu_input
        streams = {IMU: (imu_input.second_stream_samples, imu_input.second_stream_lead_s)}
        for kind in self._sequences:
            rejected = self._counters[kind].rejected.get(Reason.OUT_OF_SEQUENCE, 0)
            streams[kind] = (rejected, math.nan)
        return streams

    @property
    def covariance(self) -> np.ndarray | None:
        """Current error-state covariance (a copy; states named by :attr:`states`), None before
        alignment."""
        self.catch_up()
        return None if self._nav is None else self._nav.kalman.covariance.copy()

    @property
    def nav_state(self) -> NavState | None:
        """Current nominal state, None before alignment."""
        self.catch_up()
        return None if self._nav is None else self._nav.integrator.nav_state()

    @property
    def map_plane(self) -> earth.LocalTangentPlane | None:
        """The ``map`` frame (None until its origin is known)."""
        self.catch_up()
        return self._solutions.map_plane

    # ------------------------------------------------------------------ processing
    def _process(self, horizon: float) -> list[Emitted]:
        """Filter the buffered data up to ``horizon``: the solutions of the processed IMU
        samples, unless ``realtime_output`` predicts them ahead instead."""
        solutions: list[Emitted] = []
        buffer = self._imu_buffer
        while buffer and buffer[0][0] <= horizon:
            t, gyro, force = buffer.popleft()
            if self._point.begins_run(t):
                self._start_imu_run(t, gyro, force)
                continue
            solution = self._process_sample(t, gyro, force)
            if solution is not None:
                solutions.append(solution)
        return solutions

    def _start_imu_run(self, t: float, gyro, force) -> None:
        """Take the first sample of a run of IMU samples (the first of all, or after a gap,
        which starts the alignment again)."""
        if self._point.started:
            self._imu_gaps += 1
            self._restart_alignment()
        # Measurements up to the first sample of a run can only feed the alignment.
        queue = self._queue
        while queue.heap and queue.heap[0][0] <= t:
            self._handle_measurements(*queue.pop_stamp(), gyro)
        self._point.start_run(t, gyro, force)

    def _process_sample(self, t: float, gyro, force) -> Emitted | None:
        """Integrate to the IMU sample at ``t``, applying the measurements stamped up to it at
        their own stamps; its solution when one is due from the filter."""
        point = self._point
        point.begin_step()
        queue = self._queue
        while queue.heap and queue.heap[0][0] <= t:
            stamp, group = queue.pop_stamp()
            if not group:  # all rejected at their turn: no step to their stamp
                continue
            gyro_m, force_m = point.samples_at(stamp, t, gyro, force)
            self._advance(stamp, gyro_m, force_m, measured=True)
            self._handle_measurements(stamp, group, gyro_m)
        self._advance(t, gyro, force)
        if self._registry.pseudo and self._nav is not None:
            self._apply_pseudo_measurements(t, gyro)
        span = point.end_step()
        if self.config.realtime_output or self._nav is None or not self._output.due(t, span):
            return None
        return self._solution(self._nav.integrator, t, gyro, force)

    def _advance(self, t: float, gyro, force, measured: bool = False):
        """Integrate from the current state time to ``t`` (raw samples at both ends); with
        ``measured``, to a stamp whose measurements are applied next, which propagates the
        covariance there in the same call."""
        point = self._point
        dt = t - point.t_s
        if dt > 0.0:
            if self._nav is None:
                self._aligner.add_motion(dt, point.gyro, gyro, point.force, force)
            elif measured:
                self._nav.integrate_and_propagate(t, dt, point.gyro, gyro, point.force, force)
                self._solutions.covariance_changed()
            elif self._nav.integrate(t, dt, point.gyro, gyro, point.force, force):
                self._solutions.covariance_changed()
        point.moved_to(t, gyro, force)

    def _handle_measurements(self, t: float, group: list, gyro):
        """Apply the (source, measurement) pairs of stamp ``t`` (raw gyro rate ``gyro`` there):
        to the alignment, or gated one by one and the accepted ones in one stacked update."""
        if not group:
            return
        for _, measurement in group:
            self._contradictions.observe(t, measurement)
        self._rejudge_contradicted_velocities(t, group)
        nav = self._nav
        if nav is None:
            self._align_with(t, group, gyro)
            return
        if nav.propagate_covariance(t):
            self._solutions.covariance_changed()
        if len(group) == 1 and self._applied_compiled_update(t, *group[0], gyro):
            return
        point = nav.linearisation_point(gyro)
        if self._applied_stacked_update(t, group, point):
            return
        outcome = self._gates.gate(t, group, point, nav.kalman)
        if outcome.accepted:
            self._corrected(point.state, nav.correct(outcome.accepted))
        for source, measurement, model in outcome.persistent_rejections:
            self._reset_to_measurement(source, t, measurement, gyro, model)
        self._source_transitions.extend(outcome.transitions)
        self._judge_integrity(t, outcome.rejected_kinds)

    def _applied_compiled_update(self, t: float, source: AidingSource, measurement, gyro) -> bool:
        """Apply the one ``measurement`` of ``source`` at stamp ``t`` (raw gyro ``gyro`` there)
        through the source's compiled update, as :meth:`_handle_measurements` would; False,
        with nothing changed, when the source has none or its gate rejects the measurement
        (that one is then gated and booked the interpreted way)."""
        if not source.has_compiled_update:
            return False
        nav = self._nav
        update = source.compiled_update(measurement, gyro, nav.integrator.state_vector, nav.kalman)
        if not update.gate.accepted:
            return False
        fused, outcome = self._gates.passed(source, t, update.innovation, update.gate)
        if fused:
            linearisation_state = nav.integrator.nav_state()
            nav.apply_correction(update.correction, update.covariance, update.positive_definite)
            self._corrected(linearisation_state, update.correction)
        self._source_transitions.extend(outcome.transitions)
        self._judge_integrity(t, outcome.rejected_kinds)
        return True

    def _applied_stacked_update(self, t: float, group: list, point) -> bool:
        """Apply the (source, measurement) pairs of stamp ``t``, linearised at ``point``, as
        :meth:`_handle_measurements` would, when every source's model is one compiled call: the
        gates and the stacked update in one compiled call, booked as the gates book them. False,
        with nothing changed, when a source has no compiled model or is suspended, a model is
        not a measurement's, or one fails its gate (then they are gated and booked the
        interpreted way)."""
        gates = self._gates
        if not all(
            source.has_compiled_model and not gates.suspended(source.kind) for source, _ in group
        ):
            return False  # before any model: a mixed stamp is modelled once, the interpreted way
        models = []
        for source, measurement in group:
            model = source.model(measurement, point)
            if not isinstance(model, MeasurementModel):
                return False
            models.append(model)
        nav = self._nav
        update = nav.gated_update(models, [source.gate_probability for source, _ in group])
        if not update.accepted:
            return False
        fused = []
        transitions = []
        for (source, _), model, gate in zip(group, models, update.gates, strict=True):
            passed, outcome = gates.passed(source, t, model.innovation, gate)
            transitions.extend(outcome.transitions)
            if passed:
                fused.append(model)
        if len(fused) == len(models):
            nav.apply_correction(update.correction, update.covariance, update.positive_definite)
            self._corrected(point.state, update.correction)
        elif fused:  # a source suspended by this very outcome: the others alone
            self._corrected(point.state, nav.correct(fused))
        self._source_transitions.extend(transitions)
        self._judge_integrity(t, {})
        return True

    def _corrected(self, linearisation_state, correction) -> None:
        """The filter injected ``correction`` into its nominal state, which was
        ``linearisation_state``: the solutions and the prediction ahead follow."""
        self._solutions.covariance_changed()
        self._solutions.biases_changed()
        self._prediction.carry_over(self._point.t_s, linearisation_state, correction)

    def _align_with(self, t: float, group: list, gyro) -> None:
        """Hand the (source, measurement) pairs of stamp ``t`` to the aligner; start the filter
        when one completes the alignment. A source suspended before a realignment stays out of
        it: the new alignment would follow the sensor that disagreed with the filter."""
        # Registry order puts the antenna attitude, which may complete the alignment, last.
        for source, measurement in group:
            if self._gates.suspended(source.kind):
                self._counters[source.kind].reject(Reason.SUSPENDED)
                continue
            result = source.align(self._aligner, t, measurement, gyro)
            if isinstance(result, Reason):
                self._counters[source.kind].reject(result)
                continue
            self._counters[source.kind].used_for_alignment += 1
            if result is not None:
                self._start_filter(result, t)

    def _judge_integrity(self, t: float, rejected_kinds: dict[str, int]) -> None:
        """Act on the integrity monitor's verdict on the gate outcomes of stamp ``t``.

        Inflation widens the filter's attitude and velocity covariance; the filter's own
        covariance may shrink again as the gate lets measurements through, even towards a
        wrong state, so the published covariance keeps the inflation as long as the trust is
        not back (:meth:`SolutionBuilder.distrust`)."""
        action = self._integrity.gate_outcomes(t, rejected_kinds)
        if action == "inflate":
            self._nav.inflate(t, self._distrust_variances)
            self._solutions.covariance_changed()
        elif action == "realign":
            self._suspend_velocity_the_fixes_contradict(t)
            self._realignments += 1
            self._restart_alignment()
            # The sources' health is evidence about the sources, not about the filter that is
            # replaced: forgetting it would let the alignment follow the source that made the
            # filter wrong, again and again.
            self._keep_source_health = True
        self._solutions.distrust(None if self._integrity.trusted else self._distrust_variances)

    def _suspend_velocity_the_fixes_contradict(self, t: float) -> None:
        """Before a realignment at stamp ``t``: suspend the velocity sources whose failures
        started the episode of distrust while no position source failed, when the fixes of
        that time contradict them (:mod:`buoy_nav.contradictions`), so the alignment goes
        without them. The episode, not the last period alone: with fixes too noisy to tell a
        velocity's bias within one period, the filter realigned to the biased velocity drifts
        from the fixes, which start the next periods, and the evidence grows with each."""
        event = self._integrity.episode(VELOCITY_CHECK_SPAN_S)[0]
        kinds = set(event.kinds)
        if any(POSITION_REFERENCE in s.roles for s in self.sources if s.kind in kinds):
            return
        for source in self.sources:
            if source.kind in kinds and VELOCITY_REFERENCE in source.roles:
                self._suspend_if_contradicted(source, event.start_s, t)

    def _suspend_if_contradicted(self, source: AidingSource, from_s: float, t: float) -> bool:
        """Suspend the velocity ``source`` when the fixes of [``from_s``, ``t``] (s) contradict
        it; whether it is suspended."""
        verdict = self._contradictions.velocity_verdict(from_s, t)
        if verdict is not None and verdict.contradicted:
            self._source_transitions.extend(self._gates.judged(source, t, verdict))
        return self._gates.suspended(source.kind)

    def _rejudge_contradicted_velocities(self, t: float, group: list) -> None:
        """Once a second, lift the contradiction of a velocity source of ``group`` (stamp
        ``t``) that agrees with the fixes again."""
        if t < self._next_velocity_judgement_s:
            return
        for source, _ in group:
            if self._gates.contradicted(source.kind) and VELOCITY_REFERENCE in source.roles:
                self._next_velocity_judgement_s = t + 1.0
                verdict = self._contradictions.velocity_verdict(-math.inf, t)
                if verdict is not None and not verdict.contradicted:
                    self._source_transitions.extend(self._gates.judged(source, t, verdict))

    def _apply_pseudo_measurements(self, t: float, gyro):
        """Ask the constraints that are due at IMU stamp ``t`` for their measurements."""
        due = [source for source in self._registry.pseudo if t >= source.next_due_s]
        if not due:
            return
        nav = self._nav
        state = nav.integrator.nav_state()
        fix_age = self._recency.age_s(AIDED_QUANTITIES.index(FIX), t)
        velocity = self.states.velocity
        velocity_covariance = nav.kalman.covariance[velocity, velocity]
        group = []
        for source in due:
            verdict = self._contradictions.judge(source)
            if verdict is not None:
                self._source_transitions.extend(self._gates.judged(source, t, verdict))
            measurement = source.pseudo_measurement(t, state, fix_age, velocity_covariance)
            if measurement is not None:
                group.append((source, measurement))
        nav.gyro_drift_scale = max(source.gyro_drift_scale for source in self._registry.pseudo)
        nav.accel_noise_scale = max(source.accel_noise_scale for source in self._registry.pseudo)
        factor = max(source.take_covariance_factor() for source in self._registry.pseudo)
        if factor > 1.0:
            nav.widen(t, factor)
            self._solutions.covariance_changed()
        self._handle_measurements(t, group, gyro)

    def _reset_to_measurement(self, source: AidingSource, t: float, measurement, gyro, model):
        """Re-initialise the states a persistently rejected source observes, as it says,
        unless it is a velocity that the fixes contradict: that one is suspended instead."""
        if VELOCITY_REFERENCE in source.roles and self._suspend_if_contradicted(
            source, self._gates.run_start_s(source.kind), t
        ):
            return
        nav = self._nav
        reset = source.reset(measurement, nav.linearisation_point(gyro), model)
        if reset is None:
            return
        self._gates.source_reset(source, t)
        nav.reset(t, reset)
        self._solutions.covariance_changed()
        self._prediction.drop()

    def _start_filter(self, result: AlignmentResult, t: float):
        """Hand over from the aligner to the filter at stamp ``t``."""
        self._nav = AidedNavigation(
            result, t, self.config, self.states, self._imu_model, self.recorder
        )
        self._alignment = result
        self._alignments += 1
        self._integrity.realigned(t)
        self._solutions.distrust(None)
        self._gates.aligned(t, forget_health=not self._keep_source_health)
        self._keep_source_health = False
        if self._solutions.map_plane is None:
            state = result.state
            self._solutions.map_plane = earth.LocalTangentPlane(
                state.latitude_rad, state.longitude_rad, state.altitude_m
            )
        self._output.restart()
        self._nav_state_replaced()

    def _restart_alignment(self):
        self.recorder.end_segment(None if self._nav is None else self._nav.kalman.covariance)
        for source in self._registry.pseudo:
            source.restart()
        self._nav = None
        self._aligner.restart()
        self._nav_state_replaced()

    def _nav_state_replaced(self) -> None:
        """Solutions and the prediction ahead start afresh from the state the filter has now."""
        self._solutions.covariance_changed()
        self._solutions.biases_changed()
        self._prediction.drop()

    # ------------------------------------------------------------------ output
    def _solution(self, integrator: StrapdownIntegrator, t: float, gyro, force) -> Emitted:
        """The solution of ``integrator``'s state at stamp ``t`` (raw gyro and force there)."""
        # Coasting is judged where the filter is: measurements ahead of it are not yet used.
        return self._solutions.emit(
            integrator,
            self._nav.kalman,
            t,
            gyro,
            force,
            self._recency.coasting_flags(self._point.t_s),
        )


def _configured_map_plane(config: FusionConfig) -> earth.LocalTangentPlane | None:
    """The ``map`` frame at the configured origin (None: none is configured, the frame is set
    at the first alignment)."""
    if not config.has_origin:
        return None
    return earth.LocalTangentPlane(
        math.radians(config.origin_latitude_deg),
        math.radians(config.origin_longitude_deg),
        config.origin_altitude_m,
    )
