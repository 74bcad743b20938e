"""Dual-antenna heading (``gnss/heading``, sensor_msgs/Imu).

The receiver reports the azimuth of the horizontal projection of the primary → secondary
baseline, ``ψ = atan2(b_N, b_E)`` with ``b = R_nb · (l_s − l_p)`` in ENU (0 East,
counter-clockwise), as the yaw of the message's orientation quaternion, its variance in
``orientation_covariance[8]``. The model is exact for any tilt and any antenna placement, unlike
a plain yaw difference, which only holds for a baseline along body x on a level platform.

Jacobian under the convention ``R_true = Exp([φ×]) R_nb``: ``δb = φ × b``, and
``∂ψ/∂b = (−b_N, b_E, 0) / ρ²`` with ``ρ² = b_E² + b_N²``, so

    ∂ψ/∂φ = (−b_E b_U / ρ², −b_N b_U / ρ², 1)

and zero for every other state. It is singular when the baseline is vertical (ρ → 0): below
:data:`~buoy_nav.antenna_geometry.MIN_HORIZONTAL_BASELINE_FRACTION` of horizontal length the
heading is rejected as ``geometry``.

A baseline vector of the same stamp (:mod:`buoy_nav.aiding.gnss_baseline`), from the same
carrier-phase solution, carries this heading and the baseline's tilt: it supersedes the heading.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numba
import numpy as np

from buoy_common.contract import GNSS_HEADING_TOPIC, Reason
from buoy_nav.aiding.base import (
    GNSS_ANTENNA_PAIR,
    HEADING,
    HEADING_REFERENCE,
    ORIENTATION_RECORD_FIELDS,
    LinearisationPoint,
    MeasurementModel,
    as_floats,
    floored_covariance,
    orientation_record,
)
from buoy_nav.aiding.dual_antenna import DualAntennaSource
from buoy_nav.aiding.gnss_baseline import GnssBaselineSource
from buoy_nav.aiding.model_kernels import azimuth_model
from buoy_nav.aiding.model_kernels import floored_covariance as floored_covariance_kernel
from buoy_nav.aiding.model_kernels import wrap_angle as wrap_angle_kernel
from buoy_nav.antenna_geometry import MIN_HORIZONTAL_BASELINE_FRACTION, horizontal_fraction_enu
from buoy_nav.rotations import wrap_angle

# Quaternions shorter than this carry no heading.
MIN_QUATERNION_NORM = 1e-9


class GnssHeading(NamedTuple):
    """Azimuth of the primary → secondary baseline (rad, ENU, 0 = East, CCW) and its variance
    (rad²)."""

    yaw_rad: float
    variance_rad2: float


def yaw_from_quaternion_rad(x: float, y: float, z: float, w: float) -> float:
    """Yaw (rad, about ENU up, 0 = East, counter-clockwise) of the rotation of a quaternion
    (any norm): the azimuth of the rotated body x axis projected on the horizontal."""
    return math.atan2(2.0 * (w * z + x * y), w * w + x * x - y * y - z * z)


@numba.njit(cache=True)
def heading_stretch_model(values, state, rotation_nb, raw_gyro_rad_s, terms):
    """:meth:`GnssHeadingSource.model` over arrays, for a compiled stretch
    (:mod:`buoy_nav.aiding_epoch`): the heading ``values`` (yaw rad, variance rad²) at the
    nominal ``rotation_nb`` (the state and the raw gyro unused), with the source's ``terms``
    (:meth:`GnssHeadingSource.stretch_terms`): the innovation (rad), the Jacobian, R (rad²) and
    whether the model holds (not for a baseline too steep to have an azimuth)."""
    baseline_enu, _, predicted, jacobian = azimuth_model(
        rotation_nb, terms[1:4].copy(), int(terms[5]), int(terms[6])
    )
    # As horizontal_fraction_enu, with numpy's norm of a vector, √(b·b).
    fraction = math.hypot(baseline_enu[0], baseline_enu[1]) / math.sqrt(
        np.dot(baseline_enu, baseline_enu)
    )
    innovation = np.array((wrap_angle_kernel(values[0] - predicted),))
    covariance = floored_covariance_kernel(np.full((1, 1), values[1]), terms[0])
    return innovation, jacobian, covariance, not fraction < terms[4]


class GnssHeadingSource(DualAntennaSource):
    """The dual-antenna heading (see the module docstring)."""

    kind = "gnss_heading"
    topic = GNSS_HEADING_TOPIC
    measurement_type = GnssHeading
    aids = HEADING
    sensor = GNSS_ANTENNA_PAIR
    roles = frozenset((HEADING_REFERENCE,))
    superseded_by = GnssBaselineSource.kind
    has_compiled_model = True

    record_fields = ORIENTATION_RECORD_FIELDS

    def measurement_from_message(self, message) -> GnssHeading | Reason:
        return self.measurement_from_record(*orientation_record(message))

    def measurement_from_record(
        self, t_s: float, orientation_xyzw, orientation_covariance
    ) -> GnssHeading | Reason:
        x, y, z, w = orientation_xyzw
        norm = math.sqrt(x * x + y * y + z * z + w * w)
        if math.isfinite(norm) and norm < MIN_QUATERNION_NORM:
            return Reason.ZERO_QUATERNION
        if len(orientation_covariance) != 9:
            return Reason.MALFORMED
        return GnssHeading(yaw_from_quaternion_rad(x, y, z, w), orientation_covariance[8])

    def validated(self, measurement: GnssHeading) -> GnssHeading | Reason:
        values = as_floats(measurement.yaw_rad, measurement.variance_rad2)
        if isinstance(values, Reason):
            return values
        yaw, variance = values
        if variance <= 0.0:
            return Reason.NON_POSITIVE_VARIANCE
        return GnssHeading(wrap_angle(yaw), variance)

    def model(self, measurement: GnssHeading, point: LinearisationPoint) -> MeasurementModel | None:
        """The azimuth of the projected baseline (innovation wrapped to (−π, π]); None for a
        baseline too steep to have one."""
        states = self.states
        baseline_enu, _, predicted, jacobian = azimuth_model(
            point.rotation_nb, self._baseline_body_m, states.attitude.start, states.dim
        )
        if horizontal_fraction_enu(baseline_enu) < MIN_HORIZONTAL_BASELINE_FRACTION:
            return None
        return MeasurementModel(
            predicted=np.array((predicted,)),
            innovation=np.array((wrap_angle(measurement.yaw_rad - predicted),)),
            jacobian=jacobian,
            covariance=floored_covariance(
                measurement.variance_rad2, self._heading_variance_floor_rad2
            ),
        )

    stretch_model = staticmethod(heading_stretch_model)

    def stretch_values(self, measurement: GnssHeading, position_rad: tuple) -> tuple[float, ...]:
        """The numbers :func:`heading_stretch_model` reads of a validated heading: the yaw
        (rad) and its variance (rad²); neither depends on the filter's ``position_rad``."""
        return (measurement.yaw_rad, measurement.variance_rad2)

    def stretch_terms(self) -> np.ndarray:
        """The terms :func:`heading_stretch_model` reads: the variance floor (rad²), the
        baseline (body m), the least horizontal share of it, the error states' attitude start
        and their count."""
        states = self.states
        return np.array(
            (
                self._heading_variance_floor_rad2,
                *self._baseline_body_m,
                MIN_HORIZONTAL_BASELINE_FRACTION,
                states.attitude.start,
                states.dim,
            ),
            dtype=float,
        )

    def load_compiled_code(self) -> None:
        states = self.states
        azimuth_model(np.eye(3), self._baseline_body_m, states.attitude.start, states.dim)

    def baseline_azimuth(self, measurement: GnssHeading) -> tuple[float, float]:
        return measurement.yaw_rad, max(
            measurement.variance_rad2, self._heading_variance_floor_rad2
        )
