"""Message helpers shared by the tests that talk to nodes over DDS."""

from __future__ import annotations

import numpy as np

NANOSECONDS_PER_SECOND = 1_000_000_000


def to_rclpy(source, target):
    """Copy the fields of a rosbags message into an rclpy message of the same type."""
    for name in target.get_fields_and_field_types():
        value = getattr(source, name)
        if hasattr(value, "__dataclass_fields__"):
            to_rclpy(value, getattr(target, name))
        elif isinstance(value, np.ndarray):
            setattr(target, name, value.tolist())
        else:
            setattr(target, name, value)
    return target


def stamp_ns(message) -> int:
    """Header stamp of a message, integer nanoseconds since the epoch."""
    return message.header.stamp.sec * NANOSECONDS_PER_SECOND + message.header.stamp.nanosec
