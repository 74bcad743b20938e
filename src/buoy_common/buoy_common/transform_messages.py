"""``tf2_msgs/TFMessage`` built with rosbags' Jazzy typestore, for ``tf`` and ``tf_static``.

The messages are rosbags message objects serialised to CDR bytes, so bags carry them without
tf2 installed, and the nodes publish the same bytes (rclpy publishes serialised messages)
where it is.
"""

from __future__ import annotations

from collections.abc import Iterable
from typing import NamedTuple

from buoy_common.bag_io import jazzy_typestore
from buoy_common.contract import TF_MSGTYPE


class FrameTransform(NamedTuple):
    """Where ``child_frame`` sits in ``parent_frame``: the origin of the child in the parent's
    axes (m), and the rotation taking child-frame vectors into the parent frame (unit
    quaternion x, y, z, w)."""

    parent_frame: str
    child_frame: str
    translation_m: tuple[float, float, float]
    rotation_xyzw: tuple[float, float, float, float]


def tf_message(sec: int, nanosec: int, transforms: Iterable[FrameTransform]):
    """A ``TFMessage`` (rosbags object) holding ``transforms``, each stamped (sec, nanosec)."""
    types = jazzy_typestore().types
    stamped = []
    for transform in transforms:
        x, y, z = transform.translation_m
        qx, qy, qz, qw = transform.rotation_xyzw
        stamped.append(
            types["geometry_msgs/msg/TransformStamped"](
                header=types["std_msgs/msg/Header"](
                    stamp=types["builtin_interfaces/msg/Time"](sec=sec, nanosec=nanosec),
                    frame_id=transform.parent_frame,
                ),
                child_frame_id=transform.child_frame,
                transform=types["geometry_msgs/msg/Transform"](
                    translation=types["geometry_msgs/msg/Vector3"](x=x, y=y, z=z),
                    rotation=types["geometry_msgs/msg/Quaternion"](x=qx, y=qy, z=qz, w=qw),
                ),
            )
        )
    return types[TF_MSGTYPE](transforms=stamped)


def tf_cdr(sec: int, nanosec: int, transforms: Iterable[FrameTransform]) -> bytes:
    """:func:`tf_message` as CDR bytes, as rosbags (and rclpy) serialise it."""
    return bytes(jazzy_typestore().serialize_cdr(tf_message(sec, nanosec, transforms), TF_MSGTYPE))
