"""Strapdown mechanization in the local-level East-North-Up frame.

The integrator carries the nominal navigation state (attitude ``R_nb``, ENU velocity of the
``base_link`` origin, geodetic position, IMU bias estimates) from one IMU sample to the next.

Inputs are instantaneous samples (gyro rate ω_ib in rad/s and specific force in m/s², body
frame), not increments. Each step forms the angle and velocity increments of the interval by
integrating the parabola through the last three samples (the trapezoid rule plus a curvature
term; for equal steps the Adams-Moulton weights (−1, 8, 5)/12), then corrects them for coning
and sculling with the two-sample previous-increment algorithms. The plain trapezoid would
overstate an oscillating rate by (ΩT)²/12, and for coning motion that alone drifts as much as
the uncorrected coning term, which would leave the coning correction only half effective.
The coning and sculling corrections are exact when the rate and specific force vary linearly
across the two intervals. For intervals of unequal length (a step split at a measurement stamp)
both the curvature term and the corrections use the factor ``k = T² / (6 T_prev (T_prev + T))``,
which is 1/12 for equal lengths. The first step after (re)initialisation uses the trapezoid
without corrections.

Attitude update: ``R_nb(k) = Exp(−ω_in T) · R_nb(k−1) · Exp(φ_k)`` with φ_k the coning-corrected
rotation vector of the body and ω_in = ω_ie + ω_en the rotation of ENU with respect to inertial
space. Velocity update: the specific-force increment, rotation-compensated to third order and
sculling-corrected, turned into ENU with the start attitude (plus half the navigation-frame
rotation), then gravity and Coriolis. Position update: trapezoid on velocity, converted to
latitude/longitude with the WGS-84 radii of curvature.

Over the steps since the last covariance propagation it also sums what the discrete error model
needs (:class:`PropagationSums`). The step is compiled (:mod:`buoy_nav.strapdown_kernel`) and
updates in place the one array that holds the integrator's state.
"""

import contextlib
import copy
import signal
import threading
from dataclasses import dataclass

import numpy as np

from buoy_nav.config import FusionConfig
from buoy_nav.error_dynamics import (
    discrete_error_model,
    propagated_covariance,
    stepped_covariance,
)
from buoy_nav.error_state_filter import (
    ERROR_STATES,
    ErrorStateFilter,
    ImuErrorModel,
    NavState,
)
from buoy_nav.rotations import (
    Quaternion,
)
from buoy_nav.strapdown_kernel import (
    ACCEL_BIAS,
    ALTITUDE,
    ATTITUDE,
    DURATION,
    FORCE_DEVIATION_SQ_SUM,
    FORCE_SUM,
    GYRO_BIAS,
    LATITUDE,
    LONGITUDE,
    NAV_FRAME_RATE,
    RATE_SQ_SUM,
    ROTATION,
    ROTATION_SUM,
    STATE_SIZE,
    VELOCITY,
    inject_error_state,
    store_nominal,
    strapdown_step,
)


@dataclass(frozen=True)
class PropagationSums:
    """Integrals over the IMU steps since the last covariance propagation.

    duration_s: total time T (s).
    rotation_integral_s: ∫ R_nb dt (3×3, s); maps body-frame sensor errors into ENU.
    specific_force_increment_enu_mps: ∫ f^n dt (ENU, m/s); couples attitude error into velocity.
    gyro_rate_sq_integral_rad2_s: ∫ ω_ib² dt per body axis (rad²/s), for the scale-factor noise.
    force_deviation_sq_integral_m2_s3: ∫ (f − (0, 0, g))² dt per body axis (m²/s³): the specific
      force a floating, upright ``base_link`` sees beyond gravity, for the scale-factor noise
      (the gravity part of a scale-factor error is constant and taken up by the bias state).
    """

    duration_s: float
    rotation_integral_s: np.ndarray
    specific_force_increment_enu_mps: np.ndarray
    gyro_rate_sq_integral_rad2_s: np.ndarray
    force_deviation_sq_integral_m2_s3: np.ndarray


