"""Every committed bag is a real rosbag2 MCAP bag: rosbags and, independently, mcap +
mcap-ros2-support read it, with the contract's topics, types and the counts its rates imply."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory
from rosbags.rosbag2 import Reader

from buoy_common.bag_io import BagReader
from ros_messages import raw_stamp_ns

BAGS = sorted(p for p in (Path(__file__).resolve().parents[2] / "bags").iterdir() if p.is_dir())
SENSOR_RATES_HZ = {
    "/imu/data_raw": ("sensor_msgs/msg/Imu", 100.0),
    "/gnss/fix": ("sensor_msgs/msg/NavSatFix", 10.0),
    "/gnss/vel": ("geometry_msgs/msg/TwistWithCovarianceStamped", 10.0),
    "/gnss/heading": ("sensor_msgs/msg/Imu", 10.0),
    "/gnss/baseline": ("geometry_msgs/msg/Vector3Stamped", 10.0),
    "/anemometer/wind": ("geometry_msgs/msg/Vector3Stamped", 20.0),
    "/truth/odometry": ("nav_msgs/msg/Odometry", 50.0),
    "/truth/wind": ("geometry_msgs/msg/Vector3Stamped", 50.0),
}


# A recorder that keeps pace logs a message within a sample period or two of its stamp.
MAX_MEDIAN_LOG_DELAY_S = 0.05


@pytest.fixture(scope="module", params=BAGS, ids=[b.name for b in BAGS])
def bag(request) -> Path:
    # Module-scoped, so that pytest runs a bag's tests together and holds one bag's messages
    # at a time.
    return request.param


@pytest.fixture(scope="module")
def read_by_us(bag) -> tuple[BagReader, list]:
    """BagReader (closed: its topics and decoding remain) and every message it reads from
    ``bag``, in its order: read once for the tests of the bag."""
    with BagReader(bag) as reader:
        messages = list(reader.messages())
    return reader, messages


def test_there_are_committed_bags():
    assert len(BAGS) >= 4


def test_bag_has_contract_topics_types_and_counts(read_by_us):
    reader, messages = read_by_us
    topics = reader.topics
    imu = [message for message in messages if message.topic == "/imu/data_raw"]
    first, last = (reader.decode(message).header.stamp for message in (imu[0], imu[-1]))
    duration_s = (last.sec + last.nanosec * 1e-9) - (first.sec + first.nanosec * 1e-9)
    for topic, (msgtype, rate_hz) in SENSOR_RATES_HZ.items():
        assert topics[topic].msgtype == msgtype
        # one sample per period over the run (a topic may start or stop within a period)
        expected = duration_s * rate_hz + 1
        assert math.isclose(topics[topic].count, expected, abs_tol=2), topic


def test_bag_reader_gives_the_messages_rosbags_reads_in_its_order(bag, read_by_us):
    """BagReader reads a finished bag through the MCAP chunk index, not through rosbags: the
    same messages, bytes, types and order."""
    with Reader(bag) as reference:
        expected = [
            (connection.topic, connection.msgtype, time_ns, bytes(raw))
            for connection, time_ns, raw in reference.messages()
        ]
    read = [(m.topic, m.msgtype, m.log_time_ns, m.raw) for m in read_by_us[1]]
    assert read == expected


# mcap-ros2-support decodes in pure Python, and decoding all of a bag's messages took seconds a
# bag. Every message is still read and counted by the mcap library; its decoder reads an evenly
# spread sample of each topic, the first and last message among them. What decoding is here to
# catch, a schema in the file that does not describe the bytes recorded under it, shows in any
# message of the topic: all of a topic's messages are written from its one schema.
DECODED_PER_TOPIC = 50


def test_bag_is_read_by_mcap_independently(bag, read_by_us):
    (mcap_file,) = bag.glob("*.mcap")
    recorded: dict[str, tuple] = {}  # topic → (schema, channel, its messages)
    with open(mcap_file, "rb") as stream:
        reader = make_reader(stream, validate_crcs=True)  # of the chunks that carry one
        assert reader.get_header().profile == "ros2"
        # In file order: the library's log-time merge of the chunks costs more than the reading.
        for schema, channel, message in reader.iter_messages(log_time_order=False):
            assert schema.encoding == "ros2msg"
            recorded.setdefault(channel.topic, (schema, channel, []))[2].append(message)
    counts = {topic: len(messages) for topic, (_, _, messages) in recorded.items()}
    ours = read_by_us[0]
    assert counts == {topic: info.count for topic, info in ours.topics.items()}
    decoders = DecoderFactory()
    first = {}
    for topic, (schema, channel, messages) in recorded.items():
        decode = decoders.decoder_for(channel.message_encoding, schema)
        assert decode is not None, topic
        messages.sort(key=lambda message: message.log_time)  # ties stay in file order
        for index in np.linspace(0, len(messages) - 1, DECODED_PER_TOPIC).astype(int):
            decoded = decode(messages[index].data)
            first.setdefault(topic, decoded)
    # decoded by a reader that shares no code with ours, the physics is still there
    assert 9.0 < first["/imu/data_raw"].linear_acceleration.z < 10.6
    assert first["/anemometer/wind"].header.frame_id == "anemometer_link"
    assert -90.0 <= first["/gnss/fix"].latitude <= 90.0


def test_the_recorder_kept_pace_with_every_sensor(bag, read_by_us):
    # Log times are the recorder's receive times on the simulation clock. A recording made on a
    # machine too busy for its rate factor logs whole topics seconds after their stamps, and a
    # replay at the recorded pace then feeds the nodes measurements later than they accept.
    for topic in SENSOR_RATES_HZ:
        if topic.startswith("/truth/"):
            continue
        delays_s = np.array(
            [
                (r.log_time_ns - raw_stamp_ns(r.raw)) * 1e-9
                for r in read_by_us[1]
                if r.topic == topic
            ]
        )
        median_s = float(np.median(delays_s))
        assert 0.0 <= median_s < MAX_MEDIAN_LOG_DELAY_S, f"{bag.name} {topic}: {median_s:.3f} s"
