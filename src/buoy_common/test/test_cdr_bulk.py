"""The bulk CDR codecs against rclpy's and rosbags' own serialisation, both directions: columns
decoded from what they encode equal the values the messages were built from, bit for bit
(NaN and infinities included), and what the codecs encode is what they encode (rosbags byte
for byte, rclpy but for what its alignment padding holds); then the committed bags, and bytes
the layouts do not fit."""

from __future__ import annotations

import functools
from pathlib import Path

import numpy as np
import pytest
from geometry_msgs.msg import TwistWithCovarianceStamped, Vector3Stamped
from nav_msgs.msg import Odometry
from rclpy.serialization import deserialize_message, serialize_message
from sensor_msgs.msg import Imu, MagneticField, NavSatFix, Temperature

from buoy_common import cdr_bulk
from buoy_common.bag_io import BagReader, jazzy_typestore
from buoy_common.transform_messages import FrameTransform, tf_message

BAGS = Path(__file__).resolve().parents[3] / "bags"
RNG = np.random.default_rng(11)
# Ids of every length modulo 8 move the fields after them through every alignment.
FRAMES = ("", "m", "map", "base_link", "imu_link_", "anemometer_link", "a_much_longer_frame_name")

# The message definitions as this test states them: column → (attribute path in the message,
# the attributes of a vector's parts, or "" for a value or an array).
_HEADER = {
    "sec": ("header.stamp.sec", ""),
    "nanosec": ("header.stamp.nanosec", ""),
    "frame_id": ("header.frame_id", ""),
}
_TF = "transforms.0."
DEFINITIONS = {
    "sensor_msgs/msg/Imu": (
        Imu,
        {
            **_HEADER,
            "orientation": ("orientation", "xyzw"),
            "orientation_covariance": ("orientation_covariance", ""),
            "angular_velocity": ("angular_velocity", "xyz"),
            "angular_velocity_covariance": ("angular_velocity_covariance", ""),
            "linear_acceleration": ("linear_acceleration", "xyz"),
            "linear_acceleration_covariance": ("linear_acceleration_covariance", ""),
        },
    ),
    "geometry_msgs/msg/Vector3Stamped": (Vector3Stamped, {**_HEADER, "vector": ("vector", "xyz")}),
    "sensor_msgs/msg/NavSatFix": (
        NavSatFix,
        {
            **_HEADER,
            "status": ("status.status", ""),
            "service": ("status.service", ""),
            "latitude": ("latitude", ""),
            "longitude": ("longitude", ""),
            "altitude": ("altitude", ""),
            "position_covariance": ("position_covariance", ""),
            "position_covariance_type": ("position_covariance_type", ""),
        },
    ),
    "geometry_msgs/msg/TwistWithCovarianceStamped": (
        TwistWithCovarianceStamped,
        {
            **_HEADER,
            "linear": ("twist.twist.linear", "xyz"),
            "angular": ("twist.twist.angular", "xyz"),
            "covariance": ("twist.covariance", ""),
        },
    ),
    "sensor_msgs/msg/MagneticField": (
        MagneticField,
        {
            **_HEADER,
            "magnetic_field": ("magnetic_field", "xyz"),
            "magnetic_field_covariance": ("magnetic_field_covariance", ""),
        },
    ),
    "sensor_msgs/msg/Temperature": (
        Temperature,
        {**_HEADER, "temperature": ("temperature", ""), "variance": ("variance", "")},
    ),
    "nav_msgs/msg/Odometry": (
        Odometry,
        {
            **_HEADER,
            "child_frame_id": ("child_frame_id", ""),
            "position": ("pose.pose.position", "xyz"),
            "orientation": ("pose.pose.orientation", "xyzw"),
            "pose_covariance": ("pose.covariance", ""),
            "linear": ("twist.twist.linear", "xyz"),
            "angular": ("twist.twist.angular", "xyz"),
            "twist_covariance": ("twist.covariance", ""),
        },
    ),
    # rclpy's tf2_msgs is not installed without tf2: rosbags builds this one.
    "tf2_msgs/msg/TFMessage": (
        None,
        {
            "sec": (_TF + "header.stamp.sec", ""),
            "nanosec": (_TF + "header.stamp.nanosec", ""),
            "frame_id": (_TF + "header.frame_id", ""),
            "child_frame_id": (_TF + "child_frame_id", ""),
            "translation": (_TF + "transform.translation", "xyz"),
            "rotation": (_TF + "transform.rotation", "xyzw"),
        },
    ),
}
MSGTYPES = sorted(DEFINITIONS)
TF = "tf2_msgs/msg/TFMessage"
RCLPY_MSGTYPES = [msgtype for msgtype in MSGTYPES if msgtype != TF]
STRING_COLUMNS = ("frame_id", "child_frame_id")
INTEGER_RANGES = {
    "sec": (-(2**31), 2**31 - 1),
    "nanosec": (0, 2**32 - 1),
    "status": (-128, 127),
    "service": (0, 2**16 - 1),
    "position_covariance_type": (0, 255),
}


