"""``sim_clock_node``: the simulation clock on ``/clock``.

Simulated time starts at the scenario's epoch and runs at ``rate_factor`` times wall-clock time
(1 = real time). The sensor nodes publish the samples whose stamps the clock has reached, so one
clock keeps every node of a run on the same time. The node stops at the end of the scenario.
"""

from __future__ import annotations

import math
import time

from rosgraph_msgs.msg import Clock

from buoy_common.base_node import StartupError, SuiteNode, main_for
from buoy_common.contract import CLOCK_TOPIC
from sensor_sim.parameters import (
    PUBLISH_RATE,
    RATE_FACTOR,
    SIM_CLOCK_NODE_NAME,
    START_DELAY,
    WAIT_FOR_NODES,
    WAIT_FOR_SUBSCRIBERS,
)
from sensor_sim.sim_base_node import CLOCK_QOS, declare_scenario

END_LINGER_S = 1.0


class SimClockNode(SuiteNode):
    def __init__(self):
        super().__init__(SIM_CLOCK_NODE_NAME)
        self.scenario = declare_scenario(self)
        self.rate_factor = self.declare_value(
            RATE_FACTOR.name, RATE_FACTOR.default, RATE_FACTOR.description
        )
        publish_rate_hz = self.declare_value(
            PUBLISH_RATE.name, PUBLISH_RATE.default, PUBLISH_RATE.description
        )
        self.wait_for_subscribers = self.declare_value(
            WAIT_FOR_SUBSCRIBERS.name,
            WAIT_FOR_SUBSCRIBERS.default,
            WAIT_FOR_SUBSCRIBERS.description,
        )
        self.wait_for_nodes = set(
            self.declare_string_list(WAIT_FOR_NODES.name, WAIT_FOR_NODES.description)
        )
        self.start_delay_s = self.declare_value(
            START_DELAY.name, START_DELAY.default, START_DELAY.description
        )
        if not (math.isfinite(self.rate_factor) and 0.0 < self.rate_factor <= 1000.0):
            raise StartupError("parameter 'rate_factor' must be in (0, 1000]")
        if not (math.isfinite(publish_rate_hz) and 1.0 <= publish_rate_hz <= 2000.0):
            raise StartupError("parameter 'publish_rate_hz' must be in [1, 2000] Hz")
        self.publisher = self.create_publisher(Clock, CLOCK_TOPIC, CLOCK_QOS)
        self.wall_start_s: float | None = None
        self.ready_since_s: float | None = None
        self.ended_at_s: float | None = None
        self.create_timer(1.0 / publish_rate_hz, self.tick)
        self.get_logger().info(
            f"scenario '{self.scenario.name}': {self.scenario.duration_s:g} s at "
            f"{self.rate_factor:g}x real time"
        )

    def publish_time(self, sim_time_s: float) -> None:
        message = Clock()
        time_ns = self.scenario.start_time_ns + round(sim_time_s * 1e9)
        message.clock.sec, message.clock.nanosec = divmod(time_ns, 1_000_000_000)
        self.publisher.publish(message)

    def tick(self) -> None:
        now_s = time.monotonic()
        if self.wall_start_s is None:
            self.publish_time(0.0)
            if self.publisher.get_subscription_count() < self.wait_for_subscribers:
                return
            if not self.wait_for_nodes <= set(self.get_node_names()):
                return
            self.ready_since_s = self.ready_since_s or now_s
            if now_s - self.ready_since_s < self.start_delay_s:
                return
            self.wall_start_s = now_s
            self.get_logger().info("clock running")
        sim_time_s = (now_s - self.wall_start_s) * self.rate_factor
        if sim_time_s >= self.scenario.duration_s:
            # Keep repeating the final time for a moment so every sensor node receives it.
            self.publish_time(self.scenario.duration_s)
            if self.ended_at_s is None:
                self.ended_at_s = now_s
                self.get_logger().info("end of scenario")
            elif now_s - self.ended_at_s > END_LINGER_S:
                self.finish()
            return
        self.publish_time(sim_time_s)


main = main_for(SimClockNode, __doc__)
