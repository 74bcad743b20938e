"""What the dual-antenna sources (heading and baseline vector) share: the baseline azimuth's
role in the alignment and in a yaw reset (the geometry is :mod:`buoy_nav.antenna_geometry`).

A moving-baseline RTK receiver measures the primary → secondary antenna vector
``b = R_nb · (l_s − l_p)`` (ENU); the heading it reports is the azimuth of that vector's
horizontal projection, ``ψ = atan2(b_N, b_E)`` (0 East, counter-clockwise). This azimuth is what
both sources contribute to the alignment and to a yaw reset, solved exactly for any tilt and any
antenna placement: with ``R_nb = Rz(yaw) R_L``, ``R_L = Ry(pitch) Rx(roll)``, the azimuth is
``yaw + atan2(w_y, w_x)`` where ``w = R_L (l_s − l_p)``.
"""

from __future__ import annotations

import abc

import numba
import numpy as np

from buoy_nav.aiding.base import (
    AidingSource,
    LinearisationPoint,
    MeasurementModel,
    StateReset,
    yaw_reset,
)
from buoy_nav.aiding.model_kernels import place_block, skew


@numba.njit(cache=True)
def baseline_stretch_model(values, state, rotation_nb, raw_gyro_rad_s, terms):
    """:meth:`DualAntennaSource.baseline_vector_model` over arrays, for a compiled stretch
    (:mod:`buoy_nav.aiding_epoch`): the antenna vector ``values`` (ENU m) at the nominal
    ``rotation_nb`` (the state and the raw gyro unused), with the source's ``terms``
    (:meth:`DualAntennaSource.stretch_terms`): the innovation (m), the Jacobian, R (m²) and
    whether the model holds (always)."""
    _, innovation, jacobian = baseline_vector_model(
        values[0:3].copy(), rotation_nb, terms[0:3].copy(), int(terms[12]), int(terms[13])
    )
    return innovation, jacobian, terms[3:12].reshape(3, 3).copy(), True


class DualAntennaSource(AidingSource):
    """A source that measures the antenna baseline's azimuth, alone or with its tilt.

    Its role in the alignment is that azimuth, which completes the alignment; after persistent
    gate rejections it resets the yaw to it, keeping roll and pitch.
    """

    def __init__(self, config, states):
        super().__init__(config, states)
        self._baseline_body_m = np.array(config.baseline_body_m)
        self._heading_variance_floor_rad2 = config.gnss_heading_variance_floor_rad2

    def baseline_vector_model(
        self, measured_enu_m, point: LinearisationPoint, covariance_m2
    ) -> MeasurementModel:
        """The model of a measured antenna vector ``measured_enu_m`` (ENU, m; noise
        ``covariance_m2``, m²), ``b = R_nb · baseline`` with ∂b/∂φ = −[b×], at ``point``."""
        states = self.states
        predicted, innovation, jacobian = baseline_vector_model(
            measured_enu_m,
            point.rotation_nb,
            self._baseline_body_m,
            states.attitude.start,
            states.dim,
        )
        return MeasurementModel(predicted, innovation, jacobian, covariance_m2)

    stretch_model = staticmethod(baseline_stretch_model)

    def stretch_values(self, measurement, position_rad: tuple) -> tuple[float, ...]:
        """The numbers :func:`baseline_stretch_model` reads of a validated antenna vector: the
        vector (ENU m), whatever the filter's ``position_rad``."""
        return tuple(measurement.baseline_enu_m.tolist())

    def stretch_terms(self) -> np.ndarray:
        """The terms :func:`baseline_stretch_model` reads: the baseline (body m), the noise
        (m², row-major), the error states' attitude start and their count (a source whose
        model is :meth:`baseline_vector_model` of its ``_covariance_m2``)."""
        states = self.states
        return np.array(
            (
                *self._baseline_body_m,
                *self._covariance_m2.reshape(9),
                states.attitude.start,
                states.dim,
            ),
            dtype=float,
        )

    def load_compiled_code(self) -> None:
        states = self.states
        baseline_vector_model(
            np.zeros(3), np.eye(3), self._baseline_body_m, states.attitude.start, states.dim
        )

    @abc.abstractmethod
    def baseline_azimuth(self, measurement) -> tuple[float, float] | None:
        """Azimuth of the measured baseline (rad, ENU, 0 = East, CCW) and its variance (rad²,
        floored at ``gnss_heading_variance_floor_rad2``); None when the measurement gives
        none (a baseline too steep)."""

    def reset(self, measurement, point: LinearisationPoint, model) -> StateReset | None:
        """The yaw that puts the baseline at the measured azimuth, roll and pitch kept."""
        measured = self.baseline_azimuth(measurement)
        if measured is None:
            return None
        azimuth, variance = measured
        return yaw_reset(self.states, point, self._baseline_body_m, azimuth, variance)

    def align(self, aligner, t_s: float, measurement, raw_gyro_rad_s):
        measured = self.baseline_azimuth(measurement)
        if measured is None:
            return None
        return aligner.add_heading(t_s, *measured, raw_gyro_rad_s)


@numba.njit(cache=True)
def baseline_vector_model(
    measured_enu_m, rotation_nb, baseline_body_m, attitude_start, state_count
):
    """The measurement function of an antenna vector ``measured_enu_m`` (ENU, m) whose body
    vector is ``baseline_body_m`` (m) at the nominal R_nb: the predicted vector, the innovation
    and the Jacobian over ``state_count`` error states (the attitude's from its start)."""
    predicted = np.dot(rotation_nb, baseline_body_m)
    jacobian = np.zeros((3, state_count))
    place_block(jacobian, attitude_start, -skew(predicted))
    return predicted, measured_enu_m - predicted, jacobian
