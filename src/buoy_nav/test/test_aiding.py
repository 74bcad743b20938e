"""Aiding sources: the models the filter uses, exact predictions, Jacobians against finite
differences, resets, and the state layout they address.

Every model here is the source's own ``model`` method, the one the engine calls. The finite
differences perturb the nominal state with ``inject_error_state``, the same convention the filter
uses for its closed-loop correction. Predictions are checked against an independent path
(scipy's rotations for the antenna geometry, geodetic offsets for position, the rigid-body
velocity differentiated numerically). The geometry is not the default one: antennas off the x
axis and at different heights, attitudes tilted up to 60°.
"""

import math

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from buoy_common.contract import Reason
from buoy_nav import earth
from buoy_nav.aiding import (
    AIDING_SOURCES,
    HEADING_REFERENCE_TOPICS,
    GnssBaseline,
    GnssBaselineSource,
    GnssFix,
    GnssFixSource,
    GnssHeading,
    GnssHeadingSource,
    GnssVelocity,
    GnssVelocitySource,
    MagneticField,
    MagnetometerSource,
    topics_with_role,
)
from buoy_nav.aiding.base import (
    ATTITUDE_SOURCE,
    POSITION_REFERENCE,
    VELOCITY_REFERENCE,
    LinearisationPoint,
    floored_covariance,
)
from buoy_nav.aiding.gnss_velocity import predicted_antenna_velocity_enu_mps
from buoy_nav.alignment import InMotionAligner
from buoy_nav.antenna_geometry import baseline_azimuth_rad, horizontal_fraction
from buoy_nav.config import FusionConfig
from buoy_nav.error_state_filter import (
    ERROR_STATES,
    ImuErrorModel,
    NavState,
    inject_error_state,
)
from buoy_nav.geomagnetism import wmm_field_enu_t, wmm_field_range_along_parallel
from buoy_nav.rotations import euler_from_rotation_matrix, rotation_matrix_from_euler, wrap_angle
from buoy_nav.sensor_sets import SensorSets
from buoy_nav.state_layout import EAST, NORTH, UP, StateLayout

RNG = np.random.default_rng(77)
# Large tilts (up to 60°) and antennas off every axis, at different heights.
ATTITUDES_DEG = [(0, 0, 30), (35, -20, 120), (-60, 45, -170), (10, 55, 80), (-25, -50, 5)]
PRIMARY = np.array((0.31, -0.42, 1.17))
SECONDARY = np.array((-0.93, 0.57, 1.46))
BASELINE = SECONDARY - PRIMARY
STATES = ERROR_STATES
CONFIG = FusionConfig(
    primary_antenna_body_m=tuple(PRIMARY), secondary_antenna_body_m=tuple(SECONDARY)
)


def make_source(source_class, config=CONFIG):
    return source_class(config, STATES)


@pytest.fixture(autouse=True)
def _same_draws_whatever_ran_before():
    """Every test draws its states from a freshly seeded generator, so that its numbers do not
    depend on which tests ran before it in the same process (pytest-xdist splits a module)."""
    global RNG
    RNG = np.random.default_rng(77)


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


def point_at(state: NavState, raw_gyro=(0.0, 0.0, 0.0)) -> LinearisationPoint:
    """The linearisation point the engine builds: the nominal state, its R_nb, the raw gyro at
    the stamp and the navigation-frame rate of the nominal state."""
    frame_rate = earth.navigation_frame_rate_enu_rad_s(
        state.latitude_rad, state.altitude_m, state.velocity_enu_mps
    )
    return LinearisationPoint(state, state.rotation_nb, tuple(raw_gyro), tuple(frame_rate))


def finite_difference_jacobian(predict, state, steps):
    """Central differences of predict(inject_error_state(state, ±h e_i)) for every state."""
    columns = []
    for index in range(STATES.dim):
        delta = np.zeros(STATES.dim)
        delta[index] = steps[index]
        plus = np.atleast_1d(predict(inject_error_state(state, delta)))
        minus = np.atleast_1d(predict(inject_error_state(state, -delta)))
        columns.append((plus - minus) / (2 * steps[index]))
    return np.column_stack(columns)


