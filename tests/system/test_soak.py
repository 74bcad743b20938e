"""A short soak: 20 simulated seconds of the soak's default sensor set through the live nodes at
twice real time, every anemometer sample out once on ``wind/true`` and once on
``wind/true_with_covariance`` (the two hours are the opt-in ``soak`` section of
``tools/bench.py``, tools/soak.py).
How many come out corrected depends on how busy the machine is (a sample whose navigation is
later than the latency budget is published invalid): the figures, not this test, say it.
The samples before the first complete one the soak's listener sees are judged apart: DDS gives a
message only to the subscriptions matched when it is sent, so a busy machine may let the
simulation start a moment before every subscriber has joined; no more than a second of them
may go so."""

from __future__ import annotations

import json
import subprocess
import sys
import time
from pathlib import Path

import pytest

from sensor_sim.scenario import load_scenario
from tools.ros_domains import release_domain
from tools.soak import (
    DEFAULT_SETUP,
    DISCOVERY_S,
    LISTENER_NODE,
    OUTPUT_TOPICS,
    SETUPS,
    TOPICS,
    listener_in_a_quiet_domain,
)

pytestmark = [pytest.mark.ros, pytest.mark.long]

REPO = Path(__file__).resolve().parents[2]
SIMULATED_S = 20.0  # the alignment, then corrected wind
SIMULATED_HOURS = SIMULATED_S / 3600.0
RATE_FACTOR = 2.0


def anemometer_rate_hz() -> float:
    setup = SETUPS[DEFAULT_SETUP]
    scenario = load_scenario(setup.case.scenario, setup.overrides(SIMULATED_S), None)
    return scenario.sensors.rates.anemometer_hz


def test_short_soak_loses_no_sample(tmp_path, ros_env):
    figures = tmp_path / "soak.json"
    result = subprocess.run(
        [
            sys.executable,
            "-m",
            "tools.soak",
            "--hours",
            str(SIMULATED_HOURS),
            "--rate-factor",
            str(RATE_FACTOR),
            "--rss-period-s",
            "1",
            "--json",
            str(figures),
        ],
        env=ros_env,
        cwd=REPO,
        capture_output=True,
        text=True,
        timeout=600,
    )
    assert result.returncode == 0, result.stdout + result.stderr
    soak = json.loads(figures.read_text())
    counts = soak["counts"]
    for topic in TOPICS:
        assert counts[f"{topic} missing"] == 0, counts
        assert counts[f"{topic} twice"] == 0, counts
    assert soak["verdict"]["nothing_lost"], soak["verdict"]
    rate_hz = anemometer_rate_hz()
    before_first = [
        counts[f"before the first complete sample: {topic} missing"] for topic in TOPICS
    ]
    assert max(before_first) <= rate_hz * 1.0, counts
    # Each topic's samples and the stamps it missed add up to every stamp the listener saw.
    stamps = {
        counts[f"{topic} in"] + before for topic, before in zip(TOPICS, before_first, strict=True)
    }
    assert len(stamps) == 1, counts
    complete = min(counts[f"{topic} in"] for topic in TOPICS)
    assert complete >= 0.95 * SIMULATED_S * rate_hz, counts
    # The contract: the wind with covariance is NaN exactly where wind/true is (up to the
    # samples one of them missed before the first complete one).
    valid = [counts[f"{topic} valid"] for topic in OUTPUT_TOPICS]
    assert abs(valid[0] - valid[1]) <= max(before_first), counts


def test_nodes_of_another_run_in_the_soak_domain_are_seen(monkeypatch):
    """Another buoy's simulation in the soak's domain would mix its samples into the counts:
    its nodes, and a second node of one of the soak's own names, are reported."""
    import rclpy
    from rclpy.context import Context

    # The soak sets its domain in this process's environment: given back after the test.
    for name in ("ROS_DOMAIN_ID", "ROS_AUTOMATIC_DISCOVERY_RANGE", "ROS_LOCALHOST_ONLY"):
        monkeypatch.delenv(name, raising=False)
    listener, domain = listener_in_a_quiet_domain()
    context = Context()
    rclpy.init(context=context)
    try:
        assert listener.intruders({LISTENER_NODE}) == []
        nodes = [
            rclpy.create_node(name, context=context)
            for name in ("anemometer_sim_node", "anemometer_sim_node", "other_buoy")
        ]
        time.sleep(DISCOVERY_S)
        own = {LISTENER_NODE, "anemometer_sim_node"}
        assert listener.intruders(own) == ["anemometer_sim_node", "other_buoy"]
        for node in nodes:
            node.destroy_node()
    finally:
        rclpy.try_shutdown(context=context)
        listener.close()
        release_domain(domain)
