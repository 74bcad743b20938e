"""The I/O floor of the offline processing (tools/bench.py, section ``io_floor``).

What ``process_bag`` could take at best with the suite's own bag input and output: (a) the
suite's reader reading and decoding every message of the input bag, (b) the suite's writer
writing the messages ``process_bag`` writes, and nothing computed in between. ``process_bag``
(c) is read against a + b.

(a) two ways: one message at a time, each decoded by rosbags (``BagReader.messages`` and
``BagReader.decode``, what the tools do for the messages they do not read from CDR
themselves), and a chunk at a time, each topic's messages of it decoded into columns
(``BagReader.message_batches`` and ``bag_io.batch_columns``: :mod:`buoy_common.cdr_bulk`), what
an engine that works on arrays would read. Reading alone, without decoding, is given beside
them. (b): the messages of ``process_bag``'s output bag, held in memory beforehand (their
bytes made: encoding is not in b), handed one at a time to the writer ``process_bag`` writes
through (a ``NamespacedWriter`` over a ``BackgroundBagWriter``), up to the finished bag; their
encoding from columns by :func:`buoy_common.cdr_bulk.encode` is timed apart for the types it
handles. (c): ``process_bag`` with the shipped parameter files, in this process, as the speed
section runs it.

Each figure is the fastest of RUNS runs, alternating (the machine may be shared: the other runs
measure the neighbours as much as the code); wall and CPU time (this process and the process
writing the bag). Results go to out/bench/io_floor.json.

    python -m tools.bench_io_floor [BAG] [--runs N]   # default BAG: bags/open_ocean (180 s)
    python -m tools.bench --only io_floor             # one hour of open_ocean, simulated, cached
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from collections import defaultdict
from collections.abc import Callable
from pathlib import Path
from typing import NamedTuple

import numpy as np

from buoy_common import cdr_bulk
from buoy_common.bag_io import BackgroundBagWriter, BagReader, batch_columns
from buoy_common.namespaces import NamespacedWriter, TopicView
from buoy_nav.config import fusion_config_from_files
from buoy_processing.bag_processing import process_bag
from tools.bench_plan import PROCESSING_PARAMS, REPO
from tools.bench_speed import cpu_with_children_s
from tools.interpreter import describe, interpreter
from wind_comp.config import compensator_config_from_files

OUT_DIR = REPO / "out" / "bench"
RUNS = 3
# Messages of a topic encoded at a time: what a chunk of the bag holds, and the size of the
# batches the tools hand to their writing process.
ENCODE_CHUNK = 2048


class Timing(NamedTuple):
    """One timed step: wall and CPU s (this process and the children that ended), and the
    messages it moved."""

    wall_s: float
    cpu_s: float
    messages: int


def _timed(step: Callable[..., int], *arguments) -> Timing:
    cpu_before, wall_before = cpu_with_children_s(), time.perf_counter()
    messages = step(*arguments)
    return Timing(time.perf_counter() - wall_before, cpu_with_children_s() - cpu_before, messages)


# -- (a) reading ----------------------------------------------------------------------------------


def read_only(bag: Path) -> int:
    """Every message of ``bag`` read, none decoded; returns how many."""
    with BagReader(bag) as reader:
        return sum(1 for _ in reader.messages())


def read_one_at_a_time(bag: Path) -> int:
    """Every message of ``bag`` read and decoded by rosbags, one at a time."""
    count = 0
    with BagReader(bag) as reader:
        for message in reader.messages():
            reader.decode(message)
            count += 1
    return count


def read_in_columns(bag: Path) -> int:
    """Every message of ``bag`` read a chunk at a time, each topic of a chunk decoded
    together; BagError-free only if every message decoded."""
    count = 0
    with BagReader(bag) as reader:
        for batch in reader.message_batches():
            for topic, decoded in batch_columns(reader, batch).items():
                if decoded.columns is not None and not decoded.columns.valid.all():
                    raise RuntimeError(f"{topic}: {decoded.columns.rejected}")
            count += len(batch)
    return count


# -- (b) writing ----------------------------------------------------------------------------------


class HeldMessages(NamedTuple):
    """A bag's messages held in memory: their bytes end to end, where each one starts, its
    topic (an index into ``topics``) and log time (ns)."""

    topics: list[tuple[str, str]]
    topic_index: np.ndarray
    log_time_ns: np.ndarray
    starts: np.ndarray
    data: bytes


def hold_messages(bag: Path) -> HeldMessages:
    topics: dict[tuple[str, str], int] = {}
    index, log_times, starts, parts = [], [], [0], []
    with BagReader(bag) as reader:
        for message in reader.messages():
            key = (message.topic, message.msgtype)
            index.append(topics.setdefault(key, len(topics)))
            log_times.append(message.log_time_ns)
            starts.append(starts[-1] + len(message.raw))
            parts.append(message.raw)
    return HeldMessages(
        list(topics),
        np.asarray(index),
        np.asarray(log_times, dtype=np.int64),
        np.asarray(starts, dtype=np.int64),
        b"".join(parts),
    )


def write_held(held: HeldMessages, out_bag: Path) -> int:
    """``held`` written as ``process_bag`` writes its output, up to the finished bag."""
    topics, data = held.topics, held.data
    starts = held.starts.tolist()
    with BackgroundBagWriter(out_bag, overwrite=True) as bag_writer:
        writer = NamespacedWriter(bag_writer, TopicView())
        for number, (which, log_time_ns) in enumerate(
            zip(held.topic_index.tolist(), held.log_time_ns.tolist(), strict=True)
        ):
            topic, msgtype = topics[which]
            writer.write_raw(topic, msgtype, log_time_ns, data[starts[number] : starts[number + 1]])
    return len(held.topic_index)


def encode_columns(held: HeldMessages) -> dict:
    """CPU s of encoding the held messages of each type :mod:`buoy_common.cdr_bulk` handles
    from their columns (decoded beforehand), ENCODE_CHUNK messages of a topic at a time, RUNS
    times, the fastest; and that they come out as they were."""
    raws_of = defaultdict(list)
    for number, which in enumerate(held.topic_index.tolist()):
        raws_of[held.topics[which]].append(held.data[held.starts[number] : held.starts[number + 1]])
    encoded_messages, cpu_s = 0, 0.0
    for (topic, msgtype), raws in raws_of.items():
        if not cdr_bulk.handles(msgtype):
            continue
        decoded = cdr_bulk.decode(msgtype, raws)
        if not decoded.valid.all():
            continue  # tf_static's several transforms: no columns of one transform hold them
        chunks = [
            {name: values[start : start + ENCODE_CHUNK] for name, values in decoded.columns.items()}
            for start in range(0, len(raws), ENCODE_CHUNK)
        ]
        best = float("inf")
        for _ in range(RUNS):
            started = time.process_time()
            encoded = [raw for chunk in chunks for raw in cdr_bulk.encode(msgtype, chunk)]
            best = min(best, time.process_time() - started)
        if encoded != raws:
            raise RuntimeError(f"{topic}: encoding the decoded columns changed the messages")
        encoded_messages += len(raws)
        cpu_s += best
    return {"messages": encoded_messages, "cpu_s": cpu_s}


# -- (c) process_bag ------------------------------------------------------------------------------


def run_process_bag(in_bag: Path, out_bag: Path) -> int:
    summary = process_bag(
        str(in_bag),
        str(out_bag),
        fusion_config_from_files(PROCESSING_PARAMS),
        compensator_config_from_files(PROCESSING_PARAMS),
        overwrite=True,
    )
    return sum(summary.topic_counts.values())


# -- the runs -------------------------------------------------------------------------------------


def _best(timings: list[Timing]) -> dict:
    best = min(timings, key=lambda timing: timing.wall_s)
    return {
        "wall_s": best.wall_s,
        "cpu_s": min(timing.cpu_s for timing in timings),
        "messages": best.messages,
        "wall_us_per_message": best.wall_s / best.messages * 1e6,
        "runs_wall_s": [timing.wall_s for timing in timings],
        "runs_cpu_s": [timing.cpu_s for timing in timings],
    }


def run_io_floor(in_bag: Path, work_dir: Path, runs: int = RUNS, log=lambda text: None) -> dict:
    """The floor's steps and ``process_bag`` on ``in_bag``, ``runs`` times each, alternating;
    outputs in ``work_dir``."""
    work_dir.mkdir(parents=True, exist_ok=True)
    processed, copy = work_dir / "process_bag", work_dir / "written"
    load_before = os.getloadavg()[0]
    timings: dict[str, list[Timing]] = defaultdict(list)
    held = None
    for run in range(1, runs + 1):
        os.sync()  # what the runs before wrote is not flushed during the timing
        log(f"bench: io_floor: run {run} of {runs}: process_bag on {in_bag.name}")
        timings["process_bag"].append(_timed(run_process_bag, in_bag, processed))
        if held is None:
            held = hold_messages(processed)
        log(f"bench: io_floor: run {run} of {runs}: reading and writing")
        for step in (read_only, read_in_columns, read_one_at_a_time):
            timings[step.__name__].append(_timed(step, in_bag))
        os.sync()
        timings["write"].append(_timed(write_held, held, copy))
    steps = {step: _best(step_timings) for step, step_timings in timings.items()}
    encoding = encode_columns(held)
    with BagReader(in_bag) as reader:
        data_s = reader.duration_s
    floor_s = steps["read_in_columns"]["wall_s"] + steps["write"]["wall_s"]
    floor_one_at_a_time_s = steps["read_one_at_a_time"]["wall_s"] + steps["write"]["wall_s"]
    return {
        "bag": str(in_bag),
        "data_s": data_s,
        "runs": runs,
        "cpus": os.cpu_count(),
        "interpreter": interpreter(),
        "load_average_1min_before": load_before,
        "load_average_1min_after": os.getloadavg()[0],
        **steps,
        "encode_columns": encoding,
        "floor_wall_s": floor_s,
        "floor_one_at_a_time_wall_s": floor_one_at_a_time_s,
        "process_bag_over_floor": steps["process_bag"]["wall_s"] / floor_s,
        "process_bag_over_floor_one_at_a_time": (
            steps["process_bag"]["wall_s"] / floor_one_at_a_time_s
        ),
    }


def print_io_floor(result: dict) -> None:
    print(
        f"\nI/O floor: {result['bag']} ({result['data_s']:.0f} s of data), best of "
        f"{result['runs']} runs (machine load average {result['load_average_1min_before']:.2f} "
        f"before, {result['load_average_1min_after']:.2f} after, {result['cpus']} CPUs)"
    )
    print(f"  on {describe(result['interpreter'])}")
    print(f"  {'step':44s} {'messages':>9s} {'wall s':>7s} {'CPU s':>7s} {'µs/msg':>7s}")
    labels = {
        "read_only": "(a0) read, not decoded",
        "read_in_columns": "(a) read, a chunk at a time into columns",
        "read_one_at_a_time": "(a') read, one at a time decoded by rosbags",
        "write": "(b) write process_bag's output messages",
        "process_bag": "(c) process_bag",
    }
    for step, label in labels.items():
        s = result[step]
        print(
            f"  {label:44s} {s['messages']:9d} {s['wall_s']:7.2f} {s['cpu_s']:7.2f} "
            f"{s['wall_us_per_message']:7.2f}"
        )
    encoding = result["encode_columns"]
    print(
        f"  encoding {encoding['messages']} of the output messages from columns: "
        f"{encoding['cpu_s']:.2f} CPU s ({encoding['cpu_s'] / encoding['messages'] * 1e6:.2f} µs "
        "a message; not in b)"
    )
    print(
        f"  floor a + b = {result['floor_wall_s']:.2f} s: process_bag takes "
        f"{result['process_bag_over_floor']:.1f}× the floor "
        f"({result['process_bag_over_floor_one_at_a_time']:.1f}× a' + b)"
    )


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("bag", nargs="?", default=str(REPO / "bags" / "open_ocean"))
    parser.add_argument("--runs", type=int, default=RUNS)
    arguments = parser.parse_args(argv)
    result = run_io_floor(
        Path(arguments.bag),
        OUT_DIR / "runs" / "io_floor",
        arguments.runs,
        lambda text: print(text, file=sys.stderr, flush=True),
    )
    print_io_floor(result)
    OUT_DIR.mkdir(parents=True, exist_ok=True)
    (OUT_DIR / "io_floor.json").write_text(json.dumps(result, indent=2))


if __name__ == "__main__":
    main()
