"""CPU cost per message of the live wind correction's core, without ROS.

Replays a processed bag's ``nav/odometry``, ``nav/fix`` and ``anemometer/wind`` in log-time
order through what ``compensation_node`` runs per message (:mod:`wind_comp.compensation_messages`
to read the CDR bytes, :class:`wind_comp.pipeline.CompensationPipeline` asked after every
message, the outputs written as CDR bytes), and times each callback with the process's CPU
clock, which the neighbours of a shared machine disturb less than the wall clock. The figure of
each callback is its mean over the bag, the best of ``--runs`` runs. A bag without the
navigation (``bags/open_ocean``) is first processed by ``process_bag`` into a temporary
directory. ``--profile`` prints where the time of one run goes (cProfile) instead.

    python -m tools.bench_compensation_cost [BAG] [--runs 5] [--profile]
"""

from __future__ import annotations

import argparse
import cProfile
import json
import pstats
import sys
import tempfile
import time
from pathlib import Path

from buoy_common.bag_io import BagReader
from buoy_common.contract import NAV_FIX_TOPIC, NAV_ODOMETRY_TOPIC, WIND_RAW_TOPIC, bag_topic
from buoy_nav.config import fusion_config_from_files
from buoy_processing.bag_processing import process_bag
from wind_comp.compensation_messages import (
    anemometer_record,
    fix_record,
    flow_cdr,
    flows_with_covariance_cdr,
    odometry_record,
)
from wind_comp.config import compensator_config_from_files
from wind_comp.pipeline import wind_pipeline

REPO = Path(__file__).resolve().parents[1]
PARAMS_FILE = REPO / "src/buoy_common/config/buoy.yaml"
DEFAULT_BAG = REPO / "bags/open_ocean"
NAV_TIMEOUT_S = 1.0  # compensation.nav_timeout_s's default: the node's latency budget
TOPICS = [bag_topic(t) for t in (NAV_ODOMETRY_TOPIC, NAV_FIX_TOPIC, WIND_RAW_TOPIC)]


def messages_of(bag: Path) -> list[tuple[str, bytes]]:
    """(stored topic, CDR bytes) of the bag's navigation and wind, in log-time order."""
    with BagReader(bag) as reader:
        return [(m.topic, m.raw) for m in reader.messages(TOPICS)]


def processed(bag: Path, directory: Path) -> Path:
    """``bag`` when it holds ``nav/odometry``, else its ``process_bag`` output in ``directory``."""
    with BagReader(bag) as reader:
        if bag_topic(NAV_ODOMETRY_TOPIC) in reader.topics:
            return bag
    out = directory / "processed"
    files = [PARAMS_FILE]
    process_bag(bag, out, fusion_config_from_files(files), compensator_config_from_files(files))
    return out


def replay(messages: list[tuple[str, bytes]], config) -> dict[str, float]:
    """One run: mean CPU µs of an odometry and of a wind callback, and CPU ms per second of
    data (the wind at 20 Hz, the navigation at 100 Hz)."""
    pipeline = wind_pipeline(config)
    pending: list[tuple[int, int]] = []
    spent_s = {"odometry": 0.0, "wind": 0.0}
    counts = {"odometry": 0, "wind": 0}
    clock = time.process_time
    odometry_topic, fix_topic = TOPICS[0], TOPICS[1]

    def publish(output) -> None:
        samples = output.samples
        stamps = [pending.pop(0) for _ in range(len(samples))]
        secs, nanosecs = [s for s, _ in stamps], [n for _, n in stamps]
        flows_with_covariance_cdr(secs, nanosecs, samples.flow_enu_mps, samples.covariance.total)
        for (sec, nanosec), flow in zip(stamps, samples.flow_enu_mps.tolist(), strict=True):
            flow_cdr(sec, nanosec, flow)

    for topic, raw in messages:
        if topic == fix_topic:
            pipeline.add_fix(*fix_record(raw, None))
            continue
        started = clock()
        if topic == odometry_topic:
            pipeline.add_odometry(*odometry_record(raw, None))
            publish(pipeline.ready())
            kind = "odometry"
        else:
            sample, sec, nanosec = anemometer_record(raw, None, config.anemometer_frame_id)
            pipeline.add_sample(sample)
            pending.append((sec, nanosec))
            publish(pipeline.expire(pipeline.latest_sample_stamp_s - NAV_TIMEOUT_S))
            kind = "wind"
        spent_s[kind] += clock() - started
        counts[kind] += 1
    publish(pipeline.flush())
    per_message_us = {kind: 1e6 * spent_s[kind] / max(counts[kind], 1) for kind in spent_s}
    return {
        "odometry_us": per_message_us["odometry"],
        "wind_us": per_message_us["wind"],
        "cpu_ms_per_s_of_data": (100 * per_message_us["odometry"] + 20 * per_message_us["wind"])
        / 1000,
    }


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("bag", nargs="?", type=Path, default=DEFAULT_BAG)
    parser.add_argument("--runs", type=int, default=5)
    parser.add_argument("--profile", action="store_true")
    arguments = parser.parse_args(argv)
    config = compensator_config_from_files([PARAMS_FILE])
    with tempfile.TemporaryDirectory() as directory:
        messages = messages_of(processed(arguments.bag, Path(directory)))
    if arguments.profile:
        profile = cProfile.Profile()
        profile.runcall(replay, messages, config)
        pstats.Stats(profile, stream=sys.stdout).sort_stats("cumulative").print_stats(30)
        return
    runs = [replay(messages, config) for _ in range(arguments.runs)]
    best = {name: min(run[name] for run in runs) for name in runs[0]}
    print(json.dumps({"bag": str(arguments.bag), "best": best, "runs": runs}, indent=1))


if __name__ == "__main__":
    main()
