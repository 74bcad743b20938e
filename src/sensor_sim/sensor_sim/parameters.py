"""The simulator nodes' parameters, each declared once.

The sensor error budgets and sample timing are declared on their configuration dataclasses
(:mod:`sensor_sim.sensor_errors`, :class:`sensor_sim.streams.StreamTiming`), the parameters of
the scenario, of the start-up waits and of ``sim_clock_node`` here. :func:`parameter_sets` lists
them per node for the generated ``config/sim.yaml`` and parameters reference.
"""

from __future__ import annotations

import dataclasses

from buoy_common.parameter_declarations import (
    DeclaredParameter,
    FileSection,
    NodeParameters,
    ParameterFile,
    ParameterSets,
    declared_parameters,
)
from sensor_sim.scenario import SampleRates
from sensor_sim.streams import STREAMS, StreamSpec, StreamTiming

_STRING_LIST = "string[]"

SCENARIO = DeclaredParameter(
    "scenario", "sea_state", "shipped scenario name or path to a scenario YAML"
)
SCENARIO_OVERRIDES = DeclaredParameter(
    "scenario_overrides",
    (),
    "dotted.key=value overrides of the scenario",
    ros_type=_STRING_LIST,
)
SEED = DeclaredParameter("seed", -1, "random seed; -1: the scenario's", rule="≥ -1")
WAIT_FOR_SUBSCRIBER_NODE = DeclaredParameter(
    "wait_for_subscriber_node",
    "",
    "follow /clock only once every topic has a subscription of this node (a recorder)",
)
WAIT_FOR_SUBSCRIPTIONS = DeclaredParameter(
    "wait_for_subscriptions",
    (),
    "follow /clock only once each named node subscribes to the named topic, for the topics "
    "this sensor publishes",
    rule="NODE:TOPIC entries",
    ros_type=_STRING_LIST,
)

RATE_FACTOR = DeclaredParameter(
    "rate_factor", 1.0, "simulated seconds per wall-clock second", rule="in (0, 1000]"
)
PUBLISH_RATE = DeclaredParameter(
    "publish_rate_hz", 200.0, "wall-clock rate of /clock", unit="Hz", rule="in [1, 2000]"
)
WAIT_FOR_SUBSCRIBERS = DeclaredParameter(
    "wait_for_subscribers", 0, "hold time at 0 until /clock has this many subscribers"
)
WAIT_FOR_NODES = DeclaredParameter(
    "wait_for_nodes",
    (),
    "names of nodes not on simulated time to hold time at 0 for",
    ros_type=_STRING_LIST,
)
START_DELAY = DeclaredParameter(
    "start_delay_s", 0.5, "wall-clock pause after the subscribers are there", unit="s"
)

SIM_CLOCK_NODE_NAME = "sim_clock_node"


def stream_parameters(spec: StreamSpec) -> list[DeclaredParameter]:
    """The parameters of one sensor's (or the truth's) timing and configurations, with the
    defaults a scenario that sets none of them gives."""
    default_rate_hz = getattr(SampleRates(), spec.rate_key)
    timing = declared_parameters(StreamTiming)
    timing[0] = dataclasses.replace(
        timing[0],
        default=default_rate_hz,
        meaning=f"sample rate; default: the scenario's sensors.rates.{spec.rate_key}",
    )
    parameters = [*timing, WAIT_FOR_SUBSCRIBER_NODE, WAIT_FOR_SUBSCRIPTIONS]
    for config_type, prefix, renamed in spec.configs.values():
        parameters += declared_parameters(config_type, prefix, renamed)
    return parameters


def _sim_yaml(streams: list[tuple[str, list[DeclaredParameter]]]) -> ParameterFile:
    header = (
        "Simulated sensors: every parameter of the simulator nodes with its default. A sensor's",
        "rate and errors default to the scenario's (its sensors section), so their sections are",
        "comments: uncomment a value to override the scenario. Use together with",
        "buoy_common/config/buoy.yaml (extrinsics).",
    )
    common = (SCENARIO, SCENARIO_OVERRIDES, SEED)
    sections = [FileSection("/**", common)]
    for node, parameters in streams:
        own = tuple(p for p in parameters if not p.shared)
        sections.append(FileSection(f"/**/{node}", own, commented=True))
    clock = (RATE_FACTOR, PUBLISH_RATE, WAIT_FOR_SUBSCRIBERS, WAIT_FOR_NODES, START_DELAY)
    sections.append(FileSection(f"/**/{SIM_CLOCK_NODE_NAME}", clock, commented=True))
    return ParameterFile("src/sensor_sim/config/sim.yaml", header, tuple(sections))


def parameter_sets() -> ParameterSets:
    """The simulator nodes' parameters, for the generated parameter file and reference (entry
    point of :data:`buoy_common.parameter_declarations.ENTRY_POINT_GROUP`)."""
    common = (SCENARIO, SCENARIO_OVERRIDES, SEED)
    streams = [(spec.node_name, stream_parameters(spec)) for spec in STREAMS.values()]
    nodes = [
        NodeParameters(node, f"simulator node of the {kind} stream", (*common, *parameters))
        for kind, (node, parameters) in zip(STREAMS, streams, strict=True)
    ]
    clock = (RATE_FACTOR, PUBLISH_RATE, WAIT_FOR_SUBSCRIBERS, WAIT_FOR_NODES, START_DELAY)
    nodes.append(NodeParameters(SIM_CLOCK_NODE_NAME, "simulation clock", (*common, *clock)))
    return ParameterSets("sensor_sim", tuple(nodes), (_sim_yaml(streams),))