def _step(value, name: str):
    return value[int(name)] if name.isdigit() else getattr(value, name)


def read_field(message, path: str, parts: str):
    """The value at ``path`` of a message object (rclpy's or rosbags')."""
    value = functools.reduce(_step, path.split("."), message)
    if parts:
        return [getattr(value, part) for part in parts]
    return value


def write_field(message, path: str, parts: str, value) -> None:
    *steps, last = path.split(".")
    owner = functools.reduce(_step, steps, message)
    if parts:
        target = getattr(owner, last)
        for part, number in zip(parts, value, strict=True):
            setattr(target, part, float(number))
    elif isinstance(value, np.ndarray) and value.ndim:
        setattr(owner, last, value.astype(float))
    else:
        setattr(owner, last, value.item() if isinstance(value, np.generic) else value)


def random_floats(shape) -> np.ndarray:
    """Normal values with NaN, ±inf, -0.0 and the extremes of float64 among them."""
    values = RNG.normal(0.0, 1e3, shape)
    specials = np.array([np.nan, np.inf, -np.inf, -0.0, 1.7976931348623157e308, 5e-324])
    mask = RNG.random(shape) < 0.1
    values[mask] = RNG.choice(specials, mask.sum())
    return values


def random_columns(msgtype: str, count: int) -> dict[str, np.ndarray]:
    """Columns of ``count`` messages: random values, stamps on both sides of the epoch and to
    the limits of sec and nanosec, frame ids of every alignment mixed in one run."""
    columns = {}
    for name, (path, parts) in DEFINITIONS[msgtype][1].items():
        if name in STRING_COLUMNS:
            columns[name] = np.array([FRAMES[i] for i in RNG.integers(0, len(FRAMES), count)])
        elif name in INTEGER_RANGES:
            low, high = INTEGER_RANGES[name]
            columns[name] = RNG.integers(low, high, count, endpoint=True)
        else:
            shape = (count, len(parts)) if parts else (count,)
            if not parts:
                sample = read_field(DEFINITIONS[msgtype][0](), path, parts)
                shape = (count, len(sample)) if np.ndim(sample) else shape
            columns[name] = random_floats(shape)
    columns["sec"][:3] = (-(2**31), -1, 2**31 - 1)
    columns["nanosec"][:3] = (2**32 - 1, 999_999_999, 0)
    return columns


def rclpy_message(msgtype: str, columns, index: int):
    message_class, fields = DEFINITIONS[msgtype]
    message = message_class()
    for name, (path, parts) in fields.items():
        write_field(message, path, parts, columns[name][index])
    return message


