"""foxglove_bridge: the buoy's products on a Foxglove WebSocket, for a browser without ROS.

    foxglove_bridge [--ros-args -p port:=8765 -p address:=127.0.0.1 -p topics:=[...]]

Subscribes the topics it is given (default: :data:`DEFAULT_TOPICS`, what the shipped Foxglove
layout shows) and serves every message on a Foxglove WebSocket (the ``foxglove-sdk`` server,
subprotocol ``foxglove.sdk.v1``): each topic a channel with message encoding ``cdr`` and its
``ros2msg`` schema, the bytes passed on as DDS delivered them, never decoded. Foxglove (the web
app or the desktop app) opens ``ws://HOST:PORT`` and shows them; the buoy needs no ROS on the
viewing side, and only the topics subscribed in the browser cross the link.

``foxglove-sdk`` is an optional dependency: without it the node says how to install it and
exits with code 2. ``address`` is the interface to listen on: 127.0.0.1 (default) keeps the
server on the machine, 0.0.0.0 opens it to the network (the server has no authentication: open
it only on a private link). ``tf`` is bridged where tf2_msgs is installed.
"""

from __future__ import annotations

import time

from buoy_common.bag_io import jazzy_typestore
from buoy_common.base_node import DATA_QOS, StartupError, SuiteNode, main_for, message_class
from buoy_common.contract import (
    DIAGNOSTICS_TOPIC,
    NAV_ODOMETRY_TOPIC,
    OUTPUT_MSGTYPES,
    SENSOR_MSGTYPES,
    TF_TOPIC,
    WIND_RAW_TOPIC,
    WIND_TRUE_TOPIC,
    wind_mean_topic,
    wind_stats_topic,
)

try:  # optional: pip install foxglove-sdk (see docs/shore.md)
    import foxglove
except ImportError:
    foxglove = None

NODE_NAME = "foxglove_bridge"
DEFAULT_PORT = 8765
DEFAULT_ADDRESS = "127.0.0.1"
DEFAULT_TOPICS = (
    TF_TOPIC,
    NAV_ODOMETRY_TOPIC,
    WIND_RAW_TOPIC,
    WIND_TRUE_TOPIC,
    wind_mean_topic(60.0),
    wind_mean_topic(600.0),
    wind_stats_topic(60.0),
    wind_stats_topic(600.0),
    DIAGNOSTICS_TOPIC,
)
PRODUCT_MSGTYPES = {
    **{wind_mean_topic(w): "geometry_msgs/msg/Vector3Stamped" for w in (60.0, 600.0)},
    **{wind_stats_topic(w): "std_msgs/msg/Float64MultiArray" for w in (60.0, 600.0)},
}


def topic_msgtype(topic: str) -> str | None:
    """The contract's message type of ``topic`` (relative name), None when it has none."""
    return {**SENSOR_MSGTYPES, **OUTPUT_MSGTYPES, **PRODUCT_MSGTYPES}.get(topic)


def ros2msg_schema(msgtype: str) -> bytes:
    """The concatenated ``ros2msg`` definition of ``msgtype``, as MCAP files carry it."""
    definition, _ = jazzy_typestore().generate_msgdef(msgtype, ros_version=2)
    return definition.encode()


class FoxgloveBridge(SuiteNode):
    def __init__(self):
        super().__init__(NODE_NAME)
        if foxglove is None:
            raise StartupError(
                "foxglove-sdk is not installed: pip install foxglove-sdk==0.30.3 (see "
                "docs/shore.md, Without ROS on shore)"
            )
        port = self.declare_value("port", DEFAULT_PORT, "WebSocket port")
        address = self.declare_value("address", DEFAULT_ADDRESS, "interface to listen on")
        topics = self.declare_string_list("topics", "topics to bridge") or list(DEFAULT_TOPICS)
        self.server = foxglove.start_server(name=NODE_NAME, host=address, port=port)
        self.channels = {}
        for topic in topics:
            self._bridge(topic)
        self.get_logger().info(
            f"serving {', '.join(self.channels)} on ws://{address}:{self.server.port}"
        )

    def _bridge(self, topic: str) -> None:
        msgtype = topic_msgtype(topic)
        if msgtype is None:
            raise StartupError(f"parameter 'topics': {topic} is not a topic of the contract")
        try:
            ros_class = message_class(msgtype)
        except ImportError:
            self.get_logger().warning(f"{msgtype} is not installed: {topic} is not bridged")
            return
        channel = foxglove.Channel(
            self.resolve_topic_name(topic),
            message_encoding="cdr",
            schema=foxglove.Schema(name=msgtype, encoding="ros2msg", data=ros2msg_schema(msgtype)),
        )
        self.channels[topic] = channel
        self.create_subscription(
            ros_class,
            topic,
            lambda raw, channel=channel: channel.log(raw, log_time=time.time_ns()),
            DATA_QOS,
            raw=True,
        )

    def destroy_node(self) -> None:
        self.server.stop()
        super().destroy_node()


main = main_for(FoxgloveBridge, __doc__)
