"""Offline speed (tools/bench.py, section ``speed``, Table 5): ``fuse_bag`` and
``process_bag`` on one bag, SPEED_RUNS times each, alternating, nothing else running in the
bench.

Per run: wall time and CPU time (this process and the process that writes the output bag, which
the tools start and wait for), the input bag's messages and the messages written to the output
per second of wall time, and the data's duration over the wall time and over the CPU time (×
real time). The figure of a tool is its fastest run: on a shared machine the other runs measure
the neighbours as much as the code (all runs are kept in the results). CPU time varies less
than wall time with the machine's load and is the figure to compare versions of the code by.

Start-up: each tool started as a command on the same bag, the wall time from starting the
process to its first output message handed to the bag writer, cold (the project's bytecode
caches removed, as after a change of the sources: Python compiles every module it imports) and
warm (the caches written by the run before).

    python -m tools.bench_speed [BAG]     # default: bags/open_ocean (180 s of data)
    python -m tools.bench --only speed    # one hour of open_ocean, simulated and cached
"""

from __future__ import annotations

import json
import os
import resource
import signal
import subprocess
import sys
import time
from pathlib import Path

from mcap.writer import CompressionType, Writer
from rosbags.rosbag2 import Reader

from buoy_common.bag_io import BagReader
from buoy_common.bag_io.mcap_writer import McapWriter
from buoy_common.bag_io.writing import CHUNK_BYTES
from buoy_nav.config import fusion_config_from_files
from buoy_processing.bag_fusion import fuse_bag
from buoy_processing.bag_processing import process_bag
from tools import compiled_caches
from tools.bench_plan import (
    PROCESSING_PARAMS,
    REPO,
    SPEED_DURATION_S,
    SPEED_RUNS,
    SPEED_TARGET_REAL_TIME,
)
from wind_comp.config import compensator_config_from_files

OUT_DIR = REPO / "out" / "bench"
TOOLS = ("fuse_bag", "process_bag")
TOOL_MODULES = {
    "fuse_bag": "buoy_processing.fuse_bag",
    "process_bag": "buoy_processing.process_bag",
}
# The tool's command, with its first hand-over of output to the bag writer (a message, or the
# output side the writing process runs, which writes tf_static first) reported on stderr as
# the system-wide monotonic clock (which the starting process reads too).
_FIRST_OUTPUT_COMMAND = """
import sys, time
from buoy_common.bag_io import background
writer = background.BackgroundBagWriter
handing_over = {name: getattr(writer, name) for name in ("write_raw", "host")}
def first(name):
    def hand_over(self, *args):
        for each, method in handing_over.items():
            setattr(writer, each, method)
        print(f"first output at {time.monotonic():.6f}", file=sys.stderr, flush=True)
        handing_over[name](self, *args)
    return hand_over
for name in handing_over:
    setattr(writer, name, first(name))
from {module} import main
main(sys.argv[1:])
"""


def cpu_with_children_s() -> float:
    """CPU time of this process and of its children that have ended (user + system), s."""
    own = resource.getrusage(resource.RUSAGE_SELF)
    children = resource.getrusage(resource.RUSAGE_CHILDREN)
    return own.ru_utime + own.ru_stime + children.ru_utime + children.ru_stime


def _run(tool: str, in_bag: Path, out_bag: Path):
    """One run of ``tool``: (its summary, CPU s)."""
    config = fusion_config_from_files(PROCESSING_PARAMS)
    cpu_before = cpu_with_children_s()
    if tool == "fuse_bag":
        summary = fuse_bag(str(in_bag), str(out_bag), config, overwrite=True)
    else:
        compensator_config = compensator_config_from_files(PROCESSING_PARAMS)
        summary = process_bag(str(in_bag), str(out_bag), config, compensator_config, overwrite=True)
    return summary, cpu_with_children_s() - cpu_before