def rosbags_message(msgtype: str, columns, index: int):
    """Message ``index`` of ``columns`` as rosbags' object: through rclpy's message and its
    bytes, or for a ``TFMessage`` built with rosbags' classes."""
    if msgtype != TF:
        raw = serialize_message(rclpy_message(msgtype, columns, index))
        return jazzy_typestore().deserialize_cdr(raw, msgtype)
    transform = FrameTransform(
        str(columns["frame_id"][index]),
        str(columns["child_frame_id"][index]),
        tuple(columns["translation"][index]),
        tuple(columns["rotation"][index]),
    )
    return tf_message(int(columns["sec"][index]), int(columns["nanosec"][index]), [transform])


def assert_columns_equal(decoded: cdr_bulk.MessageColumns, expected: dict) -> None:
    """Every column as given, floats bit for bit (NaN payloads and -0.0 included)."""
    assert decoded.valid.all(), decoded.rejected
    for name, values in expected.items():
        got = decoded[name]
        if name in STRING_COLUMNS:
            assert list(got) == list(values), name
        elif np.asarray(values).dtype.kind == "f":
            assert got.dtype == np.float64
            assert np.array_equal(got.view(np.uint64), np.asarray(values).view(np.uint64)), name
        else:
            assert np.array_equal(got, values), name


def same_bytes_but_padding(written: bytes, serialized: bytes) -> bool:
    """Equal but where ``written`` holds zeros: padding, which rclpy may leave holding
    whatever its buffer held."""
    return len(written) == len(serialized) and all(
        ours in (theirs, 0) for ours, theirs in zip(written, serialized, strict=True)
    )


@pytest.mark.parametrize("msgtype", RCLPY_MSGTYPES)
def test_decodes_what_rclpy_serialises(msgtype):
    columns = random_columns(msgtype, 64)
    raws = [serialize_message(rclpy_message(msgtype, columns, i)) for i in range(64)]
    assert_columns_equal(cdr_bulk.decode(msgtype, raws), columns)


@pytest.mark.parametrize("msgtype", RCLPY_MSGTYPES)
def test_rclpy_deserialises_what_it_encodes(msgtype):
    columns = random_columns(msgtype, 64)
    encoded = cdr_bulk.encode(msgtype, columns)
    message_class = DEFINITIONS[msgtype][0]
    for index, raw in enumerate(encoded):
        expected = serialize_message(rclpy_message(msgtype, columns, index))
        assert same_bytes_but_padding(raw, expected)
        # Through rclpy's decoder and encoder again: NaN compares unequal, bytes do not.
        assert same_bytes_but_padding(
            raw, serialize_message(deserialize_message(raw, message_class))
        )


@pytest.mark.parametrize("msgtype", MSGTYPES)
def test_equals_rosbags_both_ways(msgtype):
    typestore = jazzy_typestore()
    columns = random_columns(msgtype, 64)
    rosbags_raws = [
        bytes(typestore.serialize_cdr(rosbags_message(msgtype, columns, i), msgtype))
        for i in range(64)
    ]
    assert cdr_bulk.encode(msgtype, columns) == rosbags_raws
    decoded = cdr_bulk.decode(msgtype, rosbags_raws)
    assert_columns_equal(decoded, columns)
    for index, raw in enumerate(rosbags_raws):
        message = typestore.deserialize_cdr(raw, msgtype)
        for name, (path, parts) in DEFINITIONS[msgtype][1].items():
            expected = np.asarray(read_field(message, path, parts))
            got = decoded[name][index]
            assert np.array_equal(got, expected, equal_nan=expected.dtype.kind == "f"), name


@pytest.mark.parametrize("msgtype", MSGTYPES)
def test_empty_runs(msgtype):
    decoded = cdr_bulk.decode(msgtype, [])
    assert len(decoded) == 0 and decoded.rejected == {}
    assert decoded.stamp_ns.shape == (0,)
    assert cdr_bulk.encode(msgtype, decoded.columns) == []


