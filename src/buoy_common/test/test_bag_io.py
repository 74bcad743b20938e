"""Bag input/output: what BagWriter writes, BagReader and independent MCAP readers read back."""

from __future__ import annotations

import importlib
import io
import itertools
import shutil
from pathlib import Path

import numpy as np
import pytest
import yaml
from geometry_msgs.msg import Vector3Stamped
from mcap.reader import make_reader
from mcap.writer import CompressionType, Writer
from mcap_ros2.decoder import DecoderFactory
from nav_msgs.msg import Odometry
from rclpy.serialization import deserialize_message
from rosbags.rosbag2 import Reader
from sensor_msgs.msg import Image, Imu, NavSatFix
from std_msgs.msg import Byte, ByteMultiArray, Char

from buoy_common.bag_io import BackgroundBagWriter, BagError, BagReader, BagWriter
from buoy_common.bag_io.mcap_writer import McapWriter

T0_NS = 1_700_000_000_000_000_000
IMU_PERIOD_NS = 10_000_000  # 100 Hz
SLOW_PERIOD_NS = 100_000_000  # 10 Hz
DURATION_NS = 2_000_000_000

TYPES = {
    "/imu/data_raw": ("sensor_msgs/msg/Imu", Imu),
    "/truth/odometry": ("nav_msgs/msg/Odometry", Odometry),
    "/anemometer/wind": ("geometry_msgs/msg/Vector3Stamped", Vector3Stamped),
    "/gnss/fix": ("sensor_msgs/msg/NavSatFix", NavSatFix),
}


def _stamp(message, time_ns: int) -> None:
    message.header.stamp.sec, message.header.stamp.nanosec = divmod(time_ns, 1_000_000_000)


def _imu(rng, time_ns: int) -> Imu:
    message = Imu()
    _stamp(message, time_ns)
    message.header.frame_id = "imu_link"
    message.angular_velocity.x, message.angular_velocity.y, message.angular_velocity.z = rng.normal(
        0.0, 0.1, 3
    ).tolist()
    acceleration = rng.normal(0.0, 0.05, 3) + np.array([0.0, 0.0, 9.8])
    message.linear_acceleration.x, message.linear_acceleration.y = acceleration[:2].tolist()
    message.linear_acceleration.z = float(acceleration[2])
    message.orientation_covariance[0] = -1.0
    message.angular_velocity_covariance = rng.uniform(0, 1e-4, 9)
    return message


def _odometry(rng, time_ns: int) -> Odometry:
    message = Odometry()
    _stamp(message, time_ns)
    message.header.frame_id = "map"
    message.child_frame_id = "base_link"
    position = rng.normal(0.0, 5.0, 3)
    message.pose.pose.position.x, message.pose.pose.position.y = position[:2].tolist()
    message.pose.pose.position.z = float(position[2])
    quaternion = rng.normal(size=4)
    quaternion /= np.linalg.norm(quaternion)
    pose = message.pose.pose.orientation
    pose.x, pose.y, pose.z, pose.w = quaternion.tolist()
    message.pose.covariance = rng.uniform(-1.0, 1.0, 36)
    message.twist.twist.angular.z = float(rng.normal())
    return message


def _wind(rng, time_ns: int) -> Vector3Stamped:
    message = Vector3Stamped()
    _stamp(message, time_ns)
    message.header.frame_id = "anemometer_link"
    message.vector.x, message.vector.y, message.vector.z = rng.normal(0.0, 8.0, 3).tolist()
    return message


def _fix(rng, time_ns: int) -> NavSatFix:
    message = NavSatFix()
    _stamp(message, time_ns)
    message.header.frame_id = "gnss_primary"
    message.status.status = int(rng.integers(-1, 2))
    message.status.service = 1
    message.latitude = 35.0 + float(rng.normal(0.0, 1e-4))
    message.longitude = 120.0 + float(rng.normal(0.0, 1e-4))
    message.altitude = float(rng.normal(10.0, 1.0))
    message.position_covariance = rng.uniform(0.0, 2.0, 9)
    message.position_covariance_type = NavSatFix.COVARIANCE_TYPE_DIAGONAL_KNOWN
    return message


