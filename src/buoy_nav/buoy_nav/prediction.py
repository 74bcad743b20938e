"""Real-time prediction: the filter's nominal state integrated ahead to the newest IMU sample.

The filter runs ``max_measurement_delay_s`` behind the newest IMU stamp so that late
measurements are applied in stamp order. With ``realtime_output`` a solution must nevertheless
leave with its IMU sample: a copy of the filter's nominal state (forked from its integrator) is
integrated ahead through the buffered IMU samples to the newest one and on with each new sample.

Each correction of the filter is carried over to the copy through the error dynamics over the
span between them (attitude error plus gyro-bias drift, velocity error plus the attitude error
acting on the specific-force increment and the accelerometer-bias change, position error plus
velocity error times the span), exact to first order; once per
:data:`PREDICTION_RESYNC_INTERVAL_S` of stamps the copy is instead forked afresh from the filter,
so second-order residues cannot accumulate. The prediction depends only on stamps, so a live
node and an offline run of the same data give the same solutions.
"""

import math
from collections.abc import Iterable

import numba
import numpy as np

from buoy_nav import earth
from buoy_nav.error_state_filter import ErrorStateFilter, NavState
from buoy_nav.mechanization import StrapdownIntegrator
from buoy_nav.rotations import cross_components
from buoy_nav.solution import Emitted, OutputDecimation, SolutionBuilder
from buoy_nav.state_layout import UP
from buoy_nav.strapdown_kernel import (
    ERROR_ACCEL_BIAS,
    ERROR_ATTITUDE,
    ERROR_GYRO_BIAS,
    ERROR_POSITION,
    ERROR_VELOCITY,
    ROTATION,
    STATE_SIZE,
    VELOCITY,
)

_cross = numba.njit(cache=True)(cross_components)
_normal_gravity_mps2 = numba.njit(cache=True)(earth.normal_gravity_mps2)

# Longest run of carried-over corrections before the real-time prediction is forked afresh from
# the filter (s of stamps): bounds the second-order residue of the carry-over (≪ 1e-6 rad).
PREDICTION_RESYNC_INTERVAL_S = 1.0


class RealtimePrediction:
    """The copy integrated ahead of the filter (see the module docstring); its solutions come
    from ``solutions`` at the rate ``output`` lets through. The corrections carried over are
    of :data:`buoy_nav.error_state_filter.ERROR_STATES`.
    """

    def __init__(
        self,
        max_imu_gap_s: float,
        solutions: SolutionBuilder,
        output: OutputDecimation,
    ):
        self._max_imu_gap_s = max_imu_gap_s
        self._solutions = solutions
        self._output = output
        # (integrator ahead of the filter, its time, raw gyro and force at that time); None when
        # it must be forked again from the filter.
        self._ahead: tuple[StrapdownIntegrator, float, tuple, tuple] | None = None
        self._forked_at = -math.inf
        self._last_predicted_stamp = -math.inf

    def drop(self) -> None:
        """Fork afresh from the filter at the next sample (after a reset or an alignment)."""
        self._ahead = None

    def predict(
        self,
        kalman: ErrorStateFilter,
        filter_integrator: StrapdownIntegrator,
        filter_sample: tuple,
        buffered_samples: Iterable[tuple],
        sample: tuple,
        coasting: tuple[bool, bool, bool],
    ) -> list[Emitted]:
        """The solutions up to the newest IMU ``sample`` (t, raw gyro, raw force): its own, and
        after a fork from the filter (whose state is at ``filter_sample``, the (t, raw gyro, raw
        force) it refers to) also those of the ``buffered_samples`` ahead of the filter, the
        newest included. Their covariances are ``kalman``'s, their coasting flags
        ``coasting``."""
        due = self._output.due
        solution = self._solutions.emit
        solutions = []
        if self._ahead is None:
            integrator = filter_integrator.fork()
            t, gyro, force = filter_sample
            self._forked_at = t
            samples = buffered_samples
            if t > self._last_predicted_stamp and due(t, 0.0):
                # The filter's own sample: the first one after an alignment.
                solutions.append(solution(integrator, kalman, t, gyro, force, coasting))
        else:
            integrator, t, gyro, force = self._ahead
            samples = (sample,)
        max_gap = self._max_imu_gap_s
        for t_next, gyro_next, force_next in samples:
            span = t_next - t
            if span > max_gap:
                # The filter restarts its alignment at this gap: nothing to predict from.
                self._ahead = None
                return solutions
            integrator.step(span, gyro, gyro_next, force, force_next)
            t, gyro, force = t_next, gyro_next, force_next
            if t > self._last_predicted_stamp and due(t, span):
                solutions.append(solution(integrator, kalman, t, gyro, force, coasting))
        self._last_predicted_stamp = t
        self._ahead = (integrator, t, gyro, force)
        return solutions

    @property
    def ahead(self) -> tuple[StrapdownIntegrator, float, tuple, tuple] | None:
        """(the copy ahead, its stamp s, raw gyro and force there), None when it is to be
        forked afresh at the next sample."""
        return self._ahead

    @property
    def last_predicted_stamp_s(self) -> float:
        """The stamp of the latest sample predicted (s)."""
        return self._last_predicted_stamp

    @property
    def forked_at_s(self) -> float:
        """The filter stamp (s) the copy ahead was last forked at."""
        return self._forked_at

    @property
    def resync_at_s(self) -> float:
        """The filter stamp (s) from which a correction drops the copy ahead, to be forked
        afresh."""
        return self._forked_at + PREDICTION_RESYNC_INTERVAL_S

    def quiet_fork(self, filter_sample: tuple, buffered_samples: Iterable[tuple]) -> tuple | None:
        """When the copy is to be forked afresh at the next sample: the newest of the filter's
        sample and the ``buffered_samples`` ahead of it (each (t, raw gyro, raw force)), which
        the fork would be stepped through without a solution (each was predicted before) nor a
        gap; None when it is not to be forked or would not be so."""
        if self._ahead is not None:
            return None
        newest = filter_sample
        if newest[0] > self._last_predicted_stamp:
            return None
        for sample in buffered_samples:
            t = sample[0]
            if t - newest[0] > self._max_imu_gap_s or t > self._last_predicted_stamp:
                return None
            newest = sample
        return newest

    def predicted_through(
        self,
        integrator: StrapdownIntegrator,
        sample: tuple,
        forked_at_s: float,
        fork_due: bool,
    ) -> None:
        """The copy ahead (``integrator``) was stepped through a stretch of samples to
        ``sample`` (stamp s, raw gyro, raw force), in place (:mod:`buoy_nav.imu_stretch`), last
        forked at the filter stamp ``forked_at_s`` (s) and to be forked afresh (``fork_due``)
        or not."""
        self._ahead = None if fork_due else (integrator, *sample)
        self._forked_at = forked_at_s
        self._last_predicted_stamp = sample[0]

    def carry_over(self, filter_time: float, state: NavState, correction) -> None:
        """Apply the filter's ``correction`` of its nominal ``state`` at ``filter_time`` to the
        copy ahead (or drop the copy when it is due to be forked afresh)."""
        if self._ahead is None:
            return
        if filter_time >= self.resync_at_s:
            self._ahead = None
            return
        integrator, t_ahead, _, _ = self._ahead
        span = t_ahead - filter_time
        dx = np.array(correction, dtype=float)
        if span > 0.0:
            carry_over_kernel(
                integrator.state_vector,
                state.velocity_enu_mps,
                state.latitude_rad,
                state.altitude_m,
                span,
                dx,
            )
        integrator.inject(dx)