def test_stamp_ns_on_both_sides_of_the_epoch():
    stamp_ns = np.array([-1, -1_500_000_000, 0, 1_767_225_600_123_456_789])
    sec, nanosec = cdr_bulk.stamp_parts(stamp_ns)
    assert sec.tolist() == [-1, -2, 0, 1_767_225_600]
    assert nanosec.tolist() == [999_999_999, 500_000_000, 0, 123_456_789]
    raws = cdr_bulk.encode(
        "geometry_msgs/msg/Vector3Stamped",
        {"stamp_ns": stamp_ns, "frame_id": "map", "vector": np.zeros((4, 3))},
    )
    for raw, expected_sec, expected_nanosec in zip(raws, sec, nanosec, strict=True):
        message = deserialize_message(raw, Vector3Stamped)
        assert (message.header.stamp.sec, message.header.stamp.nanosec) == (
            expected_sec,
            expected_nanosec,
        )
    decoded = cdr_bulk.decode("geometry_msgs/msg/Vector3Stamped", raws)
    assert decoded.stamp_ns.dtype == np.int64
    assert np.array_equal(decoded.stamp_ns, stamp_ns)


def committed_bag_topics():
    for bag in sorted(path for path in BAGS.iterdir() if (path / "metadata.yaml").is_file()):
        with BagReader(bag) as reader:
            for topic, info in sorted(reader.topics.items()):
                if cdr_bulk.handles(info.msgtype):
                    yield pytest.param(bag, topic, id=f"{bag.name}{topic}")


def recorded_by_topic(bag: Path) -> dict[str, tuple[str, list[bytes]]]:
    """topic → (message type, every message's bytes in log-time order) of ``bag``."""
    by_topic = {}
    with BagReader(bag) as reader:
        for message in reader.messages():
            by_topic.setdefault(message.topic, (message.msgtype, []))[1].append(message.raw)
    return by_topic


@pytest.fixture(scope="module")
def recorded():
    """:func:`recorded_by_topic`, a bag read once for all its topics' tests (which run one after
    another) rather than once a topic, and only one bag held at a time."""
    read_once = functools.lru_cache(maxsize=1)(recorded_by_topic)
    yield read_once
    read_once.cache_clear()


@pytest.mark.parametrize(("bag", "topic"), list(committed_bag_topics()))
def test_committed_bags(recorded, bag, topic):
    """Every message of every handled topic of the committed bags: the columns hold what
    rosbags decodes, and encoding them gives what rosbags encodes: the recorded bytes, less
    the padding some writers add after a message's last field."""
    typestore = jazzy_typestore()
    msgtype, raws = recorded(bag)[topic]
    decoded = cdr_bulk.decode(msgtype, raws)
    assert decoded.valid.all(), decoded.rejected
    fields = DEFINITIONS[msgtype][1]
    for index in np.linspace(0, len(raws) - 1, 50).astype(int):
        message = typestore.deserialize_cdr(raws[index], msgtype)
        for name, (path, parts) in fields.items():
            expected = np.asarray(read_field(message, path, parts))
            assert np.array_equal(
                decoded[name][index], expected, equal_nan=expected.dtype.kind == "f"
            ), name
    encoded = cdr_bulk.encode(msgtype, decoded.columns)
    for index in np.linspace(0, len(raws) - 1, 50).astype(int):
        message = typestore.deserialize_cdr(raws[index], msgtype)
        assert encoded[index] == bytes(typestore.serialize_cdr(message, msgtype))
    for ours, recorded in zip(encoded, raws, strict=True):
        assert recorded[: len(ours)] == ours
        assert len(recorded) - len(ours) < 4 and not any(recorded[len(ours) :])


# -- bytes the layouts do not fit ----------------------------------------------------------------

VECTOR3 = "geometry_msgs/msg/Vector3Stamped"


def vector_raws(count: int = 6) -> tuple[dict, list[bytes]]:
    columns = random_columns(VECTOR3, count)
    return columns, cdr_bulk.encode(VECTOR3, columns)


