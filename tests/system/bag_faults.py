"""Faults injected into a recorded bag: read a bag, apply a fault, write a new bag.

A bag is taken as a list of :class:`Record` (topic, type, log time, serialised bytes). Each fault
is a function of that list returning a new one; the messages it touches are decoded, changed and
serialised again, every other record keeps its bytes. Times are given in seconds from the first
record's log time, and a fault picks its messages by log time, which no fault on stamps moves.
The file faults (a cut file, a lost ``metadata.yaml``) act on a written bag.

The IMU faults the filter's integrity monitoring is judged on are named in :data:`IMU_FAULTS`:
five gyro samples of 30 rad/s on one axis and one accelerometer sample of 100 m/s² (inside the
magnitude limits of 35 rad/s and 160 m/s²), and the IMU's stamps stepping back or forward 5 s.
"""

from __future__ import annotations

import math
import shutil
from collections.abc import Callable, Iterable
from dataclasses import dataclass, replace
from pathlib import Path

from rclpy.serialization import deserialize_message, serialize_message

from buoy_common.bag_io import BagReader, BagWriter
from buoy_common.base_node import message_class
from buoy_common.cdr import read_stamp
from buoy_common.contract import (
    NANOSECONDS_PER_SECOND,
    SONIC_TEMPERATURE_TOPIC,
    TEMPERATURE_MSGTYPE,
    WIND_RAW_TOPIC,
    stamp_to_ns,
)

IMU_TOPIC = "/imu/data_raw"
CLOCK_STEP_S = 5.0


@dataclass(frozen=True)
class Record:
    """One message of a bag."""

    topic: str
    msgtype: str
    log_time_ns: int
    raw: bytes

    def message(self):
        return deserialize_message(self.raw, message_class(self.msgtype))

    def with_message(self, message) -> Record:
        return replace(self, raw=serialize_message(message))


Fault = Callable[[list[Record]], list[Record]]


def read_records(bag: Path, topics: Iterable[str] | None, seconds: float) -> list[Record]:
    """The first ``seconds`` (log time) of ``topics`` (None: every topic) of ``bag``, bytes
    unchanged."""
    with BagReader(bag) as reader:
        end_ns = reader.start_ns + round(seconds * NANOSECONDS_PER_SECOND)
        records = []
        for message in reader.messages(None if topics is None else list(topics)):
            if message.log_time_ns > end_ns:
                break
            records.append(Record(message.topic, message.msgtype, message.log_time_ns, message.raw))
    return records


def write_records(records: list[Record], out: Path) -> None:
    """A new bag of ``records`` in log-time order (records of equal log time keep their order)."""
    with BagWriter(out) as writer:
        for record in sorted(records, key=lambda r: r.log_time_ns):
            writer.write_raw(record.topic, record.msgtype, record.log_time_ns, record.raw)


def with_sonic_temperature(records: list[Record]) -> list[Record]:
    """``records`` and an ``anemometer/temperature`` for each ``anemometer/wind`` record, with
    its stamp, logged just after it: a sonic's temperature, following its vertical wind."""
    temperatures = []
    for record in records:
        if record.topic.lstrip("/") != WIND_RAW_TOPIC:
            continue
        wind = record.message()
        temperature = message_class(TEMPERATURE_MSGTYPE)()
        temperature.header = wind.header
        temperature.temperature = 20.0 + 0.2 * wind.vector.z
        temperatures.append(
            Record(
                "/" + SONIC_TEMPERATURE_TOPIC,
                TEMPERATURE_MSGTYPE,
                record.log_time_ns + 1000,
                serialize_message(temperature),
            )
        )
    return records + temperatures


def write_faulty_bag(
    source: Path, out: Path, seconds: float, fault: Fault, topics: Iterable[str] | None = None
) -> list[Record]:
    """The first ``seconds`` of ``source`` (its ``topics``, default all) with ``fault`` in it,
    written to ``out``; returns the records written."""
    records = sorted(fault(read_records(source, topics, seconds)), key=lambda r: r.log_time_ns)
    write_records(records, out)
    return records


def _indices(records: list[Record], topic: str, from_s: float, to_s: float = math.inf) -> list:
    """Indices of ``topic``'s records logged in [from_s, to_s) after the first record."""
    start_ns = records[0].log_time_ns
    return [
        i
        for i, r in enumerate(records)
        if r.topic == topic and from_s <= (r.log_time_ns - start_ns) / NANOSECONDS_PER_SECOND < to_s
    ]