def run_speed(in_bag: Path, work_dir: Path, log=lambda text: None) -> dict:
    """Both tools on ``in_bag``, SPEED_RUNS times each, alternating; outputs in ``work_dir``."""
    work_dir.mkdir(parents=True, exist_ok=True)
    # Other work on the machine slows this down; the load average says how much there was.
    load_before = os.getloadavg()[0]
    with BagReader(in_bag) as reader:
        messages_in = sum(info.count for info in reader.topics.values())
    runs: dict[str, list[dict]] = {tool: [] for tool in TOOLS}
    duration_s = 0.0
    for run in range(1, SPEED_RUNS + 1):
        for tool in TOOLS:
            # The bags the bench just wrote would otherwise be flushed to disk during the timing.
            os.sync()
            log(f"bench: speed: {tool} on {in_bag.name}, run {run} of {SPEED_RUNS}")
            summary, cpu_s = _run(tool, in_bag, work_dir / tool)
            duration_s = summary.duration_s
            runs[tool].append(
                {
                    "wall_s": summary.wall_s,
                    "cpu_s": cpu_s,
                    "messages_out": sum(summary.topic_counts.values()),
                }
            )
    steps = {}
    for tool, tool_runs in runs.items():
        best = min(tool_runs, key=lambda figures: figures["wall_s"])
        multiple = duration_s / best["wall_s"]
        steps[tool] = {
            "data_s": duration_s,
            "messages_in": messages_in,
            "messages_out": best["messages_out"],
            "wall_s": best["wall_s"],
            "cpu_s": min(figures["cpu_s"] for figures in tool_runs),
            "messages_in_per_s": messages_in / best["wall_s"],
            "messages_out_per_s": best["messages_out"] / best["wall_s"],
            "real_time_multiple": multiple,
            "cpu_real_time_multiple": duration_s / min(f["cpu_s"] for f in tool_runs),
            "runs_wall_s": [figures["wall_s"] for figures in tool_runs],
            "runs_cpu_s": [figures["cpu_s"] for figures in tool_runs],
            "runs_real_time_multiple": [duration_s / f["wall_s"] for f in tool_runs],
            "pass": bool(multiple >= SPEED_TARGET_REAL_TIME),
        }
    return {
        "bag": in_bag.name,
        "target_real_time_multiple": SPEED_TARGET_REAL_TIME,
        "load_average_1min_before": load_before,
        "load_average_1min_after": os.getloadavg()[0],
        "cpus": os.cpu_count(),
        **steps,
        "bag_io": run_bag_io(in_bag, work_dir / "bag_io"),
        "startup": run_startup(in_bag, work_dir / "startup", log),
    }


def tool_arguments(in_bag: Path, out_bag: Path, params, arguments=()) -> list[str]:
    """A tool's command-line arguments for a run on ``in_bag`` into ``out_bag`` (replaced when
    it exists) with the parameter files ``params`` and the further ``arguments``."""
    return [
        str(in_bag),
        str(out_bag),
        "--overwrite",
        *(argument for path in params for argument in ("--params-file", str(path))),
        *arguments,
    ]


def first_output_s(
    tool: str,
    in_bag: Path,
    out_bag: Path,
    params=PROCESSING_PARAMS,
    arguments=(),
    write_bytecode: bool = True,
) -> float:
    """Wall time, s, from starting ``tool`` on ``in_bag`` with the parameter files ``params`` and
    the further command-line ``arguments`` to its first output message; the tool is then
    interrupted (it leaves nothing under ``out_bag``)."""
    environment = dict(os.environ)
    environment.pop("PYTHONDONTWRITEBYTECODE", None)
    if not write_bytecode:
        environment["PYTHONDONTWRITEBYTECODE"] = "1"
    command = _FIRST_OUTPUT_COMMAND.replace("{module}", TOOL_MODULES[tool])
    started_s = time.monotonic()
    with subprocess.Popen(
        [sys.executable, "-c", command, *tool_arguments(in_bag, out_bag, params, arguments)],
        env=environment,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
        text=True,
    ) as process:
        lines = []
        for line in process.stderr:
            if line.startswith("first output at "):
                process.send_signal(signal.SIGINT)
                process.communicate()
                return float(line.split()[-1]) - started_s
            lines.append(line)
    raise RuntimeError(f"{tool} wrote no output: {''.join(lines[-5:])}")


