"""Third-antenna baseline vector (``gnss/baseline_tertiary``, geometry_msgs/Vector3Stamped;
paper 001, the three-antenna attitude).

A receiver with three antennas measures a second vector, primary → tertiary, in ENU:
``b₂ = R_nb · (l_t − l_p)``. One baseline leaves the rotation about itself unobserved (with the
antennas along body x, the roll, which an accelerometer bias hides at rest); a second baseline
that is not parallel to the first observes it, so the two fix all three attitude angles with
no help from the motion. The model is that of :mod:`buoy_nav.aiding.gnss_baseline` with the
tertiary lever: ``∂b₂/∂φ = −[b₂×]``, zero for every other state; the errors per axis are the
same receiver parameters (``gnss_baseline_sigma_*``). The two vectors share the primary
antenna, whose carrier-phase error enters both; it is treated as independent (the receiver
solves each baseline with its own double differences, and the shared part is below the
per-baseline noise).

**Layout.** The source is enabled only when ``gnss.tertiary_antenna`` is configured. A layout
whose two baselines are within :data:`~buoy_common.extrinsics.MIN_TERTIARY_BASELINE_ANGLE_DEG`
of each other (near-collinear antennas) adds nothing the first baseline does not observe and
would count one direction twice: the source says so (:attr:`GnssBaselineTertiarySource.
configuration_problem`, reported by the tools and the node) and rejects every measurement as
``geometry`` instead of fusing it.

**Bad input.** A measured vector whose length differs from the configured primary → tertiary
distance by more than ``gnss_tertiary_length_tolerance_m`` is a wrong lever arm or a wrong
carrier-phase fix: rejected and counted as ``out_of_range``.

The alignment takes its heading from the primary → secondary antennas only; after persistent
gate rejections this source resets the yaw to its own azimuth, as the other dual-antenna
sources do.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from buoy_common.contract import GNSS_BASELINE_TERTIARY_TOPIC, Reason, header_seconds
from buoy_common.extrinsics import MIN_TERTIARY_BASELINE_ANGLE_DEG, tertiary_baseline_angle_deg
from buoy_nav.aiding.base import (
    GNSS_THIRD_ANTENNA,
    HEADING,
    LinearisationPoint,
    MeasurementModel,
    as_float_array,
    vector_of,
)
from buoy_nav.aiding.dual_antenna import DualAntennaSource
from buoy_nav.antenna_geometry import MIN_HORIZONTAL_BASELINE_FRACTION, baseline_azimuth_rad


class GnssBaselineTertiary(NamedTuple):
    """The primary → tertiary antenna vector (ENU, m)."""

    baseline_enu_m: np.ndarray


class GnssBaselineTertiarySource(DualAntennaSource):
    """The third antenna's baseline vector (see the module docstring)."""

    kind = "gnss_baseline_tertiary"
    topic = GNSS_BASELINE_TERTIARY_TOPIC
    measurement_type = GnssBaselineTertiary
    aids = HEADING
    sensor = GNSS_THIRD_ANTENNA
    # A carrier-phase vector like the first baseline: its own faults (a wrong fix, a wrong
    # antenna) are stopped by the length check before the gate, so persistent gate rejections
    # of a valid vector mean the filter's attitude is wrong.
    witnesses_integrity = True
    has_compiled_model = True

    def __init__(self, config, states):
        super().__init__(config, states)
        tertiary = config.tertiary_baseline_body_m
        if tertiary is None:
            self._baseline_body_m = np.full(3, np.nan)
            self._baseline_length_m = np.nan
            self.configuration_problem = "no tertiary antenna configured (gnss.tertiary_antenna)"
        else:
            self._baseline_body_m = np.array(tertiary)
            self._baseline_length_m = float(np.linalg.norm(tertiary))
            angle_deg = tertiary_baseline_angle_deg(
                config.primary_antenna_body_m,
                config.secondary_antenna_body_m,
                config.tertiary_antenna_body_m,
            )
            if angle_deg < MIN_TERTIARY_BASELINE_ANGLE_DEG:
                self.configuration_problem = (
                    f"near-collinear antennas: the primary-tertiary baseline is {angle_deg:.1f}° "
                    f"from the primary-secondary one (at least "
                    f"{MIN_TERTIARY_BASELINE_ANGLE_DEG:g}° needed); gnss/baseline_tertiary is "
                    "not fused"
                )
        self._length_tolerance_m = config.gnss_tertiary_length_tolerance_m
        sigma_horizontal = config.gnss_baseline_sigma_horizontal_m
        self._covariance_m2 = np.diag(
            (sigma_horizontal**2, sigma_horizontal**2, config.gnss_baseline_sigma_vertical_m**2)
        )
        self._covariance_m2.setflags(write=False)

    @classmethod
    def enabled_by(cls, config) -> bool:
        return config.use_gnss_baseline_tertiary and config.tertiary_baseline_body_m is not None

    record_fields = ("vector",)

    def measurement_from_message(self, message) -> GnssBaselineTertiary:
        return self.measurement_from_record(
            header_seconds(message.header), vector_of(message.vector)
        )

    def measurement_from_record(self, t_s: float, vector_enu_m) -> GnssBaselineTertiary:
        return GnssBaselineTertiary(tuple(vector_enu_m))

    def validated(self, measurement: GnssBaselineTertiary) -> GnssBaselineTertiary | Reason:
        baseline = as_float_array(measurement.baseline_enu_m, (3,))
        if isinstance(baseline, Reason):
            return baseline
        if self.configuration_problem is not None:
            return Reason.GEOMETRY
        length_error = float(np.linalg.norm(baseline)) - self._baseline_length_m
        if abs(length_error) > self._length_tolerance_m:
            return Reason.OUT_OF_RANGE
        return GnssBaselineTertiary(baseline)

    def model(
        self, measurement: GnssBaselineTertiary, point: LinearisationPoint
    ) -> MeasurementModel:
        return self.baseline_vector_model(measurement.baseline_enu_m, point, self._covariance_m2)

    def baseline_azimuth(self, measurement: GnssBaselineTertiary) -> tuple[float, float] | None:
        """The azimuth of the measured vector and its variance; None when too steep."""
        azimuth, horizontal_length = baseline_azimuth_rad(measurement.baseline_enu_m)
        if horizontal_length < MIN_HORIZONTAL_BASELINE_FRACTION * self._baseline_length_m:
            return None
        variance = (self.config.gnss_baseline_sigma_horizontal_m / horizontal_length) ** 2
        return azimuth, max(variance, self._heading_variance_floor_rad2)

    def align(self, aligner, t_s: float, measurement, raw_gyro_rad_s):
        """Not used by the alignment, which takes the heading of the first baseline."""
        return None
