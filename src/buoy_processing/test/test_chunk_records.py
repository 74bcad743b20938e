"""The sensor-rate messages of a chunk read together: each record holds what the per-message
CDR reader reads of its message, at that message's place in the chunk, and feeding the fusion
from the records accepts, rejects and counts every message as feeding it one message at a
time does."""

from __future__ import annotations

import math
from pathlib import Path

import pytest

from buoy_common import cdr
from buoy_common.bag_io import BagError, BagMessage, BagReader, jazzy_typestore
from buoy_nav.config import fusion_config_from_files
from buoy_processing.chunk_records import chunk_records
from buoy_processing.offline_fusion import IMU_RECORD_FIELDS, OfflineFusion, sensor_topics_of

REPO = Path(__file__).resolve().parents[3]
BAG = REPO / "bags" / "open_ocean"
PARAMETERS = [REPO / "src/buoy_common/config/buoy.yaml", REPO / "src/buoy_nav/config/fusion.yaml"]
IMU = "/imu/data_raw"
WIND = "/anemometer/wind"
SECONDS_READ = 40.0
CHUNK_MESSAGES = 500


def first_messages(topics: list[str], seconds: float) -> list[BagMessage]:
    with BagReader(BAG) as reader:
        end_ns = reader.start_ns + round(seconds * 1e9)
        return [m for m in reader.messages(topics) if m.log_time_ns < end_ns]


def with_raw(message: BagMessage, raw: bytes) -> BagMessage:
    return message._replace(raw=raw)


def big_endian(message: BagMessage) -> BagMessage:
    store = jazzy_typestore()
    decoded = store.deserialize_cdr(message.raw, message.msgtype)
    raw = store.serialize_cdr(decoded, message.msgtype, little_endian=False)
    return with_raw(message, bytes(raw))


def with_frame_not_utf8(message: BagMessage) -> BagMessage:
    """The message with the first byte of its frame id (after the stamp and the length) made
    a byte that UTF-8 never starts with: the per-message IMU reader skips the frame id."""
    raw = bytearray(message.raw)
    raw[16] = 0xFF
    return with_raw(message, bytes(raw))


def with_value(message: BagMessage, path: str, value) -> BagMessage:
    """The message with the field at attribute ``path`` (dotted) set to ``value``."""
    store = jazzy_typestore()
    decoded = store.deserialize_cdr(message.raw, message.msgtype)
    *parents, name = path.split(".")
    owner = decoded
    for parent in parents:
        owner = getattr(owner, parent)
    setattr(owner, name, value)
    return with_raw(message, bytes(store.serialize_cdr(decoded, message.msgtype)))


def with_nan_rate(message: BagMessage) -> BagMessage:
    return with_value(message, "angular_velocity.x", math.nan)


def with_zero_orientation(message: BagMessage) -> BagMessage:
    for part in "xyzw":
        message = with_value(message, f"orientation.{part}", 0.0)
    return message


AIDING_DAMAGE = {
    "/gnss/fix": (
        lambda m: with_value(m, "latitude", math.nan),
        lambda m: with_value(m, "status.status", -1),
        big_endian,
    ),
    "/gnss/vel": (lambda m: with_value(m, "twist.twist.linear.y", math.inf), big_endian),
    "/gnss/heading": (with_zero_orientation, big_endian),
    "/gnss/baseline": (lambda m: with_value(m, "vector.z", math.nan), big_endian),
}
"""What is done to some messages of each aiding topic: values the sources reject, and
messages the bulk decoder leaves to the per-message path."""


def test_records_are_what_the_per_message_readers_read_at_each_place():
    messages = first_messages([IMU, WIND], 5.0)
    # Ties: a wind sample logged at the same time as the IMU sample before it.
    imu_at = [i for i, m in enumerate(messages) if m.topic == IMU][:20]
    tied = [messages[imu_at[0]], messages[imu_at[1]]]
    wind = next(m for m in messages if m.topic == WIND)
    batch = [
        *tied,
        wind._replace(log_time_ns=tied[1].log_time_ns),
        big_endian(messages[imu_at[2]]),
        with_raw(messages[imu_at[3]], messages[imu_at[3]].raw[:30]),
        with_frame_not_utf8(messages[imu_at[4]]),
        *messages,
    ]
    records = chunk_records(batch, {IMU: IMU_RECORD_FIELDS, WIND: ("frame_id", "vector")})
    assert set(records) == set(range(len(batch))) - {3, 4, 5}
    for position, record in records.items():
        raw = batch[position].raw
        if batch[position].topic == IMU:
            sec, nanosec, rate, acceleration = cdr.read_imu_rate_and_acceleration(raw)
            assert record == (sec, nanosec, list(rate), list(acceleration))
        else:
            sec, nanosec, frame_id, vector = cdr.read_vector3_stamped(raw)
            assert record == (sec, nanosec, frame_id, list(vector))


