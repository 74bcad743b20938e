"""An offline run leaves none of its own objects in reference cycles.

Python frees an object the moment nothing refers to it, unless it sits in a reference cycle (or
hangs off one): then it waits for the cyclic collector, which runs on counts of objects, not on
bytes, and rarely walks the oldest generation of a long-lived process. An archive's worker runs
bag after bag in one process; a cycle that held a bag's engine, pipeline or solution rows kept
them all until such a walk (a worker grew by some 10 MB a bag). So a run's objects must be freed
by reference counting alone: with the collector off, nothing of the suite's may be left that
only the collector can reclaim.
"""

from __future__ import annotations

import gc
from collections import Counter
from pathlib import Path

import pytest

from buoy_common.bag_io import BagReader, BagWriter
from buoy_nav.config import fusion_config_from_files
from buoy_processing.bag_processing import process_bag
from wind_comp.config import compensator_config_from_files

REPO = Path(__file__).resolve().parents[3]
SOURCE_BAG = REPO / "bags" / "open_ocean"
PARAMETERS = [
    str(REPO / "src/buoy_common/config/buoy.yaml"),
    str(REPO / "src/buoy_nav/config/fusion.yaml"),
]
SECONDS = 60.0
SUITE_PACKAGES = {"buoy_common", "buoy_nav", "buoy_processing", "wind_comp", "sensor_sim"}


@pytest.fixture(scope="module")
def minute_bag(tmp_path_factory) -> Path:
    """The first minute of ``open_ocean``: long enough to align and correct winds."""
    bag = tmp_path_factory.mktemp("cycles") / "minute"
    with BagReader(SOURCE_BAG) as reader, BagWriter(bag) as writer:
        end_ns = reader.start_ns + round(SECONDS * 1e9)
        for message in reader.messages():
            if message.log_time_ns >= end_ns:
                break
            writer.write_raw(message.topic, message.msgtype, message.log_time_ns, message.raw)
    return bag


def suite_objects_only_the_collector_frees(run) -> Counter:
    """The suite's objects, by type, that the second ``run()`` left for the cyclic collector:
    in a cycle, or reachable only from one. The first imports what a run imports on demand:
    an import can leave its own cycles holding the frames it ran in (matplotlib's parser
    keeps the exceptions it raised while loading), and with them the run that called it."""
    configs = (fusion_config_from_files(PARAMETERS), compensator_config_from_files(PARAMETERS))
    run(*configs)
    gc.collect()
    gc.disable()
    try:
        summary = run(*configs)
        del summary
        gc.set_debug(gc.DEBUG_SAVEALL)
        gc.collect()
        return Counter(
            type(thing).__qualname__
            for thing in gc.garbage
            if type(thing).__module__.split(".")[0] in SUITE_PACKAGES
        )
    finally:
        gc.set_debug(0)
        gc.garbage.clear()
        gc.enable()


@pytest.mark.parametrize(
    ("write_bag", "in_background"),
    [(False, False), (True, False), (True, True)],
    ids=["products only", "bag written here", "bag written by its own process"],
)
def test_an_offline_run_is_freed_without_the_collector(
    minute_bag, tmp_path, write_bag, in_background
):
    out = tmp_path / "processed"
    netcdf = tmp_path / "processed.nc"

    def run(fusion_config, compensator_config):
        summary = process_bag(
            minute_bag,
            out,
            fusion_config,
            compensator_config,
            netcdf_path=netcdf,
            write_bag=write_bag,
            write_in_background=in_background,
            say_statements=False,
            overwrite=True,
        )
        assert summary.wind.status_counts["valid"] > 0, "the run corrected winds"
        return summary

    left = suite_objects_only_the_collector_frees(run)
    assert not left, f"left in reference cycles: {dict(left)}"
