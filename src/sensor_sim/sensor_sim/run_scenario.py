"""``run_scenario``: run a simulated buoy live, each node its own process, optionally recording.

Starts the truth node, the nodes of the sensors the scenario's platform carries (IMU, GNSS,
anemometer, and a DVL where it has one) and the simulation clock (and, on request, the fusion,
compensation and current nodes and the bag recorder) as separate processes that talk over DDS,
waits until the scenario has played out, stops the long-running nodes with SIGINT and reports.
It plays the role ``ros2 launch`` would on a full ROS install.
"""

from __future__ import annotations

import json
import shutil
import signal
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass, field
from pathlib import Path

from buoy_common.cli import INTERRUPTIBLE_EXIT_CODES, ExitCode, command_parser, interruptible
from buoy_common.contract import (
    DVL_TOPIC,
    IMU_RAW_TOPIC,
    SENSOR_MSGTYPES,
    TRUTH_MSGTYPES,
    WIND_RAW_TOPIC,
)
from sensor_sim.scenario import ScenarioError, load_scenario
from sensor_sim.streams import STREAMS

# Time for the last messages to travel through fusion, compensation (or the current estimate)
# and into the recorder.
DRAIN_S = 2.0
STOP_TIMEOUT_S = 20.0
SIM_TIME = {"use_sim_time": True}
STOP_ORDER = ("fusion_node", "compensation_node", "current_node", "bag_recorder")
PROGRESS_PERIOD_S = 10.0
FIRST_SUBSCRIPTIONS = {
    "fusion_node": IMU_RAW_TOPIC,
    "compensation_node": WIND_RAW_TOPIC,
    "current_node": DVL_TOPIC,
}
"""The sensor topic each processing node must receive from the first sample on."""
SIMULATED_TOPICS = (*SENSOR_MSGTYPES, *TRUTH_MSGTYPES)
# The node whose log line announces its alignment, and the words that begin that line.
ALIGNMENT_LOGGERS = ("fusion_node",)
ALIGNMENT_MARK = "aligned at stamp"


def executable(name: str) -> str:
    """A suite executable: on PATH, or beside this Python (a venv's bin)."""
    found = shutil.which(name) or shutil.which(name, path=str(Path(sys.executable).parent))
    if found is None:
        raise FileNotFoundError(f"executable '{name}' not found on PATH or beside {sys.executable}")
    return found


@dataclass
class Process:
    name: str
    popen: subprocess.Popen
    log_path: Path
    stops_by_itself: bool

    def log_tail(self, lines: int = 15) -> str:
        text = self.log_path.read_text(errors="replace").splitlines()
        return "\n".join("    " + line for line in text[-lines:])


@dataclass
class Run:
    log_dir: Path
    processes: list[Process] = field(default_factory=list)

    def start(self, name: str, args: list[str], stops_by_itself: bool) -> Process:
        log_path = self.log_dir / f"{name}.log"
        with open(log_path, "w") as log:
            popen = subprocess.Popen(
                [executable(name), *args],
                stdout=log,
                stderr=subprocess.STDOUT,
                start_new_session=True,
            )
        process = Process(name, popen, log_path, stops_by_itself)
        self.processes.append(process)
        return process

    def failed(self) -> Process | None:
        for process in self.processes:
            code = process.popen.poll()
            if code not in (None, 0):
                return process
        return None

    def interrupt(self, processes: list[Process]) -> None:
        for process in processes:
            if process.popen.poll() is None:
                process.popen.send_signal(signal.SIGINT)
        deadline = time.monotonic() + STOP_TIMEOUT_S
        for process in processes:
            try:
                process.popen.wait(timeout=max(0.1, deadline - time.monotonic()))
            except subprocess.TimeoutExpired:
                process.popen.kill()
                process.popen.wait()


class Progress:
    """A line every ``PROGRESS_PERIOD_S`` while the scenario plays, and each processing node's
    alignment as its log reports it, so that a run of minutes never looks hung."""

    def __init__(self, started: float, expected_wall_s: float, processes: list[Process]):
        self.started = started
        self.expected_wall_s = expected_wall_s
        self.next_report = started + PROGRESS_PERIOD_S
        self.watched = [p for p in processes if p.name in ALIGNMENT_LOGGERS]

    def report(self) -> None:
        now = time.monotonic()
        for process in list(self.watched):
            line = _line_with(process.log_path, ALIGNMENT_MARK)
            if line is not None:
                print(f"run_scenario: {process.name}: {line}", flush=True)
                self.watched.remove(process)
        if now >= self.next_report:
            self.next_report += PROGRESS_PERIOD_S
            print(
                f"run_scenario: {now - self.started:.0f} s of about {self.expected_wall_s:.0f} s",
                flush=True,
            )


def _line_with(path: Path, mark: str) -> str | None:
    """The text from ``mark`` on of the first line of ``path`` holding it, or None."""
    try:
        text = path.read_text(errors="replace")
    except OSError:
        return None
    index = text.find(mark)
    return None if index < 0 else text[index:].splitlines()[0]


