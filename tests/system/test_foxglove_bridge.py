"""``foxglove_bridge`` serves a real WebSocket client on localhost: the client speaks the Foxglove
protocol (subprotocol ``foxglove.sdk.v1``), sees the channels advertised with their ``ros2msg``
schemas, subscribes to ``wind/true`` and receives the CDR bytes of a message published on DDS,
which decode (with rosbags, from the advertised schema alone) to the published wind.
"""

from __future__ import annotations

import asyncio
import json
import os
import socket
import struct
import time

import pytest
import rclpy
from geometry_msgs.msg import Vector3Stamped
from rclpy.context import Context
from rclpy.serialization import serialize_message
from rosbags.typesys import Stores, get_types_from_msg, get_typestore

from buoy_common.base_node import DATA_QOS
from buoy_common.contract import WIND_TRUE_TOPIC

websockets = pytest.importorskip("websockets")
pytest.importorskip("foxglove")

SUBPROTOCOL = "foxglove.sdk.v1"
MESSAGE_DATA_OPCODE = 0x01
WIND_ENU_MPS = (6.25, -3.5, 0.125)
TIMEOUT_S = 30.0


def free_port() -> int:
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        return probe.getsockname()[1]


async def receive_one_wind(port: int, publish) -> tuple[dict, bytes]:
    """Connect, find wind/true among the advertised channels, subscribe, publish until a message
    arrives; return the channel and the message payload."""
    deadline = time.monotonic() + TIMEOUT_S
    while True:
        try:
            connection = await websockets.connect(
                f"ws://127.0.0.1:{port}", subprotocols=[SUBPROTOCOL]
            )
            break
        except OSError:
            if time.monotonic() > deadline:
                raise
            await asyncio.sleep(0.2)
    async with connection:
        assert connection.subprotocol == SUBPROTOCOL
        channel = None
        while channel is None:
            frame = json.loads(await asyncio.wait_for(connection.recv(), TIMEOUT_S))
            if frame["op"] == "advertise":
                channel = next(
                    (c for c in frame["channels"] if c["topic"] == "/" + WIND_TRUE_TOPIC), None
                )
        await connection.send(
            json.dumps(
                {"op": "subscribe", "subscriptions": [{"id": 7, "channelId": channel["id"]}]}
            )
        )
        while time.monotonic() < deadline:
            publish()
            try:
                frame = await asyncio.wait_for(connection.recv(), 0.5)
            except TimeoutError:
                continue
            if isinstance(frame, bytes) and frame[0] == MESSAGE_DATA_OPCODE:
                subscription, _log_time_ns = struct.unpack_from("<IQ", frame, 1)
                assert subscription == 7
                return channel, frame[1 + 4 + 8 :]
        raise AssertionError("no message reached the WebSocket client")


def test_a_websocket_client_receives_the_corrected_wind(nodes):
    port = free_port()
    process = nodes.start("foxglove_bridge", "--ros-args", "-p", f"port:={port}")
    for name in ("ROS_DOMAIN_ID", "ROS_AUTOMATIC_DISCOVERY_RANGE"):
        os.environ[name] = nodes.env[name]
    context = Context()
    rclpy.init(context=context)
    try:
        node = rclpy.create_node("bridge_test", context=context)
        publisher = node.create_publisher(Vector3Stamped, WIND_TRUE_TOPIC, DATA_QOS)
        message = Vector3Stamped()
        message.header.frame_id = "map"
        message.header.stamp.sec = 1767225600
        message.vector.x, message.vector.y, message.vector.z = WIND_ENU_MPS
        # Only a subscription DDS has matched receives: the bridge must be seen first.
        deadline = time.monotonic() + TIMEOUT_S
        while publisher.get_subscription_count() == 0:
            assert time.monotonic() < deadline, "DDS never matched the bridge's subscription:\n" + (
                nodes.log_of(process)
            )
            time.sleep(0.1)
        try:
            channel, payload = asyncio.run(
                receive_one_wind(port, lambda: publisher.publish(message))
            )
        except AssertionError as error:
            raise AssertionError(f"{error}; the bridge's log:\n{nodes.log_of(process)}") from None
    finally:
        rclpy.shutdown(context=context)
    assert nodes.interrupt(process) == 0, nodes.log_of(process)

    assert channel["encoding"] == "cdr" and channel["schemaEncoding"] == "ros2msg"
    assert payload == serialize_message(message)[: len(payload)]
    # Decoded from what the client was told alone: a fresh typestore, the advertised schema.
    typestore = get_typestore(Stores.EMPTY)
    typestore.register(get_types_from_msg(channel["schema"], channel["schemaName"]))
    decoded = typestore.deserialize_cdr(payload, channel["schemaName"])
    assert (decoded.vector.x, decoded.vector.y, decoded.vector.z) == WIND_ENU_MPS
    assert decoded.header.frame_id == "map"
    assert "serving" in nodes.log_of(process)