def make_messages(seed: int = 1) -> list[tuple[str, int, object]]:
    """(topic, log time ns, rclpy message): IMU at 100 Hz, three topics at 10 Hz, 2 s."""
    rng = np.random.default_rng(seed)
    messages = []
    for time_ns in range(T0_NS, T0_NS + DURATION_NS, IMU_PERIOD_NS):
        messages.append(("/imu/data_raw", time_ns, _imu(rng, time_ns)))
        if (time_ns - T0_NS) % SLOW_PERIOD_NS == 0:
            # Slow topics are logged slightly after the IMU sample they accompany.
            messages.append(("/truth/odometry", time_ns + 1000, _odometry(rng, time_ns)))
            messages.append(("/anemometer/wind", time_ns + 2000, _wind(rng, time_ns)))
            messages.append(("/gnss/fix", time_ns + 3000, _fix(rng, time_ns)))
    return messages


def plain(value, like):
    """``value`` as nested dicts and lists, following the fields of the rclpy message ``like``.

    Works on any object that has the ROS field names as attributes (rclpy, rosbags, mcap_ros2),
    so decoded messages from different libraries compare with ``==``.
    """
    if hasattr(like, "get_fields_and_field_types"):
        return {
            name: plain(getattr(value, name), getattr(like, name))
            for name in like.get_fields_and_field_types()
        }
    if isinstance(like, str):
        return value
    if hasattr(like, "__len__"):
        assert len(value) == len(like)
        return [plain(v, item) for v, item in zip(value, like, strict=True)]
    return value


@pytest.fixture(scope="module")
def written_bag(tmp_path_factory):
    path = tmp_path_factory.mktemp("bags") / "sample"
    messages = make_messages()
    with BagWriter(path) as writer:
        for topic, time_ns, message in messages:
            writer.write(topic, TYPES[topic][0], time_ns, message)
        counts = writer.counts
    return path, messages, counts


def test_bag_reader_returns_every_message_in_log_time_order(written_bag):
    path, messages, counts = written_bag
    expected_counts = {topic: sum(1 for t, _, _ in messages if t == topic) for topic in TYPES}
    assert counts == expected_counts
    with BagReader(path) as reader:
        assert {t: (i.msgtype, i.count) for t, i in reader.topics.items()} == {
            t: (TYPES[t][0], expected_counts[t]) for t in TYPES
        }
        assert reader.start_ns == messages[0][1]
        assert reader.end_ns == max(time_ns for _, time_ns, _ in messages)
        assert reader.duration_s == pytest.approx((reader.end_ns - reader.start_ns) * 1e-9)
        read = list(reader.messages())
        assert [(m.topic, m.log_time_ns) for m in read] == [(t, n) for t, n, _ in messages]
        for bag_message, (topic, _, original) in zip(read, messages, strict=True):
            assert bag_message.msgtype == TYPES[topic][0]
            assert plain(reader.decode(bag_message), original) == plain(original, original)
            # rclpy's own deserialiser is a second, independent witness of the bytes.
            assert deserialize_message(bag_message.raw, TYPES[topic][1]) == original


def test_topic_selection_accepts_relative_names(written_bag):
    path, messages, _ = written_bag
    with BagReader(path) as reader:
        selected = list(reader.messages(["gnss/fix", "/anemometer/wind"]))
    expected = [(t, n) for t, n, _ in messages if t in ("/gnss/fix", "/anemometer/wind")]
    assert [(m.topic, m.log_time_ns) for m in selected] == expected


