"""Strapdown mechanization against analytic motions (no simulator)."""

import math
import signal

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from buoy_nav import earth, mechanization
from buoy_nav.mechanization import StrapdownIntegrator, interpolate_sample
from buoy_nav.rotations import rotation_matrix_from_euler

LATITUDE = math.radians(35.0)
LONGITUDE = math.radians(120.0)
ALTITUDE = 3.0
GRAVITY = earth.normal_gravity_mps2(LATITUDE, ALTITUDE)
EARTH_RATE = earth.earth_rate_enu_rad_s(LATITUDE)
UP_FORCE = np.array((0.0, 0.0, GRAVITY))


def attitude_error_rad(integrator, true_rotation):
    """Angle of R_true R_est^T."""
    estimate = Rotation.from_quat(integrator.attitude_xyzw)
    return np.linalg.norm((Rotation.from_matrix(true_rotation) * estimate.inv()).as_rotvec())


def stationary_samples(rotation_at, body_rate_at, t):
    """Exact gyro ω_ib = ω_nb + R^T ω_ie and specific force R^T g_up of a non-translating body."""
    rotation = rotation_at(t)
    gyro = body_rate_at(t) + rotation.T @ EARTH_RATE
    force = rotation.T @ UP_FORCE
    return gyro, force


def integrate(rotation_at, body_rate_at, dt, steps, **options):
    start = rotation_at(0.0)
    integrator = StrapdownIntegrator(
        Rotation.from_matrix(start).as_quat(),
        (0.0, 0.0, 0.0),
        LATITUDE,
        LONGITUDE,
        ALTITUDE,
        **options,
    )
    gyro0, force0 = stationary_samples(rotation_at, body_rate_at, 0.0)
    for k in range(1, steps + 1):
        gyro1, force1 = stationary_samples(rotation_at, body_rate_at, k * dt)
        integrator.step(dt, gyro0, gyro1, force0, force1)
        gyro0, force0 = gyro1, force1
    return integrator


def test_still_and_level_stays_still_for_600_s():
    rotation = rotation_matrix_from_euler(0.0, 0.0, math.radians(30.0))
    integrator = integrate(lambda t: rotation, lambda t: np.zeros(3), 0.01, 60000)
    assert attitude_error_rad(integrator, rotation) < 1e-10
    assert np.linalg.norm(integrator.velocity_enu_mps) < 1e-7
    plane = earth.LocalTangentPlane(LATITUDE, LONGITUDE, ALTITUDE)
    drift = plane.enu_from_geodetic(
        integrator.latitude_rad, integrator.longitude_rad, integrator.altitude_m
    )
    assert np.linalg.norm(drift) < 1e-5


def test_still_tilted_body_stays_still():
    rotation = rotation_matrix_from_euler(math.radians(12.0), math.radians(-25.0), 2.0)
    integrator = integrate(lambda t: rotation, lambda t: np.zeros(3), 0.01, 20000)
    assert attitude_error_rad(integrator, rotation) < 1e-10
    assert np.linalg.norm(integrator.velocity_enu_mps) < 1e-7


@pytest.mark.parametrize("axis", [0, 1, 2])
def test_constant_rate_about_one_axis_gives_the_expected_angle(axis):
    rate = 0.5
    start = rotation_matrix_from_euler(0.1, -0.2, 0.3)
    unit = np.eye(3)[axis]

    def rotation_at(t):
        return start @ Rotation.from_rotvec(unit * rate * t).as_matrix()

    integrator = integrate(rotation_at, lambda t: unit * rate, 0.01, 2000)
    # 20 s at 0.5 rad/s = 10 rad turned; what remains is the (ΩT)² quadrature error of the
    # Earth rate turning in body axes, far below a microradian.
    assert attitude_error_rad(integrator, rotation_at(20.0)) < 1e-8
    # The rotating specific force is integrated without leaking into velocity.
    assert np.linalg.norm(integrator.velocity_enu_mps) < 1e-4


