"""Measurement models: exact predictions and Jacobians checked against finite differences.

The finite differences perturb the nominal state with ``inject_error_state``, the same
convention the filter uses for its closed-loop correction, and recompute the prediction through
an independent path (geodetic offsets for position, the lever-arm formula for velocity).
"""

import math

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from buoy_nav import earth
from buoy_nav.error_state_filter import STATE_DIM, NavState, inject_error_state
from buoy_nav.measurements import floored_covariance
from buoy_nav.measurements.baseline import baseline_azimuth_rad, baseline_vector_model
from buoy_nav.measurements.gnss_position import position_model
from buoy_nav.measurements.gnss_velocity import (
    predicted_antenna_velocity_enu_mps,
    velocity_model,
)
from buoy_nav.measurements.heading import (
    heading_model,
    horizontal_fraction,
    predicted_heading_rad,
)
from buoy_nav.rotations import rotation_matrix_from_euler, wrap_angle

RNG = np.random.default_rng(77)
# Large tilts (up to 60°) and antennas off every axis.
ATTITUDES_DEG = [(0, 0, 30), (35, -20, 120), (-60, 45, -170), (10, 55, 80), (-25, -50, 5)]
PRIMARY = np.array((0.31, -0.42, 1.17))
SECONDARY = np.array((-0.93, 0.57, 1.46))


def random_state(roll_deg, pitch_deg, yaw_deg):
    rotation = rotation_matrix_from_euler(*np.radians((roll_deg, pitch_deg, yaw_deg)))
    return NavState(
        attitude_xyzw=tuple(Rotation.from_matrix(rotation).as_quat()),
        velocity_enu_mps=RNG.normal(0, 1.0, 3),
        latitude_rad=math.radians(RNG.uniform(-60, 60)),
        longitude_rad=math.radians(RNG.uniform(-180, 180)),
        altitude_m=RNG.uniform(-10, 50),
        gyro_bias_rad_s=RNG.normal(0, 0.01, 3),
        accel_bias_mps2=RNG.normal(0, 0.05, 3),
    )


def finite_difference_jacobian(predict, state, steps):
    """Central differences of predict(inject_error_state(state, ±h e_i)) for all 15 states."""
    columns = []
    for index in range(STATE_DIM):
        delta = np.zeros(STATE_DIM)
        delta[index] = steps[index]
        plus = np.atleast_1d(predict(inject_error_state(state, delta)))
        minus = np.atleast_1d(predict(inject_error_state(state, -delta)))
        columns.append((plus - minus) / (2 * steps[index]))
    return np.column_stack(columns)


STEPS = np.array([1e-6] * 3 + [1e-5] * 3 + [1e-4] * 3 + [1e-7] * 3 + [1e-5] * 3)


@pytest.mark.parametrize("attitude_deg", ATTITUDES_DEG)
def test_heading_jacobian_matches_finite_differences(attitude_deg):
    state = random_state(*attitude_deg)
    baseline = SECONDARY - PRIMARY
    model = heading_model(0.3, 1e-5, state.rotation_nb, baseline)

    def predict(s):
        return predicted_heading_rad(s.rotation_nb, baseline)

    numeric = finite_difference_jacobian(predict, state, STEPS)
    np.testing.assert_allclose(model.jacobian, numeric, atol=1e-7)
    assert np.all(model.jacobian[0, 3:] == 0.0)


@pytest.mark.parametrize("attitude_deg", ATTITUDES_DEG)
def test_baseline_vector_jacobian_matches_finite_differences(attitude_deg):
    state = random_state(*attitude_deg)
    baseline = SECONDARY - PRIMARY
    model = baseline_vector_model(np.zeros(3), 0.003, 0.006, state.rotation_nb, baseline)

    def predict(s):
        return s.rotation_nb @ baseline

    numeric = finite_difference_jacobian(predict, state, STEPS)
    np.testing.assert_allclose(model.jacobian, numeric, atol=1e-7)
    assert np.all(model.jacobian[:, 3:] == 0.0)
    # A rotation about the baseline itself leaves it unchanged: not observed.
    along_baseline = model.predicted / np.linalg.norm(model.predicted)
    np.testing.assert_allclose(model.jacobian[:, :3] @ along_baseline, 0.0, atol=1e-15)
    np.testing.assert_array_equal(model.covariance, np.diag((0.003**2, 0.003**2, 0.006**2)))


