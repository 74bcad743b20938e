"""GNSS velocity of the primary antenna (``gnss/vel``, geometry_msgs/TwistWithCovarianceStamped).

The antenna at lever arm ``l`` (``base_link``, m) moves over ground with

    v_ant = v + R_nb (ω_nb × l),   ω_nb = ω_ib − R_nb^T ω_in

(ENU, m/s), where ω_ib = ω_raw − b_g is the bias-corrected gyro rate (body, rad/s) and
ω_in = ω_ie + ω_en the rotation of ENU (rad/s). Equivalently
``v_ant = v + R_nb (ω_ib × l) − ω_in × (R_nb l)``.

Jacobian under the convention of :func:`buoy_nav.error_state_filter.inject_error_state`
(``R_true = Exp([φ×]) R_nb``, ``v_true = v + δv``, ``b_true = b + δb`` so ``ω_true = ω − δb``)::

    ∂v_ant/∂φ   = −[(R_nb (ω_ib × l))×] + [ω_in×][(R_nb l)×]
    ∂v_ant/∂δv  = I
    ∂v_ant/∂δb_g = R_nb [l×]

(the change of ω_in with δv, below 1e-6 of the other terms, is left out).

After persistent gate rejections the velocity is reset to the measured one less the lever-arm
term. In the alignment the latest velocity gives the initial velocity.
"""

from __future__ import annotations

from typing import NamedTuple

import numba
import numpy as np

from buoy_common.contract import GNSS_VELOCITY_TOPIC, Reason, header_seconds
from buoy_nav import strapdown_kernel
from buoy_nav.aiding.base import (
    GNSS_RECEIVER,
    VELOCITY,
    VELOCITY_REFERENCE,
    AidingSource,
    LinearisationPoint,
    MeasurementModel,
    StateReset,
    as_float_array,
    has_non_positive_variance,
    vector_of,
)
from buoy_nav.aiding.model_kernels import (
    cross,
    floored_covariance,
    place_block,
    place_identity,
    skew,
)
from buoy_nav.error_state_filter import NavState

# Where the strapdown state vector holds what the stretch's model reads.
_STATE_VELOCITY = strapdown_kernel.VELOCITY
_GYRO_BIAS = strapdown_kernel.GYRO_BIAS
_NAV_FRAME_RATE = strapdown_kernel.NAV_FRAME_RATE
# Beyond this speed over ground (m/s) a value is a malformed message, not a buoy's velocity.
MAX_SPEED_MPS = 100.0


class GnssVelocity(NamedTuple):
    """The primary antenna's velocity over ground (ENU, m/s) and its covariance (3×3 m²/s², or
    row-major flat)."""

    velocity_enu_mps: np.ndarray
    covariance_m2s2: np.ndarray


def predicted_antenna_velocity_enu_mps(
    velocity_enu_mps,
    rotation_nb,
    angular_rate_ib_body_rad_s,
    nav_frame_rate_enu_rad_s,
    lever_arm_body_m,
) -> np.ndarray:
    """Velocity over ground of a point at ``lever_arm_body_m`` of ``base_link`` (ENU, m/s)."""
    return _antenna_velocity(
        np.asarray(velocity_enu_mps, dtype=float),
        np.asarray(rotation_nb, dtype=float),
        np.asarray(angular_rate_ib_body_rad_s, dtype=float),
        np.asarray(nav_frame_rate_enu_rad_s, dtype=float),
        np.asarray(lever_arm_body_m, dtype=float),
    )[0]


@numba.njit(cache=True)
def _antenna_velocity(
    velocity_enu_mps, rotation_nb, rate_body_rad_s, frame_rate_enu_rad_s, lever_arm_body_m
):
    """v + R_nb (ω_ib × l) − ω_in × (R_nb l) (ENU, m/s), with R_nb l (ENU, m) and
    R_nb (ω_ib × l) (ENU, m/s), which the Jacobian takes."""
    lever_enu = np.dot(rotation_nb, lever_arm_body_m)
    rotation_velocity = np.dot(rotation_nb, cross(rate_body_rad_s, lever_arm_body_m))
    velocity = velocity_enu_mps + rotation_velocity - cross(frame_rate_enu_rad_s, lever_enu)
    return velocity, lever_enu, rotation_velocity