def steps_by_block(attitude, velocity, position, gyro_bias, accel_bias) -> np.ndarray:
    steps = np.zeros(STATES.dim)
    for name, step in (
        ("attitude", attitude),
        ("velocity", velocity),
        ("position", position),
        ("gyro_bias", gyro_bias),
        ("accel_bias", accel_bias),
    ):
        steps[STATES.slice_of(name)] = step
    return steps


STEPS = steps_by_block(1e-6, 1e-5, 1e-4, 1e-7, 1e-5)


def columns_except(*names) -> np.ndarray:
    """Mask of the Jacobian columns outside the named blocks."""
    mask = np.ones(STATES.dim, dtype=bool)
    for name in names:
        mask[STATES.slice_of(name)] = False
    return mask


# -- dual-antenna heading -----------------------------------------------------------------


@pytest.mark.parametrize("attitude_deg", ATTITUDES_DEG)
def test_heading_jacobian_matches_finite_differences(attitude_deg):
    source = make_source(GnssHeadingSource)
    state = random_state(*attitude_deg)
    measurement = GnssHeading(0.3, 1e-5)
    model = source.model(measurement, point_at(state))

    def predict(s):
        return source.model(measurement, point_at(s)).predicted

    numeric = finite_difference_jacobian(predict, state, STEPS)
    np.testing.assert_allclose(model.jacobian, numeric, atol=1e-7)
    assert np.all(model.jacobian[0, columns_except("attitude")] == 0.0)
    # Tilted, with the antennas at different heights, the heading also sees the tilt.
    assert np.abs(model.jacobian[0, STATES.attitude][:2]).max() > 0.01


def test_heading_is_the_azimuth_of_the_projected_baseline_under_tilt():
    """Exact for any tilt and geometry; a plain yaw difference is not."""
    source = make_source(GnssHeadingSource)
    for roll, pitch, yaw in ATTITUDES_DEG:
        rotation = Rotation.from_euler("ZYX", np.radians([yaw, pitch, roll]))
        enu = rotation.apply(BASELINE)
        state = random_state(roll, pitch, yaw)
        predicted = source.model(GnssHeading(0.0, 1e-5), point_at(state)).predicted[0]
        assert predicted == pytest.approx(math.atan2(enu[1], enu[0]), abs=1e-12)
    # Level: azimuth = yaw + azimuth of the baseline in the body frame.
    level = random_state(0.0, 0.0, math.degrees(0.4))
    assert source.model(GnssHeading(0.0, 1e-5), point_at(level)).predicted[0] == pytest.approx(
        wrap_angle(0.4 + math.atan2(BASELINE[1], BASELINE[0]))
    )
    # Tilted with antennas at different heights: no longer yaw + constant.
    tilted = random_state(40.0, -30.0, math.degrees(0.4))
    offset = source.model(GnssHeading(0.0, 1e-5), point_at(tilted)).predicted[0] - 0.4
    assert abs(wrap_angle(offset - math.atan2(BASELINE[1], BASELINE[0]))) > 0.05


def test_heading_innovation_is_wrapped_and_its_variance_floored():
    config = FusionConfig(
        primary_antenna_body_m=(-0.75, 0.0, 1.0),
        secondary_antenna_body_m=(0.75, 0.0, 1.0),
        gnss_heading_variance_floor_rad2=1e-6,
    )
    source = make_source(GnssHeadingSource, config)
    level = random_state(0.0, 0.0, math.degrees(-math.pi + 0.01))
    model = source.model(GnssHeading(math.pi - 0.01, 1e-8), point_at(level))
    assert model.innovation[0] == pytest.approx(-0.02, abs=1e-12)
    np.testing.assert_array_equal(model.covariance, [[1e-6]])