def load_compiled_carry_over() -> None:
    """Compile the carry-over, or load it from the cache, now (see
    :func:`buoy_nav.mechanization.load_compiled_kernels`)."""
    carry_over_kernel(
        np.zeros(STATE_SIZE), np.zeros(3), 0.7, 0.0, 0.1, np.zeros(ERROR_ACCEL_BIAS + 3)
    )


@numba.njit(cache=True)
def carry_over_kernel(
    ahead, filter_velocity_enu_mps, filter_latitude_rad, filter_altitude_m, span_s, error
):
    """Carry the filter's ``error`` (ERROR_STATES) over ``span_s`` (s) to the copy ahead, whose
    state vector (strapdown_kernel layout) is ``ahead``, in place: δp += δv T,
    δv += φ × Δv_f − ∫R dt δb_a, φ −= ∫R dt δb_g, with R_nb of the copy held over the span and
    Δv_f the specific-force increment (ENU m/s) from the filter's velocity to the copy's
    (the normal gravity at the filter's latitude (rad) and altitude (m) added back)."""
    gravity_mps2 = _normal_gravity_mps2(filter_latitude_rad, filter_altitude_m)
    force_increment = [ahead[VELOCITY + i] - filter_velocity_enu_mps[i] for i in range(3)]
    force_increment[UP] += gravity_mps2 * span_s
    turned = _cross(
        (error[ERROR_ATTITUDE], error[ERROR_ATTITUDE + 1], error[ERROR_ATTITUDE + 2]),
        (force_increment[0], force_increment[1], force_increment[2]),
    )
    for i in range(3):
        error[ERROR_POSITION + i] += error[ERROR_VELOCITY + i] * span_s
    for i in range(3):
        accel_bias, gyro_bias = 0.0, 0.0
        for j in range(3):
            rotation_integral = ahead[ROTATION + 3 * i + j] * span_s
            accel_bias += rotation_integral * error[ERROR_ACCEL_BIAS + j]
            gyro_bias += rotation_integral * error[ERROR_GYRO_BIAS + j]
        error[ERROR_VELOCITY + i] += turned[i] - accel_bias
        error[ERROR_ATTITUDE + i] -= gyro_bias
