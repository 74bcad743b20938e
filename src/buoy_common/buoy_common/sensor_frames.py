"""The static transforms ``base_link`` → each sensor frame, from the shared extrinsics.

The sensors' places are shared parameters (:mod:`buoy_common.extrinsics`): a lever arm in
``base_link`` (m) for each, and for the anemometer and the DVL a mounting as roll, pitch, yaw
(deg) applied as R = Rz(yaw)·Ry(pitch)·Rx(roll), which takes sensor-frame vectors into
``base_link``. The antennas' frames are not rotated; ``imu_link`` is ``base_link`` itself (the
IMU defines the body frame). Published on ``tf_static`` these let RViz and Foxglove draw the
sensors on the buoy.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping, Sequence
from typing import Any, NamedTuple

from buoy_common.contract import (
    ANEMOMETER_FRAME,
    BODY_FRAME,
    DVL_FRAME,
    GNSS_PRIMARY_FRAME,
    GNSS_SECONDARY_FRAME,
    GNSS_TERTIARY_FRAME,
    IMU_FRAME,
)
from buoy_common.extrinsics import field_parameter
from buoy_common.transform_messages import FrameTransform

IDENTITY_XYZW = (0.0, 0.0, 0.0, 1.0)
_ORIGIN_M = (0.0, 0.0, 0.0)


class SensorFrame(NamedTuple):
    """A sensor frame and the shared parameters that place it in ``base_link``: its lever arm
    (m) and its mounting angles (deg; None: not rotated)."""

    frame: str
    position_parameter: str
    rpy_parameter: str | None = None


SENSOR_FRAMES = (
    SensorFrame(GNSS_PRIMARY_FRAME, "gnss.primary_antenna"),
    SensorFrame(GNSS_SECONDARY_FRAME, "gnss.secondary_antenna"),
    SensorFrame(GNSS_TERTIARY_FRAME, "gnss.tertiary_antenna"),
    SensorFrame(ANEMOMETER_FRAME, "anemometer.position", "anemometer.rpy_deg"),
    SensorFrame(DVL_FRAME, "dvl.position", "dvl.rpy_deg"),
)
"""Every sensor frame placed by shared parameters (``imu_link`` is placed by definition)."""


def quaternion_from_rpy_deg(rpy_deg: Sequence[float]) -> tuple[float, float, float, float]:
    """Unit quaternion (x, y, z, w) of R = Rz(yaw)·Ry(pitch)·Rx(roll), roll, pitch, yaw in deg:
    the product qz(yaw)·qy(pitch)·qx(roll) of the three half-angle quaternions."""
    roll, pitch, yaw = (math.radians(angle) / 2.0 for angle in rpy_deg)
    cr, sr = math.cos(roll), math.sin(roll)
    cp, sp = math.cos(pitch), math.sin(pitch)
    cy, sy = math.cos(yaw), math.sin(yaw)
    return (
        sr * cp * cy - cr * sp * sy,
        cr * sp * cy + sr * cp * sy,
        cr * cp * sy - sr * sp * cy,
        cr * cp * cy + sr * sp * sy,
    )


def sensor_transforms(
    extrinsics: Mapping[str, Sequence[float]], imu_link: bool = False
) -> list[FrameTransform]:
    """``base_link`` → each sensor frame whose position parameter ``extrinsics`` holds (by
    shared parameter name: lever arms in m, mounting angles in deg), and ``base_link`` →
    ``imu_link`` (identity) with ``imu_link``. A frame whose position is not finite (the
    tertiary antenna's NaN: no such antenna) is left out."""
    transforms = []
    if imu_link:
        transforms.append(FrameTransform(BODY_FRAME, IMU_FRAME, _ORIGIN_M, IDENTITY_XYZW))
    for frame in SENSOR_FRAMES:
        position = extrinsics.get(frame.position_parameter)
        if position is None or not all(math.isfinite(c) for c in position):
            continue
        rotation = (
            IDENTITY_XYZW
            if frame.rpy_parameter is None
            else quaternion_from_rpy_deg(extrinsics[frame.rpy_parameter])
        )
        translation = tuple(float(c) for c in position)
        transforms.append(FrameTransform(BODY_FRAME, frame.frame, translation, rotation))
    return transforms


def shared_values(*configs) -> dict[str, Any]:
    """The shared parameters the configuration dataclasses ``configs`` hold, by parameter name
    (a later configuration wins: they hold the same values where they share one)."""
    return {
        parameter: getattr(config, field.name)
        for config in configs
        for field in dataclasses.fields(config)
        if (parameter := field_parameter(field)) is not None
    }