class StrapdownIntegrator:
    """Nominal navigation state integrated from consecutive IMU samples.

    Attributes (read them, and change the state only through :meth:`set_state`):
      attitude_xyzw: quaternion of R_nb (body FLU → ENU).
      rotation_elements: R_nb as a row-major 9-tuple.
      nav_frame_rate_enu_rad_s: ω_in = ω_ie + ω_en used by the last step (ENU, rad/s).
      accumulated_duration_s: time integrated since the last :meth:`take_propagation_sums`.
      velocity_enu_mps: velocity of the ``base_link`` origin over ground, ENU.
      latitude_rad, longitude_rad, altitude_m: WGS-84 position of the ``base_link`` origin.
      gyro_bias_rad_s, accel_bias_mps2: bias estimates subtracted from the raw samples (body).
    """

    def __init__(
        self,
        attitude_xyzw,
        velocity_enu_mps,
        latitude_rad: float,
        longitude_rad: float,
        altitude_m: float,
        gyro_bias_rad_s=(0.0, 0.0, 0.0),
        accel_bias_mps2=(0.0, 0.0, 0.0),
        coning_correction: bool = True,
        sculling_correction: bool = True,
    ):
        self.coning_correction = coning_correction
        self.sculling_correction = sculling_correction
        # No previous step yet, and empty sums.
        self._state = np.zeros(STATE_SIZE)
        self.set_state(
            attitude_xyzw,
            velocity_enu_mps,
            latitude_rad,
            longitude_rad,
            altitude_m,
            gyro_bias_rad_s,
            accel_bias_mps2,
        )

    def set_state(
        self,
        attitude_xyzw,
        velocity_enu_mps,
        latitude_rad: float,
        longitude_rad: float,
        altitude_m: float,
        gyro_bias_rad_s,
        accel_bias_mps2,
    ):
        """Replace the nominal state (after a filter correction); increments history is kept."""
        state = self._state
        state[VELOCITY : VELOCITY + 3] = _floats(velocity_enu_mps)
        state[LATITUDE] = float(latitude_rad)
        state[LONGITUDE] = float(longitude_rad)
        state[ALTITUDE] = float(altitude_m)
        state[GYRO_BIAS : GYRO_BIAS + 3] = _floats(gyro_bias_rad_s)
        state[ACCEL_BIAS : ACCEL_BIAS + 3] = _floats(accel_bias_mps2)
        store_nominal(state, *_floats(attitude_xyzw))

    def inject(self, error) -> None:
        """Apply the error state ``error`` (:data:`buoy_nav.error_state_filter.ERROR_STATES`)
        to the nominal state, as a filter correction does; increments history is kept."""
        inject_error_state(self._state, np.asarray(error, dtype=float))

    @property
    def state_vector(self) -> np.ndarray:
        """The state vector itself (:mod:`buoy_nav.strapdown_kernel`'s layout), for code that
        reads it in bulk (compiled kernels, the solutions); it is changed only through this
        integrator's methods."""
        return self._state

    @property
    def attitude_xyzw(self) -> Quaternion:
        return tuple(self._state[ATTITUDE : ATTITUDE + 4].tolist())

    @property
    def rotation_elements(self) -> tuple[float, ...]:
        return tuple(self._state[ROTATION : ROTATION + 9].tolist())

    @property
    def velocity_enu_mps(self) -> tuple[float, float, float]:
        return tuple(self._state[VELOCITY : VELOCITY + 3].tolist())

    @property
    def latitude_rad(self) -> float:
        return float(self._state[LATITUDE])

    @property
    def longitude_rad(self) -> float:
        return float(self._state[LONGITUDE])

    @property
    def altitude_m(self) -> float:
        return float(self._state[ALTITUDE])

    @property
    def gyro_bias_rad_s(self) -> tuple[float, float, float]:
        return tuple(self._state[GYRO_BIAS : GYRO_BIAS + 3].tolist())

    @property
    def accel_bias_mps2(self) -> tuple[float, float, float]:
        return tuple(self._state[ACCEL_BIAS : ACCEL_BIAS + 3].tolist())

    @property
    def nav_frame_rate_enu_rad_s(self) -> tuple[float, float, float]:
        return tuple(self._state[NAV_FRAME_RATE : NAV_FRAME_RATE + 3].tolist())

    @property
    def accumulated_duration_s(self) -> float:
        return float(self._state[DURATION])

    def fork(self) -> "StrapdownIntegrator":
        """An independent copy that integrates ahead without touching this one's propagation
        sums (its own sums start empty)."""
        twin = copy.copy(self)
        twin._state = self._state.copy()
        twin._state[DURATION:] = 0.0
        return twin

    def nav_state(self) -> NavState:
        """The nominal state as a :class:`NavState` (arrays are copies)."""
        state = self._state
        return NavState(
            attitude_xyzw=self.attitude_xyzw,
            velocity_enu_mps=state[VELOCITY : VELOCITY + 3].copy(),
            latitude_rad=float(state[LATITUDE]),
            longitude_rad=float(state[LONGITUDE]),
            altitude_m=float(state[ALTITUDE]),
            gyro_bias_rad_s=state[GYRO_BIAS : GYRO_BIAS + 3].copy(),
            accel_bias_mps2=state[ACCEL_BIAS : ACCEL_BIAS + 3].copy(),
        )

    def set_nav_state(self, state: NavState):
        """:meth:`set_state` from a :class:`NavState`."""
        self.set_state(
            state.attitude_xyzw,
            state.velocity_enu_mps,
            state.latitude_rad,
            state.longitude_rad,
            state.altitude_m,
            state.gyro_bias_rad_s,
            state.accel_bias_mps2,
        )

    @property
    def rotation_nb(self) -> np.ndarray:
        """R_nb as a 3×3 array."""
        return self._state[ROTATION : ROTATION + 9].reshape(3, 3).copy()

    def step(self, dt_s: float, gyro_start, gyro_end, force_start, force_end):
        """Advance the state by ``dt_s`` (s) between two raw IMU samples.

        gyro_start, gyro_end: raw angular rate ω_ib at the start and end of the step (body, rad/s).
        force_start, force_end: raw specific force at the start and end (body, m/s²).
        The bias estimates are removed here.
        """
        # Handed over as scalars, so that tuples, lists and arrays alike run the one compiled
        # specialisation (a sequence type of its own would compile again in the data path).
        g0x, g0y, g0z = gyro_start
        g1x, g1y, g1z = gyro_end
        f0x, f0y, f0z = force_start
        f1x, f1y, f1z = force_end
        strapdown_step(
            self._state,
            dt_s,
            g0x,
            g0y,
            g0z,
            g1x,
            g1y,
            g1z,
            f0x,
            f0y,
            f0z,
            f1x,
            f1y,
            f1z,
            self.coning_correction,
            self.sculling_correction,
        )

    def take_propagation_sums(self) -> PropagationSums:
        """Return the integrals accumulated since the last call and restart them."""
        state = self._state
        sums = PropagationSums(
            duration_s=float(state[DURATION]),
            rotation_integral_s=state[ROTATION_SUM : ROTATION_SUM + 9].reshape(3, 3).copy(),
            specific_force_increment_enu_mps=state[FORCE_SUM : FORCE_SUM + 3].copy(),
            gyro_rate_sq_integral_rad2_s=state[RATE_SQ_SUM : RATE_SQ_SUM + 3].copy(),
            force_deviation_sq_integral_m2_s3=state[
                FORCE_DEVIATION_SQ_SUM : FORCE_DEVIATION_SQ_SUM + 3
            ].copy(),
        )
        state[DURATION:] = 0.0
        return sums


