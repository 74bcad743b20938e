"""The simulated sensor nodes as separate processes over DDS: topics, rates, clean stops,
and equality with the offline generator (same scenario and seed give the same messages), for
the shipped buoy and for ``off_axis``'s (its own geometry, sensor stamps that never line up)."""

from __future__ import annotations

import itertools
import math
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from buoy_common.bag_io import BagReader
from buoy_common.parameters import load_parameter_files
from processed_bags import BAGS_DIR
from ros_messages import stamp_ns, wait_for
from sensor_sim.scenario import load_scenario

SCENARIO_S = 12.0
# Imports and DDS discovery of a node on a busy machine.
STARTUP_TIMEOUT_S = 30.0
RATES_HZ = {
    "imu/data_raw": 100.0,
    "gnss/fix": 10.0,
    "gnss/vel": 10.0,
    "gnss/heading": 10.0,
    "gnss/baseline": 10.0,
    "anemometer/wind": 20.0,
    "dvl/velocity": 1.0,
    "truth/odometry": 50.0,
    "truth/wind": 50.0,
    "truth/current": 50.0,
    "truth/water_velocity": 50.0,
}
CONTRACT_TYPES = {
    "imu/data_raw": "sensor_msgs/msg/Imu",
    "gnss/fix": "sensor_msgs/msg/NavSatFix",
    "gnss/vel": "geometry_msgs/msg/TwistWithCovarianceStamped",
    "gnss/heading": "sensor_msgs/msg/Imu",
    "gnss/baseline": "geometry_msgs/msg/Vector3Stamped",
    "anemometer/wind": "geometry_msgs/msg/Vector3Stamped",
    "dvl/velocity": "geometry_msgs/msg/TwistWithCovarianceStamped",
    "truth/odometry": "nav_msgs/msg/Odometry",
    "truth/wind": "geometry_msgs/msg/Vector3Stamped",
    "truth/current": "geometry_msgs/msg/Vector3Stamped",
    "truth/water_velocity": "geometry_msgs/msg/Vector3Stamped",
}
NODES = {
    "imu/data_raw": "imu_sim_node",
    "gnss/fix": "gnss_sim_node",
    "gnss/vel": "gnss_sim_node",
    "gnss/heading": "gnss_sim_node",
    "gnss/baseline": "gnss_sim_node",
    "anemometer/wind": "anemometer_sim_node",
    "dvl/velocity": "dvl_sim_node",
    "truth/odometry": "truth_node",
    "truth/wind": "truth_node",
    "truth/current": "truth_node",
    "truth/water_velocity": "truth_node",
}
START_NS = load_scenario("sea_state").start_time_ns
# The shipped buoy (the nodes' defaults) and off_axis's, given as a parameter file.
BUOYS = {"shipped": [], "off_axis": [BAGS_DIR / "off_axis.yaml"]}
FRAMES = {
    "imu/data_raw": "imu_link",
    "gnss/fix": "gnss_primary",
    "gnss/vel": "gnss_primary",
    "gnss/heading": "gnss_primary",
    "gnss/baseline": "map",
    "anemometer/wind": "anemometer_link",
    "dvl/velocity": "dvl_link",
    "truth/odometry": "map",
    "truth/wind": "map",
    "truth/current": "map",
    "truth/water_velocity": "map",
}


def messages_by_topic(bag_path):
    with BagReader(bag_path) as reader:
        result = {}
        for item in reader.messages():
            result.setdefault(item.topic.lstrip("/"), []).append(reader.decode(item))
        return result, {topic.lstrip("/"): info.msgtype for topic, info in reader.topics.items()}


# Numbers of a live and an offline message agree to round-off: the live nodes evaluate the
# models in whatever chunks the clock delivers, the generator in larger ones, and vectorised numpy
# sums differ in the last bit.
RELATIVE_TOLERANCE = 1e-12
ABSOLUTE_TOLERANCE = 1e-12


def same_message(a, b) -> bool:
    """Field-by-field equality of decoded messages, NaN == NaN, numbers to round-off.

    Arrays of numbers are compared whole and single numbers in Python, by np.isclose's rule:
    thousands of messages element by element through np.isclose take seconds.
    """
    if hasattr(a, "__dataclass_fields__"):
        return all(same_message(getattr(a, f), getattr(b, f)) for f in a.__dataclass_fields__)
    if isinstance(a, np.ndarray) and a.dtype.kind == "f":
        b = np.asarray(b)
        return a.shape == b.shape and bool(
            np.isclose(a, b, rtol=RELATIVE_TOLERANCE, atol=ABSOLUTE_TOLERANCE, equal_nan=True).all()
        )
    if isinstance(a, np.ndarray | list | tuple):
        return len(a) == len(b) and all(same_message(x, y) for x, y in zip(a, b, strict=True))
    if isinstance(a, float):
        return (
            a == b
            or (math.isfinite(b) and abs(a - b) <= ABSOLUTE_TOLERANCE + RELATIVE_TOLERANCE * abs(b))
            or (math.isnan(a) and math.isnan(b))
        )
    return a == b