def header_stamp_ns(record: Record) -> int:
    stamp = read_stamp(record.raw)
    if stamp is None:
        return stamp_to_ns(record.message().header.stamp)
    return stamp[0] * NANOSECONDS_PER_SECOND + stamp[1]


def stamp_at_s(records: list[Record], topic: str, at_s: float) -> float:
    """The header stamp (s) of the first message of ``topic`` a fault from ``at_s`` touches."""
    return header_stamp_ns(records[_indices(records, topic, at_s)[0]]) / NANOSECONDS_PER_SECOND


# -- value faults ---------------------------------------------------------------------------------


def mutate(topic: str, at_s: float, count: int, change: Callable) -> Fault:
    """``change(message)`` applied to ``count`` consecutive messages of ``topic`` from ``at_s``."""

    def fault(records: list[Record]) -> list[Record]:
        records = list(records)
        for i in _indices(records, topic, at_s)[:count]:
            message = records[i].message()
            change(message)
            records[i] = records[i].with_message(message)
        return records

    return fault


def set_vector(path: str, value: tuple[float, float, float]) -> Callable:
    """A ``change`` that sets the Vector3 at dotted attribute ``path`` (``angular_velocity``)."""

    def change(message) -> None:
        target = message
        for name in path.split("."):
            target = getattr(target, name)
        target.x, target.y, target.z = value

    return change


def set_axis(path: str, axis: str, value: float) -> Callable:
    """A ``change`` that sets one axis (``"x"``) of the Vector3 at dotted attribute ``path``."""

    def change(message) -> None:
        target = message
        for name in path.split("."):
            target = getattr(target, name)
        setattr(target, axis, value)

    return change


def add_to_vector(path: str, delta: tuple[float, float, float]) -> Callable:
    """A ``change`` that adds ``delta`` to the Vector3 at dotted attribute ``path``."""

    def change(message) -> None:
        target = message
        for name in path.split("."):
            target = getattr(target, name)
        target.x += delta[0]
        target.y += delta[1]
        target.z += delta[2]

    return change


def set_fields(**values) -> Callable:
    """A ``change`` that sets plain fields (``latitude=nan``)."""

    def change(message) -> None:
        for name, value in values.items():
            setattr(message, name, value)

    return change


def set_frame(topic: str, frame_id: str) -> Fault:
    """Every message of ``topic`` stamped in frame ``frame_id`` (a driver's own naming)."""
    return mutate(topic, 0.0, 2**62, set_fields_of_header(frame_id=frame_id))


def set_fields_of_header(**values) -> Callable:
    def change(message) -> None:
        for name, value in values.items():
            setattr(message.header, name, value)

    return change


# -- message faults -------------------------------------------------------------------------------


def duplicate(topic: str, at_s: float, count: int = 1) -> Fault:
    """``count`` messages of ``topic`` from ``at_s`` sent twice (same bytes, same log time)."""

    def fault(records: list[Record]) -> list[Record]:
        chosen = set(_indices(records, topic, at_s)[:count])
        out = []
        for i, record in enumerate(records):
            out.append(record)
            if i in chosen:
                out.append(record)
        return out

    return fault


def swap(topic: str, at_s: float) -> Fault:
    """Two consecutive messages of ``topic`` from ``at_s`` arrive in the reverse order."""

    def fault(records: list[Record]) -> list[Record]:
        records = list(records)
        first, second = _indices(records, topic, at_s)[:2]
        records[first], records[second] = (
            replace(records[second], log_time_ns=records[first].log_time_ns),
            replace(records[first], log_time_ns=records[second].log_time_ns),
        )
        return records

    return fault


def delay(topic: str, at_s: float, delay_s: float, count: int = 1) -> Fault:
    """``count`` messages of ``topic`` from ``at_s`` arrive ``delay_s`` late (log time)."""

    def fault(records: list[Record]) -> list[Record]:
        records = list(records)
        for i in _indices(records, topic, at_s)[:count]:
            late_ns = records[i].log_time_ns + round(delay_s * NANOSECONDS_PER_SECOND)
            records[i] = replace(records[i], log_time_ns=late_ns)
        return records

    return fault


def drop(topic: str, from_s: float, to_s: float) -> Fault:
    """An outage: no message of ``topic`` logged in [from_s, to_s)."""

    def fault(records: list[Record]) -> list[Record]:
        dropped = set(_indices(records, topic, from_s, to_s))
        return [r for i, r in enumerate(records) if i not in dropped]

    return fault