@numba.njit(cache=True)
def antenna_velocity_model(
    measured_enu_mps,
    measured_covariance_m2s2,
    variance_floor_m2s2,
    velocity_enu_mps,
    rotation_nb,
    rate_body_rad_s,
    frame_rate_enu_rad_s,
    lever_arm_body_m,
    attitude_start,
    velocity_start,
    gyro_bias_start,
    state_count,
):
    """The measurement function of the antenna's velocity ``measured_enu_mps`` (ENU, m/s; its
    covariance m²/s², floored at ``variance_floor_m2s2``) at the nominal velocity (ENU, m/s),
    R_nb, bias-corrected body rate ω_ib (rad/s) and ENU rate ω_in (rad/s): the predicted
    velocity, the innovation, the Jacobian over ``state_count`` error states (the blocks from
    their starts) and R."""
    predicted, lever_enu, rotation_velocity = _antenna_velocity(
        velocity_enu_mps, rotation_nb, rate_body_rad_s, frame_rate_enu_rad_s, lever_arm_body_m
    )
    jacobian = np.zeros((3, state_count))
    place_block(
        jacobian,
        attitude_start,
        -skew(rotation_velocity) + np.dot(skew(frame_rate_enu_rad_s), skew(lever_enu)),
    )
    place_identity(jacobian, velocity_start)
    place_block(jacobian, gyro_bias_start, np.dot(rotation_nb, skew(lever_arm_body_m)))
    covariance = floored_covariance(measured_covariance_m2s2, variance_floor_m2s2)
    return predicted, measured_enu_mps - predicted, jacobian, covariance


@numba.njit(cache=True)
def velocity_stretch_model(values, state, rotation_nb, raw_gyro_rad_s, terms):
    """:meth:`GnssVelocitySource.model` over arrays, for a compiled stretch
    (:mod:`buoy_nav.aiding_epoch`): the velocity ``values``
    (:meth:`GnssVelocitySource.stretch_values`) at the strapdown ``state`` vector, its R_nb
    ``rotation_nb`` and the raw gyro sample there (body rad/s), with the source's ``terms``
    (:meth:`GnssVelocitySource.stretch_terms`): the innovation (ENU m/s), the Jacobian, R
    (m²/s²) and whether the model holds (always)."""
    _, innovation, jacobian, covariance = antenna_velocity_model(
        values[0:3].copy(),
        values[3:12].reshape(3, 3).copy(),
        terms[0],
        state[_STATE_VELOCITY : _STATE_VELOCITY + 3].copy(),
        rotation_nb,
        raw_gyro_rad_s - state[_GYRO_BIAS : _GYRO_BIAS + 3],
        state[_NAV_FRAME_RATE : _NAV_FRAME_RATE + 3].copy(),
        terms[1:4].copy(),
        int(terms[4]),
        int(terms[5]),
        int(terms[6]),
        int(terms[7]),
    )
    return innovation, jacobian, covariance, True