def test_heading_geometry_degenerates_for_a_vertical_baseline():
    baseline = np.array((0.0, 0.0, 1.0))
    assert horizontal_fraction(np.eye(3), baseline) == pytest.approx(0.0)
    tilted = rotation_matrix_from_euler(math.radians(30), 0, 0)
    assert horizontal_fraction(tilted, baseline) == pytest.approx(0.5)
    # The filter's model refuses a heading it cannot linearise (counted as geometry) and
    # accepts one once the tilt lays the baseline over far enough.
    mast = FusionConfig(primary_antenna_body_m=(0, 0, 0.5), secondary_antenna_body_m=(0, 0, 1.5))
    source = make_source(GnssHeadingSource, mast)
    assert source.model(GnssHeading(0.0, 1e-5), point_at(random_state(5, 0, 0))) is None
    assert source.model(GnssHeading(0.0, 1e-5), point_at(random_state(30, 0, 0))) is not None


# -- baseline vector ------------------------------------------------------------------------


@pytest.mark.parametrize("attitude_deg", ATTITUDES_DEG)
def test_baseline_vector_jacobian_matches_finite_differences(attitude_deg):
    source = make_source(GnssBaselineSource)
    state = random_state(*attitude_deg)
    measurement = GnssBaseline(np.zeros(3))
    model = source.model(measurement, point_at(state))

    def predict(s):
        return source.model(measurement, point_at(s)).predicted

    numeric = finite_difference_jacobian(predict, state, STEPS)
    np.testing.assert_allclose(model.jacobian, numeric, atol=1e-7)
    assert np.all(model.jacobian[:, columns_except("attitude")] == 0.0)
    # A rotation about the baseline itself leaves it unchanged: not observed.
    along_baseline = model.predicted / np.linalg.norm(model.predicted)
    np.testing.assert_allclose(model.jacobian[:, STATES.attitude] @ along_baseline, 0.0, atol=1e-15)
    np.testing.assert_array_equal(model.covariance, np.diag((0.003**2, 0.003**2, 0.006**2)))


def test_baseline_vector_innovation_and_azimuth_under_tilt():
    """Predicted = R_nb·(l_s − l_p) for any tilt; its azimuth is the dual-antenna heading."""
    baseline_source = make_source(GnssBaselineSource)
    heading_source = make_source(GnssHeadingSource)
    for roll, pitch, yaw in ATTITUDES_DEG:
        rotation = Rotation.from_euler("ZYX", np.radians([yaw, pitch, roll]))
        measured = rotation.apply(BASELINE) + np.array((0.001, -0.002, 0.003))
        point = point_at(random_state(roll, pitch, yaw))
        model = baseline_source.model(GnssBaseline(measured), point)
        np.testing.assert_allclose(model.innovation, (0.001, -0.002, 0.003), atol=1e-12)
        azimuth, horizontal_length = baseline_azimuth_rad(model.predicted)
        heading = heading_source.model(GnssHeading(0.0, 1e-5), point).predicted[0]
        assert azimuth == pytest.approx(heading)
        assert horizontal_length == pytest.approx(np.hypot(*model.predicted[:2]))
        # What the baseline gives the alignment and a yaw reset: the measured azimuth.
        measured_azimuth, variance = baseline_source.baseline_azimuth(GnssBaseline(measured))
        assert measured_azimuth == pytest.approx(math.atan2(measured[1], measured[0]))
        assert variance == pytest.approx((0.003 / np.hypot(*measured[:2])) ** 2)


def test_a_steep_baseline_gives_no_azimuth_and_a_wrong_length_is_rejected():
    source = make_source(GnssBaselineSource)
    length = np.linalg.norm(BASELINE)
    assert source.baseline_azimuth(GnssBaseline((0.1 * length, 0.0, 0.99 * length))) is None
    assert source.validated(GnssBaseline(2.0 * BASELINE)) == Reason.OUT_OF_RANGE
    assert source.validated(GnssBaseline((0.0, math.nan, 1.0))) == Reason.NON_FINITE
    assert source.validated(GnssBaseline((1.0, 2.0))) == Reason.MALFORMED