def ros_arguments(arguments, values: dict[str, object]) -> list[str]:
    """``--ros-args`` for a node: the shared parameter files, then these values, namespace."""
    args = ["--ros-args"]
    for params_file in arguments.params_file:
        args += ["--params-file", params_file]
    for key, value in values.items():
        if isinstance(value, bool):
            value = "true" if value else "false"
        args += ["-p", f"{key}:={value}"]
    if arguments.namespace:
        args += ["-r", f"__ns:={arguments.namespace}"]
    return args


def scenario_values(arguments) -> dict[str, object]:
    values = {"scenario": arguments.scenario, "scenario_overrides": json.dumps(arguments.overrides)}
    if arguments.seed is not None:
        values["seed"] = arguments.seed
    return values


def parse_arguments(argv):
    parser = command_parser("run_scenario", __doc__, EXIT_CODES)
    parser.add_argument("scenario", help="shipped scenario name or path to a scenario YAML file")
    parser.add_argument(
        "--set",
        dest="overrides",
        action="append",
        default=[],
        metavar="KEY=VALUE",
        help="override a scenario value (repeatable)",
    )
    parser.add_argument("--seed", type=int, help="random seed (default: the scenario's)")
    parser.add_argument(
        "--rate-factor",
        type=float,
        default=1.0,
        help="simulated seconds per wall-clock second (default 1: real time)",
    )
    parser.add_argument(
        "--params-file",
        action="append",
        default=[],
        help="ROS parameter YAML given to every node (repeatable)",
    )
    parser.add_argument("--record", metavar="BAG", help="record the run into this new bag")
    parser.add_argument("--fusion", action="store_true", help="also run fusion_node")
    parser.add_argument(
        "--compensation", action="store_true", help="also run compensation_node (implies --fusion)"
    )
    parser.add_argument(
        "--current",
        action="store_true",
        help="also run current_node (implies --fusion; the scenario must carry a DVL)",
    )
    parser.add_argument(
        "--wait-for-subscription",
        dest="awaited_subscriptions",
        action="append",
        default=[],
        metavar="NODE:TOPIC",
        help="start the simulation only once NODE subscribes to the sensor topic TOPIC, e.g. a "
        "listener of your own (repeatable; the processing nodes started here are awaited anyway)",
    )
    parser.add_argument("--namespace", help="put every node in this namespace, e.g. /buoy1")
    parser.add_argument("--log-dir", default=None, help="where node logs go (default: a temp dir)")
    return parser.parse_args(argv)


def awaited_subscription_error(entry: str) -> str | None:
    """What is wrong with a ``--wait-for-subscription`` entry, or None."""
    node, separator, topic = entry.partition(":")
    if not (separator and node and topic):
        return f"--wait-for-subscription {entry!r}: expected NODE:TOPIC, e.g. me:{WIND_RAW_TOPIC}"
    if topic.lstrip("/") not in SIMULATED_TOPICS:
        return (
            f"--wait-for-subscription {entry!r}: the simulation does not publish {topic}; it "
            f"can wait for subscriptions to {', '.join(SIMULATED_TOPICS)}"
        )
    return None


def argument_error(arguments) -> str | None:
    """What is wrong with the arguments themselves, or None."""
    for entry in arguments.awaited_subscriptions:
        error = awaited_subscription_error(entry)
        if error:
            return error
    return None


def scenario_run_error(arguments, scenario) -> str | None:
    """Why the arguments cannot run this scenario, or None."""
    if arguments.record and Path(arguments.record).exists():
        return f"{arguments.record} exists; choose a new bag path"
    if arguments.current and not STREAMS["dvl"].carried(scenario):
        return (
            f"--current: scenario '{scenario.name}' carries no DVL "
            "(add one with --set sensors.dvl={})"
        )
    return None


def log_directory(arguments) -> Path:
    """Where the node logs go: ``--log-dir`` (created), else a new temporary directory."""
    if arguments.log_dir:
        log_dir = Path(arguments.log_dir)
        log_dir.mkdir(parents=True, exist_ok=True)
        return log_dir
    return Path(tempfile.mkdtemp(prefix="run_scenario-"))


def sensor_node_names(scenario) -> list[str]:
    """The truth node first, then the nodes of the sensors the scenario's platform carries."""
    return [
        spec.node_name
        for kind, spec in sorted(STREAMS.items(), key=lambda item: item[0] != "truth")
        if spec.carried(scenario)
    ]


def processing_node_names(arguments) -> list[str]:
    """The fusion, compensation and current nodes the arguments ask for."""
    names = []
    if arguments.fusion or arguments.compensation or arguments.current:
        names.append("fusion_node")
    if arguments.compensation:
        names.append("compensation_node")
    if arguments.current:
        names.append("current_node")
    return names


