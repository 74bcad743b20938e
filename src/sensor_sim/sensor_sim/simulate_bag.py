"""``simulate_bag``: write a scenario's sensor and truth topics straight to a bag, without DDS.

The messages are the ones the live sensor nodes would publish for the same scenario, seed and
parameters (same streams, same stamps); the log time of each message is its header stamp. It is
the fast way to make long runs for benchmarks; the committed bags are recorded live.
"""

from __future__ import annotations

import math
import sys

from tqdm import tqdm

from buoy_common.bag_io import BackgroundBagWriter, BagError
from buoy_common.cli import INTERRUPTIBLE_EXIT_CODES, command_parser, interruptible
from buoy_common.parameters import ParameterError, load_parameter_files
from sensor_sim import message_bytes
from sensor_sim.scenario import ScenarioError, load_scenario
from sensor_sim.streams import STREAMS, merged_messages
from sensor_sim.truth import TruthModel

CHUNK_S = 10.0


EXIT_CODES = INTERRUPTIBLE_EXIT_CODES


def parse_arguments(argv):
    parser = command_parser("simulate_bag", __doc__, EXIT_CODES)
    parser.add_argument("scenario", help="shipped scenario name or path to a scenario YAML file")
    parser.add_argument("output", help="bag directory to create")
    parser.add_argument(
        "--set",
        dest="overrides",
        action="append",
        default=[],
        metavar="KEY=VALUE",
        help="override a scenario value, e.g. --set wind.speed_mps=15 (repeatable)",
    )
    parser.add_argument("--seed", type=int, help="random seed (default: the scenario's)")
    parser.add_argument(
        "--params-file",
        action="append",
        default=[],
        help="ROS parameter YAML (sensor rates, errors, extrinsics), as given to the nodes",
    )
    parser.add_argument("--no-truth", action="store_true", help="leave the truth topics out")
    parser.add_argument("--overwrite", action="store_true", help="replace an existing bag")
    return parser.parse_args(argv)


def simulate(arguments) -> dict[str, int]:
    scenario = load_scenario(arguments.scenario, arguments.overrides, arguments.seed)
    truth = TruthModel(scenario)
    kinds = [
        kind
        for kind, spec in STREAMS.items()
        if spec.carried(scenario) and not (arguments.no_truth and kind == "truth")
    ]
    streams = []
    for kind in kinds:
        spec = STREAMS[kind]
        values = load_parameter_files(arguments.params_file, spec.node_name)
        streams.append(spec.build(scenario, truth, values, encoding=message_bytes))
    types = {topic: t for stream in streams for topic, t in stream.topics.items()}
    with (
        tqdm(
            total=math.ceil(scenario.duration_s),
            desc=f"simulate_bag {scenario.name}",
            unit="sim s",
            disable=None,
        ) as progress,
        BackgroundBagWriter(arguments.output, overwrite=arguments.overwrite) as writer,
    ):
        until_s = 0.0
        while not all(stream.finished() for stream in streams):
            until_s += CHUNK_S
            for topic, stamp, raw in merged_messages(streams, until_s):
                writer.write_raw(topic, types[topic], stamp, raw)
            progress.update(min(math.ceil(until_s), progress.total) - progress.n)
    return dict(writer.counts)


@interruptible("simulate_bag")
def main(argv=None) -> None:
    arguments = parse_arguments(sys.argv[1:] if argv is None else argv)
    try:
        counts = simulate(arguments)
    except (ScenarioError, ParameterError, BagError, OSError) as error:
        print(f"simulate_bag: {error}", file=sys.stderr)
        sys.exit(2)
    for topic, count in sorted(counts.items()):
        print(f"{topic:20s} {count:8d}")
    print(f"wrote {arguments.output}")
