"""The static sensor transforms against scipy's rotations (independent maths) and the lever arms."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from buoy_common.bag_io import jazzy_typestore
from buoy_common.contract import (
    ANEMOMETER_FRAME,
    BODY_FRAME,
    DVL_FRAME,
    GNSS_PRIMARY_FRAME,
    GNSS_SECONDARY_FRAME,
    GNSS_TERTIARY_FRAME,
    IMU_FRAME,
    TF_MSGTYPE,
)
from buoy_common.extrinsics import SHARED_PARAMETERS
from buoy_common.sensor_frames import quaternion_from_rpy_deg, sensor_transforms
from buoy_common.transform_messages import tf_cdr

MOUNTED = {
    "gnss.primary_antenna": (-0.75, 0.1, 1.0),
    "gnss.secondary_antenna": (0.75, -0.1, 1.2),
    "gnss.tertiary_antenna": (math.nan, math.nan, math.nan),
    "anemometer.position": (0.2, -0.3, 3.1),
    "anemometer.rpy_deg": (4.0, -7.5, 150.0),
    "dvl.position": (0.1, 0.0, -2.0),
    "dvl.rpy_deg": (180.0, 0.0, 45.0),
}


@pytest.mark.parametrize(
    "rpy_deg", [(0.0, 0.0, 0.0), (4.0, -7.5, 150.0), (-170.0, 89.0, -179.0), (30.0, 20.0, 10.0)]
)
def test_the_mounting_quaternion_is_scipys_zyx_rotation(rpy_deg):
    roll, pitch, yaw = rpy_deg
    expected = Rotation.from_euler("ZYX", [yaw, pitch, roll], degrees=True)
    quaternion = np.array(quaternion_from_rpy_deg(rpy_deg))
    assert np.linalg.norm(quaternion) == pytest.approx(1.0, abs=1e-15)
    np.testing.assert_allclose(
        Rotation.from_quat(quaternion).as_matrix(), expected.as_matrix(), atol=1e-14
    )


def test_each_sensor_frame_sits_at_its_lever_arm_with_its_mounting():
    transforms = {t.child_frame: t for t in sensor_transforms(MOUNTED, imu_link=True)}
    assert set(transforms) == {
        IMU_FRAME,
        GNSS_PRIMARY_FRAME,
        GNSS_SECONDARY_FRAME,
        ANEMOMETER_FRAME,
        DVL_FRAME,
    }
    assert all(t.parent_frame == BODY_FRAME for t in transforms.values())
    arms = {
        IMU_FRAME: ((0.0, 0.0, 0.0), None),
        GNSS_PRIMARY_FRAME: (MOUNTED["gnss.primary_antenna"], None),
        GNSS_SECONDARY_FRAME: (MOUNTED["gnss.secondary_antenna"], None),
        ANEMOMETER_FRAME: (MOUNTED["anemometer.position"], MOUNTED["anemometer.rpy_deg"]),
        DVL_FRAME: (MOUNTED["dvl.position"], MOUNTED["dvl.rpy_deg"]),
    }
    for frame, (arm, rpy_deg) in arms.items():
        transform = transforms[frame]
        rotation = Rotation.from_quat(transform.rotation_xyzw)
        # A point given in the sensor frame is R·p + t in base_link: the sensor's origin must
        # land on its lever arm.
        origin = rotation.apply([0.0, 0.0, 0.0]) + transform.translation_m
        np.testing.assert_allclose(origin, arm, atol=0.0)
        expected = (
            np.eye(3)
            if rpy_deg is None
            else Rotation.from_euler("ZYX", rpy_deg[::-1], degrees=True).as_matrix()
        )
        np.testing.assert_allclose(rotation.as_matrix(), expected, atol=1e-14)


def test_the_tertiary_antenna_is_a_frame_only_where_configured():
    assert GNSS_TERTIARY_FRAME not in {t.child_frame for t in sensor_transforms(MOUNTED)}
    placed = {**MOUNTED, "gnss.tertiary_antenna": (0.0, 0.9, 1.1)}
    tertiary = {t.child_frame: t for t in sensor_transforms(placed)}[GNSS_TERTIARY_FRAME]
    assert tertiary.translation_m == (0.0, 0.9, 1.1)
    assert tertiary.rotation_xyzw == (0.0, 0.0, 0.0, 1.0)


def test_only_the_frames_of_the_parameters_given_and_imu_link_on_request():
    anemometer = {p: MOUNTED[p] for p in ("anemometer.position", "anemometer.rpy_deg")}
    assert [t.child_frame for t in sensor_transforms(anemometer)] == [ANEMOMETER_FRAME]
    defaults = {name: p.default for name, p in SHARED_PARAMETERS.items()}
    frames = [t.child_frame for t in sensor_transforms(defaults, imu_link=True)]
    assert frames == [
        IMU_FRAME,
        GNSS_PRIMARY_FRAME,
        GNSS_SECONDARY_FRAME,
        ANEMOMETER_FRAME,
        DVL_FRAME,
    ]


def test_the_message_reads_back_as_the_transforms():
    transforms = sensor_transforms(MOUNTED, imu_link=True)
    message = jazzy_typestore().deserialize_cdr(tf_cdr(12, 34, transforms), TF_MSGTYPE)
    assert len(message.transforms) == len(transforms)
    for stamped, transform in zip(message.transforms, transforms, strict=True):
        assert (stamped.header.stamp.sec, stamped.header.stamp.nanosec) == (12, 34)
        assert stamped.header.frame_id == BODY_FRAME
        assert stamped.child_frame_id == transform.child_frame
        t, q = stamped.transform.translation, stamped.transform.rotation
        assert (t.x, t.y, t.z) == transform.translation_m
        assert (q.x, q.y, q.z, q.w) == transform.rotation_xyzw