def run_startup(in_bag: Path, work_dir: Path, log=lambda text: None) -> dict:
    """Start-up of each tool, cold and warm, SPEED_RUNS times each: wall s from the start of
    the process to its first output message (best of the runs, and every run)."""
    work_dir.mkdir(parents=True, exist_ok=True)
    runs: dict[str, dict[str, list[float]]] = {tool: {"cold": [], "warm": []} for tool in TOOLS}
    for run in range(1, SPEED_RUNS + 1):
        for tool in TOOLS:
            log(f"bench: start-up: {tool}, run {run} of {SPEED_RUNS}")
            compiled_caches.remove()
            out_bag = work_dir / tool
            runs[tool]["cold"].append(first_output_s(tool, in_bag, out_bag, write_bytecode=False))
            first_output_s(tool, in_bag, out_bag)  # writes the caches
            runs[tool]["warm"].append(first_output_s(tool, in_bag, out_bag))
    compiled_caches.rebuild()
    return {
        tool: {
            "cold_s": min(figures["cold"]),
            "warm_s": min(figures["warm"]),
            "runs_cold_s": figures["cold"],
            "runs_warm_s": figures["warm"],
        }
        for tool, figures in runs.items()
    }


def _read_us(read_all, count: int) -> float:
    """CPU µs a message of one call of ``read_all`` (reads ``count`` messages)."""
    start_s = time.process_time()
    read = read_all()
    if read != count:
        raise RuntimeError(f"read {read} messages, expected {count}")
    return (time.process_time() - start_s) / count * 1e6


def _write_us(writer_class, messages: list, path: Path) -> float:
    """CPU µs a message of writing ``messages`` (BagMessage) through ``writer_class`` into an MCAP
    file as the suite's bags are written: zstd chunks of CHUNK_BYTES with CRCs, finish included."""
    with path.open("wb") as stream:
        writer = writer_class(
            stream, chunk_size=CHUNK_BYTES, compression=CompressionType.ZSTD, enable_crcs=True
        )
        writer.start(profile="ros2", library="bench")
        channels = {}
        for topic, msgtype in sorted({(m.topic, m.msgtype) for m in messages}):
            schema_id = writer.register_schema(msgtype, "ros2msg", b"")
            channels[topic] = writer.register_channel(topic, "cdr", schema_id)
        start_s = time.process_time()
        for message in messages:
            writer.add_message(
                channels[message.topic], message.log_time_ns, message.raw, message.log_time_ns
            )
        writer.finish()
        return (time.process_time() - start_s) / len(messages) * 1e6


def run_bag_io(in_bag: Path, work_dir: Path) -> dict:
    """CPU µs a message of reading every message of ``in_bag`` through the chunk index and through
    rosbags' reader, and of writing them through McapWriter and the ``mcap`` library's Writer;
    each the best of SPEED_RUNS, alternating."""
    work_dir.mkdir(parents=True, exist_ok=True)
    with BagReader(in_bag) as reader:
        messages = list(reader.messages())

    def through_index() -> int:
        with BagReader(in_bag) as reader:
            return sum(1 for _ in reader.messages())

    def through_rosbags() -> int:
        with Reader(in_bag) as reader:
            return sum(1 for _ in reader.messages())

    figures: dict[str, list[float]] = {key: [] for key in ("read_index", "read_rosbags")}
    figures |= {"write_fast": [], "write_library": []}
    for _ in range(SPEED_RUNS):
        figures["read_index"].append(_read_us(through_index, len(messages)))
        figures["read_rosbags"].append(_read_us(through_rosbags, len(messages)))
        figures["write_fast"].append(_write_us(McapWriter, messages, work_dir / "fast.mcap"))
        figures["write_library"].append(_write_us(Writer, messages, work_dir / "library.mcap"))
    if (work_dir / "fast.mcap").read_bytes() != (work_dir / "library.mcap").read_bytes():
        raise RuntimeError("McapWriter's file differs from the mcap library's")
    return {
        "messages": len(messages),
        **{f"{key}_us_per_message": min(runs) for key, runs in figures.items()},
        "runs_us_per_message": figures,
    }