# The off-axis buoy's live run is a long run (`make test-long`); the shipped geometry's is not.
@pytest.fixture(
    scope="module",
    params=[pytest.param(name, marks=[pytest.mark.long] * (name != "shipped")) for name in BUOYS],
)
def live_bag(request, tmp_path_factory, module_ros_env):
    """A short sea_state run recorded from the live nodes, its offline twin and the parameter
    files of the buoy."""
    folder = tmp_path_factory.mktemp(f"sim_{request.param}")
    parameters = [a for path in BUOYS[request.param] for a in ("--params-file", str(path))]
    overrides = ["--set", f"duration_s={SCENARIO_S}", "--seed", "7", *parameters]
    live, offline = record_live_and_offline(folder, "sea_state", overrides, module_ros_env)
    return live, offline, BUOYS[request.param]


def record_live_and_offline(folder: Path, scenario: str, arguments: list[str], env) -> tuple:
    """The scenario recorded from the live nodes and written by simulate_bag, with the same
    arguments: (live bag, offline bag)."""
    bin_dir = Path(sys.executable).parent
    # simulate_bag (a few seconds) runs while the live nodes start up, which takes longer; the
    # live stamps come from the simulation clock whatever the load.
    offline_log = folder / "simulate_bag.log"
    with open(offline_log, "w") as log:
        offline = subprocess.Popen(
            [str(bin_dir / "simulate_bag"), scenario, str(folder / "offline"), *arguments],
            stdout=log,
            stderr=subprocess.STDOUT,
        )
    try:
        live = subprocess.run(
            [
                str(bin_dir / "run_scenario"),
                scenario,
                *arguments,
                "--rate-factor",
                "4",
                "--record",
                str(folder / "live"),
                "--log-dir",
                str(folder / "logs"),
            ],
            env=env,
            capture_output=True,
            text=True,
            timeout=120,
        )
        offline.wait(timeout=120)
    finally:
        if offline.poll() is None:
            offline.kill()
            offline.wait()
    assert live.returncode == 0, live.stdout + live.stderr
    assert offline.returncode == 0, offline_log.read_text()
    return folder / "live", folder / "offline"


# The imperfections of real flux buoys' sensors: the lagging motion pack claiming a small σ and
# the uncalibrated magnetometer; one GNSS antenna at 1 Hz off the IMU grid on a mast, silent
# for 3 s.
SILENCE_S = (4.0, 7.0)
IMPERFECT = {
    "measured_moored_no_gnss": [],
    "set_e_imperfect": ["--set", f"sensors.gnss.silent_outages_s=[{list(SILENCE_S)}]"],
}


# The single antenna's live run is a long run; the lagging pack's and the uncalibrated
# magnetometer's is not (src/sensor_sim/test holds each imperfection offline).
@pytest.fixture(
    scope="module",
    params=[
        pytest.param(name, marks=[pytest.mark.long] * (name == "set_e_imperfect"))
        for name in IMPERFECT
    ],
)
def imperfect_bags(request, tmp_path_factory, module_ros_env):
    folder = tmp_path_factory.mktemp(f"sim_{request.param}")
    arguments = ["--set", f"duration_s={SCENARIO_S}", *IMPERFECT[request.param]]
    live, offline = record_live_and_offline(folder, request.param, arguments, module_ros_env)
    return live, offline, load_scenario(request.param)


def test_imperfect_sensors_live_equal_offline(imperfect_bags):
    live, _ = messages_by_topic(imperfect_bags[0])
    offline, _ = messages_by_topic(imperfect_bags[1])
    scenario = imperfect_bags[2]
    assert set(offline) <= set(live)
    for topic in offline:
        assert len(live[topic]) == len(offline[topic]), topic
        for a, b in zip(live[topic], offline[topic], strict=True):
            assert same_message(a, b), topic
    gnss_topics = {topic for topic in live if topic.startswith("gnss/")}
    if scenario.sensors.ahrs.fitted:
        assert gnss_topics == set()
        claimed = np.degrees(np.sqrt(live["imu/data"][0].orientation_covariance[0::4]))
        assert claimed == pytest.approx(scenario.sensors.ahrs.claimed_sigma_deg)
        assert len(live["imu/data"]) == len(live["imu/data_raw"])
        return
    assert gnss_topics == {"gnss/fix", "gnss/vel"}
    for topic in gnss_topics:
        seconds = [(stamp_ns(m) - START_NS) * 1e-9 for m in live[topic]]
        # 1 Hz at 0.31 s past the second, none inside the silence.
        offset_s = scenario.sensors.rates.gnss_offset_s
        samples_s = [offset_s + k for k in range(int(SCENARIO_S))]
        expected = [t for t in samples_s if not SILENCE_S[0] <= t < SILENCE_S[1]]
        assert seconds == pytest.approx(expected, abs=1e-9), topic