def test_baseline_vector_innovation_and_azimuth_under_tilt():
    """Predicted = R_nb·(l_s − l_p) for any tilt; its azimuth is the dual-antenna heading."""
    baseline = SECONDARY - PRIMARY
    for roll, pitch, yaw in ATTITUDES_DEG:
        rotation = Rotation.from_euler("ZYX", np.radians([yaw, pitch, roll]))
        measured = rotation.apply(baseline) + np.array((0.001, -0.002, 0.003))
        model = baseline_vector_model(measured, 0.003, 0.006, rotation.as_matrix(), baseline)
        np.testing.assert_allclose(model.innovation, (0.001, -0.002, 0.003), atol=1e-12)
        azimuth, horizontal_length = baseline_azimuth_rad(model.predicted)
        assert azimuth == pytest.approx(predicted_heading_rad(rotation.as_matrix(), baseline))
        assert horizontal_length == pytest.approx(np.hypot(*model.predicted[:2]))


def test_heading_is_the_azimuth_of_the_projected_baseline_under_tilt():
    """Exact for any tilt and geometry; a plain yaw difference is not."""
    baseline = SECONDARY - PRIMARY
    for roll, pitch, yaw in ATTITUDES_DEG:
        rotation = Rotation.from_euler("ZYX", np.radians([yaw, pitch, roll]))
        enu = rotation.apply(baseline)
        predicted = predicted_heading_rad(rotation.as_matrix(), baseline)
        assert predicted == pytest.approx(math.atan2(enu[1], enu[0]), abs=1e-12)
    # Level: azimuth = yaw + azimuth of the baseline in the body frame.
    level = rotation_matrix_from_euler(0, 0, 0.4)
    assert predicted_heading_rad(level, baseline) == pytest.approx(
        wrap_angle(0.4 + math.atan2(baseline[1], baseline[0]))
    )
    # Tilted with antennas at different heights: no longer yaw + constant.
    tilted = rotation_matrix_from_euler(math.radians(40), math.radians(-30), 0.4)
    offset = predicted_heading_rad(tilted, baseline) - 0.4
    assert abs(wrap_angle(offset - math.atan2(baseline[1], baseline[0]))) > 0.05


def test_heading_innovation_is_wrapped():
    baseline = np.array((1.5, 0.0, 0.0))
    rotation = rotation_matrix_from_euler(0, 0, -math.pi + 0.01)
    model = heading_model(math.pi - 0.01, 1e-6, rotation, baseline)
    assert model.innovation[0] == pytest.approx(-0.02, abs=1e-12)


def test_heading_geometry_degenerates_for_a_vertical_baseline():
    baseline = np.array((0.0, 0.0, 1.0))
    assert horizontal_fraction(np.eye(3), baseline) == pytest.approx(0.0)
    tilted = rotation_matrix_from_euler(math.radians(30), 0, 0)
    assert horizontal_fraction(tilted, baseline) == pytest.approx(0.5)