def test_independent_mcap_reader_decodes_the_same_messages(written_bag):
    path, messages, counts = written_bag
    (mcap_file,) = path.glob("*.mcap")
    with mcap_file.open("rb") as stream:
        reader = make_reader(stream, validate_crcs=True, decoder_factories=[DecoderFactory()])
        assert reader.get_header().profile == "ros2"
        summary = reader.get_summary()
        channel_counts = {
            summary.channels[channel_id].topic: count
            for channel_id, count in summary.statistics.channel_message_counts.items()
        }
        assert channel_counts == counts
        assert {index.compression for index in summary.chunk_indexes} == {"zstd"}
        decoded = list(reader.iter_decoded_messages(log_time_order=True))
    assert len(decoded) == len(messages)
    for (schema, channel, record, message), (topic, time_ns, original) in zip(
        decoded, messages, strict=True
    ):
        assert channel.topic == topic
        assert channel.message_encoding == "cdr"
        assert schema.name == TYPES[topic][0]
        assert schema.encoding == "ros2msg"
        assert record.log_time == time_ns
        assert plain(message, original) == plain(original, original)


def test_metadata_is_rosbag2_version_9_with_one_mcap_file(written_bag):
    path, messages, counts = written_bag
    metadata = yaml.safe_load((path / "metadata.yaml").read_text())["rosbag2_bagfile_information"]
    assert metadata["version"] == 9
    assert metadata["storage_identifier"] == "mcap"
    (mcap_file,) = path.glob("*.mcap")
    assert metadata["relative_file_paths"] == [mcap_file.name]
    assert metadata["message_count"] == len(messages)
    listed = {
        entry["topic_metadata"]["name"]: (entry["topic_metadata"]["type"], entry["message_count"])
        for entry in metadata["topics_with_message_count"]
    }
    assert listed == {topic: (TYPES[topic][0], counts[topic]) for topic in TYPES}
    assert all(
        entry["topic_metadata"]["serialization_format"] == "cdr"
        for entry in metadata["topics_with_message_count"]
    )
    # Compression lives inside the MCAP chunks, so rosbag2 must not decompress the file itself.
    assert metadata["compression_mode"] == ""


def test_chunks_overlapping_in_time_are_read_in_the_order_rosbags_reads(tmp_path):
    """Log times that go back and repeat across chunks: messages come merged in log-time
    order, equal log times in rosbags' order, and checksums hold for the mcap reader."""
    path = tmp_path / "overlapping"
    payload = bytes(range(256)) * 400  # ten of these fill a chunk
    with BagWriter(path) as writer:
        for index in range(60):
            image = Image(height=1, width=len(payload), encoding="mono8", step=len(payload))
            image.data = payload
            image.header.frame_id = str(index)
            topic = "/camera_a" if index % 3 else "/camera_b"
            time_ns = T0_NS + (index * 7919 % 50) * 1000
            writer.write(topic, "sensor_msgs/msg/Image", time_ns, image)
    (mcap_file,) = path.glob("*.mcap")
    with mcap_file.open("rb") as stream:
        reader = make_reader(stream, validate_crcs=True)
        chunks = sorted(reader.get_summary().chunk_indexes, key=lambda c: c.message_start_time)
        assert sum(1 for _ in reader.iter_messages()) == 60
    assert any(
        later.message_start_time <= earlier.message_end_time
        for earlier, later in itertools.pairwise(chunks)
    )
    with Reader(path) as reference:
        expected = [
            (connection.topic, time_ns, bytes(raw))
            for connection, time_ns, raw in reference.messages()
        ]
    for topics in (None, ["/camera_a"]):
        with BagReader(path) as reader:
            read = [(m.topic, m.log_time_ns, m.raw) for m in reader.messages(topics)]
        assert read == [entry for entry in expected if topics is None or entry[0] in topics]


