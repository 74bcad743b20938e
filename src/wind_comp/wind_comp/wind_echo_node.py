"""wind_echo: print the corrected wind as it is published, one line per sample.

    wind_echo [--every N] [--ros-args ...]

Subscribes ``wind/true`` and, when published, ``wind/mean_1min`` and ``wind/stats_1min``. Each
``wind/true`` sample prints as

    2026-01-01T00:00:00.050Z  u   5.75  v   5.14  w   0.52 m/s  speed   7.71 m/s  from 228.2 deg

(UTC time of the header stamp; ENU components; horizontal speed; meteorological direction,
degrees clockwise from true North the wind blows FROM). A sample the compensation could not
correct (NaN) prints as ``invalid``. ``--every N`` prints only every N-th ``wind/true`` sample;
the 1-minute products always print. SIGINT ends it with exit code 0.
"""

from __future__ import annotations

import argparse
import math
import sys

from geometry_msgs.msg import Vector3Stamped
from rclpy.utilities import remove_ros_args
from std_msgs.msg import Float64MultiArray

from buoy_common.base_node import DATA_QOS, SuiteNode, run_node
from buoy_common.cli import NODE_EXIT_CODES, ROS_ARGUMENTS_NOTE, command_parser
from buoy_common.contract import (
    WIND_TRUE_TOPIC,
    Reason,
    seconds_to_iso8601,
    stamp_to_seconds,
    wind_mean_topic,
    wind_stats_topic,
)
from wind_comp.compensation_messages import (
    stats_values,
)
from wind_comp.products import meteorological_direction_deg

PROGRAM = "wind_echo"


EXIT_CODES = NODE_EXIT_CODES


def wind_line(t_s: float, u_east_mps: float, v_north_mps: float, w_up_mps: float) -> str:
    """One printed line for an ENU wind vector (m/s) stamped ``t_s`` (s since the epoch)."""
    if not all(math.isfinite(value) for value in (u_east_mps, v_north_mps, w_up_mps)):
        return f"{seconds_to_iso8601(t_s)}  invalid"
    speed = math.hypot(u_east_mps, v_north_mps)
    direction = meteorological_direction_deg(u_east_mps, v_north_mps)
    direction_text = "calm" if math.isnan(direction) else f"from {direction:5.1f} deg"
    return (
        f"{seconds_to_iso8601(t_s)}  u {u_east_mps:6.2f}  v {v_north_mps:6.2f}  "
        f"w {w_up_mps:6.2f} m/s  "
        f"speed {speed:6.2f} m/s  {direction_text}"
    )


def stats_line(values: dict[str, float]) -> str:
    """One printed line for a ``wind/stats_1min`` message given as {label: value}."""
    return (
        f"{seconds_to_iso8601(values['window_end_s'])}  1-min stats: "
        f"scalar mean {values['scalar_mean_speed_mps']:.2f} m/s, "
        f"vector mean {values['vector_mean_speed_mps']:.2f} m/s "
        f"from {values['vector_mean_direction_deg']:.1f} deg, gust {values['gust_mps']:.2f} m/s, "
        f"std u/v/w {values['std_u_mps']:.2f}/{values['std_v_mps']:.2f}/"
        f"{values['std_w_mps']:.2f} m/s, {int(values['n_valid'])} valid, "
        f"{int(values['n_invalid'])} invalid"
    )


class WindEcho(SuiteNode):
    def __init__(self, every: int):
        super().__init__(PROGRAM)
        self.every = every
        self.n_received = 0
        self.create_subscription(Vector3Stamped, WIND_TRUE_TOPIC, self.on_wind, DATA_QOS)
        self.create_subscription(Vector3Stamped, wind_mean_topic(60.0), self.on_mean, DATA_QOS)
        self.create_subscription(Float64MultiArray, wind_stats_topic(60.0), self.on_stats, DATA_QOS)

    def on_wind(self, message: Vector3Stamped) -> None:
        self.n_received += 1
        if (self.n_received - 1) % self.every:
            return
        vector = message.vector
        print(
            wind_line(stamp_to_seconds(message.header.stamp), vector.x, vector.y, vector.z),
            flush=True,
        )

    def on_mean(self, message: Vector3Stamped) -> None:
        vector = message.vector
        line = wind_line(stamp_to_seconds(message.header.stamp), vector.x, vector.y, vector.z)
        print(line.replace("  ", "  1-min mean: ", 1), flush=True)

    def on_stats(self, message: Float64MultiArray) -> None:
        try:
            values = stats_values(message)
            print(stats_line(values), flush=True)
        except (KeyError, ValueError):
            self.reject(wind_stats_topic(60.0), Reason.MALFORMED)


def positive_int(text: str) -> int:
    value = int(text)
    if value < 1:
        raise argparse.ArgumentTypeError(f"must be a positive integer, got {text}")
    return value


def main() -> None:
    parser = command_parser(PROGRAM, __doc__, EXIT_CODES, ROS_ARGUMENTS_NOTE)
    parser.add_argument(
        "--every", type=positive_int, default=1, metavar="N", help="print every N-th sample"
    )
    arguments = parser.parse_args(remove_ros_args(sys.argv)[1:])
    sys.exit(run_node(lambda: WindEcho(arguments.every)))