def test_live_nodes_publish_contract_topics_at_their_rates(live_bag):
    messages, types = messages_by_topic(live_bag[0])
    for topic, rate_hz in RATES_HZ.items():
        assert types[topic] == CONTRACT_TYPES[topic]
        stamps = [stamp_ns(m) for m in messages[topic]]
        offset_s = load_parameter_files(live_bag[2], NODES[topic]).get("time_offset_s", 0.0)
        # samples at t = offset + k / rate for 0 <= t <= duration
        assert len(stamps) == math.floor((SCENARIO_S - offset_s) * rate_hz + 1e-9) + 1, topic
        assert abs(stamps[0] - START_NS - offset_s * 1e9) < 1000, topic
        steps = {b - a for a, b in itertools.pairwise(stamps)}
        assert steps == {round(1e9 / rate_hz)}, topic
        assert {m.header.frame_id for m in messages[topic]} == {FRAMES[topic]}


def test_live_run_equals_offline_generation(live_bag):
    live, _ = messages_by_topic(live_bag[0])
    offline, _ = messages_by_topic(live_bag[1])
    assert set(offline) <= set(live)
    for topic in offline:
        assert len(live[topic]) == len(offline[topic]), topic
        # Same scenario, seed and parameters: every sample is the same message.
        for a, b in zip(live[topic], offline[topic], strict=True):
            assert same_message(a, b), topic


def test_imu_message_conventions(live_bag):
    messages, _ = messages_by_topic(live_bag[1])
    imu = messages["imu/data_raw"][0]
    assert imu.orientation_covariance[0] == -1.0
    # a floating buoy: specific force dominated by +g on body z (REP-145)
    assert 9.0 < imu.linear_acceleration.z < 10.6
    heading = messages["gnss/heading"][0]
    assert heading.angular_velocity_covariance[0] == -1.0
    assert heading.linear_acceleration_covariance[0] == -1.0
    assert heading.orientation_covariance[8] > 0.0
    assert heading.orientation.x == 0.0 and heading.orientation.y == 0.0


def test_dvl_message_conventions(live_bag):
    messages, _ = messages_by_topic(live_bag[1])
    dvl = messages["dvl/velocity"][0]
    covariance = np.reshape(dvl.twist.covariance, (6, 6))
    np.testing.assert_array_equal(covariance[:3, :3], 0.005**2 * np.eye(3))
    np.testing.assert_array_equal(np.diag(covariance)[3:], [-1.0, -1.0, -1.0])
    # The buoy drifts with the current: through the water it moves only with the waves.
    assert abs(dvl.twist.twist.linear.x) < 0.5


def test_dvl_node_refuses_a_platform_without_a_dvl(nodes):
    result = nodes.run("dvl_sim_node", "--ros-args", "-p", "scenario:=static", timeout_s=60)
    assert result.returncode != 0
    output = result.stdout + result.stderr
    assert "sensors.dvl" in output
    assert "Traceback" not in output


def test_sensor_node_stops_cleanly_on_sigint(nodes):
    process = nodes.start("imu_sim_node", "--ros-args", "-p", "scenario:=static")
    # Interrupted while Python still imports, any program prints a KeyboardInterrupt traceback:
    # the node is judged once it has started publishing.
    assert wait_for(lambda: "imu/data_raw at" in nodes.log_of(process), STARTUP_TIMEOUT_S), (
        nodes.log_of(process)
    )
    time.sleep(1.0)
    assert process.poll() is None, nodes.log_of(process)
    assert nodes.interrupt(process) == 0, nodes.log_of(process)
    assert "Traceback" not in nodes.log_of(process)


@pytest.mark.parametrize(
    ("arguments", "expected"),
    [
        (["-p", "scenario:=no_such_scenario"], "no_such_scenario"),
        (["-p", "rate_hz:=fast"], "rate_hz"),
        (["-p", "gnss.primary_antenna:=[1.0, 2.0]"], "gnss.primary_antenna"),
        (["--params-file", "/nonexistent/params.yaml"], "params.yaml"),
    ],
)
def test_bad_configuration_exits_with_a_named_error(nodes, arguments, expected):
    result = nodes.run("gnss_sim_node", "--ros-args", *arguments, timeout_s=60)
    assert result.returncode != 0
    output = result.stdout + result.stderr
    assert expected in output
    assert "Traceback" not in output