# -- yaw reset (heading and baseline) --------------------------------------------------------


@pytest.mark.parametrize("source_class", [GnssHeadingSource, GnssBaselineSource])
@pytest.mark.parametrize("attitude_deg", ATTITUDES_DEG)
def test_yaw_reset_puts_the_baseline_at_the_measured_azimuth_keeping_the_tilt(
    source_class, attitude_deg
):
    source = make_source(source_class)
    state = random_state(*attitude_deg)
    roll, pitch, yaw = np.radians(attitude_deg)
    # The truth: the same tilt, yaw off by 20°.
    truth = Rotation.from_euler("ZYX", [yaw + math.radians(20.0), pitch, roll])
    measured_baseline = truth.apply(BASELINE)
    if source_class is GnssHeadingSource:
        measurement = GnssHeading(math.atan2(measured_baseline[1], measured_baseline[0]), 4e-6)
    else:
        measurement = GnssBaseline(measured_baseline)
    point = point_at(state)
    model = source.model(measurement, point)
    reset = source.reset(measurement, point, model)
    assert list(reset.indices) == [STATES.index("attitude", UP)]
    np.testing.assert_allclose(reset.state.rotation_nb, truth.as_matrix(), atol=1e-12)
    reset_roll, reset_pitch, _ = euler_from_rotation_matrix(reset.state.rotation_nb)
    assert (reset_roll, reset_pitch) == pytest.approx((roll, pitch), abs=1e-12)
    np.testing.assert_allclose(
        source.model(measurement, point_at(reset.state)).innovation, 0.0, atol=1e-12
    )
    np.testing.assert_array_equal(reset.state.velocity_enu_mps, state.velocity_enu_mps)


# -- GNSS velocity ----------------------------------------------------------------------------


@pytest.mark.parametrize("attitude_deg", ATTITUDES_DEG)
def test_velocity_jacobian_matches_finite_differences(attitude_deg):
    source = make_source(GnssVelocitySource)
    state = random_state(*attitude_deg)
    raw_gyro = RNG.normal(0, 0.5, 3)
    measurement = GnssVelocity(np.zeros(3), np.eye(3) * 4e-4)

    def predict(s):
        frame_rate = earth.navigation_frame_rate_enu_rad_s(
            s.latitude_rad, s.altitude_m, s.velocity_enu_mps
        )
        return predicted_antenna_velocity_enu_mps(
            s.velocity_enu_mps, s.rotation_nb, raw_gyro - s.gyro_bias_rad_s, frame_rate, PRIMARY
        )

    model = source.model(measurement, point_at(state, raw_gyro))
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
    # The filter's model predicts the same for that state and gyro sample.
    state = NavState(
        tuple(start.as_quat()), np.zeros(3), latitude, 0.0, 0.0, np.zeros(3), np.zeros(3)
    )
    model = make_source(GnssVelocitySource).model(
        GnssVelocity(np.zeros(3), np.eye(3)),
        LinearisationPoint(state, start.as_matrix(), tuple(rate_ib), tuple(frame_rate)),
    )
    np.testing.assert_allclose(model.predicted, numeric, atol=1e-9)


