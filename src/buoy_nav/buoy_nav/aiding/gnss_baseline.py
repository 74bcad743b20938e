"""Dual-antenna baseline vector (``gnss/baseline``, geometry_msgs/Vector3Stamped; paper 001,
eq. 12–18).

A moving-baseline RTK receiver measures the primary → secondary antenna vector in ENU,
``b = R_nb · (l_s − l_p)``. Fusing the vector instead of only its azimuth also observes the
tilt of the baseline: with the antennas along body x, pitch, which an accelerometer bias
otherwise hides (a bias of β g reads as a tilt of β rad). The message has no covariance: the
1-σ errors per horizontal axis and vertically are parameters (the receiver's data sheet).

Jacobian under the convention ``R_true = Exp([φ×]) R_nb``: ``b_true = b + φ × b``, so

    ∂b/∂φ = −[b×]

and zero for every other state. The rotation about the baseline itself is not observed.

A measured baseline whose length differs from the configured antenna separation by more than
half is a wrong configuration or a wrong fix (rejected as ``out_of_range``). The source is
switched off by ``use_gnss_baseline``.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from buoy_common.contract import GNSS_BASELINE_TOPIC, Reason, header_seconds
from buoy_nav.aiding.base import (
    GNSS_ANTENNA_PAIR,
    HEADING,
    HEADING_REFERENCE,
    LinearisationPoint,
    MeasurementModel,
    as_float_array,
    vector_of,
)
from buoy_nav.aiding.dual_antenna import DualAntennaSource
from buoy_nav.antenna_geometry import MIN_HORIZONTAL_BASELINE_FRACTION, baseline_azimuth_rad

# A measured baseline whose length differs from the configured antenna separation by more than
# this fraction is a wrong configuration or a wrong fix, not a measurement.
MAX_BASELINE_LENGTH_ERROR_FRACTION = 0.5


class GnssBaseline(NamedTuple):
    """The primary → secondary antenna vector (ENU, m)."""

    baseline_enu_m: np.ndarray


class GnssBaselineSource(DualAntennaSource):
    """The dual-antenna baseline vector (see the module docstring)."""

    kind = "gnss_baseline"
    topic = GNSS_BASELINE_TOPIC
    measurement_type = GnssBaseline
    aids = HEADING
    sensor = GNSS_ANTENNA_PAIR
    roles = frozenset((HEADING_REFERENCE,))
    has_compiled_model = True

    def __init__(self, config, states):
        super().__init__(config, states)
        self._baseline_length_m = float(np.linalg.norm(self._baseline_body_m))
        sigma_horizontal = config.gnss_baseline_sigma_horizontal_m
        horizontal_variance = sigma_horizontal * sigma_horizontal
        self._covariance_m2 = np.diag(
            (horizontal_variance, horizontal_variance, config.gnss_baseline_sigma_vertical_m**2)
        )
        # Shared by every model of this source.
        self._covariance_m2.setflags(write=False)

    @classmethod
    def enabled_by(cls, config) -> bool:
        return config.use_gnss_baseline

    record_fields = ("vector",)

    def measurement_from_message(self, message) -> GnssBaseline:
        return self.measurement_from_record(
            header_seconds(message.header), vector_of(message.vector)
        )

    def measurement_from_record(self, t_s: float, vector_enu_m) -> GnssBaseline:
        return GnssBaseline(tuple(vector_enu_m))

    def validated(self, measurement: GnssBaseline) -> GnssBaseline | Reason:
        baseline = as_float_array(measurement.baseline_enu_m, (3,))
        if isinstance(baseline, Reason):
            return baseline
        length_error = float(np.linalg.norm(baseline)) - self._baseline_length_m
        if abs(length_error) > MAX_BASELINE_LENGTH_ERROR_FRACTION * self._baseline_length_m:
            return Reason.OUT_OF_RANGE
        return GnssBaseline(baseline)

    def model(self, measurement: GnssBaseline, point: LinearisationPoint) -> MeasurementModel:
        return self.baseline_vector_model(measurement.baseline_enu_m, point, self._covariance_m2)

    def baseline_azimuth(self, measurement: GnssBaseline) -> tuple[float, float] | None:
        """The azimuth of the measured vector, its variance the horizontal error over the
        horizontal length; None when the vector is too steep to have one."""
        azimuth, horizontal_length = baseline_azimuth_rad(measurement.baseline_enu_m)
        if horizontal_length < MIN_HORIZONTAL_BASELINE_FRACTION * self._baseline_length_m:
            return None
        variance = (self.config.gnss_baseline_sigma_horizontal_m / horizontal_length) ** 2
        return azimuth, max(variance, self._heading_variance_floor_rad2)
