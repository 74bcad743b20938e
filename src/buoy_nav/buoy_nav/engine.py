"""Fusion engine: the one entry point of the navigation core for live nodes and offline tools.

The engine buffers IMU samples and GNSS measurements and processes them strictly in stamp order,
``max_measurement_delay_s`` behind the newest IMU stamp, so measurements that arrive out of order
within that delay give exactly the result of in-order arrival. A measurement whose stamp falls
between two IMU samples is applied at its own stamp: the state is integrated to it with IMU
samples interpolated on the parabola through the last three samples (the curve the strapdown
integrator integrates, so splitting a step costs no accuracy), updated, and integrated on to the
next sample. Measurements sharing a stamp are gated one by one and the accepted ones applied in
one stacked update (their order: fix, velocity, baseline, heading).

The dual antennas give either the full baseline vector (``add_gnss_baseline``, which observes the
baseline's azimuth and tilt) or only its azimuth (``add_gnss_heading``). Both come from the same
carrier-phase solution, so fusing both of one epoch would count it twice: a heading with the
stamp of a baseline is set aside and counted as superseded; headings of epochs
without a baseline (a receiver that sends none, or sends them at a lower rate) are fused.

With ``realtime_output`` (the default) a solution leaves with its IMU sample, not
``max_measurement_delay_s`` later: a copy of the filter's nominal state is integrated ahead
through the buffered IMU samples to the newest one and integrated on with each new sample. Each
correction of the filter is carried over to the copy through the error dynamics over the span
between them (attitude error plus gyro-bias drift, velocity error plus the attitude error acting
on the specific-force increment and the accelerometer-bias change, position error plus velocity
error times the span), exact to first order; once per ``PREDICTION_RESYNC_INTERVAL_S`` of stamps
the copy is instead forked afresh from the filter, so second-order residues cannot accumulate.
The solution of a sample is predicted before the filter catches up with that sample's horizon
(:meth:`FusionEngine.catch_up`), so a node publishes it before the updates and covariance
propagation it triggers, and corrections reach the prediction one IMU sample later. The
prediction depends only on stamps (which measurements lie behind the previous sample's
processing horizon), so a live node and an offline run of the same data give the same solutions.
Its covariances are the filter's, from up to ``max_measurement_delay_s`` earlier.

Before alignment the IMU samples and GNSS measurements feed :class:`InMotionAligner`; once
aligned, the strapdown integrator carries the nominal state and the error-state filter corrects
it after every accepted measurement. The covariance is propagated in batches of at most
``covariance_propagation_interval_s`` and always up to a measurement stamp before an update (the
batching is exact to first order, see :mod:`buoy_nav.error_state_filter`); the covariances in a
:class:`NavSolution` are therefore at most that interval old.

Invalid input (non-finite values, absurd magnitudes, non-positive variances, IMU stamps not
increasing, duplicated measurement stamps, measurements older than what was already processed)
is rejected and counted by kind and reason; it never reaches the state. Measurements more than
``MAX_MEASUREMENT_LEAD_S`` ahead of the newest IMU sample (an IMU outage) are given up as
``beyond_imu_data``, oldest first, so an outage cannot fill the memory.
"""

import heapq
import math
from collections import deque
from dataclasses import dataclass, field

import numpy as np

from buoy_nav import earth
from buoy_nav.alignment import (
    MIN_HORIZONTAL_BASELINE_FRACTION,
    AlignmentResult,
    AlignmentState,
    InMotionAligner,
)
from buoy_nav.config import FusionConfig
from buoy_nav.error_state_filter import (
    ACCEL_BIAS,
    ATTITUDE,
    GYRO_BIAS,
    POSITION,
    VELOCITY,
    ErrorStateFilter,
    ImuErrorModel,
    NavState,
    discrete_error_model,
    inject_error_state,
)
from buoy_nav.measurements.baseline import baseline_azimuth_rad, baseline_vector_model
from buoy_nav.measurements.gnss_position import position_model
from buoy_nav.measurements.gnss_velocity import (
    predicted_antenna_velocity_enu_mps,
    velocity_model,
)
from buoy_nav.measurements.heading import heading_model, horizontal_fraction
from buoy_nav.mechanization import StrapdownIntegrator, interpolate_sample
from buoy_nav.rotations import (
    cross,
    euler_from_rotation_matrix,
    quaternion_from_rotation_matrix,
    rotation_matrix_from_euler,
    rotation_matrix_from_quaternion,
    wrap_angle,
)

IMU = "imu"
GNSS_FIX = "gnss_fix"
GNSS_VELOCITY = "gnss_velocity"
GNSS_HEADING = "gnss_heading"
GNSS_BASELINE = "gnss_baseline"
MEASUREMENT_KINDS = (GNSS_FIX, GNSS_VELOCITY, GNSS_BASELINE, GNSS_HEADING)
# Order of measurements that share a stamp: the antenna attitude, which may complete the
# alignment, comes last.
_KIND_ORDER = {GNSS_FIX: 0, GNSS_VELOCITY: 1, GNSS_BASELINE: 2, GNSS_HEADING: 3}

# Rejection reasons.
NON_FINITE = "non_finite"
OUT_OF_RANGE = "out_of_range"
NON_POSITIVE_VARIANCE = "non_positive_variance"
STAMP_NOT_INCREASING = "stamp_not_increasing"
DUPLICATE_STAMP = "duplicate_stamp"
TOO_LATE = "too_late"
GATE = "gate"
GEOMETRY = "geometry"
SINGULAR = "singular_innovation_covariance"
BEYOND_IMU_DATA = "beyond_imu_data"
MALFORMED = "malformed"
DISABLED = "disabled"