def test_velocity_reset_removes_the_lever_arm_velocity():
    source = make_source(GnssVelocitySource)
    state = random_state(35, -20, 120)
    raw_gyro = RNG.normal(0, 0.5, 3)
    point = point_at(state, raw_gyro)
    measurement = GnssVelocity(np.array((1.5, -0.7, 0.2)), np.diag((4e-4, 9e-4, 16e-4)))
    model = source.model(measurement, point)
    reset = source.reset(measurement, point, model)
    assert list(reset.indices) == list(STATES.indices("velocity"))
    np.testing.assert_array_equal(reset.variances, (4e-4, 9e-4, 16e-4))
    # At the reset state the antenna velocity is the measured one.
    after = source.model(
        measurement,
        LinearisationPoint(
            reset.state, point.rotation_nb, point.raw_gyro_rad_s, point.nav_frame_rate_enu_rad_s
        ),
    )
    np.testing.assert_allclose(after.innovation, 0.0, atol=1e-12)


# -- GNSS position ----------------------------------------------------------------------------


@pytest.mark.parametrize("attitude_deg", ATTITUDES_DEG)
def test_position_jacobian_matches_finite_differences(attitude_deg):
    source = make_source(GnssFixSource)
    state = random_state(*attitude_deg)
    # The measured position is irrelevant for H; take the true antenna plus a few centimetres.
    antenna = earth.geodetic_offset(
        state.latitude_rad,
        state.longitude_rad,
        state.altitude_m,
        state.rotation_nb @ PRIMARY + (0.02, -0.03, 0.01),
    )
    fix = GnssFix(math.degrees(antenna[0]), math.degrees(antenna[1]), antenna[2], np.eye(3) * 4e-4)
    model = source.model(source.validated(fix), point_at(state))
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

    # A reset moves base_link so that the antenna sits on the fix.
    reset = source.reset(source.validated(fix), point_at(state), model)
    assert list(reset.indices) == list(STATES.indices("position"))
    after = source.model(source.validated(fix), point_at(reset.state))
    np.testing.assert_allclose(after.innovation, 0.0, atol=1e-6)


def test_fix_validation_names_the_problem():
    source = make_source(GnssFixSource)
    covariance = np.eye(3) * 4e-4
    assert source.validated(GnssFix(95.0, 0.0, 0.0, covariance)) == Reason.OUT_OF_RANGE
    assert source.validated(GnssFix(0.0, 0.0, 2e4, covariance)) == Reason.OUT_OF_RANGE
    assert source.validated(GnssFix(math.nan, 0.0, 0.0, covariance)) == Reason.NON_FINITE
    assert source.validated(GnssFix("x", 0.0, 0.0, covariance)) == Reason.MALFORMED
    assert source.validated(GnssFix(0.0, 0.0, 0.0, np.eye(2))) == Reason.MALFORMED
    assert source.validated(GnssFix(0.0, 0.0, 0.0, -covariance)) == Reason.NON_POSITIVE_VARIANCE
    flat = source.validated(GnssFix(10, 20, 3, covariance.ravel().tolist()))
    np.testing.assert_array_equal(flat.covariance_enu_m2, covariance)
    assert flat.latitude_rad == math.radians(10.0)


def test_measurement_covariance_floor_keeps_correlations():
    covariance = np.array(((4e-6, 1e-6, 0), (1e-6, 9e-4, 0), (0, 0, 1e-3)))
    floored = floored_covariance(covariance, 1e-4)
    np.testing.assert_allclose(np.diag(floored), (1e-4, 9e-4, 1e-3))
    assert floored[0, 1] == 1e-6
    assert np.all(np.linalg.eigvalsh(floored) > 0)


# -- registry and layout ----------------------------------------------------------------------


def test_registry_applies_the_heading_references_last_and_the_baseline_before_the_heading():
    kinds = [source.kind for source in AIDING_SOURCES]
    assert kinds == [
        "gnss_fix",
        "gnss_velocity",
        "gnss_baseline",
        "gnss_baseline_tertiary",
        "gnss_heading",
        "magnetometer",
        "ahrs",
        "moored",
    ]
    assert GnssHeadingSource.superseded_by == GnssBaselineSource.kind
    assert not GnssBaselineSource.enabled_by(FusionConfig(use_gnss_baseline=False))


