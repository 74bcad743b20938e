"""Miller correction against hand-computed cases and an independent forward model."""

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from wind_comp.miller import MillerInputError, miller_correction, mounting_rotation_from_rpy_deg

IDENTITY = Rotation.identity()
ZERO = np.zeros(3)


def rodrigues_matrix(axis_angle_rad: np.ndarray) -> np.ndarray:
    """Rotation matrix exp([a×]) from an axis-angle vector, written out independently of scipy."""
    angle = np.linalg.norm(axis_angle_rad)
    if angle == 0:
        return np.eye(3)
    kx, ky, kz = axis_angle_rad / angle
    skew = np.array([[0.0, -kz, ky], [kz, 0.0, -kx], [-ky, kx, 0.0]])
    return np.eye(3) + np.sin(angle) * skew + (1 - np.cos(angle)) * skew @ skew


def cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    return np.array(
        [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]]
    )


def sensor_reading(true_wind_enu, attitude_nb, rate_body, velocity_enu, mounting_bw, lever_arm):
    """Air velocity relative to the moving sensor, anemometer axes (first principles)."""
    sensor_velocity_enu = velocity_enu + attitude_nb @ cross(rate_body, lever_arm)
    return mounting_bw.T @ attitude_nb.T @ (true_wind_enu - sensor_velocity_enu)


@pytest.mark.parametrize(
    ("rpy_deg", "sensor_axis", "body_axis"),
    [
        ((0, 0, 90), [1, 0, 0], [0, 1, 0]),  # yaw: sensor x points to body left
        ((90, 0, 0), [0, 1, 0], [0, 0, 1]),  # roll: sensor y points up
        ((0, 90, 0), [1, 0, 0], [0, 0, -1]),  # pitch: sensor x points down
        ((90, 0, 90), [0, 1, 0], [0, 0, 1]),  # roll first, then yaw about body z
        ((90, 0, 90), [1, 0, 0], [0, 1, 0]),
    ],
)
def test_mounting_rotation_follows_rz_ry_rx(rpy_deg, sensor_axis, body_axis):
    rotated = mounting_rotation_from_rpy_deg(rpy_deg).apply(sensor_axis)
    np.testing.assert_allclose(rotated, body_axis, atol=1e-15)


def test_yawed_mounting_is_undone_without_motion():
    # Air moving toward body forward at 7 m/s; the sensor is yawed 90° left, so it reads -y.
    terms = miller_correction(
        [0.0, -7.0, 0.0], IDENTITY, ZERO, ZERO, mounting_rotation_from_rpy_deg((0, 0, 90)), ZERO
    )
    np.testing.assert_allclose(terms.true_wind_enu_mps, [7.0, 0.0, 0.0], atol=1e-14)


def test_rolled_mounting_is_undone_without_motion():
    # Sensor rolled 90°: its +y axis points up, so an updraft of 2 m/s reads on sensor y.
    terms = miller_correction(
        [0.0, 2.0, 0.0], IDENTITY, ZERO, ZERO, mounting_rotation_from_rpy_deg((90, 0, 0)), ZERO
    )
    np.testing.assert_allclose(terms.true_wind_enu_mps, [0.0, 0.0, 2.0], atol=1e-14)


def test_buoy_heading_north_turns_forward_wind_north():
    attitude = Rotation.from_euler("ZYX", [90, 0, 0], degrees=True)
    terms = miller_correction([5.0, 0.0, 0.0], attitude, ZERO, ZERO, np.eye(3), ZERO)
    np.testing.assert_allclose(terms.true_wind_enu_mps, [0.0, 5.0, 0.0], atol=1e-14)


def test_yaw_rate_with_mast_on_axis_has_no_rotation_term():
    terms = miller_correction(
        [3.0, 1.0, 0.0], IDENTITY, [0.0, 0.0, 0.5], ZERO, np.eye(3), [0.0, 0.0, 3.0]
    )
    np.testing.assert_array_equal(terms.rotation_term_enu_mps, ZERO)
    np.testing.assert_allclose(terms.true_wind_enu_mps, [3.0, 1.0, 0.0])