# A measured baseline whose length differs from the configured antenna separation by more than
# this fraction is a wrong configuration or a wrong fix, not a measurement.
_MAX_BASELINE_LENGTH_ERROR_FRACTION = 0.5

# How far measurements may run ahead of the newest IMU sample (s of stamps). More can only be an
# IMU outage (or GNSS before the IMU starts): the filter could use them only for the alignment
# that follows, which needs the last seconds alone, and keeping them all would let an outage
# fill the memory and, when the IMU returns, stall the node on the backlog.
MAX_MEASUREMENT_LEAD_S = 10.0

# Longest run of carried-over corrections before the real-time prediction is forked afresh from
# the filter (s of stamps): bounds the second-order residue of the carry-over (≪ 1e-6 rad).
PREDICTION_RESYNC_INTERVAL_S = 1.0

# Plausibility limits of GNSS input beyond which a value is a malformed message, not a
# measurement: ellipsoidal altitude (m) and speed over ground (m/s) of a buoy.
_MAX_ABS_ALTITUDE_M = 1.0e4
_MAX_SPEED_MPS = 100.0


@dataclass(frozen=True, slots=True)
class NavSolution:
    """Navigation solution at one IMU sample (all arrays float64).

    t_s: stamp (s). attitude_xyzw: quaternion of R_nb (body FLU → ENU).
    angular_rate_body_rad_s: bias-corrected gyro rate ω_ib (body).
    angular_rate_nb_body_rad_s: ω_nb, rate relative to ENU (Earth and transport rate removed).
    specific_force_body_mps2: bias-corrected specific force (body).
    velocity_enu_mps: velocity over ground of the ``base_link`` origin (ENU).
    latitude_deg, longitude_deg, altitude_m: WGS-84 position of the ``base_link`` origin.
    position_map_m: the same position in the ``map`` ENU frame (m).
    attitude_covariance_rad2: covariance of the attitude error φ (ENU, 3×3, rad²), where
      R_true = Exp([φ×]) R_estimated.
    velocity_covariance_m2s2, position_covariance_m2: ENU 3×3 covariances.
    gyro_bias_rad_s, accel_bias_mps2: bias estimates (body).
    The covariance and bias arrays are read-only: consecutive solutions share them until the
    filter changes them.
    aligned: the filter is aligned (always True in emitted solutions).
    coasting_fix, coasting_velocity, coasting_heading: no measurement of that kind was accepted
      for longer than ``coasting_timeout_s`` (for the heading: neither a heading nor a baseline).
    """

    t_s: float
    attitude_xyzw: np.ndarray
    angular_rate_body_rad_s: np.ndarray
    angular_rate_nb_body_rad_s: np.ndarray
    specific_force_body_mps2: np.ndarray
    velocity_enu_mps: np.ndarray
    latitude_deg: float
    longitude_deg: float
    altitude_m: float
    position_map_m: np.ndarray
    attitude_covariance_rad2: np.ndarray
    velocity_covariance_m2s2: np.ndarray
    position_covariance_m2: np.ndarray
    gyro_bias_rad_s: np.ndarray
    accel_bias_mps2: np.ndarray
    aligned: bool
    coasting_fix: bool
    coasting_velocity: bool
    coasting_heading: bool

    @property
    def euler_rad(self) -> tuple[float, float, float]:
        """(roll, pitch, yaw) in rad of R_nb = Rz(yaw) Ry(pitch) Rx(roll)."""
        return euler_from_rotation_matrix(rotation_matrix_from_quaternion(self.attitude_xyzw))


@dataclass(frozen=True)
class InnovationRecord:
    """One gated measurement (kept when ``record_innovations`` is on).

    t_s: stamp. kind: measurement kind. innovation: measured − predicted.
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
    """Counters of one input kind.

    accepted: samples used (IMU) or filter updates applied (GNSS).
    used_for_alignment: GNSS measurements consumed by the alignment.
    superseded: headings not fused because a baseline of the same stamp carries their
    information and more.
    rejected: rejections by reason. resets: state resets after ``gate_reset_count``
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
        self.rejected[reason] = self.rejected.get(reason, 0) + 1


