"""IMU faults written into a copy of a recorded bag, for the fault tests offline and live.

A fault is a function ``fault(message, index) -> bool`` that changes a decoded ``imu/data_raw``
message from the fault's stamp on (``index``: how many it changed before) and says whether it
changed this one.
"""

from __future__ import annotations

from pathlib import Path

from buoy_common.bag_io import BagReader, BagWriter

NANOSECONDS_PER_SECOND = 1_000_000_000
CLOCK_STEP_S = 5


def gyro_spike(message, index: int) -> bool:
    if index < 5:
        message.angular_velocity.x = 30.0
        return True
    return False


def accelerometer_spike(message, index: int) -> bool:
    if index < 1:
        message.linear_acceleration.z = 100.0
        return True
    return False


def clock_back(message, index: int) -> bool:
    message.header.stamp.sec -= CLOCK_STEP_S
    return True


def clock_forward(message, index: int) -> bool:
    message.header.stamp.sec += CLOCK_STEP_S
    return True


FAULTS = {
    "gyro_spike": gyro_spike,
    "accelerometer_spike": accelerometer_spike,
    "clock_back": clock_back,
    "clock_forward": clock_forward,
}


def faulty_bag(source: Path, out: Path, kept_s: float, faults, topics=None) -> float:
    """The first ``kept_s`` (log time) of ``source`` (its ``topics``, default all) with each
    fault of ``faults`` (pairs of seconds after the first IMU stamp and fault) applied from its
    time on; returns the first IMU stamp, s."""
    first_imu_s = None
    changed = [0] * len(faults)
    with BagReader(source) as reader, BagWriter(out) as writer:
        end_ns = reader.start_ns + int(kept_s * NANOSECONDS_PER_SECOND)
        for record in reader.messages(topics):
            if record.log_time_ns > end_ns:
                break
            if record.topic == "/imu/data_raw" and faults:
                message = reader.decode(record)
                t_s = message.header.stamp.sec + message.header.stamp.nanosec * 1e-9
                first_imu_s = t_s if first_imu_s is None else first_imu_s
                touched = False
                for k, (after_s, fault) in enumerate(faults):
                    if t_s - first_imu_s >= after_s and fault(message, changed[k]):
                        changed[k] += 1
                        touched = True
                if touched:
                    writer.write(record.topic, record.msgtype, record.log_time_ns, message)
                    continue
            writer.write_raw(record.topic, record.msgtype, record.log_time_ns, record.raw)
    return first_imu_s or 0.0
