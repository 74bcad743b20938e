"""The fusion's message layer: sensor messages in (:func:`feed_message`), ``nav/*`` out
(:func:`solution_messages`, :func:`solution_cdr`).

The solutions come from the engine run on the first 15 s of the committed ``sea_state`` bag (the
filter aligns 10 s in), fed with rclpy messages deserialised from the bag, as the live node gets
them. The CDR bytes written offline must be exactly what ROS and rosbags serialise for the
messages the live node publishes, and the messages must follow the contract's frames.
"""

from __future__ import annotations

import copy
import math
from pathlib import Path
from typing import NamedTuple

import numpy as np
import pytest
from geometry_msgs.msg import TwistWithCovarianceStamped, Vector3Stamped
from nav_msgs.msg import Odometry
from rclpy.serialization import deserialize_message, serialize_message
from scipy.spatial.transform import Rotation
from sensor_msgs.msg import Imu, NavSatFix

from buoy_common.bag_io import BagReader, BagWriter, jazzy_typestore
from buoy_common.contract import (
    BODY_FRAME,
    GNSS_BASELINE_TOPIC,
    GNSS_FIX_TOPIC,
    GNSS_HEADING_TOPIC,
    GNSS_VELOCITY_TOPIC,
    IMU_RAW_TOPIC,
    MAP_FRAME,
    NAV_FIX_TOPIC,
    NAV_IMU_TOPIC,
    NAV_MSGTYPES,
    NAV_ODOMETRY_TOPIC,
    NAV_VELOCITY_TOPIC,
    TF_MSGTYPE,
    Reason,
    seconds_to_stamp,
)
from buoy_nav.config import fusion_config_from_files
from buoy_nav.engine import FusionEngine, NavSolution
from buoy_nav.fusion_messages import (
    FUSION_INPUT_MSGTYPES,
    NavMessageClasses,
    NavValues,
    StampBook,
    feed_imu_cdr,
    feed_message,
    nav_values,
    solution_cdr,
    solution_messages,
    transform_cdr,
    transform_message,
)

REPO = Path(__file__).resolve().parents[3]
SEA_STATE_BAG = REPO / "bags" / "sea_state"
BUOY_PARAMETERS = REPO / "src" / "buoy_common" / "config" / "buoy.yaml"
SECONDS_OF_BAG = 15.0
NAV_CLASSES = NavMessageClasses(Odometry, Imu, TwistWithCovarianceStamped, NavSatFix)
RCLPY_CLASSES = {
    "sensor_msgs/msg/Imu": Imu,
    "sensor_msgs/msg/NavSatFix": NavSatFix,
    "geometry_msgs/msg/TwistWithCovarianceStamped": TwistWithCovarianceStamped,
    "nav_msgs/msg/Odometry": Odometry,
    "geometry_msgs/msg/Vector3Stamped": Vector3Stamped,
}
NANOSECONDS_PER_SECOND = 1_000_000_000
# Indices of the attitude variances (E, N, U rotation-vector error) in the 6×6 pose covariance.
ATTITUDE_VARIANCE_INDICES = (21, 28, 35)


def stamp_ns(message) -> int:
    return message.header.stamp.sec * NANOSECONDS_PER_SECOND + message.header.stamp.nanosec


class Produced(NamedTuple):
    """A solution with its ``nav/*`` messages and values, made when it came out (as the node
    and the offline tools make them: the stamp book is a queue)."""

    solution: NavSolution
    values: NavValues
    messages: dict[str, object]


def run_engine(inputs, imu_from_cdr: bool = False):
    """Feed (topic, message, raw) in order; returns the engine, what it produced and the
    rejection reasons. ``imu_from_cdr``: IMU samples straight from their CDR bytes."""
    engine = FusionEngine(fusion_config_from_files([BUOY_PARAMETERS]))
    stamps = StampBook()
    produced, reasons = [], []
    for topic, message, raw in inputs:
        if imu_from_cdr and topic == IMU_RAW_TOPIC:
            new, reason = feed_imu_cdr(engine, raw, stamps)
        else:
            new, reason = feed_message(engine, topic, message, stamps)
        for solution in new:
            values = nav_values(solution, stamps)
            messages = solution_messages(solution, NAV_CLASSES, stamps)
            produced.append(Produced(solution, values, messages))
        reasons.append(reason)
    return engine, produced, reasons


