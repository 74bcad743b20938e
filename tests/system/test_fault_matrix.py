"""The fault matrix, offline and live: see :mod:`fault_matrix` for the rows and what each demands.

Each group of faults is written into one bag. ``process_bag`` runs over it (offline), and the
same bag is replayed by ``bag_player`` to ``fusion_node`` and ``compensation_node`` whose
outputs ``bag_recorder`` records (live). Both must do what every row demands; live must equal
offline sample for sample. Rows that need the filter's integrity monitoring are expected to fail
until it exists.
"""

from __future__ import annotations

import time

import bag_faults as faults
import fault_matrix as matrix
import numpy as np
import pytest
from test_live_replay import DiagnosticsWatcher

from buoy_common.bag_io import BagReader
from ros_messages import wait_for

# The replay pace and latency budget of the live equality test (see test_live_replay).
RATE = 2.0
LATENCY_BUDGET_S = 120.0
STARTUP_TIMEOUT_S = 30.0
DRAIN_TIMEOUT_S = 30.0
FLUSH_TIMEOUT_S = 10.0


def _marks(group: matrix.FaultGroup) -> list:
    if group.awaiting is None:
        return []
    return [pytest.mark.xfail(strict=True, reason=group.awaiting)]


GROUP_PARAMETERS = [
    pytest.param(group, id=group.name.replace(" ", "_"), marks=_marks(group))
    for group in matrix.GROUPS
]


@pytest.fixture(scope="module")
def faulted_bags(tmp_path_factory):
    """Each group's bag, its records, and process_bag's outcome over it (computed once)."""
    made = {}

    def make(group: matrix.FaultGroup):
        if group.name not in made:
            folder = tmp_path_factory.mktemp(group.name.replace(" ", "_"))
            records = matrix.faulted_records(group)
            bag = folder / "faulted"
            faults.write_records(records, bag)
            made[group.name] = (bag, records, matrix.run_offline(bag, folder / "offline"))
        return made[group.name]

    return make


@pytest.mark.slow
@pytest.mark.parametrize("group", GROUP_PARAMETERS)
def test_offline_does_what_each_row_demands(group, faulted_bags):
    _, records, offline = faulted_bags(group)
    failures = matrix.offline_failures(group, records, offline)
    assert not failures, "\n".join(failures)


@pytest.mark.ros
@pytest.mark.slow
@pytest.mark.parametrize("group", GROUP_PARAMETERS)
def test_live_equals_offline(group, faulted_bags, nodes, tmp_path):
    bag, records, offline = faulted_bags(group)
    n_wind = matrix.wind_input_stamps_ns(records).size
    # samples after the last navigation wait for it until the node is interrupted
    n_held_back = int(np.count_nonzero(offline.wind_ns > offline.nav_ns[-1]))
    recorded = tmp_path / "live"
    parameters = ("--ros-args", "--params-file", str(matrix.BUOY_PARAMETERS))
    watcher = DiagnosticsWatcher(nodes.env)
    try:
        fusion = nodes.start("fusion_node", *parameters)
        compensation = nodes.start(
            "compensation_node",
            *parameters,
            "-p",
            f"compensation.nav_timeout_s:={LATENCY_BUDGET_S}",
        )
        recorder = nodes.start(
            "bag_recorder", str(recorded), "--topics", "nav/odometry", "wind/true"
        )
        assert wait_for(
            lambda: all(
                f"recording /{topic} (" in nodes.log_of(recorder)
                for topic in ("nav/odometry", "wind/true")
            ),
            STARTUP_TIMEOUT_S,
        ), nodes.log_of(recorder) + nodes.log_of(fusion) + nodes.log_of(compensation)
        with BagReader(bag) as reader:
            duration_s = reader.duration_s
        player = nodes.run(
            "bag_player",
            str(bag),
            "--rate",
            str(RATE),
            "--topics",
            *matrix.SENSOR_TOPICS,
            "--wait-for-subscribers",
            "1",
            timeout_s=STARTUP_TIMEOUT_S + duration_s / RATE * 3,
        )
        assert player.returncode == 0, player.stderr

        def recorded_count(topic: str) -> int:
            return watcher.value("bag_recorder", f"count[/{topic}]")

        wait_for(
            lambda: (
                recorded_count("nav/odometry") >= offline.nav_ns.size
                and recorded_count("wind/true") >= n_wind - n_held_back
            ),
            DRAIN_TIMEOUT_S,
        )
        assert nodes.interrupt(fusion) == 0, nodes.log_of(fusion)
        assert nodes.interrupt(compensation) == 0, nodes.log_of(compensation)
        wait_for(lambda: recorded_count("wind/true") >= n_wind, FLUSH_TIMEOUT_S)
        time.sleep(0.5)
        assert nodes.interrupt(recorder) == 0, nodes.log_of(recorder)
    finally:
        watcher.close()
    live = matrix.bag_outcome(recorded)
    failures: list[str] = []
    matrix.compare_live_to_offline(live, offline, failures)
    matrix.check_outputs(records, live, f"{group.name} live", failures)
    assert not failures, "\n".join(failures)