def test_the_heading_references_are_the_sources_that_can_complete_the_alignment():
    """Computed from the roles the sources declare: the antennas, the magnetometer and the
    motion pack, each of which hands the aligner a heading; not the third antenna, which the
    alignment does not use, nor GNSS position and velocity."""
    assert HEADING_REFERENCE_TOPICS == ("gnss/baseline", "gnss/heading", "imu/mag", "imu/data")
    assert topics_with_role(ATTITUDE_SOURCE) == ("imu/data",)
    assert topics_with_role(POSITION_REFERENCE) == ("gnss/fix",)
    assert topics_with_role(VELOCITY_REFERENCE) == ("gnss/vel",)
    with pytest.raises(ValueError, match="not one of the roles"):
        topics_with_role("heading")


@pytest.mark.parametrize(
    ("active", "coasting", "label"),
    [
        ({"gnss_fix", "gnss_baseline"}, set(), "a: dual-antenna GNSS"),
        (
            {"gnss_heading", "gnss_baseline_tertiary"},
            set(),
            "a: dual-antenna GNSS + third antenna",
        ),
        ({"gnss_fix", "gnss_velocity"}, set(), "b: single-antenna GNSS"),
        ({"gnss_velocity", "magnetometer"}, set(), "b: single-antenna GNSS + magnetometer"),
        ({"magnetometer", "moored"}, set(), "c: magnetometer, no GNSS"),
        ({"ahrs", "magnetometer"}, set(), "d: motion pack + magnetometer"),
        ({"ahrs"}, set(), "d: motion pack"),
        (
            {"magnetometer"},
            {"gnss_fix", "gnss_heading", "ahrs"},
            "c: magnetometer, no GNSS (e: outage of gnss_fix, gnss_heading)",
        ),
        (set(), {"moored"}, "inertial only"),
    ],
)
def test_sensor_sets_are_named_from_the_sensors_the_sources_declare(active, coasting, label):
    assert SensorSets(AIDING_SOURCES).label(active, coasting) == label


def test_state_layout_names_every_state_once():
    assert STATES.dim == 15
    assert STATES.names == ("attitude", "velocity", "position", "gyro_bias", "accel_bias")
    covered = np.concatenate([np.arange(STATES.dim)[STATES.slice_of(n)] for n in STATES.names])
    np.testing.assert_array_equal(covered, np.arange(STATES.dim))
    assert STATES.index("attitude", UP) == STATES.attitude.start + 2
    assert STATES.index("position", EAST) == STATES.position.start
    assert list(STATES.indices("velocity")) == [
        STATES.index("velocity", a) for a in (EAST, NORTH, UP)
    ]
    # A variant with more states keeps the names of the others where they were.
    extended = StateLayout(*((n, 3) for n in STATES.names), ("gyro_drift", 3))
    assert extended.dim == 18 and extended.gyro_drift == slice(15, 18)
    assert all(extended.slice_of(n) == STATES.slice_of(n) for n in STATES.names)
    with pytest.raises(IndexError):
        STATES.index("velocity", 3)
    with pytest.raises(ValueError, match="twice"):
        StateLayout(("attitude", 3), ("attitude", 3))
    with pytest.raises(ValueError, match="dim"):
        StateLayout(("dim", 1))


def _level_buoy_at(yaw_deg: float) -> LinearisationPoint:
    """A level buoy at rest at 35° N, 120° E whose yaw is ``yaw_deg`` (ENU)."""
    rotation = Rotation.from_euler("z", yaw_deg, degrees=True)
    state = NavState(
        tuple(rotation.as_quat()),
        (0.0, 0.0, 0.0),
        math.radians(35.0),
        math.radians(120.0),
        0.0,
        (0.0, 0.0, 0.0),
        (0.0, 0.0, 0.0),
    )
    return LinearisationPoint(state, rotation.as_matrix(), (0.0, 0.0, 0.0), (0.0, 0.0, 0.0))