def coning_motion(half_angle, frequency):
    """Classic coning: R(t) = R0 · Rot(β about (0, cos Ωt, sin Ωt)), closed form.

    Quaternion (w first) q = (cos β/2, 0, sin β/2 cos Ωt, sin β/2 sin Ωt); the body rate
    ω = 2 q* ⊗ q̇ with the analytic q̇ = Ω sin β/2 (0, 0, −sin Ωt, cos Ωt).
    """
    omega = 2 * math.pi * frequency
    start = rotation_matrix_from_euler(0.0, 0.0, 0.7)
    s, c = math.sin(half_angle / 2), math.cos(half_angle / 2)

    def rotation_at(t):
        axis = np.array((0.0, math.cos(omega * t), math.sin(omega * t)))
        return start @ Rotation.from_rotvec(axis * half_angle).as_matrix()

    def body_rate_at(t):
        w, v = c, s * np.array((0.0, math.cos(omega * t), math.sin(omega * t)))
        dw, dv = 0.0, omega * s * np.array((0.0, -math.sin(omega * t), math.cos(omega * t)))
        # Vector part of 2 conj(q) ⊗ q̇ = 2 (w dv − dw v − v × dv).
        return 2.0 * (w * dv - dw * v - np.cross(v, dv))

    return rotation_at, body_rate_at


def test_coning_body_rate_is_the_textbook_one():
    beta, frequency = 0.05, 5.0
    omega = 2 * math.pi * frequency
    _, body_rate_at = coning_motion(beta, frequency)
    t = 0.123
    expected = (
        -2 * omega * math.sin(beta / 2) ** 2,
        -omega * math.sin(beta) * math.sin(omega * t),
        omega * math.sin(beta) * math.cos(omega * t),
    )
    np.testing.assert_allclose(body_rate_at(t), expected, atol=1e-12)


def test_coning_correction_reduces_the_coning_drift():
    beta, frequency, dt, steps = 0.05, 5.0, 0.01, 1000
    rotation_at, body_rate_at = coning_motion(beta, frequency)
    truth = rotation_at(steps * dt)
    plain = integrate(rotation_at, body_rate_at, dt, steps, coning_correction=False)
    corrected = integrate(rotation_at, body_rate_at, dt, steps, coning_correction=True)
    plain_error = attitude_error_rad(plain, truth)
    corrected_error = attitude_error_rad(corrected, truth)
    # Uncorrected drift rate ≈ ½ β² Ω (1 − sinc ΩT) (the classic coning error of an algorithm
    # without coning term): 6.4e-4 rad/s here, so 10 s leave 6.4 mrad.
    omega_t = 2 * math.pi * frequency * dt
    expected_drift = 0.5 * beta**2 * 2 * math.pi * frequency * (1 - math.sin(omega_t) / omega_t)
    assert plain_error == pytest.approx(expected_drift * steps * dt, rel=0.05)
    assert corrected_error < 0.1 * plain_error


