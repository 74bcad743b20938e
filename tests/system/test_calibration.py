"""The calibration commands against the simulator's own sensor errors (paper 004).

``calibrate_imu`` on the six-position run recovers the accelerometer bias and scale and the gyro
bias the simulator drew; ``calibrate_magnetometer`` on the turning run, and on a moored buoy
turned through a full circle, recovers the hard iron and the inverse of the soft iron within the
1σ it derives from the noise the record shows; both refuse a recording that lacks attitudes or
directions, naming them: a moored buoy that keeps its heading or only swings on its mooring is
refused, where the fit it would write is wrong.
"""

from __future__ import annotations

import re

import numpy as np
import pytest

from buoy_common.contract import IMU_RAW_TOPIC, MAGNETOMETER_TOPIC, header_seconds
from buoy_nav import earth
from buoy_nav.calibrate_magnetometer import main as calibrate_magnetometer_command
from buoy_nav.calibration import (
    CalibrationError,
    calibrate_imu,
    calibrate_magnetometer,
    fit_magnetometer,
    record_motion,
)
from sensor_sim.scenario import load_scenario
from sensor_sim.sensor_models import ImuSimulator
from sensor_sim.simulate_bag import parse_arguments as simulate_arguments
from sensor_sim.simulate_bag import simulate
from sensor_sim.streams import IMU_SEED_KEY, STREAMS, merged_messages
from sensor_sim.truth import TruthModel


def recorded(name: str, topic: str, duration_s: float | None = None):
    scenario = load_scenario(name)
    duration = duration_s or scenario.duration_s
    truth = TruthModel(scenario)
    stream = STREAMS["imu"].build(scenario, truth, {})
    messages = [m for t, _, m in merged_messages([stream], duration) if t == topic]
    return scenario, truth, messages


@pytest.fixture(scope="module")
def six_positions():
    scenario, truth, messages = recorded("six_position", IMU_RAW_TOPIC)
    t = np.array([header_seconds(m.header) for m in messages])
    gyro = np.array(
        [(m.angular_velocity.x, m.angular_velocity.y, m.angular_velocity.z) for m in messages]
    )
    force = np.array(
        [
            (m.linear_acceleration.x, m.linear_acceleration.y, m.linear_acceleration.z)
            for m in messages
        ]
    )
    return scenario, truth, t, gyro, force


def test_six_positions_give_the_accelerometer_bias_and_scale_and_the_gyro_bias(six_positions):
    scenario, truth, t, gyro, force = six_positions
    gravity = earth.normal_gravity_mps2(np.radians(scenario.origin_latitude_deg), 0.0)
    calibration = calibrate_imu(t, gyro, force, gravity)
    imu = ImuSimulator(truth, scenario.sensors.imu, [scenario.seed, IMU_SEED_KEY])
    assert len(calibration.positions) == 6
    # Turn-on bias (5 mg 1σ) found to 0.3 mg: the Gauss-Markov part (0.1 mg) drifts meanwhile.
    np.testing.assert_allclose(
        calibration.accel_bias_mps2, imu.accel_turn_on_bias_mps2, atol=0.3e-3 * 9.81
    )
    np.testing.assert_allclose(
        calibration.accel_scale, 1.0 + imu.accel_scale_factor_error, atol=2e-4
    )
    # Gyro bias to the 5°/h of its instability (the Earth's 15°/h cancels between positions).
    np.testing.assert_allclose(
        calibration.gyro_bias_rad_s, imu.gyro_turn_on_bias_rad_s, atol=np.radians(10.0 / 3600)
    )


def test_a_recording_without_every_axis_up_and_down_is_refused(six_positions):
    _, _, t, gyro, force = six_positions
    first_three = t - t[0] < 60.0 + 70.0 * 2 + 5.0  # z up, z down, y down: no x, no y up
    with pytest.raises(CalibrationError, match=r"\+x up.*\+x down"):
        calibrate_imu(t[first_three], gyro[first_three], force[first_three], 9.8)


