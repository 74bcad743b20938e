"""current_node as a real process over DDS, fed a perfect navigation from simulation truth and
the simulator's DVL.

The simulated DVL here has no errors, so ``current/velocity`` must be the water's velocity at
the DVL (``truth/water_velocity``: the current plus the waves' orbital velocity at its depth),
which the simulator computes with its own code. A few DVL samples are made bad on purpose: a
ping flagged invalid (NaN), a velocity beyond any DVL's range, another frame, a repeated stamp.
"""

from __future__ import annotations

import math
import os
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import numpy as np
import pytest
import rclpy
from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import TwistWithCovarianceStamped, Vector3Stamped
from nav_msgs.msg import Odometry
from rclpy.context import Context
from rclpy.executors import SingleThreadedExecutor
from scipy.spatial.transform import Rotation
from sensor_msgs.msg import NavSatFix, NavSatStatus
from std_msgs.msg import Float64MultiArray

from buoy_common.bag_io import BagReader
from buoy_common.base_node import DATA_QOS
from ros_messages import reports_publishers_on, stamp_ns, to_rclpy, wait_for
from sensor_sim.geodesy import EARTH_RATE_RAD_S
from wind_comp.compensation_messages import dvl_sample, fix_fields, odometry_fields, stats_values
from wind_comp.compensator import SampleStatus
from wind_comp.config import CURRENT_NODE_NAME, CurrentConfig
from wind_comp.pipeline import current_pipeline

pytestmark = pytest.mark.ros

# sea_state starts on a whole minute and its DVL samples once a second: the first minute's
# window is full (60 samples, for the products' test) and the second one closes at SIGINT.
SCENARIO_S = 65.0
LATITUDE_DEG = 35.0  # sea_state starts at 35 N
PLAY_RATE = 10.0
# A sample whose stamp repeats the one before is left out of its minute's window: it comes
# after the first minute, which stays full.
NAN_INDEX, FAST_INDEX, WRONG_FRAME_INDEX, REPEATED_INDEX = 20, 30, 40, 62
BAD = {NAN_INDEX, FAST_INDEX, WRONG_FRAME_INDEX, REPEATED_INDEX}
MINUTE_NS = 60 * 1_000_000_000