def test_steps_split_at_measurement_stamps_keep_the_accuracy():
    """Splitting every 10th IMU step at a random instant (what the engine does at a measurement
    stamp), with the sample there interpolated on the integrator's parabola, keeps the coning
    accuracy; linear interpolation there would bring back part of the trapezoid error."""
    beta, frequency, dt, steps = 0.05, 2.0, 0.01, 1000
    rotation_at, body_rate_at = coning_motion(beta, frequency)
    integrator = StrapdownIntegrator(
        Rotation.from_matrix(rotation_at(0.0)).as_quat(), (0, 0, 0), LATITUDE, LONGITUDE, ALTITUDE
    )
    rng = np.random.default_rng(3)
    older = stationary_samples(rotation_at, body_rate_at, -dt)
    gyro0, force0 = stationary_samples(rotation_at, body_rate_at, 0.0)
    for k in range(1, steps + 1):
        gyro1, force1 = stationary_samples(rotation_at, body_rate_at, k * dt)
        t0, t1 = (k - 1) * dt, k * dt
        if k % 10 == 0:
            t_m = t0 + rng.uniform(0.0, 1.0) * dt
            gyro_m = interpolate_sample(t_m, t0, gyro0, t1, gyro1, t0 - dt, older[0])
            force_m = interpolate_sample(t_m, t0, force0, t1, force1, t0 - dt, older[1])
            integrator.step(t_m - t0, gyro0, gyro_m, force0, force_m)
            integrator.step(t1 - t_m, gyro_m, gyro1, force_m, force1)
        else:
            integrator.step(dt, gyro0, gyro1, force0, force1)
        older = (gyro0, force0)
        gyro0, force0 = gyro1, force1
    unsplit = integrate(rotation_at, body_rate_at, dt, steps)
    truth = rotation_at(steps * dt)
    assert attitude_error_rad(integrator, truth) < 2 * attitude_error_rad(unsplit, truth) + 1e-7
    # The velocity error (tilt error × g × t) is the unsplit one.
    np.testing.assert_allclose(integrator.velocity_enu_mps, unsplit.velocity_enu_mps, atol=5e-5)


def test_constant_acceleration_and_gravity_are_integrated():
    """A level body accelerating north at a m/s² for 10 s: v = a t, s = a t² / 2."""
    accel = 0.5
    rotation = rotation_matrix_from_euler(0.0, 0.0, math.radians(90.0))  # forward = north
    integrator = StrapdownIntegrator(
        Rotation.from_matrix(rotation).as_quat(), (0, 0, 0), LATITUDE, LONGITUDE, ALTITUDE
    )
    dt, steps = 0.01, 1000
    for k in range(steps):
        # Coriolis and transport terms are what the body feels on the rotating Earth: include
        # them in the specific force so the true trajectory is a straight northward run.
        v_north = accel * k * dt
        meridian, _ = earth.radii_of_curvature_m(integrator.latitude_rad)
        coriolis = np.cross(
            2 * earth.earth_rate_enu_rad_s(integrator.latitude_rad), (0, v_north, 0)
        )
        force_enu = np.array((0.0, accel, GRAVITY)) + coriolis
        force = rotation.T @ force_enu
        gyro = rotation.T @ (
            earth.earth_rate_enu_rad_s(integrator.latitude_rad)
            + earth.transport_rate_enu_rad_s(integrator.latitude_rad, ALTITUDE, (0, v_north, 0))
        )
        integrator.step(dt, gyro, gyro, force, force)
    velocity = np.array(integrator.velocity_enu_mps)
    np.testing.assert_allclose(velocity, (0, accel * steps * dt, 0), atol=2e-3)
    meridian, _ = earth.radii_of_curvature_m(LATITUDE)
    north = (integrator.latitude_rad - LATITUDE) * (meridian + ALTITUDE)
    assert north == pytest.approx(0.5 * accel * (steps * dt) ** 2, rel=1e-3)


def test_a_stop_signal_during_compilation_is_delivered_once_the_kernels_are_ready(monkeypatch):
    # An exception raised inside numba's compiler leaves it half-built (the process then fails
    # later or crashes at exit): a tool's handler, which raises, must run only afterwards.
    delivered = []
    seen_while_compiling = []

    def compile_and_be_interrupted():
        signal.raise_signal(signal.SIGINT)
        signal.raise_signal(signal.SIGTERM)
        seen_while_compiling.extend(delivered)

    def record(caught, _frame):
        delivered.append(caught)

    previous = {number: signal.signal(number, record) for number in (signal.SIGINT, signal.SIGTERM)}
    try:
        monkeypatch.setattr(mechanization, "_run_compiled_kernels", compile_and_be_interrupted)
        mechanization.load_compiled_kernels()
        handlers_after = [signal.getsignal(number) for number in previous]
    finally:
        for number, handler in previous.items():
            signal.signal(number, handler)
    assert seen_while_compiling == []
    assert delivered == [signal.SIGINT, signal.SIGTERM]
    assert handlers_after == [record, record]
