"""compensation_node as a real process over DDS, fed a perfect navigation from simulation truth.

The test process publishes ``nav/fix``, ``nav/odometry`` (the simulator's true attitude, body
velocity and body rate, with the Earth's rotation added as a gyro would sense it) and the
simulated ``anemometer/wind``, a few of them deliberately malformed, and listens to
``wind/true``, ``wind/true_with_covariance``, the 1-minute products and ``diagnostics``. The
odometry states covariances that change from message to message, so that the covariance the
node publishes depends on each one. The buoy is ``off_axis``'s (an
anemometer off the mast axis and turned about all three axes, stamped apart from the IMU), so
each term of the correction and the mounting rotation matter; with a perfect navigation the
corrected wind is the true wind plus the anemometer's noise.
"""

from __future__ import annotations

import math
import os
import signal
import subprocess
import sys
import threading
import time
from datetime import datetime
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
from error_budget import ANEMOMETER, noise_rms_bound
from processed_bags import CASES
from ros_messages import reports_publishers_on, stamp_ns, to_rclpy, wait_for
from sensor_sim.geodesy import EARTH_RATE_RAD_S
from wind_comp.compensation_messages import (
    MalformedMessageError,
    anemometer_sample,
    fix_fields,
    odometry_fields,
    stats_values,
)
from wind_comp.compensator import SampleStatus
from wind_comp.config import COMPENSATION_NODE_NAME as NODE_NAME
from wind_comp.config import compensator_config_from_files
from wind_comp.pipeline import wind_pipeline

pytestmark = pytest.mark.ros

SCENARIO_S = 20.0
LATITUDE_DEG = 35.0  # sea_state starts at 35 N
PARAMETER_FILES = CASES["off_axis"].buoy_parameter_files
COMPENSATOR = compensator_config_from_files(PARAMETER_FILES)
PLAY_RATE = 10.0
NAV_MISSING_AT_END_S = 0.5  # shorter than the node's 1 s navigation timeout: held until SIGINT
NAN_WIND_INDEX = 40
WRONG_FRAME_INDEX = 41
ZERO_QUATERNION_AFTER_INDEX = 100
ECHO_EVERY = 10