def load_compiled_kernels(*further_loads) -> None:
    """Compile the fusion's compiled functions, or load them from the cache, now, and then call
    each of ``further_loads`` (the same for the compiled code of other parts): a node calls this
    at start-up so that no sensor message ever waits for the compiler (up to 2 s on the first
    run after an install or a change of their source)."""
    with _stop_signals_held():
        _run_compiled_kernels()
        for load in further_loads:
            load()


@contextlib.contextmanager
def _stop_signals_held():
    """Hold SIGINT and SIGTERM until the block ends, then deliver them to the handlers they had.

    An exception raised inside numba's compiler or cache loader (a tool's signal handler raises
    KeyboardInterrupt) leaves its code library half-built: the process then fails on a later
    call or crashes at exit instead of stopping cleanly. Python runs signal handlers in the main
    thread only, so elsewhere there is nothing to hold."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    held, previous = [], {}
    for number in (signal.SIGINT, signal.SIGTERM):
        handler = signal.getsignal(number)
        if handler is not None:  # None: installed outside Python, cannot be put back
            previous[number] = signal.signal(number, lambda caught, _frame: held.append(caught))
    try:
        yield
    finally:
        for number, handler in previous.items():
            signal.signal(number, handler)
        for number in held:
            signal.raise_signal(number)


def _run_compiled_kernels() -> None:
    integrator = StrapdownIntegrator((0.0, 0.0, 0.0, 1.0), (0.0, 0.0, 0.0), 0.0, 0.0, 0.0)
    integrator.step(0.01, (0.0, 0.0, 0.0), (0.0, 0.0, 0.0), (0.0, 0.0, 9.8), (0.0, 0.0, 9.8))
    imu_model = ImuErrorModel.from_config(FusionConfig())
    propagated_covariance(integrator.state_vector.copy(), np.eye(ERROR_STATES.dim), imu_model)
    stepped_covariance(
        integrator.state_vector.copy(),
        np.eye(ERROR_STATES.dim),
        0.01,
        (0.0, 0.0, 0.0),
        (0.0, 0.0, 0.0),
        (0.0, 0.0, 9.8),
        (0.0, 0.0, 9.8),
        (True, True),
        imu_model,
    )
    discrete_error_model(integrator.take_propagation_sums(), 0.0, 0.0, (0.0, 0.0, 0.0), imu_model)
    integrator.inject(np.zeros(ERROR_STATES.dim))
    kalman = ErrorStateFilter(np.eye(ERROR_STATES.dim), 0.99)
    kalman.propagate(np.eye(ERROR_STATES.dim), np.zeros((ERROR_STATES.dim, ERROR_STATES.dim)))
    jacobian = np.zeros((3, ERROR_STATES.dim))
    jacobian[:, ERROR_STATES.attitude] = np.eye(3)
    read_only = jacobian.copy()
    read_only.flags.writeable = False
    for model_jacobian in (jacobian, read_only):  # models may hand over read-only Jacobians
        kalman.gate(np.zeros(3), model_jacobian, np.eye(3))
    kalman.reset_after_injection(kalman.update(np.zeros(3), jacobian, np.eye(3)))
    kalman.gated_update(np.zeros(3), jacobian, np.eye(3), [3], [0.99])


def interpolate_sample(
    t_s: float, t_start: float, start, t_end: float, end, t_older=None, older=None
):
    """IMU sample (3 floats) at ``t_s`` within [t_start, t_end], for splitting a step there.

    With the sample before ``start`` (``t_older``, ``older``) it is read off the parabola through
    the three samples, the same parabola the integrator integrates over the step, so the two
    sub-steps add up to the unsplit step; without it, linear interpolation.
    """
    if older is None:
        fraction = (t_s - t_start) / (t_end - t_start)
        return tuple(a + (b - a) * fraction for a, b in zip(start, end, strict=True))
    w_older = (t_s - t_start) * (t_s - t_end) / ((t_older - t_start) * (t_older - t_end))
    w_start = (t_s - t_older) * (t_s - t_end) / ((t_start - t_older) * (t_start - t_end))
    w_end = (t_s - t_older) * (t_s - t_start) / ((t_end - t_older) * (t_end - t_start))
    return tuple(
        w_older * a + w_start * b + w_end * c for a, b, c in zip(older, start, end, strict=True)
    )


def _floats(values) -> tuple[float, ...]:
    return tuple(map(float, values))  # a sequence or array of numbers as Python floats