@pytest.mark.parametrize(
    ("rate_body", "mast_tip_velocity"),
    [
        # Positive roll (about forward x) swings the top of a 3 m mast toward the right, -y.
        ([0.2, 0.0, 0.0], [0.0, -0.6, 0.0]),
        # Positive pitch (about left y) swings it forward, +x.
        ([0.0, 0.2, 0.0], [0.6, 0.0, 0.0]),
    ],
)
def test_roll_and_pitch_rate_swing_the_mast_top_and_still_air_is_recovered(
    rate_body, mast_tip_velocity
):
    mast_top = [0.0, 0.0, 3.0]
    reading = -np.asarray(mast_tip_velocity)  # still air seen from the moving sensor
    terms = miller_correction(reading, IDENTITY, rate_body, ZERO, np.eye(3), mast_top)
    np.testing.assert_allclose(terms.rotation_term_enu_mps, mast_tip_velocity, atol=1e-15)
    np.testing.assert_allclose(terms.true_wind_enu_mps, ZERO, atol=1e-15)


def test_pure_rotation_in_still_air_corrects_to_zero():
    rng = np.random.default_rng(11)
    n = 500
    attitudes = Rotation.random(n, random_state=rng)
    rates = rng.normal(scale=0.5, size=(n, 3))
    mounting = Rotation.random(random_state=rng)
    lever_arm = np.array([0.4, -0.3, 3.5])
    reading = -mounting.inv().apply(np.cross(rates, lever_arm))
    terms = miller_correction(reading, attitudes, rates, ZERO, mounting, lever_arm)
    np.testing.assert_allclose(terms.true_wind_enu_mps, 0.0, atol=1e-13)
    np.testing.assert_array_equal(terms.translation_term_enu_mps, 0.0)


def test_pure_translation_adds_the_platform_velocity():
    rng = np.random.default_rng(12)
    attitude = Rotation.random(random_state=rng)
    mounting = Rotation.random(random_state=rng)
    velocity = np.array([1.5, -0.7, 0.2])
    silent = miller_correction(ZERO, attitude, ZERO, velocity, mounting, [0.0, 0.0, 3.0])
    np.testing.assert_array_equal(silent.translation_term_enu_mps, velocity)
    np.testing.assert_allclose(silent.true_wind_enu_mps, velocity)
    # Drifting with the air: the sensor reads the platform velocity backwards, truth is calm.
    reading = -mounting.inv().apply(attitude.inv().apply(velocity))
    drifting = miller_correction(reading, attitude, ZERO, velocity, mounting, [0.0, 0.0, 3.0])
    np.testing.assert_allclose(drifting.true_wind_enu_mps, ZERO, atol=1e-14)


def test_round_trip_with_independent_forward_model():
    rng = np.random.default_rng(13)
    n = 300
    attitude_matrices = np.array([rodrigues_matrix(rng.normal(size=3)) for _ in range(n)])
    mounting = rodrigues_matrix(rng.normal(size=3))
    lever_arm = rng.normal(scale=2.0, size=3)
    rates = rng.normal(scale=0.6, size=(n, 3))
    velocities = rng.normal(scale=2.0, size=(n, 3))
    true_wind = rng.normal(scale=10.0, size=(n, 3))
    readings = np.array(
        [
            sensor_reading(wind, attitude, rate, velocity, mounting, lever_arm)
            for wind, attitude, rate, velocity in zip(
                true_wind, attitude_matrices, rates, velocities, strict=True
            )
        ]
    )
    attitudes = Rotation.from_matrix(attitude_matrices)
    terms = miller_correction(readings, attitudes, rates, velocities, mounting, lever_arm)
    np.testing.assert_allclose(terms.true_wind_enu_mps, true_wind, rtol=0, atol=1e-12)
    np.testing.assert_allclose(
        terms.tilt_term_enu_mps + terms.rotation_term_enu_mps + terms.translation_term_enu_mps,
        terms.true_wind_enu_mps,
        rtol=0,
        atol=1e-13,
    )
    one = miller_correction(readings[7], attitudes[7], rates[7], velocities[7], mounting, lever_arm)
    np.testing.assert_array_equal(one.true_wind_enu_mps, terms.true_wind_enu_mps[7])