@dataclass(frozen=True)
class EngineHealth:
    """Snapshot of the engine's health.

    alignment_state: progress of the alignment. aligned: the filter runs.
    coasting_fix, coasting_velocity, coasting_heading: see :class:`NavSolution`.
    counters: per kind (``imu``, ``gnss_fix``, ``gnss_velocity``, ``gnss_baseline``,
      ``gnss_heading``).
    covariance_repairs: times P had to be made positive definite again.
    imu_gaps: IMU gaps longer than ``max_imu_gap_s``. alignments: completed alignments.
    time_s: stamp up to which data was processed (NaN before any).
    alignment: the last alignment result (None before the first).
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


@dataclass(frozen=True)
class _Fix:
    latitude_rad: float
    longitude_rad: float
    altitude_m: float
    covariance_enu_m2: np.ndarray


@dataclass(frozen=True)
class _Velocity:
    velocity_enu_mps: np.ndarray
    covariance_m2s2: np.ndarray


@dataclass(frozen=True)
class _Heading:
    yaw_rad: float
    variance_rad2: float


@dataclass(frozen=True)
class _Baseline:
    baseline_enu_m: np.ndarray


class FusionEngine:
    """Dual-antenna GNSS / strapdown INS fusion (see the module docstring)."""

    def __init__(self, config: FusionConfig):
        self.config = config
        self._imu_model = ImuErrorModel.from_config(config)
        self._primary = np.array(config.primary_antenna_body_m)
        self._baseline = np.array(config.baseline_body_m)
        self._baseline_length_m = float(np.linalg.norm(self._baseline))
        self._aligner = InMotionAligner(config, self._imu_model)
        self._integrator: StrapdownIntegrator | None = None
        self._filter: ErrorStateFilter | None = None
        self._alignment: AlignmentResult | None = None
        self._alignments = 0
        self._imu_gaps = 0
        self._map_plane = (
            earth.LocalTangentPlane(
                math.radians(config.origin_latitude_deg),
                math.radians(config.origin_longitude_deg),
                config.origin_altitude_m,
            )
            if config.has_origin
            else None
        )

        self._imu_buffer: deque = deque()
        self._measurements: list = []
        self._sequence = 0
        self._buffered_stamps: dict[str, set] = {kind: set() for kind in MEASUREMENT_KINDS}
        self._latest_imu_stamp = -math.inf
        # State of the processing: time and (raw) IMU sample the state refers to.
        self._time = -math.inf
        self._gyro: tuple[float, float, float] | None = None
        self._force: tuple[float, float, float] | None = None
        # The IMU sample before the current one (same run), for interpolation at stamps.
        self._older_imu = None
        self._last_processed_imu_stamp = -math.inf
        # Processing horizon that add_imu left for catch_up (None: nothing deferred).
        self._deferred_horizon: float | None = None

        self._counters = {kind: MeasurementCounters() for kind in (IMU, *MEASUREMENT_KINDS)}
        self._last_accepted = {kind: -math.inf for kind in MEASUREMENT_KINDS}
        self._consecutive_rejections = dict.fromkeys(MEASUREMENT_KINDS, 0)
        self.innovation_log: list[InnovationRecord] | None = (
            [] if config.record_innovations else None
        )

        self._output_period = 1.0 / config.output_rate_hz if config.output_rate_hz > 0 else 0.0
        self._next_output_time = -math.inf
        self._covariance_blocks = None
        self._bias_arrays = None
        # Real-time prediction: (integrator ahead of the filter, its time, raw gyro and force at
        # that time); None when it must be forked again from the filter state.
        self._ahead: tuple[StrapdownIntegrator, float, tuple, tuple] | None = None
        self._ahead_forked_at = -math.inf
        self._last_predicted_stamp = -math.inf
        # Why the latest add_* call rejected its input (None: accepted).
        self.last_input_rejection: str | None = None

    # ------------------------------------------------------------------ input
    def add_imu(self, t_s: float, gyro_rad_s, specific_force_mps2) -> list[NavSolution]:
        """Add an IMU sample (stamp s; ω_ib body rad/s; specific force body m/s²).

        Returns the new solutions: with ``realtime_output`` the new sample's prediction (after an
        alignment also those of the samples buffered since), the filtering it makes due left to
        :meth:`catch_up`; otherwise those of the samples that became processable (stamp ≤ newest
        IMU stamp − ``max_measurement_delay_s``).
        """
        self.catch_up()
        self.last_input_rejection = None
        counters = self._counters[IMU]
        try:
            t = float(t_s)
            gx, gy, gz = _float_triple(gyro_rad_s)
            fx, fy, fz = _float_triple(specific_force_mps2)
        except (TypeError, ValueError):
            self._reject_input(IMU, MALFORMED)
            return []
        if not (math.isfinite(t) and math.isfinite(gx + gy + gz) and math.isfinite(fx + fy + fz)):
            self._reject_input(IMU, NON_FINITE)
            return []
        config = self.config
        if (
            gx * gx + gy * gy + gz * gz > config.max_angular_rate_rad_s**2
            or fx * fx + fy * fy + fz * fz > config.max_specific_force_mps2**2
        ):
            self._reject_input(IMU, OUT_OF_RANGE)
            return []
        if t <= self._latest_imu_stamp:
            duplicate = t == self._latest_imu_stamp
            self._reject_input(IMU, DUPLICATE_STAMP if duplicate else STAMP_NOT_INCREASING)
            return []
        counters.accepted += 1
        self._latest_imu_stamp = t
        sample = (t, (gx, gy, gz), (fx, fy, fz))
        self._imu_buffer.append(sample)
        horizon = t - config.max_measurement_delay_s
        if not config.realtime_output:
            return self._process(horizon)
        solutions = self._predict_ahead(sample)
        self._deferred_horizon = horizon
        return solutions

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

    def add_gnss_fix(
        self,
        t_s: float,
        latitude_deg: float,
        longitude_deg: float,
        altitude_m: float,
        position_covariance_enu_m2,
    ) -> None:
        """Add a primary-antenna fix (WGS-84 deg, deg, ellipsoidal m; ENU covariance 3×3 m²)."""
        self.catch_up()
        self.last_input_rejection = None
        values, reason = _floats(t_s, latitude_deg, longitude_deg, altitude_m)
        covariance, covariance_reason = _float_array(position_covariance_enu_m2, (3, 3))
        reason = reason or covariance_reason
        if reason is None and (
            abs(values[1]) > 90.0 or abs(values[2]) > 360.0 or abs(values[3]) > _MAX_ABS_ALTITUDE_M
        ):
            reason = OUT_OF_RANGE
        if reason is None and np.any(np.diag(covariance) <= 0.0):
            reason = NON_POSITIVE_VARIANCE
        if reason is None:
            t, latitude, longitude, altitude = values
            payload = _Fix(math.radians(latitude), math.radians(longitude), altitude, covariance)
            self._enqueue(GNSS_FIX, t, payload)
        else:
            self._reject_input(GNSS_FIX, reason)

    def add_gnss_velocity(self, t_s: float, velocity_enu_mps, covariance_m2s2) -> None:
        """Add the primary antenna's velocity over ground (ENU m/s; covariance 3×3 m²/s²)."""
        self.catch_up()
        self.last_input_rejection = None
        stamp, reason = _floats(t_s)
        velocity, velocity_reason = _float_array(velocity_enu_mps, (3,))
        covariance, covariance_reason = _float_array(covariance_m2s2, (3, 3))
        reason = reason or velocity_reason or covariance_reason
        if reason is None and float(velocity @ velocity) > _MAX_SPEED_MPS**2:
            reason = OUT_OF_RANGE
        if reason is None and np.any(np.diag(covariance) <= 0.0):
            reason = NON_POSITIVE_VARIANCE
        if reason is None:
            self._enqueue(GNSS_VELOCITY, stamp[0], _Velocity(velocity, covariance))
        else:
            self._reject_input(GNSS_VELOCITY, reason)

    def add_gnss_heading(self, t_s: float, yaw_rad: float, variance_rad2: float) -> None:
        """Add a dual-antenna heading: baseline azimuth (rad, ENU, 0 = East, CCW), variance rad²."""
        self.catch_up()
        self.last_input_rejection = None
        values, reason = _floats(t_s, yaw_rad, variance_rad2)
        if reason is None and values[2] <= 0.0:
            reason = NON_POSITIVE_VARIANCE
        if reason is None:
            t, yaw, variance = values
            self._enqueue(GNSS_HEADING, t, _Heading(wrap_angle(yaw), variance))
        else:
            self._reject_input(GNSS_HEADING, reason)

    def add_gnss_baseline(self, t_s: float, baseline_enu_m) -> None:
        """Add a primary → secondary antenna vector (ENU, m) from moving-baseline RTK."""
        self.catch_up()
        self.last_input_rejection = None
        stamp, reason = _floats(t_s)
        baseline, baseline_reason = _float_array(baseline_enu_m, (3,))
        reason = reason or baseline_reason
        if reason is None and not self.config.use_gnss_baseline:
            reason = DISABLED
        if reason is None:
            length_error = float(np.linalg.norm(baseline)) - self._baseline_length_m
            if abs(length_error) > _MAX_BASELINE_LENGTH_ERROR_FRACTION * self._baseline_length_m:
                reason = OUT_OF_RANGE
        if reason is None:
            self._enqueue(GNSS_BASELINE, stamp[0], _Baseline(baseline))
        else:
            self._reject_input(GNSS_BASELINE, reason)

    def flush(self) -> list[NavSolution]:
        """End of data: process every buffered IMU sample and every applicable measurement.

        Measurements stamped after the last IMU sample cannot be reached and are rejected. With
        ``realtime_output`` every sample already had its solution, so none is returned.
        """
        self.catch_up()
        solutions = self._process(math.inf)
        while self._measurements:
            _, _, _, kind, _ = heapq.heappop(self._measurements)
            self._counters[kind].reject(BEYOND_IMU_DATA)
        for stamps in self._buffered_stamps.values():
            stamps.clear()
        return solutions

    # ------------------------------------------------------------------ status
    @property
    def aligned(self) -> bool:
        """True once the filter runs (after alignment)."""
        self.catch_up()
        return self._filter is not None

    def health(self) -> EngineHealth:
        """Counters, alignment and coasting state (a snapshot)."""
        self.catch_up()
        coasting = self._coasting_flags(self._time)
        return EngineHealth(
            alignment_state=AlignmentState.ALIGNED if self.aligned else self._aligner.state,
            aligned=self.aligned,
            coasting_fix=coasting[0],
            coasting_velocity=coasting[1],
            coasting_heading=coasting[2],
            counters={
                kind: MeasurementCounters(
                    c.accepted,
                    c.used_for_alignment,
                    c.superseded,
                    dict(c.rejected),
                    c.resets,
                    c.nis_sum,
                    c.nis_count,
                )
                for kind, c in self._counters.items()
            },
            covariance_repairs=self._filter.covariance_repairs if self._filter else 0,
            imu_gaps=self._imu_gaps,
            alignments=self._alignments,
            time_s=self._time if math.isfinite(self._time) else math.nan,
            alignment=self._alignment,
        )

    @property
    def covariance(self) -> np.ndarray | None:
        """Current 15×15 error-state covariance (a copy), None before alignment."""
        self.catch_up()
        return None if self._filter is None else self._filter.covariance.copy()

    @property
    def nav_state(self) -> NavState | None:
        """Current nominal state, None before alignment."""
        self.catch_up()
        return None if self._integrator is None else _nav_state(self._integrator)

    @property
    def map_plane(self) -> earth.LocalTangentPlane | None:
        """The ``map`` frame (None until its origin is known)."""
        self.catch_up()
        return self._map_plane

    # ------------------------------------------------------------------ processing
    def _enqueue(self, kind: str, t: float, payload):
        if t <= self._last_processed_imu_stamp:
            self._reject_input(kind, TOO_LATE)
            return
        stamps = self._buffered_stamps[kind]
        if t in stamps:
            self._reject_input(kind, DUPLICATE_STAMP)
            return
        stamps.add(t)
        self._sequence += 1
        heapq.heappush(self._measurements, (t, _KIND_ORDER[kind], self._sequence, kind, payload))
        if t - self._latest_imu_stamp > MAX_MEASUREMENT_LEAD_S:
            self._give_up_measurements_before(t - MAX_MEASUREMENT_LEAD_S)

    def _give_up_measurements_before(self, t: float):
        """Reject the buffered measurements ahead of the IMU data and stamped before ``t``;
        those the IMU data already covers stay for the filter."""
        latest_imu = self._latest_imu_stamp
        kept = []
        for entry in self._measurements:
            stamp, _, _, kind, _ = entry
            if latest_imu < stamp < t:
                self._buffered_stamps[kind].discard(stamp)
                self._counters[kind].reject(BEYOND_IMU_DATA)
            else:
                kept.append(entry)
        heapq.heapify(kept)
        self._measurements[:] = kept

    def _reject_input(self, kind: str, reason: str):
        self._counters[kind].reject(reason)
        self.last_input_rejection = reason

    def _process(self, horizon: float) -> list[NavSolution]:
        """Filter the buffered data up to ``horizon``: the solutions of the processed IMU
        samples, unless ``realtime_output`` predicts them ahead instead."""
        emit_solutions = not self.config.realtime_output
        solutions: list[NavSolution] = []
        buffer = self._imu_buffer
        measurements = self._measurements
        while buffer and buffer[0][0] <= horizon:
            t, gyro, force = buffer.popleft()
            if self._gyro is None or t - self._time > self.config.max_imu_gap_s:
                if self._gyro is not None:
                    self._restart_alignment()
                # Measurements up to the first sample of a run can only feed the alignment.
                while measurements and measurements[0][0] <= t:
                    self._handle_measurements(self._pop_same_stamp(), gyro)
                self._time, self._gyro, self._force = t, gyro, force
                self._older_imu = None
                self._last_processed_imu_stamp = t
                continue
            t0, gyro0, force0 = self._time, self._gyro, self._force
            older = self._older_imu
            t_older, gyro_older, force_older = older if older else (None, None, None)
            span = t - t0
            while measurements and measurements[0][0] <= t:
                group = self._pop_same_stamp()
                stamp = group[0][0]
                gyro_m = interpolate_sample(stamp, t0, gyro0, t, gyro, t_older, gyro_older)
                force_m = interpolate_sample(stamp, t0, force0, t, force, t_older, force_older)
                self._advance(stamp, gyro_m, force_m)
                self._handle_measurements(group, gyro_m)
            self._advance(t, gyro, force)
            self._older_imu = (t0, gyro0, force0)
            self._last_processed_imu_stamp = t
            if emit_solutions and self._filter is not None and self._output_due(t, span):
                solutions.append(
                    self._solution(self._integrator, self._time, self._gyro, self._force)
                )
        return solutions

    def _predict_ahead(self, sample) -> list[NavSolution]:
        """Real-time solutions up to the newest IMU ``sample`` (see the module docstring): its
        own, and after an alignment those of the buffered samples since."""
        if self._filter is None:
            return []
        max_gap = self.config.max_imu_gap_s
        solutions = []
        if self._ahead is None:
            integrator = self._integrator.fork()
            t, gyro, force = self._time, self._gyro, self._force
            self._ahead_forked_at = t
            samples = self._imu_buffer
            if t > self._last_predicted_stamp and self._output_due(t, 0.0):
                # The filter's own sample: the first one after an alignment.
                solutions.append(self._solution(integrator, t, gyro, force))
        else:
            integrator, t, gyro, force = self._ahead
            samples = (sample,)
        for t_next, gyro_next, force_next in samples:
            span = t_next - t
            if span > max_gap:
                # The filter restarts its alignment at this gap: nothing to predict from.
                self._ahead = None
                return solutions
            integrator.step(span, gyro, gyro_next, force, force_next)
            t, gyro, force = t_next, gyro_next, force_next
            if t > self._last_predicted_stamp and self._output_due(t, span):
                solutions.append(self._solution(integrator, t, gyro, force))
        self._last_predicted_stamp = t
        self._ahead = (integrator, t, gyro, force)
        return solutions

    def _pop_same_stamp(self) -> list:
        """Pop the earliest measurement and all others of the same stamp (in kind order)."""
        measurements = self._measurements
        group = [heapq.heappop(measurements)]
        while measurements and measurements[0][0] == group[0][0]:
            group.append(heapq.heappop(measurements))
        return group

    def _output_due(self, t: float, span: float) -> bool:
        """Decimation to ``output_rate_hz`` on a grid anchored at the first output."""
        period = self._output_period
        if period == 0.0:
            return True
        # Half an IMU step of tolerance absorbs stamp jitter and float rounding of the grid.
        if t + 0.5 * span < self._next_output_time:
            return False
        following = self._next_output_time + period
        self._next_output_time = following if following > t else t + period
        return True

    def _advance(self, t: float, gyro, force):
        """Integrate from the current state time to ``t`` (raw samples at both ends)."""
        dt = t - self._time
        if dt > 0.0:
            integrator = self._integrator
            if integrator is None:
                self._aligner.add_motion(dt, self._gyro, gyro, self._force, force)
            else:
                integrator.step(dt, self._gyro, gyro, self._force, force)
                interval = self.config.covariance_propagation_interval_s
                if integrator.accumulated_duration_s >= interval:
                    self._propagate_covariance()
        self._time, self._gyro, self._force = t, gyro, force

    def _propagate_covariance(self):
        integrator = self._integrator
        if integrator.accumulated_duration_s <= 0.0:
            return
        sums = integrator.take_propagation_sums()
        transition, noise = discrete_error_model(
            sums,
            integrator.latitude_rad,
            integrator.altitude_m,
            integrator.velocity_enu_mps,
            self._imu_model,
        )
        self._filter.propagate(transition, noise)
        self._covariance_blocks = None

    def _restart_alignment(self):
        self._imu_gaps += 1
        self._integrator = None
        self._filter = None
        self._aligner.restart()
        self._covariance_blocks = None
        self._ahead = None
        self._bias_arrays = None

    def _handle_measurements(self, group: list, gyro):
        """Apply the measurements of one stamp (raw gyro rate ``gyro`` at that stamp).

        Each measurement is gated on its own against the predicted covariance; the accepted
        ones are applied together in one stacked update, which equals applying them one after
        the other (their noises are independent) at a third of the cost.
        """
        t = group[0][0]
        group = self._without_superseded_headings(group)
        if not group:
            return
        for entry in group:
            self._buffered_stamps[entry[3]].discard(t)
        if self._filter is None:
            # Kind order puts the antenna attitude, which may complete the alignment, last.
            for _, _, _, kind, payload in group:
                self._align_with(kind, t, payload, gyro)
            return
        self._propagate_covariance()
        state = _nav_state(self._integrator)
        rotation = state.rotation_nb
        accepted = []
        persistent_rejections = []
        for _, _, _, kind, payload in group:
            model = self._measurement_model(kind, payload, state, rotation, gyro)
            counters = self._counters[kind]
            if model is None:
                counters.reject(GEOMETRY)
                continue
            gate = self._filter.gate(model.innovation, model.jacobian, model.covariance)
            if self.innovation_log is not None:
                self.innovation_log.append(
                    InnovationRecord(
                        t,
                        kind,
                        model.innovation,
                        gate.innovation_covariance,
                        gate.nis,
                        gate.accepted,
                    )
                )
            if gate.accepted:
                counters.accepted += 1
                counters.nis_sum += gate.nis
                counters.nis_count += 1
                self._last_accepted[kind] = t
                self._consecutive_rejections[kind] = 0
                accepted.append(model)
                continue
            counters.reject(GATE if math.isfinite(gate.nis) else SINGULAR)
            self._consecutive_rejections[kind] += 1
            if self._consecutive_rejections[kind] >= self.config.gate_reset_count:
                persistent_rejections.append((kind, payload, model))
        if accepted:
            correction = self._filter.update(
                np.concatenate([m.innovation for m in accepted]),
                np.vstack([m.jacobian for m in accepted]),
                _block_diagonal([m.covariance for m in accepted]),
            )
            self._inject(state, correction)
        for kind, payload, model in persistent_rejections:
            self._reset_to_measurement(kind, t, payload, gyro, model)

    def _without_superseded_headings(self, group: list) -> list:
        """The measurements of one stamp less the heading if a baseline has that stamp too
        (counted)."""
        t = group[0][0]
        if t not in self._buffered_stamps[GNSS_BASELINE]:
            return group
        kept = []
        for entry in group:
            if entry[3] == GNSS_HEADING:
                self._buffered_stamps[GNSS_HEADING].discard(t)
                self._counters[GNSS_HEADING].superseded += 1
            else:
                kept.append(entry)
        return kept

    def _measurement_model(self, kind, payload, state: NavState, rotation, gyro):
        """Linearised model of one measurement; None when the heading geometry is unusable."""
        config = self.config
        if kind == GNSS_FIX:
            return position_model(
                payload.latitude_rad,
                payload.longitude_rad,
                payload.altitude_m,
                payload.covariance_enu_m2,
                state.latitude_rad,
                state.longitude_rad,
                state.altitude_m,
                rotation,
                self._primary,
                config.gnss_position_variance_floor_m2,
            )
        if kind == GNSS_VELOCITY:
            return velocity_model(
                payload.velocity_enu_mps,
                payload.covariance_m2s2,
                state.velocity_enu_mps,
                rotation,
                gyro,
                state.gyro_bias_rad_s,
                self._integrator.nav_frame_rate_enu_rad_s,
                self._primary,
                config.gnss_velocity_variance_floor_m2s2,
            )
        if kind == GNSS_BASELINE:
            return baseline_vector_model(
                payload.baseline_enu_m,
                config.gnss_baseline_sigma_horizontal_m,
                config.gnss_baseline_sigma_vertical_m,
                rotation,
                self._baseline,
            )
        if horizontal_fraction(rotation, self._baseline) < MIN_HORIZONTAL_BASELINE_FRACTION:
            return None
        return heading_model(
            payload.yaw_rad,
            payload.variance_rad2,
            rotation,
            self._baseline,
            config.gnss_heading_variance_floor_rad2,
        )

    def _inject(self, state: NavState, correction):
        new_state = inject_error_state(state, correction)
        _set_nav_state(self._integrator, new_state)
        self._filter.reset_after_injection(correction)
        self._covariance_blocks = None
        self._bias_arrays = None
        if self._ahead is not None:
            if self._time >= self._ahead_forked_at + PREDICTION_RESYNC_INTERVAL_S:
                self._ahead = None
            else:
                self._carry_over(state, correction)

    def _carry_over(self, state: NavState, correction):
        """Apply a correction of the filter state ``state`` to the prediction ahead of it."""
        integrator, t_ahead, _, _ = self._ahead
        span = t_ahead - self._time
        dx = np.array(correction, dtype=float)
        if span > 0.0:
            rotation_integral = integrator.rotation_nb * span
            velocity_ahead = np.array(integrator.velocity_enu_mps)
            gravity = earth.normal_gravity_mps2(state.latitude_rad, state.altitude_m)
            force_increment = velocity_ahead - state.velocity_enu_mps
            force_increment[2] += gravity * span
            phi, dv = dx[ATTITUDE], dx[VELOCITY].copy()
            dx[POSITION] += dv * span
            dx[VELOCITY] += cross(phi, force_increment) - rotation_integral @ dx[ACCEL_BIAS]
            dx[ATTITUDE] -= rotation_integral @ dx[GYRO_BIAS]
        _set_nav_state(integrator, inject_error_state(_nav_state(integrator), dx))

    def _reset_to_measurement(self, kind, t, payload, gyro, model):
        """Re-initialise the states a persistently rejected measurement kind observes."""
        attitude_kind = kind in (GNSS_HEADING, GNSS_BASELINE)
        measured = self._antenna_heading(kind, payload) if attitude_kind else None
        if attitude_kind and measured is None:
            return
        state = _nav_state(self._integrator)
        counters = self._counters[kind]
        counters.resets += 1
        self._consecutive_rejections[kind] = 0
        self._last_accepted[kind] = t
        rotation = state.rotation_nb
        if attitude_kind:
            azimuth, variance = measured
            roll, pitch, _ = euler_from_rotation_matrix(rotation)
            levelled = rotation_matrix_from_euler(roll, pitch, 0.0) @ self._baseline
            yaw = azimuth - math.atan2(levelled[1], levelled[0])
            new_rotation = rotation_matrix_from_euler(roll, pitch, yaw)
            new_state = NavState(
                quaternion_from_rotation_matrix(new_rotation),
                state.velocity_enu_mps,
                state.latitude_rad,
                state.longitude_rad,
                state.altitude_m,
                state.gyro_bias_rad_s,
                state.accel_bias_mps2,
            )
            self._filter.reset_states([2], [variance])
        elif kind == GNSS_VELOCITY:
            velocity = payload.velocity_enu_mps - (
                predicted_antenna_velocity_enu_mps(
                    np.zeros(3),
                    rotation,
                    np.asarray(gyro) - state.gyro_bias_rad_s,
                    self._integrator.nav_frame_rate_enu_rad_s,
                    self._primary,
                )
            )
            new_state = NavState(
                state.attitude_xyzw,
                velocity,
                state.latitude_rad,
                state.longitude_rad,
                state.altitude_m,
                state.gyro_bias_rad_s,
                state.accel_bias_mps2,
            )
            self._filter.reset_states(range(3, 6), np.diag(model.covariance))
        else:
            latitude, longitude, altitude = earth.geodetic_offset(
                payload.latitude_rad,
                payload.longitude_rad,
                payload.altitude_m,
                -(rotation @ self._primary),
            )
            new_state = NavState(
                state.attitude_xyzw,
                state.velocity_enu_mps,
                latitude,
                longitude,
                altitude,
                state.gyro_bias_rad_s,
                state.accel_bias_mps2,
            )
            self._filter.reset_states(range(6, 9), np.diag(model.covariance))
        _set_nav_state(self._integrator, new_state)
        self._filter.ensure_positive_definite()
        self._covariance_blocks = None
        self._ahead = None

    def _align_with(self, kind: str, t: float, payload, gyro):
        counters = self._counters[kind]
        counters.used_for_alignment += 1
        aligner = self._aligner
        if kind == GNSS_FIX:
            aligner.add_fix(
                t,
                payload.latitude_rad,
                payload.longitude_rad,
                payload.altitude_m,
                payload.covariance_enu_m2,
            )
            return
        if kind == GNSS_VELOCITY:
            aligner.add_velocity(t, payload.velocity_enu_mps, payload.covariance_m2s2)
            return
        measured = self._antenna_heading(kind, payload)
        if measured is None:
            return
        result = aligner.add_heading(t, *measured, gyro)
        if result is None:
            return
        state = result.state
        self._integrator = StrapdownIntegrator(
            state.attitude_xyzw,
            state.velocity_enu_mps,
            state.latitude_rad,
            state.longitude_rad,
            state.altitude_m,
            state.gyro_bias_rad_s,
            state.accel_bias_mps2,
        )
        self._filter = ErrorStateFilter(result.covariance, self.config.gate_probability)
        self._alignment = result
        self._alignments += 1
        for measurement_kind in MEASUREMENT_KINDS:
            self._last_accepted[measurement_kind] = t
            self._consecutive_rejections[measurement_kind] = 0
        if self._map_plane is None:
            self._map_plane = earth.LocalTangentPlane(
                state.latitude_rad, state.longitude_rad, state.altitude_m
            )
        self._next_output_time = -math.inf
        self._covariance_blocks = None
        self._bias_arrays = None
        self._ahead = None

    def _antenna_heading(self, kind: str, payload) -> tuple[float, float] | None:
        """Baseline azimuth (rad, ENU) and its variance (rad², floored) of a heading or a
        baseline measurement; None for a baseline too steep to give one."""
        config = self.config
        if kind == GNSS_HEADING:
            yaw, variance = payload.yaw_rad, payload.variance_rad2
        else:
            yaw, horizontal_length = baseline_azimuth_rad(payload.baseline_enu_m)
            if horizontal_length < MIN_HORIZONTAL_BASELINE_FRACTION * self._baseline_length_m:
                return None
            variance = (config.gnss_baseline_sigma_horizontal_m / horizontal_length) ** 2
        return yaw, max(variance, config.gnss_heading_variance_floor_rad2)

    # ------------------------------------------------------------------ output
    def _coasting_flags(self, t: float) -> tuple[bool, bool, bool]:
        timeout = self.config.coasting_timeout_s
        last = self._last_accepted
        return (
            t - last[GNSS_FIX] > timeout,
            t - last[GNSS_VELOCITY] > timeout,
            t - max(last[GNSS_HEADING], last[GNSS_BASELINE]) > timeout,
        )

    def _solution(self, integrator: StrapdownIntegrator, t: float, gyro, force) -> NavSolution:
        """The solution of ``integrator``'s state at stamp ``t`` (raw gyro and force there)."""
        if self._covariance_blocks is None:
            covariance = self._filter.covariance
            # Shared by the solutions until P changes again, hence read-only.
            self._covariance_blocks = tuple(
                _read_only(covariance[block, block].copy())
                for block in (ATTITUDE, VELOCITY, POSITION)
            )
        if self._bias_arrays is None:
            self._bias_arrays = (
                _read_only(np.array(integrator.gyro_bias_rad_s)),
                _read_only(np.array(integrator.accel_bias_mps2)),
            )
        bgx, bgy, bgz = integrator.gyro_bias_rad_s
        bax, bay, baz = integrator.accel_bias_mps2
        gx, gy, gz = gyro
        fx, fy, fz = force
        wx, wy, wz = gx - bgx, gy - bgy, gz - bgz
        r00, r01, r02, r10, r11, r12, r20, r21, r22 = integrator.rotation_elements
        ie, in_, iu = integrator.nav_frame_rate_enu_rad_s
        latitude = integrator.latitude_rad
        longitude = integrator.longitude_rad
        altitude = integrator.altitude_m
        # Coasting is judged where the filter is: measurements ahead of it are not yet used.
        coasting = self._coasting_flags(self._time)
        attitude_cov, velocity_cov, position_cov = self._covariance_blocks
        gyro_bias, accel_bias = self._bias_arrays
        return NavSolution(
            t_s=t,
            attitude_xyzw=np.array(integrator.attitude_xyzw),
            angular_rate_body_rad_s=np.array((wx, wy, wz)),
            angular_rate_nb_body_rad_s=np.array(
                (
                    wx - (r00 * ie + r10 * in_ + r20 * iu),
                    wy - (r01 * ie + r11 * in_ + r21 * iu),
                    wz - (r02 * ie + r12 * in_ + r22 * iu),
                )
            ),
            specific_force_body_mps2=np.array((fx - bax, fy - bay, fz - baz)),
            velocity_enu_mps=np.array(integrator.velocity_enu_mps),
            latitude_deg=math.degrees(latitude),
            longitude_deg=math.degrees(longitude),
            altitude_m=altitude,
            position_map_m=np.array(
                self._map_plane.enu_from_geodetic_scalar(latitude, longitude, altitude)
            ),
            attitude_covariance_rad2=attitude_cov,
            velocity_covariance_m2s2=velocity_cov,
            position_covariance_m2=position_cov,
            gyro_bias_rad_s=gyro_bias,
            accel_bias_mps2=accel_bias,
            aligned=True,
            coasting_fix=coasting[0],
            coasting_velocity=coasting[1],
            coasting_heading=coasting[2],
        )