class GnssVelocitySource(AidingSource):
    """Velocity of the primary antenna (see the module docstring)."""

    kind = "gnss_velocity"
    topic = GNSS_VELOCITY_TOPIC
    measurement_type = GnssVelocity
    aids = VELOCITY
    sensor = GNSS_RECEIVER
    roles = frozenset((VELOCITY_REFERENCE,))
    has_compiled_model = True

    def __init__(self, config, states):
        super().__init__(config, states)
        self._lever_arm_body_m = np.array(config.primary_antenna_body_m)
        self._variance_floor_m2s2 = config.gnss_velocity_variance_floor_m2s2

    record_fields = ("linear", "covariance")

    def measurement_from_message(self, message) -> GnssVelocity | Reason:
        twist = message.twist
        return self.measurement_from_record(
            header_seconds(message.header), vector_of(twist.twist.linear), twist.covariance
        )

    def measurement_from_record(
        self, t_s: float, linear_enu_mps, twist_covariance
    ) -> GnssVelocity | Reason:
        """The linear part of the twist; its covariance is the linear 3×3 block of the 6×6."""
        covariance = np.asarray(twist_covariance, dtype=float)
        if covariance.shape != (36,):
            return Reason.MALFORMED
        return GnssVelocity(tuple(linear_enu_mps), covariance.reshape(6, 6)[:3, :3])

    def validated(self, measurement: GnssVelocity) -> GnssVelocity | Reason:
        velocity = as_float_array(measurement.velocity_enu_mps, (3,))
        covariance = as_float_array(measurement.covariance_m2s2, (3, 3))
        if isinstance(velocity, Reason):
            return velocity
        if isinstance(covariance, Reason):
            return covariance
        if float(velocity @ velocity) > MAX_SPEED_MPS**2:
            return Reason.OUT_OF_RANGE
        if has_non_positive_variance(covariance):
            return Reason.NON_POSITIVE_VARIANCE
        return GnssVelocity(velocity, covariance)

    def model(self, measurement: GnssVelocity, point: LinearisationPoint) -> MeasurementModel:
        state = point.state
        states = self.states
        predicted, innovation, jacobian, covariance = antenna_velocity_model(
            measurement.velocity_enu_mps,
            measurement.covariance_m2s2,
            self._variance_floor_m2s2,
            state.velocity_enu_mps,
            point.rotation_nb,
            np.asarray(point.raw_gyro_rad_s, dtype=float) - state.gyro_bias_rad_s,
            np.asarray(point.nav_frame_rate_enu_rad_s, dtype=float),
            self._lever_arm_body_m,
            states.attitude.start,
            states.velocity.start,
            states.gyro_bias.start,
            states.dim,
        )
        return MeasurementModel(predicted, innovation, jacobian, covariance)

    stretch_model = staticmethod(velocity_stretch_model)

    def stretch_values(self, measurement: GnssVelocity, position_rad: tuple) -> tuple[float, ...]:
        """The numbers :func:`velocity_stretch_model` reads of a validated velocity: the
        velocity (ENU m/s), its covariance (m²/s², row-major); none depends on the filter's
        ``position_rad``."""
        return (
            *measurement.velocity_enu_mps.tolist(),
            *measurement.covariance_m2s2.reshape(9).tolist(),
        )

    def stretch_terms(self) -> np.ndarray:
        """The terms :func:`velocity_stretch_model` reads: the variance floor (m²/s²), the lever
        arm (body m), the error states' attitude, velocity and gyro bias starts, their count."""
        states = self.states
        return np.array(
            (
                self._variance_floor_m2s2,
                *self._lever_arm_body_m,
                states.attitude.start,
                states.velocity.start,
                states.gyro_bias.start,
                states.dim,
            ),
            dtype=float,
        )

    def load_compiled_code(self) -> None:
        states = self.states
        antenna_velocity_model(
            np.zeros(3),
            np.eye(3),
            self._variance_floor_m2s2,
            np.zeros(3),
            np.eye(3),
            np.zeros(3),
            np.zeros(3),
            self._lever_arm_body_m,
            states.attitude.start,
            states.velocity.start,
            states.gyro_bias.start,
            states.dim,
        )
        # The reset's, rare: loaded now, so that it never waits for the compiler either.
        predicted_antenna_velocity_enu_mps(
            np.zeros(3), np.eye(3), np.zeros(3), np.zeros(3), self._lever_arm_body_m
        )

    def reset(self, measurement: GnssVelocity, point: LinearisationPoint, model) -> StateReset:
        """The velocity to the measured one less the lever-arm term, with its variances."""
        state = point.state
        lever_arm_velocity = predicted_antenna_velocity_enu_mps(
            np.zeros(3),
            point.rotation_nb,
            np.asarray(point.raw_gyro_rad_s) - state.gyro_bias_rad_s,
            point.nav_frame_rate_enu_rad_s,
            self._lever_arm_body_m,
        )
        return StateReset(
            NavState(
                state.attitude_xyzw,
                measurement.velocity_enu_mps - lever_arm_velocity,
                state.latitude_rad,
                state.longitude_rad,
                state.altitude_m,
                state.gyro_bias_rad_s,
                state.accel_bias_mps2,
            ),
            self.states.indices("velocity"),
            np.diag(model.covariance),
        )

    def align(self, aligner, t_s: float, measurement: GnssVelocity, raw_gyro_rad_s) -> None:
        aligner.add_velocity(t_s, measurement.velocity_enu_mps, measurement.covariance_m2s2)
