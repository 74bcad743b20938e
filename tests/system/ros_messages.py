"""Message and waiting helpers shared by the tests that talk to nodes over DDS or read bags."""

from __future__ import annotations

import struct
import time

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


def raw_stamp_ns(raw: bytes) -> int:
    """Header stamp of a CDR message that starts with a std_msgs/Header (little endian)."""
    assert raw[:2] == b"\x00\x01", "little-endian CDR"
    sec, nanosec = struct.unpack_from("<iI", raw, 4)
    return sec * NANOSECONDS_PER_SECOND + nanosec


def wait_for(condition, timeout_s: float) -> bool:
    """Poll ``condition()`` until it holds (True) or ``timeout_s`` passes (False)."""
    deadline = time.monotonic() + timeout_s
    while not condition():
        if time.monotonic() > deadline:
            return False
        time.sleep(0.02)
    return True


def reports_publishers_on(status, topics) -> bool:
    """A node's diagnostics ``status`` reports a matched publisher on each of ``topics``
    (relative names). Until then, a sample sent to the node arrives later, in a burst of its
    topic alone, out of stamp order with the other topics."""
    values = {item.key: item.value for item in status.values}
    return all(int(values.get(f"publishers[/{topic}]", 0)) > 0 for topic in topics)
