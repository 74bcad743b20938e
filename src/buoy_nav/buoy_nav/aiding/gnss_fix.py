"""GNSS position of the primary antenna (``gnss/fix``, sensor_msgs/NavSatFix).

The measured antenna position (WGS-84) is expressed in the ENU tangent plane at the nominal
``base_link`` position, where the prediction is the lever arm turned into ENU, ``R_nb l``. The
position error δp is in ENU metres of that plane (better conditioned than δL, δλ, δh), so under
the convention of :func:`buoy_nav.error_state_filter.inject_error_state`::

    p_ant = δp + Exp([φ×]) R_nb l   ⇒   ∂p_ant/∂φ = −[(R_nb l)×],   ∂p_ant/∂δp = I.

After persistent gate rejections the position is reset to the fix moved back along the lever
arm. In the alignment the latest fix gives the initial position.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numba
import numpy as np

from buoy_common.contract import GNSS_FIX_TOPIC, Reason, header_seconds
from buoy_nav import earth
from buoy_nav.aiding.base import (
    FIX,
    GNSS_RECEIVER,
    POSITION_REFERENCE,
    AidingSource,
    LinearisationPoint,
    MeasurementModel,
    StateReset,
    as_float_array,
    as_floats,
    has_non_positive_variance,
)
from buoy_nav.aiding.model_kernels import (
    enu_offset,
    floored_covariance,
    place_block,
    place_identity,
    skew,
)
from buoy_nav.error_state_filter import NavState
from buoy_nav.strapdown_kernel import ALTITUDE, LATITUDE, LONGITUDE

# sensor_msgs/NavSatStatus: a status below this is no fix.
STATUS_FIX = 0
# Beyond this ellipsoidal altitude (m) a value is a malformed message, not a buoy's position.
MAX_ABS_ALTITUDE_M = 1.0e4


class GnssFix(NamedTuple):
    """A primary-antenna fix: WGS-84 latitude and longitude (deg), ellipsoidal altitude (m),
    ENU covariance (3×3 m², or row-major flat)."""

    latitude_deg: float
    longitude_deg: float
    altitude_m: float
    covariance_enu_m2: np.ndarray

    @property
    def latitude_rad(self) -> float:
        return math.radians(self.latitude_deg)

    @property
    def longitude_rad(self) -> float:
        return math.radians(self.longitude_deg)


@numba.njit(cache=True)
def antenna_position_model(
    measured_enu_m,
    measured_covariance_enu_m2,
    variance_floor_m2,
    rotation_nb,
    lever_arm_body_m,
    attitude_start,
    position_start,
    state_count,
):
    """The measurement function of the antenna's position ``measured_enu_m`` (ENU m at the
    nominal position; its covariance m², floored at ``variance_floor_m2``) at the nominal R_nb:
    the predicted position R_nb l, the innovation, the Jacobian over ``state_count`` error
    states (the blocks from their starts) and R."""
    lever_enu = np.dot(rotation_nb, lever_arm_body_m)
    jacobian = np.zeros((3, state_count))
    place_block(jacobian, attitude_start, -skew(lever_enu))
    place_identity(jacobian, position_start)
    covariance = floored_covariance(measured_covariance_enu_m2, variance_floor_m2)
    return lever_enu, measured_enu_m - lever_enu, jacobian, covariance


@numba.njit(cache=True)
def fix_stretch_model(values, state, rotation_nb, raw_gyro_rad_s, terms):
    """:meth:`GnssFixSource.model` over arrays, for a compiled stretch
    (:mod:`buoy_nav.aiding_epoch`): the fix ``values`` (:meth:`GnssFixSource.stretch_values`)
    at the strapdown ``state`` vector and its R_nb ``rotation_nb`` (the raw gyro unused), with
    the source's ``terms`` (:meth:`GnssFixSource.stretch_terms`): the innovation (ENU m), the
    Jacobian, R (m²) and whether the model holds (always)."""
    measured = np.array(
        enu_offset(
            state[LATITUDE], state[LONGITUDE], state[ALTITUDE], values[0], values[1], values[2]
        )
    )
    _, innovation, jacobian, covariance = antenna_position_model(
        measured,
        values[3:12].reshape(3, 3).copy(),
        terms[0],
        rotation_nb,
        terms[1:4].copy(),
        int(terms[4]),
        int(terms[5]),
        int(terms[6]),
    )
    return innovation, jacobian, covariance, True


class GnssFixSource(AidingSource):
    """Position of the primary antenna (see the module docstring)."""

    kind = "gnss_fix"
    topic = GNSS_FIX_TOPIC
    measurement_type = GnssFix
    aids = FIX
    sensor = GNSS_RECEIVER
    roles = frozenset((POSITION_REFERENCE,))
    has_compiled_model = True

    def __init__(self, config, states):
        super().__init__(config, states)
        self._lever_arm_body_m = np.array(config.primary_antenna_body_m)
        self._variance_floor_m2 = config.gnss_position_variance_floor_m2

    record_fields = ("status", "latitude", "longitude", "altitude", "position_covariance")

    def measurement_from_message(self, message) -> GnssFix | Reason:
        return self.measurement_from_record(
            header_seconds(message.header),
            message.status.status,
            message.latitude,
            message.longitude,
            message.altitude,
            message.position_covariance,
        )

    def measurement_from_record(
        self,
        t_s: float,
        status: int,
        latitude_deg: float,
        longitude_deg: float,
        altitude_m: float,
        position_covariance_m2,
    ) -> GnssFix | Reason:
        if status < STATUS_FIX:
            return Reason.NO_FIX
        return GnssFix(
            latitude_deg,
            longitude_deg,
            altitude_m,
            np.asarray(position_covariance_m2, dtype=float),
        )

    def validated(self, measurement: GnssFix) -> GnssFix | Reason:
        values = as_floats(
            measurement.latitude_deg, measurement.longitude_deg, measurement.altitude_m
        )
        covariance = as_float_array(measurement.covariance_enu_m2, (3, 3))
        if isinstance(values, Reason):
            return values
        if isinstance(covariance, Reason):
            return covariance
        latitude, longitude, altitude = values
        if abs(latitude) > 90.0 or abs(longitude) > 360.0 or abs(altitude) > MAX_ABS_ALTITUDE_M:
            return Reason.OUT_OF_RANGE
        if has_non_positive_variance(covariance):
            return Reason.NON_POSITIVE_VARIANCE
        return GnssFix(latitude, longitude, altitude, covariance)

    def model(self, measurement: GnssFix, point: LinearisationPoint) -> MeasurementModel:
        """Antenna position in ENU metres at the nominal position."""
        state = point.state
        measured = np.array(
            earth.enu_offset_scalar(
                state.latitude_rad,
                state.longitude_rad,
                state.altitude_m,
                measurement.latitude_rad,
                measurement.longitude_rad,
                measurement.altitude_m,
            )
        )
        states = self.states
        predicted, innovation, jacobian, covariance = antenna_position_model(
            measured,
            measurement.covariance_enu_m2,
            self._variance_floor_m2,
            point.rotation_nb,
            self._lever_arm_body_m,
            states.attitude.start,
            states.position.start,
            states.dim,
        )
        return MeasurementModel(predicted, innovation, jacobian, covariance)

    stretch_model = staticmethod(fix_stretch_model)

    def stretch_values(self, measurement: GnssFix, position_rad: tuple) -> tuple[float, ...]:
        """The numbers :func:`fix_stretch_model` reads of a validated fix: latitude and
        longitude (rad), altitude (m), the covariance (m², row-major); none depends on the filter's
        ``position_rad``."""
        return (
            measurement.latitude_rad,
            measurement.longitude_rad,
            measurement.altitude_m,
            *measurement.covariance_enu_m2.reshape(9).tolist(),
        )

    def stretch_terms(self) -> np.ndarray:
        """The terms :func:`fix_stretch_model` reads: the variance floor (m²), the lever arm
        (body m), the error states' attitude and position starts and their count."""
        states = self.states
        return np.array(
            (
                self._variance_floor_m2,
                *self._lever_arm_body_m,
                states.attitude.start,
                states.position.start,
                states.dim,
            ),
            dtype=float,
        )

    def load_compiled_code(self) -> None:
        states = self.states
        antenna_position_model(
            np.zeros(3),
            np.eye(3),
            self._variance_floor_m2,
            np.eye(3),
            self._lever_arm_body_m,
            states.attitude.start,
            states.position.start,
            states.dim,
        )

    def reset(self, measurement: GnssFix, point: LinearisationPoint, model) -> StateReset:
        """The position to the fix moved back along the lever arm, with the fix's variances."""
        state = point.state
        latitude, longitude, altitude = earth.geodetic_offset(
            measurement.latitude_rad,
            measurement.longitude_rad,
            measurement.altitude_m,
            -(point.rotation_nb @ self._lever_arm_body_m),
        )
        return StateReset(
            NavState(
                state.attitude_xyzw,
                state.velocity_enu_mps,
                latitude,
                longitude,
                altitude,
                state.gyro_bias_rad_s,
                state.accel_bias_mps2,
            ),
            self.states.indices("position"),
            np.diag(model.covariance),
        )

    def align(self, aligner, t_s: float, measurement: GnssFix, raw_gyro_rad_s) -> None:
        aligner.add_fix(
            t_s,
            measurement.latitude_rad,
            measurement.longitude_rad,
            measurement.altitude_m,
            measurement.covariance_enu_m2,
        )