@pytest.fixture(scope="module")
def turning():
    scenario, _, messages = recorded("turning", MAGNETOMETER_TOPIC)
    field = np.array(
        [(m.magnetic_field.x, m.magnetic_field.y, m.magnetic_field.z) for m in messages]
    )
    return scenario, field


def test_a_turn_gives_hard_and_soft_iron(turning):
    scenario, field = turning
    errors = scenario.sensors.magnetometer
    calibration = calibrate_magnetometer(field)
    np.testing.assert_allclose(
        calibration.hard_iron_t, np.array(errors.hard_iron_ut) * 1e-6, atol=0.1e-6
    )
    # The symmetric soft iron is found up to the field's scale (the fit keeps the magnitude).
    inverse = np.linalg.inv(np.reshape(errors.soft_iron, (3, 3)))
    found = calibration.soft_iron / np.cbrt(np.linalg.det(calibration.soft_iron))
    expected = inverse / np.cbrt(np.linalg.det(inverse))
    np.testing.assert_allclose(found, expected, atol=5e-3)
    # The residual is the sensor noise (0.1 µT per axis); min/max alone leaves far more.
    assert calibration.residual_t < 0.2e-6
    assert calibration.min_max_residual_t > 5 * calibration.residual_t


def test_the_turn_is_found_within_the_sigma_it_states(turning):
    scenario, field = turning
    calibration = calibrate_magnetometer(field)
    error_t = calibration.hard_iron_t - np.array(scenario.sensors.magnetometer.hard_iron_ut) * 1e-6
    assert np.all(np.abs(error_t) < 4.0 * calibration.hard_iron_sigma_t)


def test_half_of_the_turn_is_refused(turning):
    _, field = turning
    with pytest.raises(CalibrationError, match="is not determined"):
        calibrate_magnetometer(field[:300])  # 30 s at 10 Hz: 180° of turning


MOORED = "measured_moored_no_gnss"
MOORED_SEA = ("sensors.ahrs.fitted=false",)
"""The moored buoy's sea (roll 9°, pitch 7.5°, ±3° wobble at 6.5 s), the magnetometer alone."""


def moored_record(duration_s: float, *overrides: str):
    """(scenario, field (T), IMU times (s), gyro (rad/s), specific force (m/s²)) of the moored
    buoy with ``overrides``."""
    scenario = load_scenario(MOORED, [*MOORED_SEA, f"duration_s={duration_s}", *overrides], None)
    truth = TruthModel(scenario)
    stream = STREAMS["imu"].build(scenario, truth, {})
    messages = [(topic, m) for topic, _, m in merged_messages([stream], duration_s)]
    field = np.array(
        [
            (m.magnetic_field.x, m.magnetic_field.y, m.magnetic_field.z)
            for topic, m in messages
            if topic == MAGNETOMETER_TOPIC
        ]
    )
    imu = [m for topic, m in messages if topic == IMU_RAW_TOPIC]
    t = np.array([header_seconds(m.header) for m in imu])
    gyro = np.array(
        [(m.angular_velocity.x, m.angular_velocity.y, m.angular_velocity.z) for m in imu]
    )
    force = np.array(
        [(m.linear_acceleration.x, m.linear_acceleration.y, m.linear_acceleration.z) for m in imu]
    )
    return scenario, truth, field, t, gyro, force


def hard_iron_error_t(calibration, scenario) -> np.ndarray:
    return calibration.hard_iron_t - np.array(scenario.sensors.magnetometer.hard_iron_ut) * 1e-6


def test_a_moored_buoy_keeping_its_heading_is_refused_where_its_fit_is_wrong():
    """The ellipsoid through a fixed heading's few directions fits no better than the noise
    allows and lies far from the iron: the record is refused, saying how it moved."""
    scenario, _, field, t, gyro, force = moored_record(300.0, "motion.mooring_yaw_amplitude_deg=0")
    fit = fit_magnetometer(field)
    assert np.linalg.norm(hard_iron_error_t(fit, scenario)) > 10e-6
    # The record's own noise estimate is the simulator's sensor noise.
    assert fit.noise_t == pytest.approx(scenario.sensors.magnetometer.noise_ut * 1e-6, rel=0.1)
    with pytest.raises(CalibrationError, match=r"heading swung over about .*full turn"):
        calibrate_magnetometer(field, record_motion(t, gyro, force))


