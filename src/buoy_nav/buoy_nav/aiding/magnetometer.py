"""Magnetometer heading (``imu/mag``, sensor_msgs/MagneticField, tesla, uncalibrated).

**Model: a heading derived from the field, not the 3-D field.** The calibrated field
``m_b = S (m_raw − h)`` (soft iron S, hard iron h: ``calibrate_magnetometer``) is turned into
ENU with the nominal attitude, ``m = R_nb m_b``, and its horizontal projection must point to
magnetic north, whose ENU azimuth is ``π/2 − D`` (declination D east positive, from
``magnetic.declination_deg`` or the WMM at the position)::

    h(x) = atan2(m_N, m_E),   z = π/2 − D.

Why not the 3-D field: a 3-D model also needs the field's magnitude and dip to a fraction of a
percent and lets every residual soft-iron error and every steel hull that passes pull on roll
and pitch, which the accelerometers and the inertial solution already hold far better than a
compass can. The derived heading carries the one thing the magnetometer is needed for; its
dependence on tilt is kept exactly in the Jacobian (below), so no approximation is made, and a
disturbance is gated as a heading (one that passes moves the tilt only through the dip's terms).

Jacobian under ``R_true = Exp([φ×]) R_nb`` (the same geometry as the antenna heading, with the
field in place of the baseline): ``∂h/∂φ = (−m_E m_U / ρ², −m_N m_U / ρ², 1)``, ρ² = m_E² + m_N².
Noise: the sensor's own (``magnetic_field_covariance``, over ρ²), white, plus
``magnetometer_heading_sigma_deg`` for what calibration leaves and local fields. That part is no
white noise: a residual hard iron turns the heading by an error that depends on the heading
itself, and the buoy's heading changes over minutes, so consecutive samples share one error.
Fused as white it would claim a heading √(rate·T) times better than the calibration allows (a
tenth of its σ after a minute at 1 Hz), and a magnetometer a few degrees off, as an uncalibrated
one whose field still passes the checks below is, would pull the heading off the motion pack's
with a σ of a tenth of a degree. It is weighted as the motion pack's error is: one sample's worth
per ``magnetometer_error_correlation_time_s`` (the variance of each sample times the samples in
that time). The gate still asks of each sample whether it is what the magnetometer claims (one
sample's variance): a heading off by more than its calibration allows fails it, and a
magnetometer that keeps failing is suspended. A yaw reset and the alignment take one sample's
variance too. A field whose
horizontal part is under :data:`MIN_HORIZONTAL_FIELD_FRACTION` of its length (near the magnetic
poles, or a steep tilt) carries no heading (``geometry``).

**The field checked against the Earth's.** A calibrated magnetometer reproduces the World
Magnetic Model's field (:func:`buoy_nav.geomagnetism.wmm_field_range_at`): its strength within
``magnetometer_strength_tolerance`` (a share) and its dip, the angle under the horizon seen with
the nominal attitude, within ``magnetometer_dip_tolerance_deg``. A site given by its latitude
alone leaves the longitude unknown (the navigation's is 0): the field is then judged against
the range of the model's strength and dip along that parallel
(:func:`buoy_nav.geomagnetism.wmm_field_range_along_parallel`), no longitude favoured. A field
that does not (an uncalibrated sensor, hard iron near it, a passing hull) would give a wrong
heading whatever its noise: its sample is refused as ``magnetic_field_inconsistent``, counted
as a failed outcome for the source's health (an uncalibrated magnetometer is soon suspended),
and never gives the alignment its heading (there judged with the levelled attitude). PX4's EKF2
checks its magnetometer the same way (field strength and inclination).

Bad input: a non-finite component (``non_finite``), a component at full scale
(``magnetometer_full_scale_t``: saturated, ``out_of_range``), a field below
:data:`MIN_FIELD_T` after calibration (``out_of_range``). Disturbances (a steel hull passing, a
winch motor) fail the chi-square gate and are counted as ``gate``; the yaw is reset to the
magnetometer only after :data:`RESET_AFTER_GATE_RESETS` times the usual count of consecutive
rejections, since a compass that disagrees for seconds is disturbed, not right.
"""

from __future__ import annotations

import math
from collections import deque
from typing import NamedTuple

import numba
import numpy as np