def shift_stamps(topic: str, from_s: float, shift_s: float) -> Fault:
    """A clock jump: the header stamps of ``topic`` from ``from_s`` on moved by ``shift_s``."""

    def change(message) -> None:
        shifted_ns = stamp_to_ns(message.header.stamp) + round(shift_s * NANOSECONDS_PER_SECOND)
        message.header.stamp.sec, message.header.stamp.nanosec = divmod(
            shifted_ns, NANOSECONDS_PER_SECOND
        )

    return mutate(topic, from_s, 2**62, change)


def combine(*faults: Fault) -> Fault:
    """Several faults, applied in order."""

    def fault(records: list[Record]) -> list[Record]:
        for one in faults:
            records = one(records)
        return records

    return fault


def intruder(
    other: list[Record], topics: Iterable[str], from_s: float, to_s: float, offset_s: float
) -> Fault:
    """A second buoy on the same topics: the records of ``topics`` that ``other`` (a bag of
    another buoy starting at the same log time) logged in [``from_s``, ``to_s``), logged at their
    own header stamps (as live nodes deliver them, not in a recorder's bursts) and interleaved by
    log time, their header stamps then moved by ``offset_s`` (its own clock)."""
    kept = set(topics)
    start_ns = other[0].log_time_ns
    window = [
        r
        for r in other
        if r.topic in kept and from_s <= (r.log_time_ns - start_ns) / NANOSECONDS_PER_SECOND < to_s
    ]
    shifted = shift_stamps_of_all(logged_at_stamps(kept)(window), offset_s)

    def fault(records: list[Record]) -> list[Record]:
        return sorted([*records, *shifted], key=lambda r: r.log_time_ns)

    return fault


def logged_at_stamps(topics: Iterable[str]) -> Fault:
    """The records of ``topics`` logged at their header stamps: delivered as they were stamped."""
    kept = set(topics)

    def fault(records: list[Record]) -> list[Record]:
        return [
            replace(r, log_time_ns=header_stamp_ns(r)) if r.topic in kept else r for r in records
        ]

    return fault


def shift_stamps_of_all(records: list[Record], shift_s: float) -> list[Record]:
    """``records`` with every header stamp moved by ``shift_s``."""
    shift_ns = round(shift_s * NANOSECONDS_PER_SECOND)
    shifted = []
    for record in records:
        message = record.message()
        stamp_ns = stamp_to_ns(message.header.stamp) + shift_ns
        message.header.stamp.sec, message.header.stamp.nanosec = divmod(
            stamp_ns, NANOSECONDS_PER_SECOND
        )
        shifted.append(record.with_message(message))
    return shifted


# -- the IMU faults of the integrity monitoring ------------------------------------------------


def gyro_spike(at_s: float) -> Fault:
    """Five gyro samples of 30 rad/s about x from ``at_s``."""
    return mutate(IMU_TOPIC, at_s, 5, set_axis("angular_velocity", "x", 30.0))


def accelerometer_spike(at_s: float) -> Fault:
    """One accelerometer sample of 100 m/s² along z at ``at_s``."""
    return mutate(IMU_TOPIC, at_s, 1, set_axis("linear_acceleration", "z", 100.0))


def imu_clock_back(at_s: float) -> Fault:
    """The IMU's stamps 5 s behind from ``at_s`` on."""
    return shift_stamps(IMU_TOPIC, at_s, -CLOCK_STEP_S)


def imu_clock_forward(at_s: float) -> Fault:
    """The IMU's stamps 5 s ahead from ``at_s`` on."""
    return shift_stamps(IMU_TOPIC, at_s, CLOCK_STEP_S)


IMU_FAULTS: dict[str, Callable[[float], Fault]] = {
    "gyro_spike": gyro_spike,
    "accelerometer_spike": accelerometer_spike,
    "clock_back": imu_clock_back,
    "clock_forward": imu_clock_forward,
}


# -- file faults ----------------------------------------------------------------------------------


def mcap_file(bag: Path) -> Path:
    return next(bag.glob("*.mcap"))


def truncate_file(bag: Path, fraction: float) -> None:
    """Cut the bag's data file to ``fraction`` of its length, as a power loss would."""
    path = mcap_file(bag)
    data = path.read_bytes()
    path.write_bytes(data[: int(len(data) * fraction)])


def remove_metadata(bag: Path) -> None:
    (bag / "metadata.yaml").unlink()


def copy_bag(source: Path, out: Path) -> Path:
    shutil.copytree(source, out)
    return out
