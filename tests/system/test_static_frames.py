"""``tf_static`` live: the nodes broadcast the sensor frames of the shared parameters they read,
once, to subscribers that come later too, where tf2_msgs is installed."""

from __future__ import annotations

import importlib
import subprocess
import sys
import time
import types
from pathlib import Path

import numpy as np
import pytest
import rclpy
import yaml
from bag_faults import read_records, write_records
from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory
from rclpy.context import Context
from rclpy.executors import SingleThreadedExecutor
from rclpy.qos import DurabilityPolicy
from scipy.spatial.transform import Rotation
from std_msgs.msg import ByteMultiArray

from buoy_common.bag_io import jazzy_typestore
from buoy_common.base_node import TF_STATIC_QOS, SuiteNode
from buoy_common.contract import (
    ANEMOMETER_FRAME,
    BODY_FRAME,
    DVL_FRAME,
    GNSS_PRIMARY_FRAME,
    GNSS_SECONDARY_FRAME,
    IMU_FRAME,
    TF_MSGTYPE,
    TF_STATIC_TOPIC,
)
from buoy_common.sensor_frames import sensor_transforms, shared_values
from buoy_nav import fusion_node
from buoy_nav.config import FusionConfig
from processed_bags import BAGS_DIR, BUOY_PARAMETERS
from wind_comp import compensation_node
from wind_comp.config import CompensatorConfig, CurrentConfig

RECEIVE_TIMEOUT_S = 10.0
BIN = Path(sys.executable).parent


def test_each_node_places_the_frames_of_the_parameters_it_reads():
    def frames(config, imu_link=False):
        return [t.child_frame for t in sensor_transforms(shared_values(config), imu_link)]

    assert frames(FusionConfig(), imu_link=True) == [
        IMU_FRAME,
        GNSS_PRIMARY_FRAME,
        GNSS_SECONDARY_FRAME,
    ]
    assert frames(CompensatorConfig()) == [ANEMOMETER_FRAME]
    assert frames(CurrentConfig()) == [DVL_FRAME]


@pytest.mark.parametrize("node_module", [fusion_node, compensation_node])
def test_tf_static_is_broadcast_exactly_when_tf2_msgs_is_importable(monkeypatch, node_module):
    """The guarded import: absent here (PyPI wheels), present on a full install (a stand-in)."""
    monkeypatch.setitem(sys.modules, "tf2_msgs", None)
    monkeypatch.setitem(sys.modules, "tf2_msgs.msg", None)
    assert importlib.reload(node_module).TFMessage is None
    stand_in = types.ModuleType("tf2_msgs.msg")
    stand_in.TFMessage = type("TFMessage", (), {})
    monkeypatch.setitem(sys.modules, "tf2_msgs", types.ModuleType("tf2_msgs"))
    monkeypatch.setitem(sys.modules, "tf2_msgs.msg", stand_in)
    try:
        assert importlib.reload(node_module).TFMessage is stand_in.TFMessage
    finally:
        monkeypatch.undo()
        importlib.reload(node_module)


@pytest.fixture
def context(ros_env, monkeypatch):
    for name in ("ROS_DOMAIN_ID", "ROS_AUTOMATIC_DISCOVERY_RANGE"):
        monkeypatch.setenv(name, ros_env[name])
    context = Context()
    rclpy.init(context=context)
    yield context
    rclpy.try_shutdown(context=context)


def test_a_subscriber_that_comes_later_receives_the_transforms(context):
    transforms = sensor_transforms(shared_values(FusionConfig(), CurrentConfig()), imu_link=True)
    broadcaster = SuiteNode("static_frames_test", context=context)
    # tf2_msgs is not installed here: an installed type stands in for TFMessage's class; what
    # is published are TFMessage's bytes, and a raw subscription receives them unchanged.
    broadcaster.broadcast_static_transforms(ByteMultiArray, transforms)
    publisher = broadcaster.static_transforms_publisher
    assert publisher.topic_name == "/" + TF_STATIC_TOPIC
    assert publisher.qos_profile.durability == DurabilityPolicy.TRANSIENT_LOCAL

    late = rclpy.create_node("late_listener", context=context)
    received = []
    late.create_subscription(
        ByteMultiArray, TF_STATIC_TOPIC, received.append, TF_STATIC_QOS, raw=True
    )
    executor = SingleThreadedExecutor(context=context)
    executor.add_node(late)
    deadline = time.monotonic() + RECEIVE_TIMEOUT_S
    while not received and time.monotonic() < deadline:
        executor.spin_once(timeout_sec=0.1)
    executor.shutdown()
    assert len(received) == 1
    message = jazzy_typestore().deserialize_cdr(received[0], TF_MSGTYPE)
    sent = {t.child_frame: t for t in transforms}
    assert [t.child_frame_id for t in message.transforms] == list(sent)
    for stamped in message.transforms:
        assert stamped.header.frame_id == BODY_FRAME
        translation = stamped.transform.translation
        rotation = stamped.transform.rotation
        transform = sent[stamped.child_frame_id]
        assert (translation.x, translation.y, translation.z) == transform.translation_m
        assert (rotation.x, rotation.y, rotation.z, rotation.w) == transform.rotation_xyzw


