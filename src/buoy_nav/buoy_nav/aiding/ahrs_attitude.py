"""A motion pack's own attitude (``imu/data``, sensor_msgs/Imu) as a measurement.

The pack (an AHRS) reports ``R_m``, body→ENU of its yaw reference, and its covariance as a small
rotation about the ENU axes (rad²). With ``ahrs.yaw_reference: magnetic_north`` its yaw is a
compass's, so the true attitude is ``Rz(−D) R_m`` (declination D east positive, from
``magnetic.declination_deg`` or the WMM at the position).

**Its lag.** The pack's own filter trusts its gyro over a time constant τ and so follows the
motion late: at a wave's rate ω the lag costs ω·τ of attitude (10° of roll at 9 s period with
τ = 0.2 s is 1.4° at the peak rate). The fusion avoids the cost twice over: the measurement is
carried forward by the configured lag with the bias-corrected gyro,
``R_m' = R_m Exp([ω_ib τ]×)``, what remains of an unknown lag is noise
``(|ω_ib| · ahrs_lag_uncertainty_s)²`` per axis, and the pack's error, which stays alike for
``ahrs_error_correlation_time_s``, is weighted as one sample per that time. The pack then only
holds the fusion's slow attitude (minutes), while the IMU carries the wave motion.

Model: ``R_true = Exp([φ×]) R_nb``, so the innovation ``Log(R_m' R_nbᵀ)`` measures φ directly:
H = I on the attitude error. Gated as a whole; no reset (a pack that disagrees for long is
reported through the gate counts, and the yaw alignment starts from it).

Bad input: a zero quaternion (``zero_quaternion``), a quaternion whose norm is off 1 by more
than :data:`UNIT_NORM_TOLERANCE` (``non_unit_quaternion``), a stamp not after the previous one
(``stamp_not_increasing``, ``duplicate_stamp``), a non-finite or non-positive covariance.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numba
import numpy as np

from buoy_common.contract import AHRS_TOPIC, Reason
from buoy_nav import kalman_kernel
from buoy_nav.aiding.base import (
    ATTITUDE_SOURCE,
    HEADING,
    HEADING_REFERENCE,
    MOTION_PACK,
    ORIENTATION_RECORD_FIELDS,
    AidingSource,
    LinearisationPoint,
    MeasurementModel,
    as_float_array,
    has_non_positive_variance,
    orientation_record,
    samples_per_correlation_time,
    samples_per_correlation_times,
)
from buoy_nav.aiding.model_kernels import place_identity
from buoy_nav.error_state_filter import GateResult
from buoy_nav.geomagnetism import declination_rad, declinations_rad, wmm_cell_bounds_rad
from buoy_nav.rotations import (
    quaternion_from_rotation_elements,
    quaternion_from_rotation_vector,
    rotation_matrix_elements,
    rotation_matrix_from_euler,
    rotation_matrix_from_quaternion,
    rotation_matrix_from_rotation_vector,
    rotation_vector_from_quaternion,
)
from buoy_nav.strapdown_kernel import ATTITUDE, GYRO_BIAS, LATITUDE, LONGITUDE, STATE_SIZE

UNIT_NORM_TOLERANCE = 1e-3
MIN_QUATERNION_NORM = 1e-9
BODY_X = np.array((1.0, 0.0, 0.0))

AT_ONCE_FROM = 16
"""Records (or attitudes) from which :meth:`AhrsAttitudeSource.measurements_from_records` and
:meth:`AhrsAttitudeSource.stretch_values_of` make them at once: their arrays cost some 100 µs a
call, one by one some 8 µs each (with the model's declination), so fewer are made one by one."""

# What :meth:`AhrsAttitudeSource.measurements_from_records` finds of each record, as a code.
_REASONS = (
    None,
    Reason.NON_FINITE,
    Reason.ZERO_QUATERNION,
    Reason.NON_UNIT_QUATERNION,
    Reason.DUPLICATE_STAMP,
    Reason.STAMP_NOT_INCREASING,
)
(
    _VALID,
    _NON_FINITE,
    _ZERO_QUATERNION,
    _NON_UNIT_QUATERNION,
    _DUPLICATE_STAMP,
    _STAMP_NOT_INCREASING,
) = range(len(_REASONS))

# The rotation functions the innovation calls, compiled from their one source.
_quaternion_from_rotation_vector = numba.njit(cache=True)(quaternion_from_rotation_vector)
_rotation_matrix_elements = numba.njit(cache=True)(rotation_matrix_elements)
_quaternion_from_rotation_elements = numba.njit(cache=True)(quaternion_from_rotation_elements)
_rotation_vector_from_quaternion = numba.njit(cache=True)(rotation_vector_from_quaternion)


@numba.njit(cache=True)
def _model_covariance(covariance_rad2, floor_rad2, lag_variance_rad2, weight):
    """The update's R (3×3, ENU rad²): the pack's ``covariance_rad2`` symmetrised, its
    variances raised to ``floor_rad2``, the lag's variance added to each axis and the whole
    multiplied by the sample's ``weight``, element by element as
    ``(floored_covariance(C, floor) + I·lag) · weight`` computes it in numpy, to the bit."""
    result = np.empty((3, 3))
    for i in range(3):
        for j in range(3):
            value = 0.5 * (covariance_rad2[i, j] + covariance_rad2[j, i])
            if i == j and value < floor_rad2:
                value = floor_rad2
            identity = 1.0 if i == j else 0.0
            result[i, j] = (value + identity * lag_variance_rad2) * weight
    return result


@numba.njit(cache=True)
def _attitude_innovation(measured_nb, rotation_nb, rate_x, rate_y, rate_z, lag_s):
    """Log(R_m' R_nbᵀ) (rad, ENU): the pack's true-north attitude ``measured_nb`` (3×3,
    body→ENU) carried forward by ``lag_s`` (s) with the bias-corrected body rate (rad/s),
    R_m' = R_m Exp([ω τ]×), against the nominal ``rotation_nb``. Compiled: at the pack's rate
    the interpreter's cost of the small products outweighed their arithmetic."""
    carried = measured_nb
    if lag_s > 0.0:
        lag = _rotation_matrix_elements(
            *_quaternion_from_rotation_vector(rate_x * lag_s, rate_y * lag_s, rate_z * lag_s)
        )
        carried = np.zeros((3, 3))
        for i in range(3):
            for j in range(3):
                carried[i, j] = (
                    measured_nb[i, 0] * lag[j] + measured_nb[i, 1] * lag[3 + j]
                ) + measured_nb[i, 2] * lag[6 + j]
    product = np.zeros(9)
    for i in range(3):
        for j in range(3):
            product[3 * i + j] = (
                carried[i, 0] * rotation_nb[j, 0] + carried[i, 1] * rotation_nb[j, 1]
            ) + carried[i, 2] * rotation_nb[j, 2]
    return _rotation_vector_from_quaternion(
        *_quaternion_from_rotation_elements(
            product[0],
            product[1],
            product[2],
            product[3],
            product[4],
            product[5],
            product[6],
            product[7],
            product[8],
        )
    )


@numba.njit(cache=True)
def attitude_update(
    covariance,
    integrator_state,
    measured_nb,
    rate_x,
    rate_y,
    rate_z,
    lag_s,
    measurement_covariance_rad2,
    floor_rad2,
    lag_variance_rad2,
    weight,
    jacobian,
    gate_threshold,
    attitude_start,
):
    """:class:`CompiledUpdate`'s fields of the pack's true-north attitude ``measured_nb``
    against the nominal state vector ``integrator_state`` and ``covariance``: the innovation of
    :func:`_attitude_innovation` (bias-corrected body rate in rad/s, ``lag_s`` s), R of
    :func:`_model_covariance`, the gate at ``gate_threshold`` and, when it passes, the Joseph
    update and the attitude reset (the error states' attitude from ``attitude_start``)."""
    elements = _rotation_matrix_elements(
        integrator_state[ATTITUDE],
        integrator_state[ATTITUDE + 1],
        integrator_state[ATTITUDE + 2],
        integrator_state[ATTITUDE + 3],
    )
    rotation_nb = np.empty((3, 3))
    for index in range(9):
        rotation_nb[index // 3, index % 3] = elements[index]
    innovation = np.array(
        _attitude_innovation(measured_nb, rotation_nb, rate_x, rate_y, rate_z, lag_s)
    )
    model_covariance = _model_covariance(
        measurement_covariance_rad2, floor_rad2, lag_variance_rad2, weight
    )
    nis, innovation_covariance = kalman_kernel.innovation_test(
        covariance, innovation, jacobian, model_covariance
    )
    if not nis <= gate_threshold:
        return (
            innovation,
            nis,
            innovation_covariance,
            False,
            covariance,
            np.zeros(covariance.shape[0]),
            True,
        )
    posterior, correction, _ = kalman_kernel.joseph_update(
        covariance, innovation, jacobian, model_covariance
    )
    reset, positive = kalman_kernel.attitude_reset(posterior, correction, attitude_start)
    return innovation, nis, innovation_covariance, True, reset, correction, positive


# What :func:`attitude_stretch_model` reads of an attitude (``values``): its true-north R_nb
# (row-major), its covariance (ENU rad², row-major), the sample's weight and the bounds (rad)
# of latitude and longitude within which that true north holds.
TRUE_NORTH, COVARIANCE, WEIGHT, CELL = 0, 9, 18, 19
# What it reads of the source (``terms``): the lag (s) and its uncertainty squared (s²), the
# variance floor (rad²), the error states' attitude start and their count.
LAG, LAG_UNCERTAINTY_SQ, FLOOR, ATTITUDE_START, STATE_COUNT = range(5)


@numba.njit(cache=True)
def attitude_stretch_model(values, state, rotation_nb, raw_gyro_rad_s, terms):
    """:meth:`AhrsAttitudeSource.model` over arrays, for a compiled stretch
    (:mod:`buoy_nav.aiding_epoch`): the attitude ``values`` (laid out above) at the nominal
    ``state`` vector, its ``rotation_nb`` and the raw gyro sample there (body rad/s), with the
    source's ``terms``: the innovation (rad, ENU), the Jacobian, R (rad²) and whether the model
    holds (not where the filter has left the cell the true north was taken in)."""
    rate_x = raw_gyro_rad_s[0] - state[GYRO_BIAS]
    rate_y = raw_gyro_rad_s[1] - state[GYRO_BIAS + 1]
    rate_z = raw_gyro_rad_s[2] - state[GYRO_BIAS + 2]
    square = 2.0 + 0.0 * rate_x  # a run-time exponent: the C library's pow, as the interpreter's
    lag_variance = (
        math.pow(rate_x, square) + math.pow(rate_y, square) + math.pow(rate_z, square)
    ) * terms[LAG_UNCERTAINTY_SQ]
    innovation = np.array(
        _attitude_innovation(
            values[TRUE_NORTH:COVARIANCE].reshape(3, 3).copy(),
            rotation_nb,
            rate_x,
            rate_y,
            rate_z,
            terms[LAG],
        )
    )
    covariance = _model_covariance(
        values[COVARIANCE:WEIGHT].reshape(3, 3).copy(), terms[FLOOR], lag_variance, values[WEIGHT]
    )
    jacobian = np.zeros((3, int(terms[STATE_COUNT])))
    place_identity(jacobian, int(terms[ATTITUDE_START]))
    latitude, longitude = state[LATITUDE], state[LONGITUDE]
    in_cell = (
        values[CELL] < latitude < values[CELL + 1]
        and values[CELL + 2] < longitude < values[CELL + 3]
    )
    return innovation, jacobian, covariance, in_cell


class AhrsAttitude(NamedTuple):
    """The pack's attitude: R_m body→ENU of its yaw reference (3×3), its covariance (3×3 ENU
    rad²), the interval to the previous sample (s; NaN for the first) and its stamp (s)."""

    rotation_nb: np.ndarray
    covariance_rad2: np.ndarray
    interval_s: float
    t_s: float


class CompiledUpdate(NamedTuple):
    """What :meth:`AhrsAttitudeSource.compiled_update` made of one measurement: its innovation
    (rad, ENU), the gate's result and, when the gate accepted it, the covariance after the
    update and the reset (else the one given), the correction (error state; zeros when
    rejected) and whether that covariance is positive definite."""

    innovation: np.ndarray
    gate: GateResult
    covariance: np.ndarray
    correction: np.ndarray
    positive_definite: bool


class AhrsAttitudeSource(AidingSource):
    """The motion pack's attitude (see the module docstring)."""

    kind = "ahrs"
    topic = AHRS_TOPIC
    measurement_type = AhrsAttitude
    aids = HEADING
    sensor = MOTION_PACK
    roles = frozenset((HEADING_REFERENCE, ATTITUDE_SOURCE))
    has_compiled_update = True

    def __init__(self, config, states):
        super().__init__(config, states)
        self._magnetic = config.ahrs_yaw_reference == "magnetic_north"
        self._declination_deg = config.magnetic_declination_deg
        self._lag_s = config.ahrs_lag_s
        self._lag_uncertainty_s = config.ahrs_lag_uncertainty_s
        self._floor_rad2 = config.ahrs_variance_floor_rad2
        self._correlation_s = config.ahrs_error_correlation_time_s
        self._last_stamp_s = -math.inf
        # The rotation from magnetic to true north, made again only when the declination
        # changes (a configured one never does).
        self._declination_rotation: tuple[float, np.ndarray] | None = None
        jacobian = np.zeros((3, states.dim))
        jacobian[:, states.attitude] = np.eye(3)
        jacobian.flags.writeable = False
        self._jacobian = jacobian

    @classmethod
    def enabled_by(cls, config) -> bool:
        return config.use_ahrs

    record_fields = ORIENTATION_RECORD_FIELDS

    def measurement_from_message(self, message) -> AhrsAttitude | Reason:
        return self.measurement_from_record(*orientation_record(message))

    def measurement_from_record(
        self, t_s: float, orientation_xyzw, orientation_covariance
    ) -> AhrsAttitude | Reason:
        x, y, z, w = orientation_xyzw
        norm = math.sqrt(x * x + y * y + z * z + w * w)
        if not math.isfinite(norm):
            return Reason.NON_FINITE
        if norm < MIN_QUATERNION_NORM:
            return Reason.ZERO_QUATERNION
        if abs(norm - 1.0) > UNIT_NORM_TOLERANCE:
            return Reason.NON_UNIT_QUATERNION
        if not math.isfinite(t_s):
            return Reason.NON_FINITE
        if t_s <= self._last_stamp_s:
            return (
                Reason.DUPLICATE_STAMP if t_s == self._last_stamp_s else Reason.STAMP_NOT_INCREASING
            )
        interval = t_s - self._last_stamp_s
        self._last_stamp_s = t_s
        if len(orientation_covariance) != 9:
            return Reason.MALFORMED
        return AhrsAttitude(
            rotation_matrix_from_quaternion((x / norm, y / norm, z / norm, w / norm)),
            np.asarray(orientation_covariance, dtype=float).reshape(3, 3),
            interval if math.isfinite(interval) else math.nan,
            t_s,
        )

    def measurements_from_records(
        self, stamps_s: list, orientations_xyzw: list, orientation_covariances: list
    ) -> list[AhrsAttitude | Reason] | None:
        """:meth:`measurement_from_record` of consecutive records at once, to the bit: their
        stamps (s), quaternions and covariances, each one's attitude or the reason it is none;
        None, nothing changed, for fewer than :data:`AT_ONCE_FROM` records or records that are
        not all four and nine numbers (the caller makes them one by one)."""
        count = len(stamps_s)
        if count < AT_ONCE_FROM:
            return None
        try:
            quaternions = np.array(orientations_xyzw, dtype=float)
            covariances = np.array(orientation_covariances, dtype=float)
        except (TypeError, ValueError):
            quaternions = covariances = None
        if (
            quaternions is None
            or quaternions.shape != (count, 4)
            or covariances.shape != (count, 9)
        ):
            return None
        stamps = np.array(stamps_s, dtype=float)
        x, y, z, w = quaternions.T
        with np.errstate(invalid="ignore", divide="ignore", over="ignore"):
            norm = np.sqrt(x * x + y * y + z * z + w * w)
            reasons, previous = self._record_reasons(norm, stamps)
            intervals = stamps - previous
            elements = rotation_matrix_elements(x / norm, y / norm, z / norm, w / norm)
        rotations = np.stack(elements, axis=1).reshape(count, 3, 3)
        covariances = covariances.reshape(count, 3, 3)
        intervals = np.where(np.isfinite(intervals), intervals, math.nan).tolist()
        return [
            AhrsAttitude(rotations[index], covariances[index], intervals[index], stamps_s[index])
            if reason == _VALID
            else _REASONS[reason]
            for index, reason in enumerate(reasons.tolist())
        ]

    def _record_reasons(
        self, norms: np.ndarray, stamps_s: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray]:
        """What :meth:`measurement_from_record` finds of consecutive records of quaternion
        ``norms`` and stamps ``stamps_s`` (s), as codes, and the stamp (s) kept before each
        one; the stamp kept after them all is kept."""
        reasons = np.select(
            (
                ~np.isfinite(norms),
                norms < MIN_QUATERNION_NORM,
                np.abs(norms - 1.0) > UNIT_NORM_TOLERANCE,
                ~np.isfinite(stamps_s),
            ),
            (_NON_FINITE, _ZERO_QUATERNION, _NON_UNIT_QUATERNION, _NON_FINITE),
            _VALID,
        )
        # A record that passes the checks before the stamp's is kept if it is later than every
        # such record before it: one not later moved nothing.
        latest = np.maximum.accumulate(
            np.concatenate(([self._last_stamp_s], np.where(reasons == _VALID, stamps_s, -np.inf)))
        )
        previous = latest[:-1]
        reasons = np.where(
            (reasons == _VALID) & (stamps_s <= previous),
            np.where(stamps_s == previous, _DUPLICATE_STAMP, _STAMP_NOT_INCREASING),
            reasons,
        )
        self._last_stamp_s = float(latest[-1])
        return reasons, previous

    def validated(self, measurement: AhrsAttitude) -> AhrsAttitude | Reason:
        rotation = as_float_array(measurement.rotation_nb, (3, 3))
        covariance = as_float_array(measurement.covariance_rad2, (3, 3))
        if isinstance(rotation, Reason):
            return rotation
        if isinstance(covariance, Reason):
            return covariance
        if has_non_positive_variance(covariance):
            return Reason.NON_POSITIVE_VARIANCE
        return AhrsAttitude(rotation, covariance, measurement.interval_s, measurement.t_s)

    def _true_north(self, measurement: AhrsAttitude, latitude_rad, longitude_rad) -> np.ndarray:
        rotation = measurement.rotation_nb
        if self._magnetic:
            declination = declination_rad(
                self._declination_deg, latitude_rad, longitude_rad, measurement.t_s
            )
            cached = self._declination_rotation
            if cached is None or cached[0] != declination:
                self._declination_rotation = (
                    declination,
                    rotation_matrix_from_euler(0.0, 0.0, -declination),
                )
            rotation = self._declination_rotation[1] @ rotation
        return rotation

    def _weight(self, measurement: AhrsAttitude) -> float:
        """Variance multiplier of one sample: samples per correlation time share one error."""
        return samples_per_correlation_time(measurement.interval_s, self._correlation_s)

    def model(self, measurement: AhrsAttitude, point: LinearisationPoint) -> MeasurementModel:
        state = point.state
        rate, lag_variance = self._rate_and_lag_variance(
            point.raw_gyro_rad_s, state.gyro_bias_rad_s
        )
        measured = self._true_north(measurement, state.latitude_rad, state.longitude_rad)
        innovation = np.array(
            _attitude_innovation(
                np.ascontiguousarray(measured, dtype=float), point.rotation_nb, *rate, self._lag_s
            )
        )
        covariance = _model_covariance(
            measurement.covariance_rad2, self._floor_rad2, lag_variance, self._weight(measurement)
        )
        return MeasurementModel(
            predicted=np.zeros(3),
            innovation=innovation,
            jacobian=self._jacobian,
            covariance=covariance,
        )

    def _rate_and_lag_variance(self, raw_gyro_rad_s, gyro_bias_rad_s) -> tuple[tuple, float]:
        """The bias-corrected body rate (rad/s) and the variance (rad²) an unknown lag adds to
        each axis at that rate."""
        gyro, bias = raw_gyro_rad_s, gyro_bias_rad_s
        rate = (gyro[0] - bias[0], gyro[1] - bias[1], gyro[2] - bias[2])
        lag_variance = (rate[0] ** 2 + rate[1] ** 2 + rate[2] ** 2) * self._lag_uncertainty_s**2
        return rate, lag_variance

    def compiled_update(
        self, measurement: AhrsAttitude, raw_gyro_rad_s, integrator_state, kalman
    ) -> CompiledUpdate:
        """The model, gate and update of ``measurement`` in one compiled call, from the nominal
        state vector ``integrator_state`` (:mod:`buoy_nav.strapdown_kernel`'s layout) with the
        raw gyro sample there (body rad/s) and the covariance of ``kalman``; nothing is changed.
        The same arithmetic as :meth:`model`, :meth:`ErrorStateFilter.gate`,
        :meth:`ErrorStateFilter.update` and :meth:`ErrorStateFilter.reset_after_injection`."""
        arguments = self.update_arguments(measurement, raw_gyro_rad_s, integrator_state, kalman)
        innovation, nis, innovation_covariance, accepted, covariance, correction, positive = (
            attitude_update(kalman.covariance, integrator_state, *arguments)
        )
        return CompiledUpdate(
            innovation,
            GateResult(accepted, nis, arguments[-2], innovation_covariance),
            covariance,
            correction,
            positive,
        )

    def update_arguments(
        self, measurement: AhrsAttitude, raw_gyro_rad_s, integrator_state, kalman
    ) -> tuple:
        """The arguments of the compiled update (:func:`attitude_update`) after the covariance
        and the state vector, for ``measurement`` at the nominal ``integrator_state`` with the
        raw gyro sample there (body rad/s) and the gate of ``kalman``: for code that composes it
        with other kernels."""
        rate, lag_variance = self._rate_and_lag_variance(
            raw_gyro_rad_s, integrator_state[GYRO_BIAS : GYRO_BIAS + 3]
        )
        measured = self._true_north(
            measurement, float(integrator_state[LATITUDE]), float(integrator_state[LONGITUDE])
        )
        return (
            np.ascontiguousarray(measured, dtype=float),
            *rate,
            self._lag_s,
            measurement.covariance_rad2,
            self._floor_rad2,
            lag_variance,
            self._weight(measurement),
            self._jacobian,
            kalman.gate_threshold(3, self.gate_probability),
            self.states.attitude.start,
        )

    stretch_model = staticmethod(attitude_stretch_model)

    def stretch_values(self, measurement: AhrsAttitude, position_rad: tuple) -> tuple:
        """The numbers :func:`attitude_stretch_model` reads of a validated attitude, its true
        north taken at the filter's ``position_rad`` (latitude, longitude; laid out with the
        model)."""
        latitude_rad, longitude_rad = position_rad
        return (
            *self._true_north(measurement, latitude_rad, longitude_rad).reshape(9).tolist(),
            *measurement.covariance_rad2.reshape(9).tolist(),
            self._weight(measurement),
            *self._cell_bounds_rad(latitude_rad, longitude_rad),
        )

    def stretch_values_of(
        self, measurements: list, position_rad: tuple
    ) -> tuple[list, np.ndarray] | None:
        """:meth:`validated` and :meth:`stretch_values` of many attitudes at once, to the bit:
        each one validated (or the :class:`Reason` it is not valid) and the rows of their numbers
        (n × those of :meth:`stretch_values`; a row of an invalid one is left unread); None for
        fewer than :data:`AT_ONCE_FROM` or attitudes that do not stack (not all 3 × 3 numbers:
        the caller makes them one by one). The true north of all of one declination is one
        stacked product, which numpy computes as it computes each alone."""
        count = len(measurements)
        if count < AT_ONCE_FROM:
            return None
        try:
            rotations = np.array([m.rotation_nb for m in measurements], dtype=float)
            covariances = np.array([m.covariance_rad2 for m in measurements], dtype=float)
        except (TypeError, ValueError):
            rotations = covariances = None
        if (
            rotations is None
            or rotations.shape != (count, 3, 3)
            or covariances.shape != (count, 3, 3)
        ):
            return None
        validated = self._validated_stack(measurements, rotations, covariances)
        latitude_rad, longitude_rad = position_rad
        true_north = rotations
        if self._magnetic:
            stamps = np.array([m.t_s for m in measurements], dtype=float)
            declinations = declinations_rad(
                self._declination_deg, latitude_rad, longitude_rad, stamps
            )
            true_north = np.empty_like(rotations)
            for declination in np.unique(declinations).tolist():
                alike = declinations == declination
                turn = rotation_matrix_from_euler(0.0, 0.0, -declination)
                true_north[alike] = turn @ rotations[alike]
        intervals = np.array([m.interval_s for m in measurements], dtype=float)
        values = np.empty((count, CELL + 4))
        values[:, TRUE_NORTH:COVARIANCE] = true_north.reshape(count, 9)
        values[:, COVARIANCE:WEIGHT] = covariances.reshape(count, 9)
        values[:, WEIGHT] = samples_per_correlation_times(intervals, self._correlation_s)
        values[:, CELL:] = self._cell_bounds_rad(latitude_rad, longitude_rad)
        return validated, values

    def _validated_stack(self, measurements: list, rotations, covariances) -> list:
        """:meth:`validated` of each of ``measurements``, whose rotations and covariances are
        stacked (n × 3 × 3) in ``rotations`` and ``covariances``: each valid one holds its own
        of them."""
        rotation_finite = np.isfinite(rotations).all(axis=(1, 2))
        covariance_finite = np.isfinite(covariances).all(axis=(1, 2))
        positive = (np.diagonal(covariances, axis1=1, axis2=2) > 0.0).all(axis=1)
        validated = []
        for index, measurement in enumerate(measurements):
            if not (rotation_finite[index] and covariance_finite[index]):
                validated.append(Reason.NON_FINITE)
            elif not positive[index]:
                validated.append(Reason.NON_POSITIVE_VARIANCE)
            else:
                validated.append(
                    AhrsAttitude(
                        rotations[index],
                        covariances[index],
                        measurement.interval_s,
                        measurement.t_s,
                    )
                )
        return validated

    def _cell_bounds_rad(self, latitude_rad: float, longitude_rad: float) -> tuple:
        """The bounds (rad) of latitude and longitude within which the true north taken at the
        position holds: the model's cell with the model's declination, anywhere otherwise."""
        if self._magnetic and math.isnan(self._declination_deg):
            return wmm_cell_bounds_rad(latitude_rad, longitude_rad)
        return (-math.inf, math.inf, -math.inf, math.inf)

    def stretch_terms(self) -> np.ndarray:
        """The terms :func:`attitude_stretch_model` reads: the lag (s) and its uncertainty
        squared (s²), the variance floor (rad²), the error states' attitude start and their
        count."""
        states = self.states
        return np.array(
            (
                self._lag_s,
                self._lag_uncertainty_s**2,
                self._floor_rad2,
                states.attitude.start,
                states.dim,
            ),
            dtype=float,
        )

    @property
    def jacobian(self) -> np.ndarray:
        """The update's H (3 × states; read-only)."""
        return self._jacobian

    def load_compiled_code(self) -> None:
        _attitude_innovation(np.eye(3), np.eye(3), 0.0, 0.0, 0.0, self._lag_s)
        _model_covariance(np.eye(3), self._floor_rad2, 0.0, 1.0)
        state = np.zeros(STATE_SIZE)
        state[ATTITUDE + 3] = 1.0
        covariance = np.eye(self.states.dim)
        for jacobian in (self._jacobian, self._jacobian.copy()):  # read-only and writable
            attitude_update(
                covariance,
                state,
                np.eye(3),
                0.0,
                0.0,
                0.0,
                self._lag_s,
                np.eye(3),
                self._floor_rad2,
                0.0,
                1.0,
                jacobian,
                7.8,
                self.states.attitude.start,
            )

    def align(self, aligner, t_s: float, measurement: AhrsAttitude, raw_gyro_rad_s):
        """The pack's heading (azimuth of its body x axis) completes the alignment at a known
        place; the levelling is the fusion's own. The pack's attitude is carried forward by its
        lag with the raw gyro, and what is not known of the lag adds its variance, as in the
        update: a buoy yawing at 5 °/s leaves a pack lagging 0.2 s a degree behind, five times
        the σ a pack claims."""
        place = aligner.latest_position_rad()
        if place is None:
            return None
        rate = np.asarray(raw_gyro_rad_s, dtype=float)
        rotation = self._true_north(measurement, *place) @ rotation_matrix_from_rotation_vector(
            rate * self._lag_s
        )
        forward = rotation @ BODY_X
        lag_variance = float(rate @ rate) * self._lag_uncertainty_s**2
        variance = max(float(measurement.covariance_rad2[2, 2]), self._floor_rad2) + lag_variance
        return aligner.add_heading(
            t_s, math.atan2(forward[1], forward[0]), variance, raw_gyro_rad_s, body_vector=BODY_X
        )
