"""The calibration commands against the simulator's own sensor errors (paper 004).

``calibrate_imu`` on the six-position run recovers the accelerometer bias and scale and the gyro
bias the simulator drew; ``calibrate_magnetometer`` on the turning run recovers the hard iron
and the inverse of the soft iron; both refuse a recording that lacks attitudes, naming them.
"""

from __future__ import annotations

import numpy as np
import pytest

from buoy_common.contract import IMU_RAW_TOPIC, MAGNETOMETER_TOPIC, header_seconds
from buoy_nav import earth
from buoy_nav.calibration import CalibrationError, calibrate_imu, calibrate_magnetometer
from sensor_sim.scenario import load_scenario
from sensor_sim.sensor_models import ImuSimulator
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


def test_a_turn_that_is_not_a_full_circle_is_refused(turning):
    _, field = turning
    with pytest.raises(CalibrationError, match="never seen"):
        calibrate_magnetometer(field[:300])  # 30 s at 10 Hz: 180° of turning