def test_a_moored_buoy_swinging_on_its_mooring_is_refused():
    _, _, field, t, gyro, force = moored_record(
        300.0, "motion.mooring_yaw_amplitude_deg=20", "motion.mooring_yaw_period_s=300"
    )
    with pytest.raises(CalibrationError, match=r"not determined|no ellipsoid"):
        calibrate_magnetometer(field, record_motion(t, gyro, force))


@pytest.fixture(scope="module")
def moored_full_turn():
    return moored_record(
        400.0,
        "motion.mooring_yaw_amplitude_deg=0",
        "motion.roll_amplitude_deg=20",
        "motion.pitch_amplitude_deg=20",
        "motion.rotation_range_deg=360",
        "motion.rotation_rate_deg_s=2",
    )


def test_a_moored_buoy_turned_full_circle_gives_the_iron_within_its_sigma(moored_full_turn):
    scenario, _, field, t, gyro, force = moored_full_turn
    calibration = calibrate_magnetometer(field, record_motion(t, gyro, force))
    error_t = hard_iron_error_t(calibration, scenario)
    assert np.all(np.abs(error_t) < 4.0 * calibration.hard_iron_sigma_t)
    inverse = np.linalg.inv(np.reshape(scenario.sensors.magnetometer.soft_iron, (3, 3)))
    found = calibration.soft_iron / np.cbrt(np.linalg.det(calibration.soft_iron))
    expected = inverse / np.cbrt(np.linalg.det(inverse))
    assert np.all(np.abs(found - expected) < 4.0 * calibration.soft_iron_sigma)


def test_the_record_motion_is_the_truth_s_heading_swing_and_tilt(moored_full_turn):
    """The heading swing integrated from the gyro is the truth's within what the gyro's drawn
    turn-on bias adds over the record (the Gauss-Markov part is far smaller) plus 2°."""
    scenario, truth, _, t, gyro, force = moored_full_turn
    motion = record_motion(t, gyro, force)
    euler = truth.motion.evaluate(t - t[0]).euler_rad[0]
    imu = ImuSimulator(truth, scenario.sensors.imu, [scenario.seed, IMU_SEED_KEY])
    drift_deg = np.degrees(np.abs(imu.gyro_turn_on_bias_rad_s).max()) * (t[-1] - t[0])
    swing_deg = np.degrees(np.ptp(euler[:, 2]))
    assert abs(motion.heading_swing_deg - swing_deg) < drift_deg + 2.0
    assert motion.tilt_deg > 15.0


def test_the_command_refuses_a_moored_record_saying_how_the_buoy_moved(tmp_path, capsys):
    """``calibrate_magnetometer`` on a bag: exit code 2, one line naming the heading swing it
    read from the bag's IMU, and no parameter file."""
    bag, output = tmp_path / "moored", tmp_path / "magnetometer.yaml"
    arguments = [MOORED, str(bag), "--no-truth", "--set", "duration_s=120"]
    for override in (*MOORED_SEA, "motion.mooring_yaw_amplitude_deg=0"):
        arguments += ["--set", override]
    simulate(simulate_arguments(arguments))
    with pytest.raises(SystemExit) as exit_info:
        calibrate_magnetometer_command([str(bag), str(output)])
    assert exit_info.value.code == 2
    error = capsys.readouterr().err.strip()
    assert len(error.splitlines()) == 1
    assert re.search(r"heading swung over about \d+°.*record the buoy through a full turn", error)
    assert not output.exists()


def test_a_stuck_magnetometer_axis_is_refused_by_name(moored_full_turn):
    _, _, field, _, _, _ = moored_full_turn
    stuck = field.copy()
    stuck[:, 1] = stuck[0, 1]
    with pytest.raises(CalibrationError, match="reads the same value throughout"):
        calibrate_magnetometer(stuck)