def _magnetometer_at(yaw_deg: float, field_body_t):
    """The magnetometer's model of a field (body, T) on a level buoy whose yaw is ``yaw_deg``
    (ENU)."""
    source = MagnetometerSource(FusionConfig(), ERROR_STATES)
    field = MagneticField(np.asarray(field_body_t), 0.0, T_2026_S)
    return source.model(field, _level_buoy_at(yaw_deg))


T_2026_S = 1767225600.0


def test_a_latitude_alone_judges_the_field_against_the_models_along_the_parallel():
    """A site at 35° N without a longitude (the navigation's 0): a field of the model at a
    longitude where it is unlike the field at longitude 0 is accepted; one beyond the range of
    strength or dip along the parallel is refused."""
    latitude = math.radians(35.0)
    latitude_only = MagnetometerSource(
        FusionConfig(site_latitude_deg=35.0, magnetic_declination_deg=0.0), ERROR_STATES
    )
    at_longitude_zero = MagnetometerSource(
        FusionConfig(site_latitude_deg=35.0, site_longitude_deg=0.0), ERROR_STATES
    )
    fields = [
        np.array(wmm_field_enu_t(latitude, math.radians(longitude), T_2026_S))
        for longitude in range(-180, 180, 5)
    ]
    unlike_longitude_zero = [
        field
        for field in fields
        if at_longitude_zero.field_refusal(field, latitude, 0.0, T_2026_S) is not None
    ]
    assert unlike_longitude_zero  # the parallel's fields differ beyond the tolerances
    for field in fields:
        assert latitude_only.field_refusal(field, latitude, 0.0, T_2026_S) is None
    expected = wmm_field_range_along_parallel(latitude, T_2026_S)
    tolerance = FusionConfig().magnetometer_strength_tolerance
    strongest = unlike_longitude_zero[0] / np.linalg.norm(unlike_longitude_zero[0])
    too_strong = strongest * expected.strength_t[1] * (1.0 + tolerance) * 1.05
    assert latitude_only.field_refusal(too_strong, latitude, 0.0, T_2026_S) is not None
    horizontal = np.hypot(*strongest[:2])
    steeper = math.tan(expected.dip_rad[1] + math.radians(15.0))
    too_steep = np.array([*strongest[:2], -horizontal * steeper]) * (
        expected.strength_t[0] / np.linalg.norm([horizontal, horizontal * steeper])
    )
    assert latitude_only.field_refusal(too_steep, latitude, 0.0, T_2026_S) is not None


@pytest.mark.parametrize(
    ("scale", "tilt_deg", "agrees"),
    [
        (1.0, 0.0, True),
        (1.15, 0.0, True),
        (1.3, 0.0, False),
        (0.75, 0.0, False),
        (1.0, 7.0, True),
        (1.0, 14.0, False),
    ],
)
def test_the_magnetometer_refuses_a_field_unlike_the_earths(scale, tilt_deg, agrees):
    """The Earth's field (WMM) seen from the buoy is modelled; one 30 % too strong or weak, or
    whose dip is 14° off, is refused as magnetic_field_inconsistent (tolerances 20 % and 10°)."""
    yaw_deg = 40.0
    field_enu = np.array(wmm_field_enu_t(math.radians(35.0), math.radians(120.0), T_2026_S))
    # Turn the field about the horizontal axis normal to it: its dip changes by tilt_deg.
    axis = np.cross(field_enu, (0.0, 0.0, 1.0))
    turned = Rotation.from_rotvec(math.radians(tilt_deg) * axis / np.linalg.norm(axis))
    field_body = (
        Rotation.from_euler("z", yaw_deg, degrees=True).inv().apply(scale * turned.apply(field_enu))
    )
    model = _magnetometer_at(yaw_deg, field_body)
    if agrees:
        assert not isinstance(model, Reason)
        # Scaled or turned in its vertical plane, the field still points to magnetic north.
        assert abs(model.innovation[0]) < 1e-6
    else:
        assert model == Reason.MAGNETIC_FIELD_INCONSISTENT


