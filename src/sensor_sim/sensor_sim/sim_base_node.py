"""The common shape of the simulated sensor nodes.

Each sensor node evaluates the scenario's truth at its own sample times. It follows the
simulation clock on ``/clock`` (published by ``sim_clock_node``): whenever the clock moves, it
publishes every sample whose stamp has been reached. Stamps therefore never depend on
scheduling, and a run is fully defined by the scenario file, the overrides and the seed.
"""

from __future__ import annotations

from rclpy.duration import Duration
from rclpy.qos import QoSProfile, ReliabilityPolicy
from rosgraph_msgs.msg import Clock

from buoy_common.base_node import (
    DATA_QOS,
    DiagnosticsPublisher,
    StartupError,
    SuiteNode,
    main_for,
    message_class,
)
from buoy_common.contract import CLOCK_TOPIC
from buoy_common.parameters import ParameterError, to_ros_value
from sensor_sim.parameters import (
    SCENARIO,
    SCENARIO_OVERRIDES,
    SEED,
    WAIT_FOR_SUBSCRIBER_NODE,
    WAIT_FOR_SUBSCRIPTIONS,
)
from sensor_sim.scenario import ScenarioError, load_scenario
from sensor_sim.streams import STREAMS
from sensor_sim.truth import TruthModel

CLOCK_QOS = QoSProfile(depth=100, reliability=ReliabilityPolicy.RELIABLE)
ACK_TIMEOUT_S = 5.0
# How often a sensor waiting for its subscribers looks at its topics' subscriptions, s.
READINESS_POLL_PERIOD_S = 0.05


def declare_scenario(node: SuiteNode):
    """Declare ``scenario``, ``scenario_overrides`` and ``seed``; load the scenario."""
    name = node.declare_value(SCENARIO.name, SCENARIO.default, SCENARIO.description)
    overrides = node.declare_string_list(SCENARIO_OVERRIDES.name, SCENARIO_OVERRIDES.description)
    seed = node.declare_value(SEED.name, SEED.default, SEED.description)
    try:
        return load_scenario(name, overrides, None if seed < 0 else seed)
    except ScenarioError as error:
        raise StartupError(str(error)) from error


class SimulatedSensorNode(SuiteNode):
    """Publishes one sensor stream, driven by the simulation clock."""

    def __init__(self, kind: str):
        self.spec = STREAMS[kind]
        super().__init__(self.spec.node_name)
        self.scenario = declare_scenario(self)
        if not self.spec.carried(self.scenario):
            raise StartupError(
                f"scenario '{self.scenario.name}' has no {self.spec.sensor} on its platform: "
                f"give it a sensors.{self.spec.sensor} section (or the scenario_overrides "
                f"entry 'sensors.{self.spec.sensor}={{}}' for the default one)"
            )
        # build coerces the values itself: it gets them in the form ROS holds them (intervals
        # as flat lists), which coercing twice would not keep.
        values = {
            name: to_ros_value(self.declare_value(name, default))
            for name, default in self.spec.parameters(self.scenario)
        }
        try:
            self.stream = self.spec.build(self.scenario, TruthModel(self.scenario), values)
        except ParameterError as error:
            raise StartupError(str(error)) from error
        self.wait_for_subscriber_node = self.declare_value(
            WAIT_FOR_SUBSCRIBER_NODE.name,
            WAIT_FOR_SUBSCRIBER_NODE.default,
            WAIT_FOR_SUBSCRIBER_NODE.description,
        )
        self.publishers_by_topic = {
            topic: self.create_publisher(message_class(type_name), topic, DATA_QOS)
            for topic, type_name in self.stream.topics.items()
        }
        self.awaited_subscriptions = self._awaited_subscriptions(
            self.declare_string_list(
                WAIT_FOR_SUBSCRIPTIONS.name, WAIT_FOR_SUBSCRIPTIONS.description
            )
        )
        self.published = 0
        self.sim_time_s = float("nan")
        if self.awaited_subscriptions:
            # The clock holds time at the start until every sensor subscribes to it, so a
            # sensor that subscribes only once the recorder (or a processing node, a listener)
            # takes its topics holds the whole simulation for them: nothing is held back and
            # sent in a burst later.
            self._readiness_timer = self.create_timer(
                READINESS_POLL_PERIOD_S, self._subscribe_to_clock_when_ready
            )
        else:
            self._subscribe_to_clock()
        DiagnosticsPublisher(self, self.health)
        self.get_logger().info(
            f"scenario '{self.scenario.name}' seed {self.scenario.seed}: "
            f"{', '.join(self.stream.topics)} at {self.stream.timing.rate_hz:g} Hz"
        )

    def _awaited_subscriptions(self, entries: list[str]) -> list[tuple[str, str]]:
        """(node, topic) pairs to see before following /clock: every topic of this sensor for
        ``wait_for_subscriber_node``, and the entries of ``wait_for_subscriptions`` whose topic
        this sensor publishes."""
        recorder = self.wait_for_subscriber_node
        awaited = [(recorder, t) for t in self.publishers_by_topic] if recorder else []
        for entry in entries:
            node, separator, topic = entry.partition(":")
            if not (separator and node and topic):
                raise StartupError(
                    f"parameter 'wait_for_subscriptions': {entry!r} is not NODE:TOPIC "
                    "(e.g. compensation_node:anemometer/wind)"
                )
            if topic.lstrip("/") in self.publishers_by_topic:
                awaited.append((node, topic.lstrip("/")))
        return awaited

    def subscribers_ready(self) -> bool:
        """Each awaited node subscribes to its topic, as this node's own graph shows it: so this
        node's publisher has matched that subscription, and its first sample reaches it. A count
        would also be met by another node's subscription while the awaited one is on its way."""
        return all(
            any(endpoint.node_name == node for endpoint in self.get_subscriptions_info_by_topic(t))
            for node, t in self.awaited_subscriptions
        )

    def _subscribe_to_clock_when_ready(self) -> None:
        if self.subscribers_ready():
            self._readiness_timer.cancel()
            self._subscribe_to_clock()

    def _subscribe_to_clock(self) -> None:
        self.create_subscription(Clock, CLOCK_TOPIC, self.on_clock, CLOCK_QOS)

    def on_clock(self, clock: Clock) -> None:
        clock_ns = clock.clock.sec * 1_000_000_000 + clock.clock.nanosec
        self.sim_time_s = (clock_ns - self.scenario.start_time_ns) * 1e-9
        for topic, _, message in self.stream.advance(self.sim_time_s):
            self.publishers_by_topic[topic].publish(message)
            self.published += 1
        if self.stream.finished():
            # Reliable delivery of the last samples must complete before the process exits.
            for publisher in self.publishers_by_topic.values():
                publisher.wait_for_all_acked(Duration(seconds=ACK_TIMEOUT_S))
            self.get_logger().info(f"end of scenario: {self.published} messages published")
            self.finish()

    def health(self):
        level = "ok" if self.published else "warn"
        message = "publishing" if self.published else "waiting for /clock or subscribers"
        return level, message, {"sim_time_s": self.sim_time_s, "published": self.published}


def main_for_stream(kind: str, docstring: str):
    """Console-script entry point of the node that publishes stream ``kind``; ``docstring``
    (its module's) says what it does in ``--help``."""
    return main_for(lambda: SimulatedSensorNode(kind), docstring)
