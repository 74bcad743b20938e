"""fusion_node over DDS on a moored buoy whose gyro wanders more than the fusion is told.

The FDCHP-like moored buoy of ``test_moored_gyro_wander`` (a motion pack at 10 Hz, no GNSS,
its gyro bias wandering by 150 °/h while the fusion keeps its default gyro model) is fed to a
live ``fusion_node`` and to a FusionEngine offline, both configured from one parameter file.
Within the first four minutes the blocks' mean velocity (:mod:`buoy_nav.mean_velocity_watch`)
widens the gyro's drift, first at about 160 s: the node must publish exactly the offline
solutions across the widening (it changes the filter's process noise and raises its
covariance, so any difference in when the node does it shows in every later solution), log the
mooring's warnings at the offline stamps, and hold the same warning in its diagnostics.
"""

from __future__ import annotations

from collections import Counter
from pathlib import Path

import pytest
from test_fusion_node import (
    NODE,
    Listener,
    assert_same_messages,
    config_from_files,
    nav_messages,
    received_count,
    solution_stamps_ns,
)
from test_moored_gyro_wander import FDCHP_LIKE_MOORED_BUOY, fdchp_like_config
from test_nav_sensor_sets import scenario_messages

from buoy_common.contract import NAV_MSGTYPES, NAV_ODOMETRY_TOPIC
from buoy_nav.engine import FusionEngine
from buoy_nav.fusion_messages import FUSION_INPUT_MSGTYPES, StampBook, feed_message
from buoy_nav.health import diagnostic_values
from buoy_nav.source_health import HealthChange
from ros_messages import stamp_ns, wait_for

pytestmark = [pytest.mark.ros, pytest.mark.long]

DURATION_S = 240.0
"""Simulated time (s): the drift is widened at about 160 s and again at about 220 s."""
REPLAY_RATE = 10.0
"""Times real time: the buoy's two 10 Hz topics then carry fewer messages a second than a
simulated bag's 100 Hz IMU at the usual replay rate."""
WIDENED = "drift widened"


def fdchp_like_parameters(path: Path, latitude_deg: float, longitude_deg: float) -> Path:
    """A parameter file at ``path`` for the FDCHP-like moored buoy at the site (deg)."""
    path.write_text(
        "/**:\n  ros__parameters:\n"
        f"    site.latitude_deg: {latitude_deg}\n"
        f"    site.longitude_deg: {longitude_deg}\n"
        "    ahrs.yaw_reference: magnetic_north\n"
        "    fusion.moored: true\n"
        "    fusion.ahrs_lag_s: 0.2\n"
    )
    return path


def test_live_node_widens_the_gyro_drift_as_the_offline_fusion_does(nodes, tmp_path):
    scenario, _, messages = scenario_messages("open_ocean", DURATION_S, FDCHP_LIKE_MOORED_BUOY)
    stream = [(topic, m) for topic, _, m in messages if topic in FUSION_INPUT_MSGTYPES]
    parameters = fdchp_like_parameters(
        tmp_path / "fdchp_like.yaml",
        scenario.origin_latitude_deg,
        scenario.origin_longitude_deg,
    )
    config = config_from_files([parameters])
    assert config == fdchp_like_config()

    engine = FusionEngine(config)
    offline = {topic: [] for topic in NAV_MSGTYPES}
    stamps = StampBook()
    for topic, message in stream:
        nav_messages(feed_message(engine, topic, message, stamps)[0], offline, stamps)
    widenings = [
        transition
        for transition in engine.take_source_transitions()
        if transition.change is HealthChange.WARNED and WIDENED in transition.message
    ]
    assert widenings
    offline_warning = diagnostic_values(engine.health())["moored.warning"]
    assert WIDENED in offline_warning
    n_solutions = len(offline[NAV_ODOMETRY_TOPIC])
    widened_ns = round(widenings[0].t_s * 1e9)
    assert sum(stamp_ns(m) > widened_ns for m in offline[NAV_ODOMETRY_TOPIC]) > 100

    listener = Listener(nodes.env)
    try:
        process = nodes.start(NODE, "--ros-args", "--params-file", str(parameters))
        assert listener.wait_for_node(), nodes.log_of(process)
        assert {topic for topic, _ in stream} <= set(listener.node_inputs())
        listener.play(
            [(stamp_ns(m), topic, m) for topic, m in stream],
            solution_stamps_ns(offline),
            REPLAY_RATE,
        )
        wait_for(lambda: received_count(listener) >= n_solutions, 20.0)
        counts = Counter(topic for topic, _ in stream)
        final = listener.latest_diagnostics_where(
            lambda values: all(
                values.get(f"messages_in[{topic}]") == str(count) for topic, count in counts.items()
            ),
            5.0,
        )
        live = listener.received()
        assert nodes.interrupt(process) == 0, nodes.log_of(process)
    finally:
        listener.close()

    largest_relative_difference = assert_same_messages(live, offline)
    print(f"{n_solutions} solutions, largest relative difference {largest_relative_difference:g}")
    assert final is not None, nodes.log_of(process)
    assert final["moored.warning"] == offline_warning
    log = nodes.log_of(process)
    for widening in widenings:
        assert f"stamp {widening.t_s:.3f} s: {widening.message}" in log, log
