"""The aided navigation between two alignments: the strapdown integrator that carries the
nominal state, the error-state filter that corrects it, and the recorder told of every change
of the filter (:mod:`buoy_nav.epoch_recorder`).

The covariance is propagated in batches of at most ``covariance_propagation_interval_s`` and
always up to a measurement stamp before an update (the batching is exact to first order, see
:mod:`buoy_nav.error_state_filter`).
"""

import numpy as np

from buoy_nav.aiding.base import LinearisationPoint, MeasurementModel, StateReset
from buoy_nav.alignment import AlignmentResult
from buoy_nav.config import FusionConfig
from buoy_nav.epoch_recorder import EpochRecorder
from buoy_nav.error_dynamics import (
    noise_coefficients,
    propagated_covariance,
    stepped_covariance,
)
from buoy_nav.error_state_filter import (
    ErrorStateFilter,
    ImuErrorModel,
    StackedUpdate,
    block_diagonal,
)
from buoy_nav.mechanization import StrapdownIntegrator
from buoy_nav.state_layout import StateLayout


class AidedNavigation:
    """The filter started from the alignment ``result`` at stamp ``t_s`` (s), over the error
    states ``states``, with the IMU's error model ``imu_model``; tells ``recorder`` of each
    epoch, correction and reset."""

    def __init__(
        self,
        result: AlignmentResult,
        t_s: float,
        config: FusionConfig,
        states: StateLayout,
        imu_model: ImuErrorModel,
        recorder: EpochRecorder,
    ):
        state = result.state
        self.integrator = StrapdownIntegrator(
            state.attitude_xyzw,
            state.velocity_enu_mps,
            state.latitude_rad,
            state.longitude_rad,
            state.altitude_m,
            state.gyro_bias_rad_s,
            state.accel_bias_mps2,
        )
        self.kalman = ErrorStateFilter(result.covariance, config.gate_probability, states)
        self._propagation_interval_s = config.covariance_propagation_interval_s
        self._imu_model = imu_model
        self.gyro_drift_scale = 1.0
        """Factor on the σ of the gyro's drift in the process noise (the aiding sources')."""
        self.accel_noise_scale = 1.0
        """Factor on the σ of the accelerometer's velocity random walk (the sources')."""
        self._recorder = recorder
        recorder.begin_segment(t_s, self.kalman.covariance)

    def integrate(self, t_s: float, dt_s: float, gyro_start, gyro_end, force_start, force_end):
        """Integrate the ``dt_s`` (s) up to stamp ``t_s`` (s) between two raw IMU samples (body:
        rad/s, m/s²), and propagate the covariance when a batch is full. Returns whether it
        was propagated."""
        integrator = self.integrator
        integrator.step(dt_s, gyro_start, gyro_end, force_start, force_end)
        if integrator.accumulated_duration_s >= self._propagation_interval_s:
            return self.propagate_covariance(t_s)
        return False

    def integrate_and_propagate(
        self, t_s: float, dt_s: float, gyro_start, gyro_end, force_start, force_end
    ) -> None:
        """:meth:`integrate` and then :meth:`propagate_covariance`, to stamp ``t_s`` (s), in
        one compiled call: the step to a stamp a measurement is applied at, whose covariance
        is always propagated (the same arithmetic, whether or not a batch was full)."""
        integrator = self.integrator
        posterior = self.kalman.covariance
        transition, self.kalman.covariance = stepped_covariance(
            integrator.state_vector,
            posterior,
            dt_s,
            gyro_start,
            gyro_end,
            force_start,
            force_end,
            (integrator.coning_correction, integrator.sculling_correction),
            self._imu_model,
            self.gyro_drift_scale,
            self.accel_noise_scale,
        )
        self._recorder.propagated(t_s, transition, self.kalman.covariance, posterior)

    def noise_terms(self) -> tuple[float, ...]:
        """The process noise's terms the covariance is propagated with now
        (:func:`~buoy_nav.error_dynamics.noise_coefficients`)."""
        return noise_coefficients(self._imu_model, self.gyro_drift_scale, self.accel_noise_scale)

    @property
    def records_epochs(self) -> bool:
        """Whether the recorder keeps the epochs (a smoother's), not the engine's default."""
        return type(self._recorder) is not EpochRecorder

    def propagate_covariance(self, t_s: float) -> bool:
        """Propagate the covariance over the interval integrated so far, to stamp ``t_s`` (s).
        Returns whether there was an interval to propagate over."""
        integrator = self.integrator
        if integrator.accumulated_duration_s <= 0.0:
            return False
        posterior = self.kalman.covariance
        transition, self.kalman.covariance = propagated_covariance(
            integrator.state_vector,
            posterior,
            self._imu_model,
            self.gyro_drift_scale,
            self.accel_noise_scale,
        )
        self._recorder.propagated(t_s, transition, self.kalman.covariance, posterior)
        return True

    def linearisation_point(self, raw_gyro_rad_s) -> LinearisationPoint:
        """The nominal state now, for the models of measurements at the current stamp (raw gyro
        sample there, body rad/s)."""
        integrator = self.integrator
        state = integrator.nav_state()
        return LinearisationPoint(
            state, state.rotation_nb, raw_gyro_rad_s, integrator.nav_frame_rate_enu_rad_s
        )

    def correct(self, models: list[MeasurementModel]) -> np.ndarray:
        """Apply the accepted ``models`` of one stamp (linearised at the nominal state now) in
        one stacked update, which equals applying them one after the other (their noises are
        independent) at a fraction of the cost, and inject the correction into the nominal
        state. Returns the correction."""
        if len(models) == 1:
            (model,) = models
            correction = self.kalman.update(model.innovation, model.jacobian, model.covariance)
        else:
            correction = self.kalman.update(*_stacked(models))
        self.integrator.inject(correction)
        self.kalman.reset_after_injection(correction)
        self._recorder.corrected(correction)
        return correction

    def gated_update(self, models: list[MeasurementModel], probabilities) -> StackedUpdate:
        """Gate each of the ``models`` of one stamp (linearised at the nominal state now) at its
        chi-square probability (``probabilities``, in order) and, when each passes, the stacked
        update of :meth:`correct`, in one compiled call, each gated with its gate's noise;
        nothing is changed (take the update with :meth:`apply_correction`)."""
        gate_covariance = None
        if any(model.gate_covariance is not None for model in models):
            gate_covariance = block_diagonal([model.gated_covariance for model in models])
        return self.kalman.gated_update(
            *_stacked(models),
            [model.innovation.shape[0] for model in models],
            probabilities,
            gate_covariance,
        )

    def apply_correction(self, correction, covariance, positive_definite: bool) -> None:
        """Inject a ``correction`` computed elsewhere (a source's compiled update, the same
        arithmetic as :meth:`correct` of one model) and take ``covariance``, the covariance
        after it and the reset, repaired when not ``positive_definite``."""
        self.integrator.inject(correction)
        self.kalman.adopt_reset_covariance(covariance, positive_definite)
        self._recorder.corrected(correction)

    def reset(self, t_s: float, reset: StateReset) -> None:
        """Re-initialise the states of ``reset`` at stamp ``t_s`` (s): a new segment for the
        recorder, since the nominal state is set other than by a correction."""
        self._recorder.end_segment(self.kalman.covariance)
        self.integrator.set_nav_state(reset.state)
        self.kalman.reset_states(reset.indices, reset.variances)
        self.kalman.ensure_positive_definite()
        self._recorder.begin_segment(t_s, self.kalman.covariance)

    def inflate(self, t_s: float, variances: tuple[float, float]) -> None:
        """Widen the attitude and velocity uncertainty at stamp ``t_s`` (s) by ``variances``
        (attitude rad², velocity m²/s², per axis): the filter has found itself wrong."""
        states = self.kalman.states
        covariance = self.kalman.covariance.copy()
        attitude_variance, velocity_variance = variances
        for index in states.indices("attitude"):
            covariance[index, index] += attitude_variance
        for index in states.indices("velocity"):
            covariance[index, index] += velocity_variance
        self._recorder.noise_added(t_s, self.kalman.covariance, covariance)
        self.kalman.covariance = covariance

    def widen(self, t_s: float, factor: float) -> None:
        """Multiply the attitude and velocity variances at stamp ``t_s`` (s) by ``factor`` (≥ 1),
        as added noise: the filter has found them that much too small."""
        states = self.kalman.states
        covariance = self.kalman.covariance.copy()
        for index in (*states.indices("attitude"), *states.indices("velocity")):
            covariance[index, index] *= factor
        self._recorder.noise_added(t_s, self.kalman.covariance, covariance)
        self.kalman.covariance = covariance


def _stacked(models: list[MeasurementModel]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The innovations, Jacobians and noises of ``models`` stacked: ν (m,), H (m × states) and
    the block-diagonal R (m × m)."""
    return (
        np.concatenate([m.innovation for m in models]),
        np.vstack([m.jacobian for m in models]),
        block_diagonal([m.covariance for m in models]),
    )