@pytest.fixture(scope="module")
def sensor_inputs():
    """(relative topic, rclpy message, CDR bytes) of the bag's first seconds, in log-time
    order."""
    inputs = []
    with BagReader(SEA_STATE_BAG) as reader:
        end_ns = reader.start_ns + int(SECONDS_OF_BAG * NANOSECONDS_PER_SECOND)
        stored = {name.lstrip("/") for name in reader.topics}
        topics = [t for t in FUSION_INPUT_MSGTYPES if t in stored]
        for record in reader.messages(topics):
            if record.log_time_ns > end_ns:
                break
            message = deserialize_message(record.raw, RCLPY_CLASSES[record.msgtype])
            inputs.append((record.topic.lstrip("/"), message, record.raw))
    return inputs


@pytest.fixture(scope="module")
def clean_run(sensor_inputs):
    engine, produced, reasons = run_engine(sensor_inputs)
    assert all(reason is None for reason in reasons), set(reasons)
    assert len(produced) > 300, "the filter should be aligned for the last few seconds"
    return engine, produced


@pytest.fixture(scope="module")
def produced(clean_run):
    return clean_run[1]


def test_cdr_deserialises_with_rclpy_to_exactly_the_published_messages(produced):
    for solution, values, messages in produced:
        raw_by_topic = solution_cdr(values)
        assert set(raw_by_topic) == set(messages) == set(NAV_MSGTYPES)
        for topic, message in messages.items():
            decoded = deserialize_message(raw_by_topic[topic], type(message))
            assert decoded == message, (topic, solution.t_s)
            # rclpy writes uninitialised bytes into CDR padding, so only the length can be
            # compared byte-wise with its own serialisation.
            assert len(serialize_message(message)) == len(raw_by_topic[topic]), topic