def simulated_scenario(folder: Path):
    """Messages to publish, in stamp order, and the simulator's true wind by stamp."""
    bag = folder / "sim"
    simulated = subprocess.run(
        [
            str(Path(sys.executable).parent / "simulate_bag"),
            "sea_state",
            str(bag),
            "--set",
            f"duration_s={SCENARIO_S}",
            "--seed",
            "3",
            *(a for path in PARAMETER_FILES for a in ("--params-file", str(path))),
        ],
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert simulated.returncode == 0, simulated.stderr
    winds, odometries, truth_wind = [], [], {}
    with BagReader(bag) as reader:
        for record in reader.messages(["anemometer/wind", "truth/odometry", "truth/wind"]):
            message = reader.decode(record)
            if record.topic.endswith("anemometer/wind"):
                winds.append(to_rclpy(message, Vector3Stamped()))
            elif record.topic.endswith("truth/odometry"):
                odometries.append(to_rclpy(message, Odometry()))
            else:
                truth_wind[stamp_ns(message)] = np.array(
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
        odometry.child_frame_id = "base_link"
    for k, odometry in enumerate(odometries):
        odometry.pose.covariance, odometry.twist.covariance = stated_covariances(k)

    end_ns = stamp_ns(winds[-1])
    odometries = [o for o in odometries if stamp_ns(o) <= end_ns - NAV_MISSING_AT_END_S * 1e9]
    zero_quaternion = Odometry()
    after = odometries[ZERO_QUATERNION_AFTER_INDEX].header
    zero_quaternion.header.frame_id = after.frame_id
    zero_quaternion.header.stamp.sec = after.stamp.sec
    zero_quaternion.header.stamp.nanosec = after.stamp.nanosec + 1000
    zero_quaternion.child_frame_id = "base_link"
    zero_quaternion.pose.pose.orientation.w = 0.0
    odometries.insert(ZERO_QUATERNION_AFTER_INDEX + 1, zero_quaternion)

    winds[NAN_WIND_INDEX].vector.x = math.nan
    winds[WRONG_FRAME_INDEX].header.frame_id = "imu_link"

    fix = NavSatFix()
    fix.header.stamp = odometries[0].header.stamp
    fix.header.frame_id = "base_link"
    fix.status.status = NavSatStatus.STATUS_FIX
    fix.latitude, fix.longitude = LATITUDE_DEG, 120.0
    return winds, odometries, fix, truth_wind


def stated_covariances(k: int) -> tuple[list, list]:
    """Pose and twist covariances (36 row-major each) of the k-th odometry: attitude 1σ of
    0.2–0.6° (rad²), body velocity 1σ of 1–3 cm/s (m²/s²) and body rate 1σ of 0.01–0.03 °/s."""
    scale = 2.0 + math.sin(0.1 * k)
    pose, twist = [0.0] * 36, [0.0] * 36
    for index in (21, 28, 35):
        pose[index] = (math.radians(0.2) * scale) ** 2
    pose[22] = pose[27] = 0.3 * pose[21]
    for index in (0, 7, 14):
        twist[index] = (0.01 * scale) ** 2
    for index in (21, 28, 35):
        twist[index] = (math.radians(0.01) * scale) ** 2
    return pose, twist


class Listener:
    """An in-process DDS participant in the test's isolated domain."""

    def __init__(self, env: dict[str, str]):
        for name in ("ROS_DOMAIN_ID", "ROS_AUTOMATIC_DISCOVERY_RANGE"):
            os.environ[name] = env[name]
        self.context = Context()
        rclpy.init(context=self.context)
        self.node = rclpy.create_node("compensation_test", context=self.context)
        self.received = {
            "wind/true": [],
            "wind/true_with_covariance": [],
            "wind/mean_1min": [],
            "wind/stats_1min": [],
        }
        self.diagnostics = []
        for topic, message_type in (
            ("wind/true", Vector3Stamped),
            ("wind/true_with_covariance", TwistWithCovarianceStamped),
            ("wind/mean_1min", Vector3Stamped),
            ("wind/stats_1min", Float64MultiArray),
        ):
            self.node.create_subscription(
                message_type, topic, self.received[topic].append, DATA_QOS
            )
        self.node.create_subscription(DiagnosticArray, "diagnostics", self.diagnostics.append, 10)
        self.wind = self.node.create_publisher(Vector3Stamped, "anemometer/wind", DATA_QOS)
        self.odometry = self.node.create_publisher(Odometry, "nav/odometry", DATA_QOS)
        self.fix = self.node.create_publisher(NavSatFix, "nav/fix", DATA_QOS)
        self.executor = SingleThreadedExecutor(context=self.context)
        self.executor.add_node(self.node)
        self.thread = threading.Thread(target=self.executor.spin, daemon=True)
        self.thread.start()

    def node_sees_publishers(self) -> bool:
        """The node's latest diagnostics report a matched publisher on every input."""
        statuses = [s for a in self.diagnostics for s in a.status if s.hardware_id == NODE_NAME]
        return bool(statuses) and reports_publishers_on(
            statuses[-1], ("anemometer/wind", "nav/odometry", "nav/fix")
        )

    def close(self):
        self.executor.shutdown()
        self.node.destroy_node()
        rclpy.try_shutdown(context=self.context)
        self.thread.join(timeout=5.0)


@pytest.fixture(scope="module")
def live_run(module_ros_env, tmp_path_factory):
    """Run compensation_node on the scenario; returns the scenario, what the node published and
    its exit code."""
    log_path = tmp_path_factory.mktemp("compensation_logs") / "compensation_node.log"
    listener = Listener(module_ros_env)
    with open(log_path, "w") as log:
        process = subprocess.Popen(
            [
                str(Path(sys.executable).parent / "compensation_node"),
                "--ros-args",
                *(a for path in PARAMETER_FILES for a in ("--params-file", str(path))),
            ],
            env=module_ros_env,
            stdout=log,
            stderr=subprocess.STDOUT,
            start_new_session=True,
        )
    echo_log_path = log_path.with_name("wind_echo.log")
    with open(echo_log_path, "w") as echo_log:
        echo = subprocess.Popen(
            [str(Path(sys.executable).parent / "wind_echo"), "--every", str(ECHO_EVERY)],
            env=module_ros_env,
            stdout=echo_log,
            stderr=subprocess.STDOUT,
            start_new_session=True,
        )
    try:
        # The nodes start (seconds of imports and discovery) while the scenario is simulated.
        scenario = simulated_scenario(tmp_path_factory.mktemp("compensation"))
        winds, odometries, fix, _ = scenario
        assert wait_for(
            lambda: (
                min(
                    listener.wind.get_subscription_count(),
                    listener.odometry.get_subscription_count(),
                    listener.fix.get_subscription_count(),
                    listener.node.count_publishers("wind/true"),
                    listener.node.count_subscribers("wind/stats_1min") - 1,
                )
                > 0
                and listener.node_sees_publishers()
            ),
            timeout_s=20.0,
        ), log_path.read_text()
        listener.fix.publish(fix)
        time.sleep(0.3)  # the latitude must be in before the first navigation sample

        inputs = sorted(
            [(stamp_ns(m), 1, listener.wind, m) for m in winds]
            + [(stamp_ns(m), 0, listener.odometry, m) for m in odometries],
            key=lambda row: row[:2],
        )
        start_wall_s, first_ns = time.monotonic(), inputs[0][0]
        for time_ns, _, publisher, message in inputs:
            delay_s = (time_ns - first_ns) * 1e-9 / PLAY_RATE - (time.monotonic() - start_wall_s)
            if delay_s > 0:
                time.sleep(delay_s)
            publisher.publish(message)

        n_held = sum(
            stamp_ns(w) > stamp_ns(odometries[-1]) for w in winds
        )  # no navigation after them
        wait_for(lambda: len(listener.received["wind/true"]) >= len(winds) - n_held, 10.0)
        n_before_interrupt = len(listener.received["wind/true"])
        n_diagnostics = len(listener.diagnostics)
        wait_for(lambda: len(listener.diagnostics) > n_diagnostics, 5.0)
        diagnostics_before_interrupt = list(listener.diagnostics)

        process.send_signal(signal.SIGINT)
        exit_code = process.wait(timeout=15.0)
        wait_for(
            lambda: (
                len(listener.received["wind/true"]) >= len(winds)
                and len(listener.received["wind/true_with_covariance"]) >= len(winds)
                and listener.received["wind/stats_1min"]
            ),
            5.0,
        )
        wait_for(lambda: "1-min stats" in echo_log_path.read_text(), 5.0)
        echo_exit_code = process_exit_code(echo)
        return {
            "scenario": scenario,
            "echo_exit_code": echo_exit_code,
            "echo": echo_log_path.read_text(),
            "exit_code": exit_code,
            "log": log_path.read_text(),
            "n_held": n_held,
            "n_before_interrupt": n_before_interrupt,
            "diagnostics": diagnostics_before_interrupt,
            **{topic: list(messages) for topic, messages in listener.received.items()},
        }
    finally:
        for started in (process, echo):
            if started.poll() is None:
                started.kill()
                started.wait()
        listener.close()


@pytest.fixture(scope="module")
def scenario(live_run):
    """The messages the live run published to the node and the simulator's true wind
    (:func:`simulated_scenario`)."""
    return live_run["scenario"]


def process_exit_code(process: subprocess.Popen) -> int:
    """SIGINT, as Ctrl-C would, and the exit code."""
    process.send_signal(signal.SIGINT)
    return process.wait(timeout=15.0)


def vectors(messages) -> np.ndarray:
    return np.array([[m.vector.x, m.vector.y, m.vector.z] for m in messages])


def test_one_output_per_anemometer_sample_with_its_stamp(scenario, live_run):
    winds = scenario[0]
    outputs = live_run["wind/true"]
    assert live_run["exit_code"] == 0, live_run["log"]
    assert [stamp_ns(m) for m in outputs] == [stamp_ns(m) for m in winds]
    assert {m.header.frame_id for m in outputs} == {"map"}


def test_samples_waiting_for_navigation_are_flushed_at_sigint(scenario, live_run):
    winds = scenario[0]
    assert live_run["n_held"] >= 5
    assert live_run["n_before_interrupt"] == len(winds) - live_run["n_held"]
    held = vectors(live_run["wind/true"][-live_run["n_held"] :])
    assert np.all(np.isnan(held))


def assert_noise_only(stamps_ns, corrected_enu_mps, truth_wind, what: str) -> None:
    """Corrected − true wind at the valid samples that share a truth stamp: with a perfect
    navigation, nothing but the anemometer's noise."""
    common = [
        i
        for i, stamp in enumerate(stamps_ns)
        if stamp in truth_wind and np.all(np.isfinite(corrected_enu_mps[i]))
    ]
    assert len(common) > 0.4 * len(stamps_ns), "the truth shares every other anemometer stamp"
    errors = np.array([corrected_enu_mps[i] - truth_wind[stamps_ns[i]] for i in common])
    rms = np.sqrt(np.mean(errors**2, axis=0))
    budget = noise_rms_bound(ANEMOMETER.noise_mps, len(common))
    figures = (
        f"{what}: RMS error E, N, U {np.round(rms, 4)} m/s, anemometer noise up to {budget:.4f}"
    )
    assert np.all(rms <= budget), figures
    print(figures)


def test_corrected_wind_matches_truth_and_raw_does_not(scenario, live_run):
    winds, odometries, _, truth_wind = scenario
    outputs = live_run["wind/true"]
    stamps = [stamp_ns(m) for m in outputs]
    corrected = vectors(outputs)
    assert_noise_only(stamps, corrected, truth_wind, "live")

    common = [
        i for i, stamp in enumerate(stamps) if stamp in truth_wind and np.isfinite(corrected[i, 0])
    ]
    truth = np.array([truth_wind[stamps[i]] for i in common])
    raw = vectors([winds[i] for i in common])
    raw_rms = np.sqrt(np.mean(np.sum((raw - truth) ** 2, axis=1)))
    assert raw_rms > 1.0

    # Levelled only (attitude and mounting applied, lever arm and buoy velocity ignored): still
    # off by the motion the correction removes, well beyond the noise.
    attitude_by_ns = {
        stamp_ns(o): Rotation.from_quat([getattr(o.pose.pose.orientation, axis) for axis in "xyzw"])
        for o in odometries
        if o.pose.pose.orientation.w != 0.0
    }
    mounting = Rotation.from_euler("ZYX", COMPENSATOR.anemometer_rpy_deg[::-1], degrees=True)
    usable = [k for k, i in enumerate(common) if stamps[i] in attitude_by_ns]
    levelled = np.array(
        [(attitude_by_ns[stamps[common[k]]] * mounting).apply(raw[k]) for k in usable]
    )
    assert np.sqrt(np.mean((levelled - truth[usable]) ** 2)) > 5 * ANEMOMETER.noise_mps


def test_live_output_equals_the_pipeline_run_offline(scenario, live_run):
    # The node's output is the pipeline's fed in one stretch, the messages in stamp order.
    winds, odometries, fix, truth_wind = scenario
    pipeline = wind_pipeline(COMPENSATOR)
    assert pipeline.add_fix(*fix_fields(fix)) is None
    rejected = {}
    in_stamp_order = sorted(
        [(stamp_ns(m), 0, k) for k, m in enumerate(odometries)]
        + [(stamp_ns(m), 1, k) for k, m in enumerate(winds)]
    )
    for _, is_wind, k in in_stamp_order:
        if is_wind:
            pipeline.add_sample(anemometer_sample(winds[k]))
            continue
        try:
            assert pipeline.add_odometry(*odometry_fields(odometries[k])) is None
        except MalformedMessageError as error:
            rejected[error.reason] = rejected.get(error.reason, 0) + 1
    assert rejected == {"zero_quaternion": 1}
    batch = pipeline.flush().samples
    live = vectors(live_run["wind/true"])
    np.testing.assert_array_equal(live, batch.flow_enu_mps)
    # The same samples with their covariances, bit for bit, one per wind sample with its stamp.
    with_covariance = live_run["wind/true_with_covariance"]
    assert [stamp_ns(m) for m in with_covariance] == [stamp_ns(m) for m in winds]
    assert {m.header.frame_id for m in with_covariance} == {"map"}
    np.testing.assert_array_equal(
        [[m.twist.twist.linear.x, m.twist.twist.linear.y, m.twist.twist.linear.z]
         for m in with_covariance],
        batch.flow_enu_mps,
    )  # fmt: skip
    covariances = np.array([np.reshape(m.twist.covariance, (6, 6)) for m in with_covariance])
    np.testing.assert_array_equal(covariances[:, :3, :3], batch.covariance.total)
    np.testing.assert_array_equal(
        covariances[:, 3:, 3:], np.broadcast_to(-np.eye(3), (len(winds), 3, 3))
    )
    np.testing.assert_array_equal(covariances[:, :3, 3:], 0.0)
    valid = batch.valid
    assert (
        np.isfinite(covariances[valid, :3, :3]).all()
        and np.isnan(covariances[~valid, :3, :3]).all()
    )
    # The navigation's stated errors reach the wind: more than the anemometer's noise alone.
    noise_variances = np.square(COMPENSATOR.anemometer_noise_sigma_mps)
    assert np.all(np.trace(covariances[valid, :3, :3], axis1=1, axis2=2) > noise_variances.sum())
    counts = batch.counts()
    assert counts[SampleStatus.INVALID_MEASUREMENT] == 2
    assert counts[SampleStatus.NO_NAVIGATION] == live_run["n_held"]
    # Equal outputs broken alike would pass the above: the batch one is also the true wind.
    assert_noise_only([stamp_ns(m) for m in winds], batch.flow_enu_mps, truth_wind, "batch")


def test_malformed_messages_yield_nan_outputs_and_counted_rejections(scenario, live_run):
    outputs = live_run["wind/true"]
    for index in (NAN_WIND_INDEX, WRONG_FRAME_INDEX):
        assert np.all(np.isnan(vectors([outputs[index]])))
    assert not np.any(np.isnan(vectors(outputs[NAN_WIND_INDEX - 5 : NAN_WIND_INDEX])))
    values = {kv.key: kv.value for kv in live_run["diagnostics"][-1].status[0].values}
    assert values["rejected[anemometer/wind: non_finite]"] == "1"
    assert values["rejected[anemometer/wind: wrong_frame]"] == "1"
    assert values["rejected[nav/odometry: zero_quaternion]"] == "1"
    assert values["rejected_total"] == "3"
    # the wrong frame is named with the expected one, once
    assert (
        live_run["log"].count("anemometer/wind in frame 'imu_link', expected 'anemometer_link'")
        == 1
    )


def test_one_minute_products_summarise_the_published_wind(live_run):
    outputs = live_run["wind/true"]
    assert len(live_run["wind/mean_1min"]) == len(live_run["wind/stats_1min"]) == 1
    stats = stats_values(live_run["wind/stats_1min"][0])
    mean = live_run["wind/mean_1min"][0]
    winds = vectors(outputs)
    valid = ~np.any(np.isnan(winds), axis=1)
    assert stats["n_valid"] == np.count_nonzero(valid)
    assert stats["n_invalid"] == np.count_nonzero(~valid)
    assert stats["window_end_s"] - stats["window_start_s"] == 60.0
    assert stamp_ns(mean) == round(stats["window_end_s"] * 1e9)
    np.testing.assert_allclose(vectors([mean])[0], winds[valid].mean(axis=0), atol=1e-12)
    speeds = np.hypot(winds[valid, 0], winds[valid, 1])
    assert stats["scalar_mean_speed_mps"] == pytest.approx(speeds.mean(), abs=1e-12)
    assert stats["vector_mean_speed_mps"] <= stats["scalar_mean_speed_mps"]
    assert stats["gust_mps"] >= stats["scalar_mean_speed_mps"]


def test_wind_echo_prints_every_nth_sample_and_the_products(live_run):
    outputs = live_run["wind/true"]
    assert live_run["echo_exit_code"] == 0, live_run["echo"]
    lines = live_run["echo"].splitlines()
    sample_lines = [line for line in lines if "1-min" not in line and line[:4].isdigit()]
    # DDS delivers only to a subscription already matched: on a busy machine the echo may take
    # its first samples a moment after the node sends them. It counts from its first one.
    first_stamp_ns = round(
        datetime.fromisoformat(sample_lines[0].split()[0].replace("Z", "+00:00")).timestamp() * 1e9
    )
    joined = int(np.argmin([abs(stamp_ns(m) - first_stamp_ns) for m in outputs]))
    assert abs(stamp_ns(outputs[joined]) - first_stamp_ns) < 1_000_000  # printed to the ms
    assert joined < 5 * ECHO_EVERY, f"the echo missed the first {joined} samples"
    shown = outputs[joined::ECHO_EVERY]
    assert len(sample_lines) == len(shown)
    for line, message in zip(sample_lines, shown, strict=True):
        if math.isnan(message.vector.x):
            assert line.endswith("invalid")
            continue
        speed = math.hypot(message.vector.x, message.vector.y)
        assert f"speed {speed:6.2f} m/s" in line
        # Meteorological: the direction the wind blows FROM, clockwise from North.
        direction = math.degrees(math.atan2(-message.vector.x, -message.vector.y)) % 360.0
        assert f"from {direction:5.1f} deg" in line
    assert sum("1-min mean" in line for line in lines) == 1
    assert sum("1-min stats" in line for line in lines) == 1