def _nav_state(integrator: StrapdownIntegrator) -> NavState:
    return NavState(
        attitude_xyzw=integrator.attitude_xyzw,
        velocity_enu_mps=np.array(integrator.velocity_enu_mps),
        latitude_rad=integrator.latitude_rad,
        longitude_rad=integrator.longitude_rad,
        altitude_m=integrator.altitude_m,
        gyro_bias_rad_s=np.array(integrator.gyro_bias_rad_s),
        accel_bias_mps2=np.array(integrator.accel_bias_mps2),
    )


def _set_nav_state(integrator: StrapdownIntegrator, state: NavState):
    integrator.set_state(
        state.attitude_xyzw,
        state.velocity_enu_mps,
        state.latitude_rad,
        state.longitude_rad,
        state.altitude_m,
        state.gyro_bias_rad_s,
        state.accel_bias_mps2,
    )


def _read_only(array: np.ndarray) -> np.ndarray:
    array.setflags(write=False)
    return array


def _block_diagonal(blocks) -> np.ndarray:
    size = sum(block.shape[0] for block in blocks)
    matrix = np.zeros((size, size))
    offset = 0
    for block in blocks:
        n = block.shape[0]
        matrix[offset : offset + n, offset : offset + n] = block
        offset += n
    return matrix


def _float_triple(values) -> tuple[float, float, float]:
    """Three floats from a 3-element array or sequence (ValueError/TypeError otherwise)."""
    if isinstance(values, np.ndarray) and values.dtype == np.float64:
        x, y, z = values.tolist()
        return x, y, z
    x, y, z = values
    return float(x), float(y), float(z)


def _floats(*values) -> tuple[tuple[float, ...] | None, str | None]:
    """Scalar inputs as floats, or (None, reason) when one is malformed or not finite."""
    try:
        numbers = tuple(float(v) for v in values)
    except (TypeError, ValueError):
        return None, MALFORMED
    if not all(math.isfinite(n) for n in numbers):
        return None, NON_FINITE
    return numbers, None


def _float_array(values, shape: tuple[int, ...]) -> tuple[np.ndarray | None, str | None]:
    """An input as a float array of ``shape`` (a 3×3 may come row-major flat), or (None, reason)."""
    try:
        array = np.array(values, dtype=float)
    except (TypeError, ValueError):
        return None, MALFORMED
    if array.size == math.prod(shape) and array.ndim == 1:
        array = array.reshape(shape)
    if array.shape != shape:
        return None, MALFORMED
    if not np.all(np.isfinite(array)):
        return None, NON_FINITE
    return array, None