def test_cdr_is_byte_for_byte_what_rosbags_writes_for_the_messages(produced, tmp_path):
    sample = [*produced[:: max(1, len(produced) // 60)], produced[-1]]
    bag = tmp_path / "nav"
    with BagWriter(bag) as writer:
        for index, (_, _, messages) in enumerate(sample):
            for topic, message in messages.items():
                writer.write(topic, NAV_MSGTYPES[topic], index + 1, message)
    written = {topic: [] for topic in NAV_MSGTYPES}
    with BagReader(bag) as reader:
        for record in reader.messages():
            written[record.topic.lstrip("/")].append(record.raw)
    for index, (solution, values, messages) in enumerate(sample):
        for topic, raw in solution_cdr(values).items():
            assert raw == written[topic][index], (topic, solution.t_s)
            # and rosbags reads our bytes back to the very stamp
            decoded = jazzy_typestore().deserialize_cdr(raw, NAV_MSGTYPES[topic])
            assert stamp_ns(decoded) == stamp_ns(messages[topic])


def test_tf_is_what_rosbags_serialises_and_carries_the_odometry_pose(produced):
    for solution, values, messages in produced:
        raw = transform_cdr(values)
        expected = transform_message(
            values.sec, values.nanosec, values.position_map_m, values.attitude_xyzw
        )
        assert raw == bytes(jazzy_typestore().serialize_cdr(expected, TF_MSGTYPE)), solution.t_s
        (transform,) = jazzy_typestore().deserialize_cdr(raw, TF_MSGTYPE).transforms
        odometry = messages[NAV_ODOMETRY_TOPIC]
        assert transform.header.frame_id == odometry.header.frame_id == MAP_FRAME
        assert transform.child_frame_id == odometry.child_frame_id == BODY_FRAME
        assert stamp_ns(transform) == stamp_ns(odometry)
        pose = odometry.pose.pose
        t, q = transform.transform.translation, transform.transform.rotation
        assert (t.x, t.y, t.z) == (pose.position.x, pose.position.y, pose.position.z)
        assert (q.x, q.y, q.z, q.w) == (
            pose.orientation.x,
            pose.orientation.y,
            pose.orientation.z,
            pose.orientation.w,
        )


def test_nav_stamps_are_the_imu_stamps_to_the_nanosecond(sensor_inputs, produced):
    imu_stamps = [stamp_ns(m) for topic, m, _ in sensor_inputs if topic == IMU_RAW_TOPIC]
    published = [stamp_ns(p.messages[NAV_ODOMETRY_TOPIC]) for p in produced]
    # one solution per IMU sample from alignment on, each with its sample's own stamp
    assert published == imu_stamps[-len(published) :]
    for solution, values, messages in produced:
        raw = solution_cdr(values)
        stamps = {
            stamp_ns(deserialize_message(raw[t], RCLPY_CLASSES[NAV_MSGTYPES[t]])) for t in raw
        }
        assert stamps == {stamp_ns(m) for m in messages.values()}
        assert len(stamps) == 1, "all four messages of a solution carry its stamp"
        # the float stamp the engine works with is the nearest double to it
        assert (values.sec, values.nanosec) == (
            messages[NAV_FIX_TOPIC].header.stamp.sec,
            messages[NAV_FIX_TOPIC].header.stamp.nanosec,
        )
        assert values.sec + values.nanosec * 1e-9 == solution.t_s


def test_a_restamped_sample_is_stamped_alike_however_far_the_input_was_read():
    """After a step back of the IMU's clock the engine re-stamps the samples onto the aiding
    clock, and the headers of the seconds after the step run over the same stamps again. A
    re-stamped solution is stamped by rounding, whether the book already holds a later sample
    whose header has its float stamp (offline, the input read ahead) or not yet (live)."""
    step_s = -5.000000123
    restamped_s = 1_767_225_634.99
    steps = [(restamped_s - 0.5, step_s)]
    header = (1_767_225_634, 990_000_000)  # a later sample's, read ahead
    float_stamp = header[0] + header[1] * 1e-9
    assert float_stamp == restamped_s
    before = (1_767_225_620, 990_000_000)  # a sample's before the step
    before_s = before[0] + before[1] * 1e-9
    read_ahead, live = StampBook(steps), StampBook(steps)
    for book in (read_ahead, live):
        book.remember(before_s, *before)
    read_ahead.remember(float_stamp, *header)
    rounded = seconds_to_stamp(restamped_s)
    assert rounded != header
    # Before the step, and with no step at all, the header's own stamp.
    assert read_ahead.exact(before_s) == live.exact(before_s) == before
    assert read_ahead.exact(restamped_s) == live.exact(restamped_s) == rounded
    plain = StampBook()
    plain.remember(float_stamp, *header)
    assert plain.exact(restamped_s) == header


def test_imu_samples_from_cdr_bytes_give_the_same_solutions(sensor_inputs, produced):
    _, from_cdr, reasons = run_engine(sensor_inputs, imu_from_cdr=True)
    assert all(reason is None for reason in reasons)
    assert [p.values for p in from_cdr] == [p.values for p in produced]


def test_frames_and_conventions_of_the_four_messages(produced):
    for solution, _, messages in produced[:: max(1, len(produced) // 100)]:
        odometry = messages[NAV_ODOMETRY_TOPIC]
        imu = messages[NAV_IMU_TOPIC]
        velocity = messages[NAV_VELOCITY_TOPIC]
        fix = messages[NAV_FIX_TOPIC]
        assert (odometry.header.frame_id, odometry.child_frame_id) == ("map", "base_link")
        assert imu.header.frame_id == "base_link"
        assert velocity.header.frame_id == "map"

        q = odometry.pose.pose.orientation
        attitude_xyzw = np.array([q.x, q.y, q.z, q.w])
        np.testing.assert_array_equal(attitude_xyzw, solution.attitude_xyzw)
        rotation_nb = Rotation.from_quat(attitude_xyzw).as_matrix()
        v = velocity.twist.twist.linear
        velocity_enu = np.array([v.x, v.y, v.z])
        np.testing.assert_array_equal(velocity_enu, solution.velocity_enu_mps)
        # Odometry convention: twist in the child frame, v_body = R_nbᵀ·v_ENU.
        body = odometry.twist.twist.linear
        np.testing.assert_allclose(
            [body.x, body.y, body.z], rotation_nb.T @ velocity_enu, rtol=0, atol=1e-12
        )
        rate = odometry.twist.twist.angular
        np.testing.assert_array_equal([rate.x, rate.y, rate.z], solution.angular_rate_body_rad_s)
        np.testing.assert_array_equal(
            [imu.angular_velocity.x, imu.angular_velocity.y, imu.angular_velocity.z],
            solution.angular_rate_body_rad_s,
        )
        force = imu.linear_acceleration
        np.testing.assert_array_equal(
            [force.x, force.y, force.z], solution.specific_force_body_mps2
        )
        position = odometry.pose.pose.position
        np.testing.assert_array_equal([position.x, position.y, position.z], solution.position_map_m)

        pose_covariance = np.array(odometry.pose.covariance).reshape(6, 6)
        np.testing.assert_array_equal(pose_covariance[:3, :3], solution.position_covariance_m2)
        np.testing.assert_array_equal(pose_covariance[3:, 3:], solution.attitude_covariance_rad2)
        assert not pose_covariance[:3, 3:].any() and not pose_covariance[3:, :3].any()
        assert all(pose_covariance.flat[i] > 0 for i in ATTITUDE_VARIANCE_INDICES)
        np.testing.assert_array_equal(
            np.array(imu.orientation_covariance).reshape(3, 3), solution.attitude_covariance_rad2
        )
        twist_covariance = np.array(odometry.twist.covariance).reshape(6, 6)
        np.testing.assert_allclose(
            twist_covariance[:3, :3],
            rotation_nb.T @ solution.velocity_covariance_m2s2 @ rotation_nb,
            rtol=0,
            atol=1e-15,
        )
        # The rate is the raw gyro less the bias estimate: its error is the bias estimate's.
        np.testing.assert_array_equal(
            twist_covariance[3:, 3:], solution.gyro_bias_covariance_rad2_s2
        )
        assert np.all(np.diag(solution.gyro_bias_covariance_rad2_s2) > 0.0)
        assert not twist_covariance[3:, :3].any() and not twist_covariance[:3, 3:].any()
        np.testing.assert_array_equal(
            np.array(imu.angular_velocity_covariance).reshape(3, 3),
            solution.gyro_bias_covariance_rad2_s2,
        )
        enu_twist_covariance = np.array(velocity.twist.covariance).reshape(6, 6)
        np.testing.assert_array_equal(
            enu_twist_covariance[:3, :3], solution.velocity_covariance_m2s2
        )
        assert not enu_twist_covariance[3:, :].any()

        assert (fix.latitude, fix.longitude, fix.altitude) == (
            solution.latitude_deg,
            solution.longitude_deg,
            solution.altitude_m,
        )
        np.testing.assert_array_equal(
            np.array(fix.position_covariance).reshape(3, 3), solution.position_covariance_m2
        )
        assert fix.status.status == 0 and fix.position_covariance_type == 3


# -- rejected input --------------------------------------------------------------------------


def _zero_quaternion(message):
    message.orientation.x = message.orientation.y = 0.0
    message.orientation.z = message.orientation.w = 0.0


def _no_fix(message):
    message.status.status = -1


def _nan_latitude(message):
    message.latitude = math.nan


def _nan_rate(message):
    message.angular_velocity.y = math.nan


def _infinite_velocity(message):
    message.twist.twist.linear.x = math.inf


def _nan_heading(message):
    message.orientation.z = math.nan


def _nan_baseline(message):
    message.vector.z = math.nan


def _tenfold_baseline(message):
    message.vector.x *= 10.0
    message.vector.y *= 10.0
    message.vector.z *= 10.0


# (topic, how to spoil a copy of a valid message of the topic, expected reason, the engine's
# input that counts the rejection: the aiding source that reads the topic, or the IMU)
SPOILED = [
    (GNSS_HEADING_TOPIC, _zero_quaternion, Reason.ZERO_QUATERNION, "gnss_heading"),
    (GNSS_FIX_TOPIC, _no_fix, Reason.NO_FIX, "gnss_fix"),
    (GNSS_VELOCITY_TOPIC, "twist.covariance:35", Reason.MALFORMED, "gnss_velocity"),
    (GNSS_HEADING_TOPIC, "orientation_covariance:8", Reason.MALFORMED, "gnss_heading"),
    (IMU_RAW_TOPIC, "angular_velocity:3", Reason.MALFORMED, "imu"),
    (GNSS_FIX_TOPIC, _nan_latitude, "non_finite", "gnss_fix"),
    (IMU_RAW_TOPIC, _nan_rate, "non_finite", "imu"),
    (GNSS_VELOCITY_TOPIC, _infinite_velocity, "non_finite", "gnss_velocity"),
    (GNSS_HEADING_TOPIC, _nan_heading, "non_finite", "gnss_heading"),
    (GNSS_BASELINE_TOPIC, _nan_baseline, "non_finite", "gnss_baseline"),
    (GNSS_BASELINE_TOPIC, _tenfold_baseline, "out_of_range", "gnss_baseline"),
]
INSERTED_AT_FRACTIONS = (0.3, 0.85)  # of each topic's messages: before and after alignment


class _Spoiled:
    """A valid message's fields as plain attributes, so that any of them may be malformed."""

    def __init__(self, message):
        for name in message.get_fields_and_field_types():
            value = getattr(message, name)
            if hasattr(value, "get_fields_and_field_types"):
                value = _Spoiled(value)
            elif not isinstance(value, (int, float, str)):
                value = np.array(value)
            setattr(self, name, value)


def spoiled_copy(message, spoil):
    if isinstance(spoil, str):
        path, length = spoil.split(":")
        spoilt = _Spoiled(message)
        holder = spoilt
        *parents, leaf = path.split(".")
        for name in parents:
            holder = getattr(holder, name)
        setattr(holder, leaf, np.zeros(int(length)))
        return spoilt
    spoilt = copy.deepcopy(message)
    spoil(spoilt)
    return spoilt


def with_spoiled_messages(inputs):
    """The inputs with each spoiled message inserted twice: before and after alignment.

    A spoiled message carries the stamp of the next valid message of its topic, so that a
    rejected message that still left a trace (a registered stamp) would get the valid one
    rejected as a duplicate.
    """
    positions = {
        topic: [i for i, (t, _, _) in enumerate(inputs) if t == topic]
        for topic in FUSION_INPUT_MSGTYPES
    }
    insertions = {}
    for case, (topic, spoil, reason, _) in enumerate(SPOILED):
        for fraction in INSERTED_AT_FRACTIONS:
            index = positions[topic][int(fraction * len(positions[topic])) + case]
            insertions.setdefault(index, []).append(
                (topic, spoiled_copy(inputs[index][1], spoil), reason)
            )
    mixed, expected_reasons = [], []
    for index, (topic, message, raw) in enumerate(inputs):
        for spoilt_topic, spoilt, reason in insertions.get(index, []):
            mixed.append((spoilt_topic, spoilt, None))
            expected_reasons.append(reason)
        mixed.append((topic, message, raw))
        expected_reasons.append(None)
    return mixed, expected_reasons


def test_spoiled_messages_are_rejected_with_their_reason_and_leave_no_trace(
    sensor_inputs, clean_run
):
    clean_engine, clean_produced = clean_run
    mixed, expected_reasons = with_spoiled_messages(sensor_inputs)
    assert len(mixed) == len(sensor_inputs) + len(INSERTED_AT_FRACTIONS) * len(SPOILED)
    engine, produced, reasons = run_engine(mixed)

    assert reasons == expected_reasons
    assert len(produced) == len(clean_produced)
    for spoilt_run, clean in zip(produced, clean_produced, strict=True):
        assert spoilt_run.values == clean.values
        np.testing.assert_array_equal(
            spoilt_run.solution.gyro_bias_rad_s, clean.solution.gyro_bias_rad_s
        )
        np.testing.assert_array_equal(
            spoilt_run.solution.accel_bias_mps2, clean.solution.accel_bias_mps2
        )
    np.testing.assert_array_equal(engine.covariance, clean_engine.covariance)

    health, clean_health = engine.health(), clean_engine.health()
    engine_rejections = {}
    for _, _, reason, kind in SPOILED:
        rejections = engine_rejections.setdefault(kind, {})
        rejections[reason] = rejections.get(reason, 0) + len(INSERTED_AT_FRACTIONS)
    for kind, counters in health.counters.items():
        clean_counters = clean_health.counters[kind]
        assert counters.accepted == clean_counters.accepted, kind
        assert counters.used_for_alignment == clean_counters.used_for_alignment, kind
        assert (counters.nis_sum, counters.nis_count) == (
            clean_counters.nis_sum,
            clean_counters.nis_count,
        ), kind
        assert counters.resets == clean_counters.resets, kind
        assert counters.superseded == clean_counters.superseded, kind
        assert counters.rejected == engine_rejections.get(kind, {}), kind
    assert health.time_s == clean_health.time_s


def test_an_unknown_topic_is_a_programming_error(sensor_inputs):
    engine = FusionEngine(fusion_config_from_files([BUOY_PARAMETERS]))
    with pytest.raises(ValueError, match="input topic"):
        feed_message(engine, "anemometer/wind", sensor_inputs[0][1])