def test_a_chunk_of_other_topics_has_no_records():
    messages = first_messages([WIND], 2.0)
    assert chunk_records(messages, {IMU: IMU_RECORD_FIELDS}) == {}
    assert chunk_records([], {IMU: IMU_RECORD_FIELDS}) == {}


class HeldWriter:
    """What the fusion writes, kept in order."""

    def __init__(self):
        self.written = []

    def write_raw(self, topic: str, msgtype: str, log_time_ns: int, raw: bytes) -> None:
        self.written.append((topic, msgtype, log_time_ns, raw))


def feed(reader: BagReader, sensors: dict[str, str], batches, in_chunks: bool):
    """The messages written, the rejections and the counters of a fusion fed ``batches`` of
    ``reader``'s bag."""
    relative_of = {stored: relative for relative, stored in sensors.items()}
    writer = HeldWriter()
    fusion = OfflineFusion(fusion_config_from_files([str(p) for p in PARAMETERS]), writer)
    solutions = []
    for batch in batches:
        records = chunk_records(batch, fusion.record_fields(sensors)) if in_chunks else {}
        for position, message in enumerate(batch):
            topic = relative_of[message.topic]
            solutions += fusion.add_message(reader, topic, message, records.get(position))
    solutions += fusion.finish()
    health = fusion.engine.health()
    counters = {kind: (c.accepted, dict(c.rejected)) for kind, c in health.counters.items()}
    assert len(writer.written) == 5 * len(solutions)
    return writer.written, fusion.rejections, counters


def test_fusion_fed_by_chunks_equals_fusion_fed_one_message_at_a_time():
    with BagReader(BAG) as reader:
        sensors = sensor_topics_of(reader, fusion_config_from_files([str(p) for p in PARAMETERS]))
        messages = first_messages(list(sensors.values()), SECONDS_READ)
        imu_at = [i for i, m in enumerate(messages) if m.topic == IMU]
        for number, change in enumerate((with_nan_rate, big_endian, with_frame_not_utf8)):
            for at in imu_at[1000 + 300 * number :][:3]:
                messages[at] = change(messages[at])
        for topic, changes in AIDING_DAMAGE.items():
            topic_at = [i for i, m in enumerate(messages) if m.topic == topic]
            for number, change in enumerate(changes):
                at = topic_at[len(topic_at) // 2 + 7 * number]
                messages[at] = change(messages[at])
        batches = [
            messages[start : start + CHUNK_MESSAGES]
            for start in range(0, len(messages), CHUNK_MESSAGES)
        ]
        written, rejections, counters = feed(reader, sensors, batches, in_chunks=True)
        expected = feed(reader, sensors, batches, in_chunks=False)
    assert len(written) > 5 * 2000, "the fusion aligned and navigated"
    assert rejections == expected[1] and rejections["imu/data_raw: non_finite"] == 3
    assert counters == expected[2]
    assert rejections["gnss/fix: no_fix"] == 1
    for kind in ("gnss_fix", "gnss_velocity", "gnss_baseline"):
        assert counters[kind][1].get("non_finite", 0) >= 1, kind
    assert counters["gnss_heading"][1].get("zero_quaternion", 0) == 1
    assert written == expected[0]


def test_an_undecodable_imu_message_stops_the_run_as_one_at_a_time():
    with BagReader(BAG) as reader:
        sensors = sensor_topics_of(reader, fusion_config_from_files([str(p) for p in PARAMETERS]))
        messages = first_messages(list(sensors.values()), 2.0)
        at = next(i for i, m in enumerate(messages) if m.topic == IMU)
        messages[at] = with_raw(messages[at], messages[at].raw[:30])
        for in_chunks in (True, False):
            with pytest.raises(BagError, match="cannot decode"):
                feed(reader, sensors, [messages], in_chunks)