from buoy_common.contract import MAGNETOMETER_TOPIC, Reason, header_seconds
from buoy_nav.aiding.base import (
    HEADING,
    HEADING_REFERENCE,
    MAGNETOMETER,
    AidingSource,
    LinearisationPoint,
    MeasurementModel,
    as_float_array,
    samples_per_correlation_time,
    vector_of,
    yaw_reset,
)
from buoy_nav.aiding.model_kernels import (
    HOLDS,
    LEFT_TO_THE_ENGINE,
    NO_GEOMETRY,
    REFUSED,
    azimuth_model,
    wrap_angle,
)
from buoy_nav.geomagnetism import (
    declination_rad,
    wmm_cell_bounds_rad,
    wmm_field_range_along_parallel,
    wmm_field_range_at,
)
from buoy_nav.rotations import wrap_angle as wrap_angle_rad
from buoy_nav.strapdown_kernel import LATITUDE, LONGITUDE

MIN_HORIZONTAL_FIELD_FRACTION = 0.15
_MIN_HORIZONTAL_FIELD_FRACTION_SQ = MIN_HORIZONTAL_FIELD_FRACTION**2
MIN_FIELD_T = 1e-6
"""The Earth's field is 22–67 µT; under 1 µT the sensor reads no field at all."""
RESET_AFTER_GATE_RESETS = 100


# The Earth's field a field is judged against and headed to (``geomagnetic``): magnetic north's
# ENU azimuth (rad), the least and greatest strength (T) and dip (rad, positive down) allowed.
(NORTH_AZIMUTH, STRENGTH_LOW, STRENGTH_HIGH, DIP_LOW, DIP_HIGH) = range(5)
GEOMAGNETIC_SIZE = 5
# What :func:`magnetometer_stretch_model` reads of a field (``values``): the calibrated field
# (body T), its noise variance (T²), the sample's weight, the Earth's field (``geomagnetic``)
# and the bounds (rad) of latitude and longitude within which that is the Earth's field.
FIELD, NOISE, WEIGHT, GEOMAGNETIC = 0, 3, 4, 5
CELL = GEOMAGNETIC + GEOMAGNETIC_SIZE
# What it reads of the source (``terms``): the calibration's heading variance (rad²), the error
# states' attitude start and their count.
CALIBRATION, ATTITUDE_START, STATE_COUNT = range(3)


@numba.njit(cache=True)
def field_agrees(field_enu_t, strength_low_t, strength_high_t, dip_low_rad, dip_high_rad):
    """Whether a field (ENU, T) has a strength (T) and a dip, its angle under the horizontal
    (rad, positive pointing down), within the bounds given."""
    strength = math.sqrt(np.dot(field_enu_t, field_enu_t))
    if not strength_low_t <= strength <= strength_high_t:
        return False
    dip = math.atan2(-field_enu_t[2], math.hypot(field_enu_t[0], field_enu_t[1]))
    return dip_low_rad <= dip <= dip_high_rad


@numba.njit(cache=True, error_model="numpy")
def magnetic_heading_model(
    rotation_nb,
    field_body_t,
    noise_variance_t2,
    weight,
    geomagnetic,
    calibration_variance_rad2,
    attitude_start,
    state_count,
):
    """The heading of a calibrated field (body T, its noise variance T²) at the nominal R_nb against
    the Earth's field (``geomagnetic``, laid out above), the calibration's heading variance (rad²)
    shared by ``weight`` samples (see the module docstring): what became of it
    (:data:`~buoy_nav.aiding.model_kernels.HOLDS`; ``REFUSED``: its strength or dip is not the
    Earth's; ``NO_GEOMETRY``: its horizontal part is too short to head by), the predicted azimuth
    (rad, ENU), the innovation (rad), the Jacobian (1 × ``state_count``, on the attitude from
    ``attitude_start``), R and the gate's noise (rad²)."""
    field, horizontal_sq, predicted, jacobian = azimuth_model(
        rotation_nb, field_body_t, attitude_start, state_count
    )
    status = HOLDS
    if not field_agrees(
        field,
        geomagnetic[STRENGTH_LOW],
        geomagnetic[STRENGTH_HIGH],
        geomagnetic[DIP_LOW],
        geomagnetic[DIP_HIGH],
    ):
        status = REFUSED
    elif horizontal_sq < _MIN_HORIZONTAL_FIELD_FRACTION_SQ * np.dot(field, field):
        status = NO_GEOMETRY
    innovation = np.array((wrap_angle(geomagnetic[NORTH_AZIMUTH] - predicted),))
    noise = noise_variance_t2 / horizontal_sq
    covariance = np.full((1, 1), calibration_variance_rad2 * weight + noise)
    gate_covariance = np.full((1, 1), calibration_variance_rad2 + noise)
    return status, predicted, innovation, jacobian, covariance, gate_covariance


