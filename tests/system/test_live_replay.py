"""The live pipeline equals the offline one: a committed bag replayed over DDS to
``fusion_node`` and ``compensation_node`` gives, recorded by ``bag_recorder``, the
``nav/odometry`` and ``wind/true`` that ``process_bag`` writes for the same messages, and both
are as close to the simulator's truth as the sensors allow (two outputs broken the same way
would be equal too). Likewise ``current_node`` and ``current/velocity`` for a bag with a DVL.

The first minute of ``sea_state`` (shipped geometry) and of ``off_axis`` (its own buoy, sensor
stamps that never line up), sensor topics and the anemometer cut by log time, is played at twice
its pace (:mod:`live_replay`); and a minute of ``sea_state`` with its DVL written by
``simulate_bag`` (the committed bags carry no DVL). The eddy-covariance fluxes alike, over
windows of 20 s, with a sonic temperature added to the first 50 s of ``sea_state``. The same
replay of faulted bags is the live half of the fault matrix (``test_fault_matrix``).
"""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import bag_faults
import numpy as np
import pytest
from live_replay import (
    CURRENT,
    SENSOR_TOPICS,
    assert_offline_run_is_near_the_truth,
    differences_from_offline,
    flux_window_parameters,
    process_offline,
    replay,
    started_pipeline,
    vector_arrays,
)

from buoy_common.bag_io import BagReader
from buoy_common.contract import wind_fluxes_topic
from processed_bags import CASES
from wind_comp.compensation_messages import FLUX_FIELDS

pytestmark = pytest.mark.ros

REPO = Path(__file__).resolve().parents[2]
BUOY_PARAMETERS = REPO / "src" / "buoy_common" / "config" / "buoy.yaml"
PLAYED_S = 60.0


# Long runs: in `make test`, the fluxes' replay below holds the live navigation and wind equal
# to process_bag's on the same minute of sea_state.
@pytest.mark.long
@pytest.mark.parametrize("name", ["sea_state", "off_axis"])
def test_live_pipeline_equals_process_bag(nodes, tmp_path, name):
    parameter_files = CASES[name].parameter_files(tmp_path)
    played = tmp_path / "played"
    bag_faults.write_records(
        bag_faults.read_records(CASES[name].bag_path, SENSOR_TOPICS, PLAYED_S), played
    )
    offline = tmp_path / "offline"
    process_offline(played, offline, parameter_files)
    assert_offline_run_is_near_the_truth(name, played, offline, f"{name}, first {PLAYED_S:g} s")
    recorded = tmp_path / "live"
    figures = replay(nodes, played, parameter_files, offline, recorded)
    differences = differences_from_offline(recorded, offline)
    assert not differences, "; ".join(differences) + f"; {figures}"


FLUX_WINDOW_S = 20.0
# Three flux windows, the first before the fusion's alignment (at 10 s) and the last a half
# one, which the nodes publish at SIGINT as process_bag does at the end of its data; and 400
# corrected winds to judge against the truth (at least 300 needed).
FLUX_PLAYED_S = 50.0


def flux_rows(bag: Path) -> list[list[float]]:
    with BagReader(bag) as reader:
        return [
            list(reader.decode(message).data)
            for message in reader.messages([wind_fluxes_topic(FLUX_WINDOW_S)])
        ]


def test_live_fluxes_equal_process_bag(nodes, tmp_path):
    parameter_files = CASES["sea_state"].parameter_files(tmp_path)
    parameter_files = [*parameter_files, flux_window_parameters(tmp_path, FLUX_WINDOW_S)]
    recorded = tmp_path / "live"
    also_recorded = (wind_fluxes_topic(FLUX_WINDOW_S),)
    # The nodes start (seconds of imports and discovery) while the reference is computed.
    with started_pipeline(nodes, parameter_files, recorded, also_recorded=also_recorded) as live:
        played = tmp_path / "played"
        records = bag_faults.read_records(CASES["sea_state"].bag_path, SENSOR_TOPICS, FLUX_PLAYED_S)
        bag_faults.write_records(bag_faults.with_sonic_temperature(records), played)
        offline = tmp_path / "offline"
        process_offline(played, offline, parameter_files)
        assert_offline_run_is_near_the_truth(
            "sea_state", played, offline, f"sea_state with temperature, first {FLUX_PLAYED_S:g} s"
        )
        offline_fluxes = flux_rows(offline)
        assert len(offline_fluxes) >= 3
        n_temperature = FLUX_FIELDS.index("n_temperature")
        assert all(row[n_temperature] > 0 for row in offline_fluxes)
        figures = live.replay(played, offline)
    assert not differences_from_offline(recorded, offline), figures
    live_fluxes = flux_rows(recorded)
    assert len(live_fluxes) == len(offline_fluxes), figures
    np.testing.assert_allclose(live_fluxes, offline_fluxes, rtol=0, atol=1e-9)


@pytest.mark.long
def test_live_current_equals_process_bag(nodes, tmp_path):
    simulated = tmp_path / "simulated"
    result = subprocess.run(
        [
            str(Path(sys.executable).parent / "simulate_bag"),
            "sea_state",
            str(simulated),
            "--set",
            f"duration_s={PLAYED_S}",
            "--params-file",
            str(BUOY_PARAMETERS),
            "--no-truth",
        ],
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert result.returncode == 0, result.stderr
    played = tmp_path / "played"
    wanted = {topic.lstrip("/") for topic in CURRENT.sensor_topics}
    with BagReader(simulated) as reader:
        # simulate_bag names its topics without the leading slash the recorder writes
        topics = [name for name in reader.topics if name.lstrip("/") in wanted]
    bag_faults.write_records(bag_faults.read_records(simulated, topics, PLAYED_S), played)
    parameter_files = [BUOY_PARAMETERS]
    offline = tmp_path / "offline"
    process_offline(played, offline, parameter_files, current=True)
    _, offline_current = vector_arrays(offline, CURRENT.output_topic)
    n_valid = int(np.count_nonzero(np.isfinite(offline_current).all(axis=1)))
    assert n_valid > 0.5 * len(offline_current), f"{n_valid} of {len(offline_current)} valid"
    recorded = tmp_path / "live"
    figures = replay(nodes, played, parameter_files, offline, recorded, correction=CURRENT)
    differences = differences_from_offline(recorded, offline, CURRENT)
    assert not differences, "; ".join(differences) + f"; {figures}"