def _mcap_file_of(writer_class) -> bytes:
    """An MCAP file written by ``writer_class``: three channels, one registered between
    messages, log times out of order, messages of every size up to a few hundred bytes, chunks
    of 4 KiB (dozens of them, some overlapping in time) and one flushed early."""
    rng = np.random.default_rng(7)
    stream = io.BytesIO()
    writer = writer_class(stream, chunk_size=4096, compression=CompressionType.ZSTD)
    writer.start(profile="ros2", library="test")
    schema = writer.register_schema("std_msgs/msg/String", "ros2msg", b"string data")
    channels = [writer.register_channel(f"/topic_{i}", "cdr", schema) for i in range(2)]
    for index in range(600):
        if index == 200:
            channels.append(writer.register_channel("/late", "cdr", schema, {"k": "v"}))
        if index == 300:
            writer.flush()
        log_time_ns = T0_NS + int(rng.integers(0, 1_000_000_000))
        data = rng.bytes(int(rng.integers(0, 400)))
        channel = channels[index % len(channels)]
        writer.add_message(channel, log_time_ns, data, log_time_ns + 7, sequence=index)
    writer.finish()
    return stream.getvalue()


def test_lean_message_writer_writes_the_mcap_librarys_bytes():
    """BagWriter's writer packs message records itself: the file must stay the library's, byte
    for byte (chunk boundaries, message indexes, statistics); this fails if the internals of
    the pinned mcap version it relies on change."""
    library_file = _mcap_file_of(Writer)
    assert len(make_reader(io.BytesIO(library_file)).get_summary().chunk_indexes) > 20
    assert _mcap_file_of(McapWriter) == library_file


def test_bag_reader_reads_what_rosbags_reads_of_a_bag_the_writer_wrote(written_bag):
    """The chunk index path of BagReader against rosbags' own reading."""
    path, _, _ = written_bag
    with Reader(path) as reference:
        expected = [
            (connection.topic, connection.msgtype, time_ns, bytes(raw))
            for connection, time_ns, raw in reference.messages()
        ]
    with BagReader(path) as reader:
        read = [(m.topic, m.msgtype, m.log_time_ns, m.raw) for m in reader.messages()]
    assert read == expected


def test_chunk_compression_makes_the_bag_smaller(tmp_path):
    messages = make_messages(seed=2)
    path = tmp_path / "compressed"
    with BagWriter(path) as writer:
        for topic, time_ns, message in messages:
            writer.write(topic, TYPES[topic][0], time_ns, message)
    with BagReader(path) as reader:
        raw_sizes = [len(message.raw) for message in reader.messages()]
    assert len(raw_sizes) == len(messages)
    (mcap_file,) = path.glob("*.mcap")
    assert mcap_file.stat().st_size < 0.7 * sum(raw_sizes)


def test_rclpy_byte_char_and_sequence_fields_round_trip(tmp_path):
    byte = Byte(data=b"\xff")
    byte_array = ByteMultiArray(data=[b"\x01", b"\xfe", b"\x80"])
    char = Char(data=65)
    image = Image(height=1, width=3, encoding="mono8", step=3, data=bytes([0, 127, 255]))
    written = [
        ("/byte", "std_msgs/msg/Byte", byte),
        ("/bytes", "std_msgs/msg/ByteMultiArray", byte_array),
        ("/char", "std_msgs/msg/Char", char),
        ("/image", "sensor_msgs/msg/Image", image),
    ]
    with BagWriter(tmp_path / "fields") as writer:
        for index, (topic, msgtype, message) in enumerate(written):
            writer.write(topic, msgtype, T0_NS + index, message)
    with BagReader(tmp_path / "fields") as reader:
        read = {m.topic: m for m in reader.messages()}
    for topic, _, message in written:
        assert deserialize_message(read[topic].raw, type(message)) == message


def test_require_names_missing_topics_and_lists_present_ones(written_bag):
    path, _, _ = written_bag
    with BagReader(path) as reader:
        reader.require("imu/data_raw", "/gnss/fix")
        with pytest.raises(BagError) as raised:
            reader.require("imu/data_raw", "wind/true", "/nav/odometry")
        with pytest.raises(BagError, match="wind/true"):
            reader.messages(["wind/true"])
    text = str(raised.value)
    assert str(path) in text
    assert "wind/true" in text and "/nav/odometry" in text
    for topic, (msgtype, _) in TYPES.items():
        assert topic in text and msgtype in text