def sensor_node_values(arguments, processing_nodes: list[str]) -> dict[str, object]:
    """The sensor nodes' parameters: the scenario, and whom they wait for before the clock
    may start."""
    # A recording must start with the first sample of every topic; without a recorder some
    # topics (truth, baseline) may have no subscriber at all, and the clock's own wait for the
    # fusion and compensation nodes is what keeps them from missing the start.
    values = scenario_values(arguments)
    if arguments.record:
        values["wait_for_subscriber_node"] = "bag_recorder"
    # A node in the graph may not have subscribed yet, nor been matched by the sensors: each
    # sensor holds the clock until the processing nodes' subscriptions to its topics reach it.
    awaited = [
        f"{node}:{topic}" for node, topic in FIRST_SUBSCRIPTIONS.items() if node in processing_nodes
    ]
    awaited += arguments.awaited_subscriptions
    if awaited:
        values["wait_for_subscriptions"] = json.dumps(awaited)
    return values


def start_nodes(run: Run, arguments, scenario, processing_nodes: list[str]) -> None:
    """Start the recorder (if asked), the processing nodes, the sensors and the clock."""
    sensor_nodes = sensor_node_names(scenario)
    clock_subscribers = len(sensor_nodes)
    if arguments.record:
        run.start("bag_recorder", [arguments.record, *ros_arguments(arguments, SIM_TIME)], False)
        clock_subscribers += 1
    # The processing nodes run on header stamps and the wall clock, as on a buoy: on simulated
    # time each would also take every /clock message, a callback per 5 ms for nothing.
    for name in processing_nodes:
        run.start(name, ros_arguments(arguments, {}), False)
    sensor_values = sensor_node_values(arguments, processing_nodes)
    for name in sensor_nodes:
        run.start(name, ros_arguments(arguments, sensor_values), True)
    clock_values = {
        **scenario_values(arguments),
        "rate_factor": arguments.rate_factor,
        "wait_for_subscribers": clock_subscribers,
    }
    if processing_nodes:
        clock_values["wait_for_nodes"] = f"[{','.join(processing_nodes)}]"
    run.start("sim_clock_node", ros_arguments(arguments, clock_values), True)


def report_failure(failure: Process) -> None:
    print(
        f"run_scenario: {failure.name} exited with code {failure.popen.returncode}:\n"
        f"{failure.log_tail()}",
        file=sys.stderr,
    )


def play_out(run: Run, expected_wall_s: float) -> int | None:
    """Wait until the self-stopping nodes (sensors, clock) have finished, then let the last
    messages drain: None, or the exit code of a run that failed, overran or was interrupted
    (every node then stopped)."""
    self_stopping = [p for p in run.processes if p.stops_by_itself]
    started = time.monotonic()
    deadline = started + expected_wall_s + 60.0
    progress = Progress(started, expected_wall_s, run.processes)
    try:
        while any(p.popen.poll() is None for p in self_stopping):
            progress.report()
            failure = run.failed()
            if failure is not None:
                report_failure(failure)
                run.interrupt(run.processes)
                return 1
            if time.monotonic() > deadline:
                print("run_scenario: the simulation did not finish in time", file=sys.stderr)
                run.interrupt(run.processes)
                return 1
            time.sleep(0.2)
        time.sleep(DRAIN_S)
    except KeyboardInterrupt:
        print("run_scenario: interrupted, stopping the nodes", file=sys.stderr)
        run.interrupt(run.processes)
        return 130
    except BaseException:
        # A closed output pipe or any other way out: the nodes run in sessions of their own and
        # would outlive this process.
        run.interrupt(run.processes)
        raise
    return None


def stop_long_running(run: Run) -> int:
    """Stop the processing nodes and the recorder; 0, or 1 when a node had failed."""
    # Upstream first: each node publishes what it holds back when it stops, and the recorder,
    # stopped last, records that too.
    long_running = [p for p in run.processes if not p.stops_by_itself]
    for process in sorted(long_running, key=lambda p: STOP_ORDER.index(p.name)):
        run.interrupt([process])
    failure = run.failed()
    if failure is not None:
        report_failure(failure)
        return 1
    return 0


def run(arguments) -> int:
    error = argument_error(arguments)
    if error is None:
        scenario = load_scenario(arguments.scenario, arguments.overrides, arguments.seed)
        error = scenario_run_error(arguments, scenario)
    if error is not None:
        print(f"run_scenario: {error}", file=sys.stderr)
        return 2
    log_dir = log_directory(arguments)
    run = Run(log_dir)
    processing_nodes = processing_node_names(arguments)
    start_nodes(run, arguments, scenario, processing_nodes)
    print(
        f"run_scenario: '{scenario.name}' seed {scenario.seed}, {scenario.duration_s:g} s at "
        f"{arguments.rate_factor:g}x; node logs in {log_dir}",
        flush=True,
    )
    code = play_out(run, scenario.duration_s / arguments.rate_factor)
    if code is not None:
        return code
    code = stop_long_running(run)
    if code == 0 and arguments.record:
        print(f"run_scenario: recorded {arguments.record}")
    return code


EXIT_CODES = (
    *INTERRUPTIBLE_EXIT_CODES,
    ExitCode(1, "a node failed (its log is named on stderr) or the run did not finish in time"),
)


@interruptible("run_scenario")
def main(argv=None) -> None:
    arguments = parse_arguments(sys.argv[1:] if argv is None else argv)
    try:
        sys.exit(run(arguments))
    except (ScenarioError, FileNotFoundError) as error:
        print(f"run_scenario: {error}", file=sys.stderr)
        sys.exit(2)