def test_only_a_field_judged_in_strength_and_dip_counts_toward_the_magnetometers_alignment():
    """Before the levelling is done the field's strength alone can be judged. A field of the
    Earth's strength whose dip is 25° off (the hard iron of an uncalibrated sensor) passes that;
    such passes must not count as agreement, or the first levelled field that agrees (as an
    uncalibrated field does at some headings) would give the filter its heading. Only fields
    judged whole count: the alignment completes after a window of them, not before."""
    config = FusionConfig(site_latitude_deg=35.0, site_longitude_deg=120.0)
    source = MagnetometerSource(config, ERROR_STATES)
    aligner = InMotionAligner(config, ImuErrorModel.from_config(config))
    latitude = math.radians(35.0)
    yaw = Rotation.from_euler("z", 40.0, degrees=True)
    field_enu = np.array(wmm_field_enu_t(latitude, math.radians(120.0), T_2026_S))
    axis = np.cross(field_enu, (0.0, 0.0, 1.0))
    bent = Rotation.from_rotvec(math.radians(25.0) * axis / np.linalg.norm(axis))
    bent_field_body = yaw.inv().apply(bent.apply(field_enu))
    true_field_body = yaw.inv().apply(field_enu)
    gyro = yaw.inv().apply(earth.earth_rate_enu_rad_s(latitude))
    force = yaw.inv().apply((0.0, 0.0, earth.normal_gravity_mps2(latitude, 0.0)))
    window = config.source_health_rule.min_samples

    def offer(t_s, field_body):
        return source.align(aligner, t_s, MagneticField(field_body, 0.0, T_2026_S + t_s), gyro)

    t_s = 0.0
    while aligner.levelled_rotation() is None:
        assert offer(t_s, bent_field_body) is None  # the strength agrees
        for _ in range(10):
            aligner.add_motion(0.01, gyro, gyro, force, force)
        t_s += 0.1
        assert t_s < 120.0
    assert t_s > 0.1 * window
    offers = [offer(t_s + 0.1 * k, true_field_body) for k in range(window + 1)]
    assert all(result is None for result in offers[: window - 1])
    assert offers[-1] is not None and not isinstance(offers[-1], Reason)


@pytest.mark.parametrize("rate_hz", [1.0, 10.0, 50.0])
def test_the_magnetometers_calibration_error_is_one_samples_worth_per_correlation_time(rate_hz):
    """The heading's error beyond the sensor noise is shared by the samples of a correlation
    time: the update weights each sample by their number, so that a correlation time of samples
    holds one sample's information; the gate takes one sample's variance, and so does the first
    sample, whose interval is unknown."""
    config = FusionConfig(magnetometer_error_correlation_time_s=60.0)
    source = MagnetometerSource(config, ERROR_STATES)
    field_enu = np.array(wmm_field_enu_t(math.radians(35.0), math.radians(120.0), T_2026_S))
    field_body = Rotation.from_euler("z", 40.0, degrees=True).inv().apply(field_enu)
    point = _level_buoy_at(40.0)
    calibration = math.radians(config.magnetometer_heading_sigma_deg) ** 2
    first = source.model(MagneticField(field_body, 0.0, T_2026_S), point)
    later = source.model(MagneticField(field_body, 0.0, T_2026_S, 1.0 / rate_hz), point)
    assert first.covariance[0, 0] == pytest.approx(calibration)
    assert later.gated_covariance[0, 0] == pytest.approx(calibration)
    samples_per_correlation_time = 60.0 * rate_hz
    assert later.covariance[0, 0] == pytest.approx(calibration * samples_per_correlation_time)
    # n samples of one shared error, weighted so, inform as one sample does
    information = samples_per_correlation_time / later.covariance[0, 0]
    assert information == pytest.approx(1.0 / calibration)
