"""Pass-through stand-ins for fusion_node and compensation_node: the live benchmark's floor.

    python -m tools.passthrough_node fusion_node|compensation_node [--ros-args ...]

They keep the suite's node names, processes, topics, QoS and executor, and compute nothing:

- ``fusion_node`` republishes every ``imu/data_raw`` message, unchanged, on ``nav/imu``;
- ``compensation_node`` republishes every ``anemometer/wind`` message, unchanged, on
  ``wind/true`` as soon as ``nav/imu`` of the same header stamp has arrived (at once if it
  already has), as the real node waits for the navigation at its sample's stamp.

Run in place of the real nodes (``tools/bench_live.py --passthrough``), the latency they show
is what the middleware, the Python executor and the machine's scheduling cost on the same
path, so the real nodes' figures can be read against it.
"""

from __future__ import annotations

import sys

from geometry_msgs.msg import Vector3Stamped
from sensor_msgs.msg import Imu

from buoy_common import cdr
from buoy_common.base_node import DATA_QOS, SuiteNode, run_node

# Stamps of navigation seen, kept for matching wind samples that arrive after them.
NAV_STAMPS_KEPT = 1000


def passthrough_fusion(node) -> None:
    publisher = node.create_publisher(Imu, "nav/imu", DATA_QOS)
    node.create_subscription(Imu, "imu/data_raw", publisher.publish, DATA_QOS, raw=True)


def passthrough_compensation(node) -> None:
    publisher = node.create_publisher(Vector3Stamped, "wind/true", DATA_QOS)
    waiting_wind: dict[tuple[int, int], bytes] = {}
    nav_stamps: dict[tuple[int, int], None] = {}

    def on_wind(raw: bytes) -> None:
        stamp = cdr.read_stamp(raw)
        if stamp in nav_stamps:
            publisher.publish(raw)
        else:
            waiting_wind[stamp] = raw

    def on_nav(raw: bytes) -> None:
        stamp = cdr.read_stamp(raw)
        nav_stamps[stamp] = None
        if len(nav_stamps) > NAV_STAMPS_KEPT:
            del nav_stamps[next(iter(nav_stamps))]
        wind = waiting_wind.pop(stamp, None)
        if wind is not None:
            publisher.publish(wind)

    node.create_subscription(Vector3Stamped, "anemometer/wind", on_wind, DATA_QOS, raw=True)
    node.create_subscription(Imu, "nav/imu", on_nav, DATA_QOS, raw=True)


ROLES = {"fusion_node": passthrough_fusion, "compensation_node": passthrough_compensation}


def main(argv: list[str]) -> int:
    if len(argv) < 2 or argv[1] not in ROLES:
        print(f"usage: passthrough_node.py {'|'.join(ROLES)} [--ros-args ...]", file=sys.stderr)
        return 2
    role = argv[1]

    def stand_in() -> SuiteNode:
        node = SuiteNode(role)
        ROLES[role](node)
        return node

    # The real nodes' start-up, executor and spin loop.
    return run_node(stand_in, argv)


if __name__ == "__main__":
    sys.exit(main(sys.argv))
