"""What Foxglove and RViz are given: ``tf`` in processed bags, and the shipped Foxglove layout.

The ``tf`` of a processed bag is read back with mcap + mcap-ros2-support, independently of the
rosbags typestore that wrote it, and judged against the simulator's truth; the layout may name
only topics a processed bag or the running nodes carry, and only fields their types have.
"""

from __future__ import annotations

import json
import re
from pathlib import Path

import numpy as np
import pytest
from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory
from rosbags.interfaces import Nodetype
from scipy.spatial.transform import Rotation

from buoy_common.bag_io import BagReader, jazzy_typestore
from buoy_common.contract import (
    BODY_FRAME,
    DIAGNOSTICS_TOPIC,
    MAP_FRAME,
    OUTPUT_MSGTYPES,
    SENSOR_MSGTYPES,
    TF_MSGTYPE,
    TF_TOPIC,
    TRUTH_MSGTYPES,
)
from processed_bags import processed_bag

REPO = Path(__file__).resolve().parents[2]
LAYOUT = REPO / "src" / "buoy_common" / "config" / "foxglove_layout.json"
# The attitude error the fusion achieves on sea_state (docs/benchmarks.md: 0.06° roll max after
# the filter's 1σ settles); the 3-D view need not be better, but must be that good.
ATTITUDE_TOLERANCE_DEG = 0.3
SETTLING_S = 30.0
CHECKED_S = 60.0


@pytest.fixture(scope="module")
def processed(tmp_path_factory) -> Path:
    return processed_bag(tmp_path_factory, "sea_state")


def decoded(bag: Path, topic: str) -> list:
    """``topic``'s messages of the first ``CHECKED_S`` decoded by mcap-ros2-support, in
    log-time order."""
    (mcap_file,) = bag.glob("*.mcap")
    with mcap_file.open("rb") as stream:
        reader = make_reader(stream, validate_crcs=True, decoder_factories=[DecoderFactory()])
        start_ns = reader.get_summary().statistics.message_start_time
        return [
            (channel, message)
            for _, channel, _, message in reader.iter_decoded_messages(
                topics=[topic], ending_before=start_ns + int(CHECKED_S * 1e9), log_time_order=True
            )
        ]


def stamp_ns(header) -> int:
    return header.stamp.sec * 1_000_000_000 + header.stamp.nanosec


def test_processed_bag_tf_is_the_navigation_and_matches_the_truth(processed):
    transforms = decoded(processed, "/" + TF_TOPIC)
    odometry = decoded(processed, "/nav/odometry")
    truth = {stamp_ns(m.header): m for _, m in decoded(processed, "/truth/odometry")}
    assert transforms and len(transforms) == len(odometry)
    assert transforms[0][0].schema_id is not None
    errors_deg, t0 = [], None
    for (channel, tf), (_, nav) in zip(transforms, odometry, strict=True):
        assert channel.message_encoding == "cdr"
        (transform,) = tf.transforms
        assert transform.header.frame_id == MAP_FRAME and transform.child_frame_id == BODY_FRAME
        assert stamp_ns(transform.header) == stamp_ns(nav.header)
        t, q = transform.transform.translation, transform.transform.rotation
        p, o = nav.pose.pose.position, nav.pose.pose.orientation
        assert (t.x, t.y, t.z, q.x, q.y, q.z, q.w) == (p.x, p.y, p.z, o.x, o.y, o.z, o.w)
        true_pose = truth.get(stamp_ns(transform.header))
        t0 = stamp_ns(transform.header) if t0 is None else t0
        if true_pose is None or stamp_ns(transform.header) - t0 < SETTLING_S * 1e9:
            continue
        tq = true_pose.pose.pose.orientation
        difference = Rotation.from_quat([q.x, q.y, q.z, q.w]).inv() * Rotation.from_quat(
            [tq.x, tq.y, tq.z, tq.w]
        )
        errors_deg.append(np.degrees(difference.magnitude()))
    print(f"{len(errors_deg)} stamps, largest attitude error {max(errors_deg):.3f} deg")
    assert len(errors_deg) > 500
    assert max(errors_deg) < ATTITUDE_TOLERANCE_DEG


def layout_paths() -> list[str]:
    """Every topic or message path the layout names."""
    layout = json.loads(LAYOUT.read_text())
    found = []
    for panel in layout["configById"].values():
        found += [path["value"] for path in panel.get("paths", [])]
        found += list(panel.get("topics", {}))
        if "topicToRender" in panel:
            found.append(panel["topicToRender"])
    return found


def field_type(msgtype: str, fields: list[str]) -> str:
    """The type reached from ``msgtype`` through ``fields`` (``covariance[21]`` indexes an array);
    KeyError when a field does not exist, IndexError when an index lies outside a fixed array."""
    typestore = jazzy_typestore()
    for name in fields:
        match = re.fullmatch(r"(\w+)(?:\[(\d+)\])?", name)
        field_name, index = match.group(1), match.group(2)
        node = dict(typestore.fielddefs[msgtype][1])[field_name]
        if index is not None:
            assert node[0] == Nodetype.ARRAY, f"{msgtype}.{field_name} is not a fixed array"
            node, length = node[1]
            if int(index) >= length:
                raise IndexError(f"{msgtype}.{field_name}[{index}] beyond {length}")
        msgtype = node[1] if node[0] == Nodetype.NAME else str(node[1])
    return msgtype


def test_the_layout_names_only_existing_topics_and_fields(processed):
    with BagReader(processed) as reader:
        in_bag = {name: info.msgtype for name, info in reader.topics.items()}
    contract = {
        "/" + topic: msgtype
        for topic, msgtype in {**SENSOR_MSGTYPES, **TRUTH_MSGTYPES, **OUTPUT_MSGTYPES}.items()
    }
    live_only = {"/" + DIAGNOSTICS_TOPIC}
    paths = layout_paths()
    assert any(p.startswith("/" + TF_TOPIC) for p in paths)
    for path in paths:
        topic, _, fields = path.partition(".")
        assert topic in in_bag or topic in live_only, f"layout names {topic}, which no bag has"
        msgtype = in_bag.get(topic, contract.get(topic))
        assert msgtype == contract.get(topic, msgtype), topic
        if fields:
            field_type(msgtype, fields.split("."))
    assert in_bag["/" + TF_TOPIC] == TF_MSGTYPE


def test_the_field_check_catches_a_wrong_field():
    with pytest.raises(KeyError):
        field_type("geometry_msgs/msg/Vector3Stamped", ["vector", "w"])
    with pytest.raises(IndexError):
        field_type("nav_msgs/msg/Odometry", ["pose", "covariance[36]"])