def test_rotation_term_matches_finite_difference_of_the_mast_position():
    # Constant body rate: R(t) = R0·exp([ω×]t); the anemometer sits at p_b(t) + R(t)·B.
    rng = np.random.default_rng(14)
    attitude_0 = rodrigues_matrix(rng.normal(size=3))
    rate_body = np.array([0.3, -0.2, 0.4])
    lever_arm = np.array([0.5, 0.2, 3.0])
    velocity = np.array([0.8, -0.4, 0.1])
    step_s = 1e-5

    def anemometer_position(t_s):
        return velocity * t_s + attitude_0 @ rodrigues_matrix(rate_body * t_s) @ lever_arm

    sensor_velocity = (anemometer_position(step_s) - anemometer_position(-step_s)) / (2 * step_s)
    mounting = rodrigues_matrix(np.array([0.1, 0.2, 1.3]))
    true_wind = np.array([6.0, -2.0, 0.3])
    reading = mounting.T @ attitude_0.T @ (true_wind - sensor_velocity)
    terms = miller_correction(
        reading, Rotation.from_matrix(attitude_0), rate_body, velocity, mounting, lever_arm
    )
    np.testing.assert_allclose(terms.true_wind_enu_mps, true_wind, atol=1e-8)


def test_single_and_batch_shapes():
    rng = np.random.default_rng(15)
    single = miller_correction([1.0, 2.0, 3.0], IDENTITY, ZERO, ZERO, np.eye(3), ZERO)
    assert single.true_wind_enu_mps.shape == (3,)
    attitudes = Rotation.random(4, random_state=rng)
    broadcast = miller_correction([1.0, 0.0, 0.0], attitudes, ZERO, ZERO, np.eye(3), ZERO)
    assert broadcast.true_wind_enu_mps.shape == (4, 3)
    np.testing.assert_allclose(broadcast.true_wind_enu_mps, attitudes.apply([1.0, 0.0, 0.0]))


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"wind_sensor_mps": [1.0, 2.0]}, "wind_sensor_mps"),
        ({"wind_sensor_mps": np.ones((5, 3)), "velocity_enu_mps": np.ones((4, 3))}, "batch"),
        ({"attitude_nb": np.eye(3)}, "attitude_nb"),
        ({"mounting_rotation_bw": np.diag([1.0, 1.0, -1.0])}, "mounting_rotation_bw"),
        ({"anemometer_position_body_m": [0.0, 3.0]}, "anemometer_position_body_m"),
    ],
)
def test_malformed_inputs_raise_naming_the_input(kwargs, message):
    arguments = {
        "wind_sensor_mps": ZERO,
        "attitude_nb": IDENTITY,
        "angular_rate_body_rad_s": ZERO,
        "velocity_enu_mps": ZERO,
        "mounting_rotation_bw": np.eye(3),
        "anemometer_position_body_m": ZERO,
    } | kwargs
    with pytest.raises(MillerInputError, match=message):
        miller_correction(**arguments)


def test_mounting_rpy_must_be_three_finite_angles():
    with pytest.raises(MillerInputError, match="rpy_deg"):
        mounting_rotation_from_rpy_deg([0.0, 1.0])
    with pytest.raises(MillerInputError, match="finite"):
        mounting_rotation_from_rpy_deg([0.0, np.nan, 1.0])
