"""Faults of the simulated GNSS receiver's messages, for the tests that feed them to an engine."""

from buoy_common.contract import GNSS_VELOCITY_TOPIC


def biased_velocity(messages, from_s: float, start_ns: int, bias_east_mps: float):
    """The messages with ``bias_east_mps`` added to every GNSS velocity from ``from_s``."""
    for topic, stamp_ns, message in messages:
        if topic == GNSS_VELOCITY_TOPIC and stamp_ns - start_ns >= from_s * 1e9:
            message.twist.twist.linear.x += bias_east_mps
        yield topic, stamp_ns, message
