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


def test_there_are_committed_bags():
    assert len(BAGS) >= 4


@pytest.mark.parametrize("bag", BAGS, ids=[b.name for b in BAGS])
def test_bag_has_contract_topics_types_and_counts(bag):
    with BagReader(bag) as reader:
        topics = reader.topics
        stamps_s = {}
        for message in reader.messages(["/imu/data_raw"]):
            decoded = reader.decode(message)
            stamps_s.setdefault(message.topic, []).append(
                decoded.header.stamp.sec + decoded.header.stamp.nanosec * 1e-9
            )
    duration_s = stamps_s["/imu/data_raw"][-1] - stamps_s["/imu/data_raw"][0]
    for topic, (msgtype, rate_hz) in SENSOR_RATES_HZ.items():
        assert topics[topic].msgtype == msgtype
        # one sample per period over the run (a topic may start or stop within a period)
        expected = duration_s * rate_hz + 1
        assert math.isclose(topics[topic].count, expected, abs_tol=2), topic


@pytest.mark.parametrize("bag", BAGS, ids=[b.name for b in BAGS])
def test_bag_reader_gives_the_messages_rosbags_reads_in_its_order(bag):
    """BagReader reads a finished bag through the MCAP chunk index, not through rosbags: the
    same messages, bytes, types and order."""
    with Reader(bag) as reference:
        expected = [
            (connection.topic, connection.msgtype, time_ns, bytes(raw))
            for connection, time_ns, raw in reference.messages()
        ]
    with BagReader(bag) as reader:
        read = [(m.topic, m.msgtype, m.log_time_ns, m.raw) for m in reader.messages()]
    assert read == expected


@pytest.mark.parametrize("bag", BAGS, ids=[b.name for b in BAGS])
def test_bag_is_read_by_mcap_independently(bag):
    (mcap_file,) = bag.glob("*.mcap")
    counts: dict[str, int] = {}
    with open(mcap_file, "rb") as stream:
        reader = make_reader(stream, decoder_factories=[DecoderFactory()])
        assert reader.get_header().profile == "ros2"
        first = {}
        for schema, channel, _, decoded in reader.iter_decoded_messages():
            assert schema.encoding == "ros2msg"
            counts[channel.topic] = counts.get(channel.topic, 0) + 1
            first.setdefault(channel.topic, decoded)
    with BagReader(bag) as ours:
        assert counts == {topic: info.count for topic, info in ours.topics.items()}
    # decoded by a reader that shares no code with ours, the physics is still there
    assert 9.0 < first["/imu/data_raw"].linear_acceleration.z < 10.6
    assert first["/anemometer/wind"].header.frame_id == "anemometer_link"
    assert -90.0 <= first["/gnss/fix"].latitude <= 90.0


@pytest.mark.parametrize("bag", BAGS, ids=[b.name for b in BAGS])
def test_the_recorder_kept_pace_with_every_sensor(bag):
    # Log times are the recorder's receive times on the simulation clock. A recording made on a
    # machine too busy for its rate factor logs whole topics seconds after their stamps, and a
    # replay at the recorded pace then feeds the nodes measurements later than they accept.
    with BagReader(bag) as reader:
        for topic in SENSOR_RATES_HZ:
            if topic.startswith("/truth/"):
                continue
            delays_s = np.array(
                [(r.log_time_ns - raw_stamp_ns(r.raw)) * 1e-9 for r in reader.messages([topic])]
            )
            median_s = float(np.median(delays_s))
            assert 0.0 <= median_s < MAX_MEDIAN_LOG_DELAY_S, f"{bag.name} {topic}: {median_s:.3f} s"