def test_big_endian_messages_are_decoded_by_rosbags():
    typestore = jazzy_typestore()
    columns, raws = vector_raws()
    big = [
        bytes(
            typestore.serialize_cdr(
                typestore.deserialize_cdr(raw, VECTOR3), VECTOR3, little_endian=False
            )
        )
        for raw in raws
    ]
    assert big[0][:2] == b"\x00\x00"
    mixed = [big[i] if i % 2 else raws[i] for i in range(len(raws))]
    assert_columns_equal(cdr_bulk.decode(VECTOR3, mixed), columns)


def test_bad_messages_are_rejected_with_their_reason_and_the_others_kept():
    columns, raws = vector_raws()
    not_utf8 = bytearray(raws[1])
    length = int.from_bytes(not_utf8[12:16], "little")
    not_utf8[16:20] = b"\x00\x00\x00\x00"  # a frame id of one byte: not UTF-8
    not_utf8[12:16], not_utf8[16] = (2).to_bytes(4, "little"), 0xFF
    assert length >= 1
    truncated = raws[2][:20]
    huge_string = bytearray(raws[3])
    huge_string[12:16] = (2**31).to_bytes(4, "little")
    bad = [raws[0], bytes(not_utf8), truncated, bytes(huge_string), raws[4], b"", b"\x00"]
    decoded = cdr_bulk.decode(VECTOR3, bad)
    assert decoded.valid.tolist() == [True, False, False, False, True, False, False]
    assert set(decoded.rejected) == {1, 2, 3, 5, 6}
    assert all(VECTOR3 in reason for reason in decoded.rejected.values())
    for kept, source in ((0, 0), (4, 4)):
        assert decoded["frame_id"][kept] == columns["frame_id"][source]
        assert np.array_equal(decoded["vector"][kept], columns["vector"][source], equal_nan=True)
    assert np.isnan(decoded["vector"][[1, 2, 3]]).all()


def test_a_tf_message_of_other_than_one_transform_is_rejected():
    typestore = jazzy_typestore()
    columns = random_columns(TF, 4)
    one = cdr_bulk.encode(TF, columns)[0]
    message = typestore.deserialize_cdr(one, TF)
    two = type(message)(transforms=[message.transforms[0]] * 2)
    none = type(message)(transforms=[])
    raws = [
        one,
        bytes(typestore.serialize_cdr(two, TF)),
        bytes(typestore.serialize_cdr(none, TF)),
    ]
    decoded = cdr_bulk.decode(TF, raws)
    assert decoded.valid.tolist() == [True, False, False]
    assert decoded.rejected == {1: "holds 2 transforms, not one", 2: "holds 0 transforms, not one"}


@pytest.mark.parametrize(
    ("change", "complaint"),
    [
        ({"sec": np.array([2**31])}, "sec"),
        ({"nanosec": np.array([-1])}, "nanosec"),
        ({"vector": np.zeros((1, 2))}, "vector"),
        ({"frame_id": [b"map"]}, "frame_id"),
        ({"frame_id": ["\ud800"]}, "frame_id"),
        ({"sec": np.array([1.5])}, "sec"),
    ],
)
def test_values_a_message_cannot_hold_are_refused(change, complaint):
    columns = {"sec": np.array([0]), "nanosec": np.array([0]), "frame_id": ["map"]}
    columns["vector"] = np.zeros((1, 3))
    with pytest.raises(ValueError, match=complaint):
        cdr_bulk.encode(VECTOR3, {**columns, **change})


def test_unknown_types_and_missing_columns_are_refused():
    with pytest.raises(ValueError, match="no bulk CDR layout"):
        cdr_bulk.decode("std_msgs/msg/String", [])
    with pytest.raises(ValueError, match="lack vector"):
        cdr_bulk.encode(VECTOR3, {"sec": [0], "nanosec": [0], "frame_id": "map"})