def _garbage_metadata(bag: Path, target: Path) -> None:
    shutil.copytree(bag, target)
    (target / "metadata.yaml").write_text("rosbag2_bagfile_information: [unclosed\n  : :")


def _metadata_of_another_kind(bag: Path, target: Path) -> None:
    shutil.copytree(bag, target)
    (target / "metadata.yaml").write_text("just a string\n")


def _scrambled_chunk(bag: Path, target: Path) -> None:
    shutil.copytree(bag, target)
    (mcap_file,) = target.glob("*.mcap")
    data = bytearray(mcap_file.read_bytes())
    middle = len(data) // 2
    data[middle : middle + 64] = bytes(b ^ 0x5A for b in data[middle : middle + 64])
    mcap_file.write_bytes(bytes(data))


def _understated_count(bag: Path, target: Path) -> None:
    shutil.copytree(bag, target)
    text = (target / "metadata.yaml").read_text()
    (target / "metadata.yaml").write_text(text.replace("message_count: 200", "message_count: 199"))


def _empty_directory(bag: Path, target: Path) -> None:
    target.mkdir()


def _plain_file(bag: Path, target: Path) -> None:
    target.write_text("not a bag\n")


def _missing(bag: Path, target: Path) -> None:
    pass


@pytest.mark.parametrize(
    ("spoil", "expected"),
    [
        (_missing, "does not exist"),
        (_plain_file, "not a bag"),
        (_empty_directory, "no metadata.yaml"),
        (_garbage_metadata, "unreadable or corrupt"),
        (_metadata_of_another_kind, "unreadable or corrupt"),
        (_scrambled_chunk, "corrupt"),
        (_understated_count, "counts differ from metadata.yaml"),
    ],
)
def test_bad_bags_raise_bag_error_naming_the_bag(written_bag, tmp_path, spoil, expected):
    path, _, _ = written_bag
    target = tmp_path / "spoiled"
    spoil(path, target)
    with pytest.raises(BagError) as raised, BagReader(target) as reader:
        for message in reader.messages():
            reader.decode(message)
    assert str(target) in str(raised.value)
    assert expected in str(raised.value)


def test_writer_refuses_existing_paths_unless_overwriting_a_bag(written_bag, tmp_path):
    path, _, _ = written_bag
    with pytest.raises(BagError, match="already exists"):
        BagWriter(path)
    copy = tmp_path / "copy"
    shutil.copytree(path, copy)
    with BagWriter(copy, overwrite=True) as writer:
        writer.write("/gnss/baseline", "geometry_msgs/msg/Vector3Stamped", T0_NS, Vector3Stamped())
    with BagReader(copy) as reader:
        assert {t: i.count for t, i in reader.topics.items()} == {"/gnss/baseline": 1}
    not_a_bag = tmp_path / "notes"
    not_a_bag.mkdir()
    (not_a_bag / "notes.txt").write_text("precious")
    with pytest.raises(BagError, match="not removing"):
        BagWriter(not_a_bag, overwrite=True)
    assert (not_a_bag / "notes.txt").read_text() == "precious"


def test_writer_rejects_inconsistent_types(tmp_path):
    with BagWriter(tmp_path / "types") as writer:
        writer.write("/imu/data_raw", "sensor_msgs/msg/Imu", T0_NS, Imu())
        with pytest.raises(BagError, match="holds sensor_msgs/msg/Imu"):
            writer.write("/imu/data_raw", "sensor_msgs/msg/NavSatFix", T0_NS, NavSatFix())
        with pytest.raises(BagError, match="is a sensor_msgs/msg/Imu, not a"):
            writer.write("/gnss/fix", "sensor_msgs/msg/NavSatFix", T0_NS, Imu())
        with pytest.raises(BagError, match="unknown message type"):
            writer.write_raw("/odd", "my_pkg/msg/Odd", T0_NS, b"\x00\x01\x00\x00")