@pytest.mark.parametrize("attitude_deg", ATTITUDES_DEG)
def test_velocity_jacobian_matches_finite_differences(attitude_deg):
    state = random_state(*attitude_deg)
    raw_gyro = RNG.normal(0, 0.5, 3)

    def predict(s):
        frame_rate = earth.navigation_frame_rate_enu_rad_s(
            s.latitude_rad, s.altitude_m, s.velocity_enu_mps
        )
        return predicted_antenna_velocity_enu_mps(
            s.velocity_enu_mps, s.rotation_nb, raw_gyro - s.gyro_bias_rad_s, frame_rate, PRIMARY
        )

    frame_rate = earth.navigation_frame_rate_enu_rad_s(
        state.latitude_rad, state.altitude_m, state.velocity_enu_mps
    )
    model = velocity_model(
        np.zeros(3),
        np.eye(3) * 4e-4,
        state.velocity_enu_mps,
        state.rotation_nb,
        raw_gyro,
        state.gyro_bias_rad_s,
        frame_rate,
        PRIMARY,
    )
    np.testing.assert_allclose(model.predicted, predict(state), atol=1e-12)
    numeric = finite_difference_jacobian(predict, state, STEPS)
    np.testing.assert_allclose(model.jacobian, numeric, atol=2e-6)


def test_antenna_velocity_is_the_rigid_body_velocity():
    """v_ant = v + R(ω_nb × l): compare with differentiating R(t) l numerically."""
    rate_nb = np.array((0.3, -0.2, 0.5))
    start = Rotation.from_euler("ZYX", [0.5, -0.2, 0.3])
    dt = 1e-6

    def antenna(t):
        return (start * Rotation.from_rotvec(rate_nb * t)).apply(PRIMARY)

    numeric = (antenna(dt) - antenna(-dt)) / (2 * dt)
    latitude = 0.6
    frame_rate = earth.navigation_frame_rate_enu_rad_s(latitude, 0.0, np.zeros(3))
    # The gyro measures ω_ib = ω_nb + R^T ω_in; the model removes ω_in again.
    rate_ib = rate_nb + start.inv().apply(frame_rate)
    predicted = predicted_antenna_velocity_enu_mps(
        np.zeros(3), start.as_matrix(), rate_ib, frame_rate, PRIMARY
    )
    np.testing.assert_allclose(predicted, numeric, atol=1e-9)


@pytest.mark.parametrize("attitude_deg", ATTITUDES_DEG)
def test_position_jacobian_matches_finite_differences(attitude_deg):
    state = random_state(*attitude_deg)
    # The measured position is irrelevant for H; take the true antenna plus a few centimetres.
    antenna = earth.geodetic_offset(
        state.latitude_rad,
        state.longitude_rad,
        state.altitude_m,
        state.rotation_nb @ PRIMARY + (0.02, -0.03, 0.01),
    )
    model = position_model(
        *antenna,
        np.eye(3) * 4e-4,
        state.latitude_rad,
        state.longitude_rad,
        state.altitude_m,
        state.rotation_nb,
        PRIMARY,
    )
    np.testing.assert_allclose(model.innovation, (0.02, -0.03, 0.01), atol=1e-8)

    def predict(s):
        # Antenna of the perturbed state, as geodetic, expressed in the tangent plane at the
        # unperturbed nominal position (where the filter expresses the measurement).
        point = earth.geodetic_offset(
            s.latitude_rad, s.longitude_rad, s.altitude_m, s.rotation_nb @ PRIMARY
        )
        origin = (state.latitude_rad, state.longitude_rad, state.altitude_m)
        return np.array(earth.enu_offset_scalar(*origin, *point))

    # Geodetic round trips carry ~1e-9 m of rounding: steps move the antenna by ~1 mm, where
    # the neglected curvature of the Earth (δp²/R) is still far below the tolerance.
    numeric = finite_difference_jacobian(predict, state, STEPS * 1e3)
    np.testing.assert_allclose(model.jacobian, numeric, atol=2e-6)


def test_measurement_covariance_floor_keeps_correlations():
    covariance = np.array(((4e-6, 1e-6, 0), (1e-6, 9e-4, 0), (0, 0, 1e-3)))
    floored = floored_covariance(covariance, 1e-4)
    np.testing.assert_allclose(np.diag(floored), (1e-4, 9e-4, 1e-3))
    assert floored[0, 1] == 1e-6
    assert np.all(np.linalg.eigvalsh(floored) > 0)