def simulated_scenario(folder: Path):
    """DVL and odometry messages to publish, the fix, and the simulator's water velocity at the
    DVL by stamp."""
    bag = folder / "sim"
    error_free_dvl = [
        "sensors.dvl.scale_factor_error_percent=0",
        "sensors.dvl.bias_mps=[0, 0, 0]",
        "sensors.dvl.noise_mps=0",
        "sensors.dvl.ping_loss_probability=0",
    ]
    overrides = [item for setting in error_free_dvl for item in ("--set", setting)]
    simulated = subprocess.run(
        [
            str(Path(sys.executable).parent / "simulate_bag"),
            "sea_state",
            str(bag),
            "--set",
            f"duration_s={SCENARIO_S}",
            *overrides,
            "--seed",
            "3",
        ],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert simulated.returncode == 0, simulated.stderr
    samples, odometries, water = [], [], {}
    with BagReader(bag) as reader:
        topics = ["dvl/velocity", "truth/odometry", "truth/water_velocity"]
        for record in reader.messages(topics):
            message = reader.decode(record)
            if record.topic.endswith("dvl/velocity"):
                samples.append(to_rclpy(message, TwistWithCovarianceStamped()))
            elif record.topic.endswith("truth/odometry"):
                odometries.append(to_rclpy(message, Odometry()))
            else:
                water[stamp_ns(message)] = np.array(
                    [message.vector.x, message.vector.y, message.vector.z]
                )
    # A gyro senses the Earth's rotation too: ω_ib = ω_nb + R_nb^T ω_ie^n.
    earth_rate_enu = EARTH_RATE_RAD_S * np.array(
        [0.0, math.cos(math.radians(LATITUDE_DEG)), math.sin(math.radians(LATITUDE_DEG))]
    )
    for odometry in odometries:
        q = odometry.pose.pose.orientation
        rate = odometry.twist.twist.angular
        sensed = np.array([rate.x, rate.y, rate.z]) + Rotation.from_quat(
            [q.x, q.y, q.z, q.w]
        ).inv().apply(earth_rate_enu)
        rate.x, rate.y, rate.z = sensed.tolist()

    samples[NAN_INDEX].twist.twist.linear.x = math.nan
    samples[FAST_INDEX].twist.twist.linear.x = 25.0
    samples[WRONG_FRAME_INDEX].header.frame_id = "base_link"
    samples[REPEATED_INDEX].header.stamp = samples[REPEATED_INDEX - 1].header.stamp

    fix = NavSatFix()
    fix.header.stamp = odometries[0].header.stamp
    fix.status.status = NavSatStatus.STATUS_FIX
    fix.latitude, fix.longitude = LATITUDE_DEG, 120.0
    return samples, odometries, fix, water


OUTPUT_TOPICS = {
    "current/velocity": Vector3Stamped,
    "current/mean_1min": Vector3Stamped,
    "current/stats_1min": Float64MultiArray,
}


class Listener:
    """An in-process DDS participant in the test's isolated domain."""

    def __init__(self, env: dict[str, str]):
        for name in ("ROS_DOMAIN_ID", "ROS_AUTOMATIC_DISCOVERY_RANGE"):
            os.environ[name] = env[name]
        self.context = Context()
        rclpy.init(context=self.context)
        self.node = rclpy.create_node("current_test", context=self.context)
        self.received = {topic: [] for topic in OUTPUT_TOPICS}
        for topic, message_type in OUTPUT_TOPICS.items():
            self.node.create_subscription(
                message_type, topic, self.received[topic].append, DATA_QOS
            )
        self.diagnostics = []
        self.node.create_subscription(DiagnosticArray, "diagnostics", self.diagnostics.append, 10)
        self.dvl = self.node.create_publisher(TwistWithCovarianceStamped, "dvl/velocity", DATA_QOS)
        self.odometry = self.node.create_publisher(Odometry, "nav/odometry", DATA_QOS)
        self.fix = self.node.create_publisher(NavSatFix, "nav/fix", DATA_QOS)
        self.executor = SingleThreadedExecutor(context=self.context)
        self.executor.add_node(self.node)
        self.thread = threading.Thread(target=self.executor.spin, daemon=True)
        self.thread.start()

    def node_status(self):
        statuses = [
            s for a in self.diagnostics for s in a.status if s.hardware_id == CURRENT_NODE_NAME
        ]
        return statuses[-1] if statuses else None

    def close(self):
        self.executor.shutdown()
        self.node.destroy_node()
        rclpy.try_shutdown(context=self.context)
        self.thread.join(timeout=5.0)


@pytest.fixture(scope="module")
def live_run(module_ros_env, tmp_path_factory):
    """Run current_node on the scenario; returns the scenario, what the node published and its
    exit code."""
    log_path = tmp_path_factory.mktemp("current_logs") / "current_node.log"
    listener = Listener(module_ros_env)
    with open(log_path, "w") as log:
        process = subprocess.Popen(
            [str(Path(sys.executable).parent / "current_node")],
            env=module_ros_env,
            stdout=log,
            stderr=subprocess.STDOUT,
            start_new_session=True,
        )
    try:
        # The node starts (seconds of imports and discovery) while the scenario is simulated.
        scenario = simulated_scenario(tmp_path_factory.mktemp("current"))
        samples, odometries, fix, _ = scenario
        assert wait_for(
            lambda: (
                listener.node.count_publishers("current/velocity") > 0
                and listener.node_status() is not None
                and reports_publishers_on(
                    listener.node_status(), ("dvl/velocity", "nav/odometry", "nav/fix")
                )
            ),
            timeout_s=20.0,
        ), log_path.read_text()
        listener.fix.publish(fix)
        time.sleep(0.3)  # the latitude must be in before the first navigation sample
        inputs = sorted(
            [(stamp_ns(m), 1, listener.dvl, m) for m in samples]
            + [(stamp_ns(m), 0, listener.odometry, m) for m in odometries],
            key=lambda row: row[:2],
        )
        start_wall_s, first_ns = time.monotonic(), inputs[0][0]
        for time_ns, _, publisher, message in inputs:
            delay_s = (time_ns - first_ns) * 1e-9 / PLAY_RATE - (time.monotonic() - start_wall_s)
            if delay_s > 0:
                time.sleep(delay_s)
            publisher.publish(message)
        # The last DVL sample shares its stamp with the last odometry: all are answered.
        wait_for(lambda: len(listener.received["current/velocity"]) >= len(samples), 10.0)
        n_diagnostics = len(listener.diagnostics)
        wait_for(lambda: len(listener.diagnostics) > n_diagnostics, 5.0)
        status = listener.node_status()
        process.send_signal(signal.SIGINT)
        exit_code = process.wait(timeout=15.0)
        # A minute's window closes with the first sample after it, the last one at SIGINT.
        n_minutes = len({stamp_ns(m) // MINUTE_NS for m in samples})
        wait_for(lambda: len(listener.received["current/stats_1min"]) >= n_minutes, 5.0)
        return {
            "scenario": scenario,
            "exit_code": exit_code,
            "log": log_path.read_text(),
            "diagnostics": {kv.key: kv.value for kv in status.values},
            **{topic: list(messages) for topic, messages in listener.received.items()},
        }
    finally:
        if process.poll() is None:
            process.kill()
            process.wait()
        listener.close()


@pytest.fixture(scope="module")
def scenario(live_run):
    """The messages the live run published to the node and the simulator's water velocity
    (:func:`simulated_scenario`)."""
    return live_run["scenario"]


def vectors(messages) -> np.ndarray:
    return np.array([[m.vector.x, m.vector.y, m.vector.z] for m in messages])


def test_one_output_per_dvl_sample_with_its_stamp(scenario, live_run):
    samples = scenario[0]
    outputs = live_run["current/velocity"]
    assert live_run["exit_code"] == 0, live_run["log"]
    assert [stamp_ns(m) for m in outputs] == [stamp_ns(m) for m in samples]
    assert {m.header.frame_id for m in outputs} == {"map"}


def test_current_is_the_water_velocity_the_simulator_put_at_the_dvl(scenario, live_run):
    samples, _, _, water = scenario
    current = vectors(live_run["current/velocity"])
    good = [i for i in range(len(samples)) if i not in BAD]
    truth = np.array([water[stamp_ns(samples[i])] for i in good])
    # Error-free DVL and navigation: what remains is the latitude of one fix for the whole
    # drift in the Earth's rate (< 1e-9 m/s) and round-off.
    np.testing.assert_allclose(current[good], truth, atol=1e-8)
    # The buoy drifts with the current: the DVL's own reading is only the motion through it.
    readings = np.array([[m.twist.twist.linear.x, m.twist.twist.linear.y, 0.0] for m in samples])
    assert np.max(np.abs(readings[good, :2] + truth[:, :2])) > 0.05


def test_bad_samples_give_nan_and_are_counted_by_reason(live_run):
    current = vectors(live_run["current/velocity"])
    for index in range(len(current)):
        assert np.isnan(current[index]).all() == (index in BAD), index
    values = live_run["diagnostics"]
    assert values["invalid[invalid_dvl]"] == "2"
    assert values["invalid[dvl_speed_out_of_range]"] == "1"
    assert values["invalid[invalid_stamp]"] == "1"
    assert values["rejected[dvl/velocity: non_finite]"] == "1"
    assert values["rejected[dvl/velocity: wrong_frame]"] == "1"
    assert values["rejected[dvl/velocity: stamp_not_increasing]"] == "1"


def test_live_output_equals_the_pipeline_run_offline(scenario, live_run):
    samples, odometries, fix, _ = scenario
    pipeline = current_pipeline(CurrentConfig())
    assert pipeline.add_fix(*fix_fields(fix)) is None
    in_stamp_order = sorted(
        [(stamp_ns(m), 0, k) for k, m in enumerate(odometries)]
        + [(stamp_ns(m), 1, k) for k, m in enumerate(samples)]
    )
    for _, is_dvl, k in in_stamp_order:
        if is_dvl:
            pipeline.add_sample(dvl_sample(samples[k]))
        else:
            assert pipeline.add_odometry(*odometry_fields(odometries[k])) is None
    batch = pipeline.flush().samples
    np.testing.assert_array_equal(vectors(live_run["current/velocity"]), batch.flow_enu_mps)
    assert batch.counts()[SampleStatus.VALID] == len(samples) - len(BAD)


def test_one_minute_products_with_the_direction_the_water_goes(live_run):
    current = vectors(live_run["current/velocity"])
    stamps = np.array([stamp_ns(m) * 1e-9 for m in live_run["current/velocity"]])
    full = [
        (mean, stats_values(stats))
        for mean, stats in zip(
            live_run["current/mean_1min"], live_run["current/stats_1min"], strict=True
        )
        if stats_values(stats)["n_valid"] + stats_values(stats)["n_invalid"] == 60
    ]
    assert full
    for mean, stats in full:
        inside = (stamps >= stats["window_start_s"]) & (stamps < stats["window_end_s"])
        valid = inside & ~np.isnan(current).any(axis=1)
        assert stats["n_valid"] == np.count_nonzero(valid)
        expected = current[valid].mean(axis=0)
        np.testing.assert_allclose(vectors([mean])[0], expected, atol=1e-12)
        assert stats["speed_mps"] == pytest.approx(math.hypot(*expected[:2]), abs=1e-12)
        toward = math.degrees(math.atan2(expected[0], expected[1])) % 360.0
        assert stats["direction_deg"] == pytest.approx(toward, abs=1e-9)
        # sea_state: 0.15 m/s toward 60° plus a tide toward 150°: between the two.
        assert 60.0 < stats["direction_deg"] < 150.0