def test_without_tf2_msgs_nothing_is_published(context):
    node = SuiteNode("static_frames_test", context=context)
    node.broadcast_static_transforms(None, sensor_transforms(shared_values(CurrentConfig())))
    assert node.static_transforms_publisher is None
    assert node.count_publishers(TF_STATIC_TOPIC) == 0


# -- offline ---------------------------------------------------------------------------------------


def buoy_geometry(parameter_files: list[Path]) -> dict[str, dict[str, list[float]]]:
    """Section → key → value of the ``/**`` parameters of ``parameter_files``, later files
    winning: read with plain YAML, not with the suite's parameter loader."""
    geometry: dict[str, dict[str, list[float]]] = {}
    for path in parameter_files:
        parameters = yaml.safe_load(path.read_text())["/**"]["ros__parameters"]
        for section in ("gnss", "anemometer", "dvl"):
            geometry.setdefault(section, {}).update(parameters.get(section, {}))
    return geometry


def static_messages(bag: Path) -> tuple[list, int]:
    """The decoded ``/tf_static`` messages of ``bag`` with their log times, and the bag's first
    log time, read by mcap + mcap-ros2-support."""
    (mcap_file,) = bag.glob("*.mcap")
    with open(mcap_file, "rb") as stream:
        reader = make_reader(stream, decoder_factories=[DecoderFactory()])
        first_ns = reader.get_summary().statistics.message_start_time
        found = [
            (message.log_time, decoded)
            for _, _, message, decoded in reader.iter_decoded_messages(
                topics=["/" + TF_STATIC_TOPIC], log_time_order=True
            )
        ]
    return found, first_ns


FIRST_SECONDS_S = 30.0


@pytest.mark.parametrize("tool", ["process_bag", "fuse_bag"])
def test_a_processed_bag_places_the_sensors_of_its_buoy(tmp_path, tool):
    parameter_files = [BUOY_PARAMETERS, BAGS_DIR / "off_axis.yaml"]
    # The transforms are written before the first solution: the bag's first seconds suffice.
    first_seconds = tmp_path / "off_axis_first_seconds"
    write_records(read_records(BAGS_DIR / "off_axis", None, FIRST_SECONDS_S), first_seconds)
    out_bag = tmp_path / "out"
    arguments = [str(first_seconds), str(out_bag)]
    for path in parameter_files:
        arguments += ["--params-file", str(path)]
    completed = subprocess.run(
        [str(BIN / tool), *arguments], capture_output=True, text=True, timeout=300
    )
    assert completed.returncode == 0, completed.stderr

    found, first_ns = static_messages(out_bag)
    assert len(found) == 1
    log_time_ns, message = found[0]
    assert log_time_ns == first_ns  # before every other message of the bag
    geometry = buoy_geometry(parameter_files)
    expected = {
        IMU_FRAME: ([0.0, 0.0, 0.0], [0.0, 0.0, 0.0]),
        GNSS_PRIMARY_FRAME: (geometry["gnss"]["primary_antenna"], [0.0, 0.0, 0.0]),
        GNSS_SECONDARY_FRAME: (geometry["gnss"]["secondary_antenna"], [0.0, 0.0, 0.0]),
    }
    if tool == "process_bag":
        for frame, section in ((ANEMOMETER_FRAME, "anemometer"), (DVL_FRAME, "dvl")):
            expected[frame] = (geometry[section]["position"], geometry[section]["rpy_deg"])
    assert [t.child_frame_id for t in message.transforms] == list(expected)
    assert geometry["anemometer"]["rpy_deg"] == [4.0, -3.0, 150.0]  # off_axis's own mounting
    for stamped in message.transforms:
        assert stamped.header.frame_id == BODY_FRAME
        stamp = stamped.header.stamp
        assert stamp.sec * 1_000_000_000 + stamp.nanosec == log_time_ns
        position, (roll, pitch, yaw) = expected[stamped.child_frame_id]
        t, q = stamped.transform.translation, stamped.transform.rotation
        assert [t.x, t.y, t.z] == position
        mounting = Rotation.from_euler("ZYX", [yaw, pitch, roll], degrees=True)
        np.testing.assert_allclose(
            Rotation.from_quat([q.x, q.y, q.z, q.w]).as_matrix(), mounting.as_matrix(), atol=1e-14
        )