def print_bag_io(result: dict) -> None:
    print(
        f"\n  Bag I/O, CPU µs a message over the {result['messages']} messages of the bag "
        "(best of the runs; writing: zstd chunks and CRCs included)"
    )
    print(
        f"    read:  chunk index {result['read_index_us_per_message']:5.1f}   "
        f"rosbags' reader {result['read_rosbags_us_per_message']:5.1f}"
    )
    print(
        f"    write: McapWriter  {result['write_fast_us_per_message']:5.1f}   "
        f"mcap's Writer   {result['write_library_us_per_message']:5.1f}   (same bytes)"
    )


def print_speed(result: dict, quick: bool = False) -> None:
    print(
        f"\nTable 5 — offline speed: {result['bag']}, in the bench process, nothing else "
        f"running in the bench (machine load average {result['load_average_1min_before']:.2f} "
        f"before, {result['load_average_1min_after']:.2f} after, {result['cpus']} CPUs)"
    )
    if quick:
        print(f"  (--quick: {SPEED_DURATION_S['quick']:g} s of data instead of one hour)")
    print(
        "  CPU: the tool's process and the one writing its bag; msg/s: the input bag's "
        "messages and those written to the output, per wall-clock second"
    )
    print(
        f"  {'step':12s} {'data s':>7s} {'wall s':>7s} {'× real time':>11s}  {'target ≥ 100×':13s} "
        f"{'CPU s':>7s} {'× per CPU s':>11s} {'in msg/s':>9s} {'out msg/s':>9s}   "
        "× real time of each run"
    )
    for tool in TOOLS:
        s = result[tool]
        runs = " / ".join(f"{multiple:.1f}" for multiple in s["runs_real_time_multiple"])
        verdict = "PASS" if s["pass"] else "MISS"
        print(
            f"  {tool:12s} {s['data_s']:7.0f} {s['wall_s']:7.2f} {s['real_time_multiple']:11.1f}  "
            f"{verdict:13s} {s['cpu_s']:7.2f} {s['cpu_real_time_multiple']:11.1f} "
            f"{s['messages_in_per_s']:9.0f} {s['messages_out_per_s']:9.0f}   {runs}"
        )
    print_bag_io(result["bag_io"])
    print_startup(result["startup"])


def print_startup(result: dict) -> None:
    print(
        "\n  Start-up, wall s from starting the command to its first output message (best of "
        "the runs; cold: the project's bytecode caches removed)"
    )
    for tool in TOOLS:
        s = result[tool]
        print(f"    {tool:12s} cold {s['cold_s']:5.2f}   warm {s['warm_s']:5.2f}")


def print_to_stderr(text: str) -> None:
    print(text, file=sys.stderr, flush=True)


def main(argv=None) -> None:
    arguments = sys.argv[1:] if argv is None else argv
    in_bag = Path(arguments[0]) if arguments else REPO / "bags" / "open_ocean"
    result = run_speed(
        in_bag, OUT_DIR / "runs" / "speed", lambda text: print(text, file=sys.stderr)
    )
    print_speed(result)
    OUT_DIR.mkdir(parents=True, exist_ok=True)
    with open(OUT_DIR / "speed.json", "w") as stream:
        json.dump(result, stream, indent=2)


if __name__ == "__main__":
    main()
