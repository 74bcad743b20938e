"""The live pipeline equals the offline one: a committed bag replayed over DDS to
``fusion_node`` and ``compensation_node`` gives, recorded by ``bag_recorder``, the
``nav/odometry`` and ``wind/true`` that ``process_bag`` writes for the same messages, and both
are as close to the simulator's truth as the sensors allow (two outputs broken the same way
would be equal too).

The first minute of ``sea_state`` (shipped geometry) and of ``off_axis`` (its own buoy, sensor
stamps that never line up), sensor topics and the anemometer cut by log time, is played at twice
its pace (:mod:`live_replay`). The same replay of faulted bags is the live half of the fault
matrix (``test_fault_matrix``).
"""

from __future__ import annotations

import bag_faults
import pytest
from live_replay import (
    SENSOR_TOPICS,
    assert_offline_run_is_near_the_truth,
    differences_from_offline,
    replay,
)

from buoy_nav.config import fusion_config_from_files
from processed_bags import CASES
from wind_comp.bag_processing import process_bag
from wind_comp.config import compensator_config_from_files

pytestmark = pytest.mark.ros

PLAYED_S = 60.0


@pytest.mark.parametrize("name", ["sea_state", "off_axis"])
def test_live_pipeline_equals_process_bag(nodes, tmp_path, name):
    parameter_files = CASES[name].parameter_files(tmp_path)
    played = tmp_path / "played"
    bag_faults.write_records(
        bag_faults.read_records(CASES[name].bag_path, SENSOR_TOPICS, PLAYED_S), played
    )
    offline = tmp_path / "offline"
    process_bag(
        played,
        offline,
        fusion_config_from_files(parameter_files),
        compensator_config_from_files(parameter_files),
    )
    assert_offline_run_is_near_the_truth(name, played, offline, f"{name}, first {PLAYED_S:g} s")
    recorded = tmp_path / "live"
    figures = replay(nodes, played, parameter_files, offline, recorded)
    differences = differences_from_offline(recorded, offline)
    assert not differences, "; ".join(differences) + f"; {figures}"