@numba.njit(cache=True)
def magnetometer_stretch_model(values, state, rotation_nb, raw_gyro_rad_s, terms):
    """:meth:`MagnetometerSource.model` over arrays, for a compiled stretch
    (:mod:`buoy_nav.aiding_epoch`): the field ``values`` (laid out above) at the nominal
    ``state`` vector and its ``rotation_nb`` (the raw gyro unused), with the source's ``terms``:
    the innovation (rad), the Jacobian, R and the gate's noise (rad²), and its fate
    (:mod:`buoy_nav.aiding.model_kernels`: ``REFUSED`` for a field the Earth's does not
    explain, ``NO_GEOMETRY`` for one too steep to head by, ``LEFT_TO_THE_ENGINE`` where the
    filter has left the cell the Earth's field was taken in)."""
    status, _, innovation, jacobian, covariance, gate_covariance = magnetic_heading_model(
        rotation_nb,
        values[FIELD : FIELD + 3].copy(),
        values[NOISE],
        values[WEIGHT],
        values[GEOMAGNETIC:CELL].copy(),
        terms[CALIBRATION],
        int(terms[ATTITUDE_START]),
        int(terms[STATE_COUNT]),
    )
    latitude, longitude = state[LATITUDE], state[LONGITUDE]
    in_cell = (
        values[CELL] < latitude < values[CELL + 1]
        and values[CELL + 2] < longitude < values[CELL + 3]
    )
    return (
        innovation,
        jacobian,
        covariance,
        gate_covariance,
        status if in_cell else LEFT_TO_THE_ENGINE,
    )


class MagneticField(NamedTuple):
    """A raw magnetometer sample: field in ``imu_link`` (T), its mean per-axis noise variance
    (T², 0 when unknown), its stamp (s, for the geomagnetic model's date) and the interval to
    the previous sample (s; NaN for the first)."""

    field_body_t: np.ndarray
    noise_variance_t2: float
    t_s: float
    interval_s: float = math.nan