@pytest.mark.parametrize("writer_class", [BagWriter, BackgroundBagWriter])
def test_aborted_writer_leaves_nothing_under_the_bag_name(tmp_path, writer_class):
    path = tmp_path / "aborted"
    with pytest.raises(RuntimeError) as raised, writer_class(path) as writer:
        writer.write("/imu/data_raw", "sensor_msgs/msg/Imu", T0_NS, Imu())
        raise RuntimeError("the tool failed")
    assert any(str(path) in note and "not written" in note for note in raised.value.__notes__)
    assert list(tmp_path.iterdir()) == []
    with pytest.raises(BagError, match="does not exist"):
        BagReader(path)


@pytest.mark.parametrize("writer_class", [BagWriter, BackgroundBagWriter])
def test_a_bag_appears_under_its_name_only_once_complete(tmp_path, writer_class):
    path = tmp_path / "bag"
    with writer_class(path) as writer:
        for index in range(3000):
            writer.write("/imu/data_raw", "sensor_msgs/msg/Imu", T0_NS + index, Imu())
            if index % 1000 == 0:
                assert not path.exists()
        assert not path.exists()
    assert [p.name for p in tmp_path.iterdir()] == ["bag"]
    with BagReader(path) as reader:
        assert reader.recovery is None
        assert reader.topics["/imu/data_raw"].count == 3000


def test_a_recording_written_in_place_is_finished_even_when_abandoned(tmp_path):
    path = tmp_path / "recording"
    with pytest.raises(RuntimeError) as raised, BagWriter(path, in_place=True) as writer:
        writer.write("/imu/data_raw", "sensor_msgs/msg/Imu", T0_NS, Imu())
        writer.flush()
        assert (path / "recording.mcap").stat().st_size > 0
        assert not (path / "metadata.yaml").exists()
        raise RuntimeError("the recorder failed")
    assert any("closed after 1 messages" in note for note in raised.value.__notes__)
    with BagReader(path) as reader:
        assert reader.recovery is None
        assert {t: i.count for t, i in reader.topics.items()} == {"/imu/data_raw": 1}
    with pytest.raises(BagError, match="already exists"):
        BagWriter(path, overwrite=True, in_place=True)


def test_overwrite_replaces_the_old_bag_only_once_the_new_one_is_complete(written_bag, tmp_path):
    path, _, _ = written_bag
    copy = tmp_path / "copy"
    shutil.copytree(path, copy)
    before = {p.name: p.read_bytes() for p in copy.iterdir()}
    with pytest.raises(RuntimeError), BagWriter(copy, overwrite=True) as writer:
        writer.write("/imu/data_raw", "sensor_msgs/msg/Imu", T0_NS, Imu())
        assert {p.name: p.read_bytes() for p in copy.iterdir()} == before
        raise RuntimeError("the tool failed")
    assert {p.name: p.read_bytes() for p in copy.iterdir()} == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["copy"]
    with BagWriter(copy, overwrite=True) as writer:
        writer.write("/imu/data_raw", "sensor_msgs/msg/Imu", T0_NS, Imu())
        assert {p.name: p.read_bytes() for p in copy.iterdir()} == before
    with BagReader(copy) as reader:
        assert {t: i.count for t, i in reader.topics.items()} == {"/imu/data_raw": 1}


def test_empty_bag_is_valid(tmp_path):
    with BagWriter(tmp_path / "empty"):
        pass
    with BagReader(tmp_path / "empty") as reader:
        assert reader.topics == {}
        assert list(reader.messages()) == []
        assert reader.duration_s == 0.0


def test_every_name_of_the_package_comes_from_its_module():
    """The package loads its names lazily: each one it lists resolves, to its module's object."""
    import buoy_common.bag_io as bag_io

    for name in bag_io.__all__:
        module = importlib.import_module(f"buoy_common.bag_io.{bag_io._MODULE_OF[name]}")
        assert getattr(bag_io, name) is getattr(module, name)
    assert sorted(bag_io.__all__) == sorted(bag_io._MODULE_OF)