class MagnetometerSource(AidingSource):
    """Magnetic heading (see the module docstring)."""

    kind = "magnetometer"
    topic = MAGNETOMETER_TOPIC
    measurement_type = MagneticField
    aids = HEADING
    sensor = MAGNETOMETER
    roles = frozenset((HEADING_REFERENCE,))
    # A steel hull or a winch disturbs the field for tens of seconds: the gate stops it, and the
    # filter is not to be distrusted for it.
    witnesses_integrity = False

    def __init__(self, config, states):
        super().__init__(config, states)
        self._hard_iron_t = np.array(config.magnetometer_hard_iron_t, dtype=float)
        self._soft_iron = np.array(config.magnetometer_soft_iron, dtype=float).reshape(3, 3)
        self._heading_variance_rad2 = math.radians(config.magnetometer_heading_sigma_deg) ** 2
        self._correlation_s = config.magnetometer_error_correlation_time_s
        self._last_stamp_s = -math.inf
        self._full_scale_t = config.magnetometer_full_scale_t
        self._declination_deg = config.magnetic_declination_deg
        self._strength_tolerance = config.magnetometer_strength_tolerance
        self._dip_tolerance_rad = math.radians(config.magnetometer_dip_tolerance_deg)
        # A latitude given alone puts the buoy at longitude 0 for the navigation: its field is
        # then judged against the model's along the whole parallel.
        self._longitude_unknown = config.site_latitude_only_deg is not None
        self.reset_after_rejections = config.gate_reset_count * RESET_AFTER_GATE_RESETS
        rule = config.source_health_rule
        self._alignment_resume_share = rule.resume_share
        self._alignment_field_checks: deque[bool] = deque(maxlen=rule.min_samples)
        """Whether each of the recent fields offered to the alignment disagreed with the
        Earth's: the alignment trusts the magnetometer only as a suspended source would be
        resumed, after ``min_samples`` fields judged in strength and dip of which no more than
        ``resume_share`` disagreed."""

    @classmethod
    def enabled_by(cls, config) -> bool:
        return config.use_magnetometer

    record_fields = ("magnetic_field", "magnetic_field_covariance")

    def measurement_from_message(self, message) -> MagneticField | Reason:
        return self.measurement_from_record(
            header_seconds(message.header),
            vector_of(message.magnetic_field),
            message.magnetic_field_covariance,
        )

    def measurement_from_record(
        self, t_s: float, magnetic_field_t, magnetic_field_covariance_t2
    ) -> MagneticField | Reason:
        covariance = np.asarray(magnetic_field_covariance_t2, dtype=float)
        if covariance.shape != (9,):
            return Reason.MALFORMED
        variance = float(np.mean(covariance[0::4]))
        interval = t_s - self._last_stamp_s
        if math.isfinite(t_s) and t_s > self._last_stamp_s:
            self._last_stamp_s = t_s
        return MagneticField(
            tuple(magnetic_field_t),
            variance if math.isfinite(variance) and variance > 0.0 else 0.0,
            t_s,
            interval if math.isfinite(interval) and interval > 0.0 else math.nan,
        )

    def validated(self, measurement: MagneticField) -> MagneticField | Reason:
        raw = as_float_array(measurement.field_body_t, (3,))
        if isinstance(raw, Reason):
            return raw
        if np.any(np.abs(raw) >= self._full_scale_t):
            return Reason.OUT_OF_RANGE
        calibrated = self._soft_iron @ (raw - self._hard_iron_t)
        if float(np.linalg.norm(calibrated)) < MIN_FIELD_T:
            return Reason.OUT_OF_RANGE
        variance = float(measurement.noise_variance_t2)
        return MagneticField(
            calibrated,
            variance if math.isfinite(variance) else 0.0,
            float(measurement.t_s),
            float(measurement.interval_s),
        )

    def magnetic_north_azimuth_rad(self, latitude_rad: float, longitude_rad: float, t_s: float):
        """ENU azimuth (rad, 0 = East, counter-clockwise) of magnetic north at a place."""
        return wrap_angle_rad(
            0.5 * math.pi - declination_rad(self._declination_deg, latitude_rad, longitude_rad, t_s)
        )

    def field_refusal(
        self,
        field_enu_t,
        latitude_rad: float,
        longitude_rad: float,
        t_s: float,
        judge_dip: bool = True,
    ) -> Reason | None:
        """``magnetic_field_inconsistent`` when a calibrated field (ENU, T) differs from the
        Earth's at a place (rad) and time (s since the Unix epoch) in strength or (with
        ``judge_dip``) dip beyond the tolerances; None when it agrees."""
        strength_low, strength_high, dip_low, dip_high = self._field_bounds(
            latitude_rad, longitude_rad, t_s
        )
        if not judge_dip:
            dip_low, dip_high = -math.inf, math.inf
        field = np.ascontiguousarray(field_enu_t, dtype=float)
        if field_agrees(field, strength_low, strength_high, dip_low, dip_high):
            return None
        return Reason.MAGNETIC_FIELD_INCONSISTENT

    def _field_bounds(self, latitude_rad: float, longitude_rad: float, t_s: float) -> tuple:
        """The least and greatest strength (T) and dip (rad) a calibrated field may have at a
        place (rad) and time (s since the Unix epoch): the Earth's there within the tolerances.
        With a site's latitude given alone (the navigation's longitude 0 then), the Earth's
        field is any the model gives along that parallel."""
        expected = (
            wmm_field_range_along_parallel(latitude_rad, t_s)
            if self._longitude_unknown
            else wmm_field_range_at(latitude_rad, longitude_rad, t_s)
        )
        weakest, strongest = expected.strength_t
        tolerance = self._strength_tolerance
        shallowest, steepest = expected.dip_rad
        return (
            weakest * (1.0 - tolerance),
            strongest * (1.0 + tolerance),
            shallowest - self._dip_tolerance_rad,
            steepest + self._dip_tolerance_rad,
        )

    def _geomagnetic(self, latitude_rad: float, longitude_rad: float, t_s: float) -> np.ndarray:
        """The Earth's field a field is judged against and headed to at a place (rad) and time
        (s since the Unix epoch): :func:`magnetic_heading_model`'s ``geomagnetic``."""
        return np.array(
            (
                self.magnetic_north_azimuth_rad(latitude_rad, longitude_rad, t_s),
                *self._field_bounds(latitude_rad, longitude_rad, t_s),
            )
        )

    def _one_sample_variance(self, measurement: MagneticField, horizontal_sq: float) -> float:
        """The heading's variance (rad²) of one sample, the calibration's whole."""
        return self._heading_variance_rad2 + measurement.noise_variance_t2 / horizontal_sq

    def _weight(self, measurement: MagneticField) -> float:
        """Samples per correlation time: they share one error of the calibration."""
        return samples_per_correlation_time(measurement.interval_s, self._correlation_s)

    def model(self, measurement: MagneticField, point: LinearisationPoint):
        state = point.state
        states = self.states
        status, predicted, innovation, jacobian, covariance, gate_covariance = (
            magnetic_heading_model(
                point.rotation_nb,
                measurement.field_body_t,
                measurement.noise_variance_t2,
                self._weight(measurement),
                self._geomagnetic(state.latitude_rad, state.longitude_rad, measurement.t_s),
                self._heading_variance_rad2,
                states.attitude.start,
                states.dim,
            )
        )
        if status == REFUSED:
            return Reason.MAGNETIC_FIELD_INCONSISTENT
        if status == NO_GEOMETRY:
            return None
        return MeasurementModel(
            predicted=np.array((predicted,)),
            innovation=innovation,
            jacobian=jacobian,
            covariance=covariance,
            gate_covariance=gate_covariance,
        )

    has_compiled_model = True
    stretch_model = staticmethod(magnetometer_stretch_model)
    stretch_refusal = Reason.MAGNETIC_FIELD_INCONSISTENT

    def stretch_values(self, measurement: MagneticField, position_rad: tuple) -> tuple:
        """The numbers :func:`magnetometer_stretch_model` reads of a validated field, the
        Earth's field taken at the filter's ``position_rad`` (latitude, longitude) and the
        field's stamp (laid out with the model)."""
        latitude_rad, longitude_rad = position_rad
        return (
            *measurement.field_body_t.tolist(),
            measurement.noise_variance_t2,
            self._weight(measurement),
            *self._geomagnetic(latitude_rad, longitude_rad, measurement.t_s).tolist(),
            *wmm_cell_bounds_rad(latitude_rad, longitude_rad),
        )

    def stretch_terms(self) -> np.ndarray:
        """The terms :func:`magnetometer_stretch_model` reads: the calibration's heading
        variance (rad²), the error states' attitude start and their count."""
        states = self.states
        return np.array(
            (self._heading_variance_rad2, states.attitude.start, states.dim), dtype=float
        )

    def load_compiled_code(self) -> None:
        states = self.states
        magnetic_heading_model(
            np.eye(3), np.ones(3), 0.0, 1.0, np.zeros(GEOMAGNETIC_SIZE), 0.0, 0, states.dim
        )
        field_agrees(np.ones(3), 0.0, 1.0, 0.0, 1.0)

    def reset(self, measurement: MagneticField, point: LinearisationPoint, model):
        """The yaw that puts the field's horizontal part on magnetic north, tilt kept."""
        field = measurement.field_body_t
        # Turning about the vertical keeps the horizontal part's length: the current attitude
        # gives it.
        horizontal = np.asarray(point.rotation_nb, dtype=float) @ field
        horizontal_sq = horizontal[0] ** 2 + horizontal[1] ** 2
        state = point.state
        target = self.magnetic_north_azimuth_rad(
            state.latitude_rad, state.longitude_rad, measurement.t_s
        )
        variance = self._one_sample_variance(measurement, max(horizontal_sq, MIN_FIELD_T**2))
        return yaw_reset(self.states, point, field, target, variance)

    def align(self, aligner, t_s: float, measurement: MagneticField, raw_gyro_rad_s):
        """The azimuth of the field's horizontal part (magnetic north) completes the alignment
        at a known place (a fix, or the configured site), when the field agrees with the
        Earth's there (judged with the levelled attitude) and has agreed over the recent samples
        (:meth:`_field_agreed_long_enough`); a field that disagrees is refused as
        ``magnetic_field_inconsistent``."""
        place = aligner.latest_position_rad()
        if place is None:
            return None
        levelled = aligner.levelled_rotation()
        # Until the levelling is done, the field's strength alone is judged (it needs no
        # attitude), so that the evidence is in when the alignment could complete.
        field = (
            measurement.field_body_t if levelled is None else levelled @ measurement.field_body_t
        )
        refusal = self.field_refusal(field, *place, measurement.t_s, judge_dip=levelled is not None)
        # A strength that agrees says nothing of the dip, which hard iron bends as much: only a
        # field judged whole counts as agreeing, while one that fails either way counts against.
        if refusal is not None or levelled is not None:
            self._alignment_field_checks.append(refusal is not None)
        if refusal is not None:
            return refusal
        if levelled is None or not self._field_agreed_long_enough():
            return None
        target = self.magnetic_north_azimuth_rad(*place, measurement.t_s)
        field = measurement.field_body_t
        variance = self._heading_variance_rad2 + measurement.noise_variance_t2 / float(
            field @ field
        )
        return aligner.add_heading(t_s, target, variance, raw_gyro_rad_s, body_vector=field)

    def _field_agreed_long_enough(self) -> bool:
        """Whether the recent fields offered to the alignment agree with the Earth's as a
        suspended source's outcomes must to resume (an uncalibrated magnetometer passes now and
        then, at some headings, and one such field must not give the filter its heading)."""
        checks = self._alignment_field_checks
        if len(checks) < checks.maxlen:
            return False
        return sum(checks) <= self._alignment_resume_share * len(checks)
