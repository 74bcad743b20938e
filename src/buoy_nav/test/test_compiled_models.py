"""The GNSS sources' compiled measurement functions give to the bit what numpy makes of the same
algebra (numba's ``np.dot`` calls numpy's BLAS), so that compiling them changes no output; and
the filter's stacked gate and update in one compiled call is, to the bit, each measurement's
gate followed by the stacked update and the reset. (Their physics, the Jacobians against
finite differences and the rigid-body velocity, is held by ``test_aiding.py``.)"""

import dataclasses
import math
from collections import Counter

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from buoy_common.contract import Reason
from buoy_nav import earth, strapdown_kernel
from buoy_nav.aiding import (
    AhrsAttitude,
    AhrsAttitudeSource,
    GnssBaseline,
    GnssBaselineSource,
    GnssBaselineTertiary,
    GnssBaselineTertiarySource,
    GnssFix,
    GnssFixSource,
    GnssHeading,
    GnssHeadingSource,
    GnssVelocity,
    GnssVelocitySource,
    MagneticField,
    MagnetometerSource,
    MooredSource,
    MooringAnchor,
)
from buoy_nav.aiding.base import LinearisationPoint
from buoy_nav.aiding.model_kernels import (
    HOLDS,
    LEFT_TO_THE_ENGINE,
    NO_GEOMETRY,
    REFUSED,
    azimuth_model,
)
from buoy_nav.antenna_geometry import horizontal_fraction
from buoy_nav.config import FusionConfig
from buoy_nav.error_state_filter import (
    ERROR_STATES,
    ErrorStateFilter,
    NavState,
    strapdown_vector,
)
from buoy_nav.geomagnetism import SECONDS_PER_JULIAN_YEAR, wmm_field_enu_t
from buoy_nav.innovation_watch import SCALE
from buoy_nav.rotations import cross, skew, wrap_angle
from buoy_nav.stretched_aiding import stretch_values_of

STATES = ERROR_STATES
CASES = 500
CONFIG = FusionConfig(
    primary_antenna_body_m=(0.31, -0.42, 1.17),
    secondary_antenna_body_m=(-0.93, 0.57, 1.46),
    tertiary_antenna_body_m=(0.8, 1.1, 1.3),
)
PACK_CONFIG = dataclasses.replace(CONFIG, ahrs_yaw_reference="magnetic_north", ahrs_lag_s=0.2)


@pytest.fixture
def rng():
    return np.random.default_rng(61)


def random_point(rng) -> LinearisationPoint:
    """A nominal state anywhere, tilted and turning as a buoy in a sea does."""
    state = NavState(
        attitude_xyzw=tuple(Rotation.random(random_state=rng).as_quat()),
        velocity_enu_mps=rng.normal(0.0, 1.5, 3),
        latitude_rad=math.radians(rng.uniform(-70.0, 70.0)),
        longitude_rad=math.radians(rng.uniform(-180.0, 180.0)),
        altitude_m=rng.uniform(-5.0, 20.0),
        gyro_bias_rad_s=rng.normal(0.0, 0.01, 3),
        accel_bias_mps2=rng.normal(0.0, 0.05, 3),
    )
    frame_rate = earth.navigation_frame_rate_enu_rad_s(
        state.latitude_rad, state.altitude_m, state.velocity_enu_mps
    )
    raw_gyro = tuple(rng.normal(0.0, 0.4, 3))
    return LinearisationPoint(state, state.rotation_nb, raw_gyro, tuple(frame_rate))


def random_covariance(rng, scale: float) -> np.ndarray:
    root = rng.normal(0.0, math.sqrt(scale), (3, 3))
    return root @ root.T + np.eye(3) * scale * rng.choice([1e-6, 1.0])


def numpy_floored(covariance, floor):
    symmetric = 0.5 * (covariance + covariance.T)
    np.fill_diagonal(symmetric, np.maximum(np.diag(symmetric), floor))
    return symmetric


def assert_same_bits(model, predicted, innovation, jacobian, covariance):
    for name, value, expected in (
        ("predicted", model.predicted, predicted),
        ("innovation", model.innovation, innovation),
        ("jacobian", model.jacobian, jacobian),
        ("covariance", model.covariance, covariance),
    ):
        assert np.asarray(value).tobytes() == np.asarray(expected).tobytes(), name


def test_antenna_velocity_model_is_the_numpy_algebra_to_the_bit(rng):
    source = GnssVelocitySource(CONFIG, STATES)
    lever_arm = np.array(CONFIG.primary_antenna_body_m)
    floor = CONFIG.gnss_velocity_variance_floor_m2s2
    for _ in range(CASES):
        point = random_point(rng)
        measurement = source.validated(
            GnssVelocity(rng.normal(0.0, 2.0, 3), random_covariance(rng, 1e-3))
        )
        state, rotation = point.state, point.rotation_nb
        rate = np.asarray(point.raw_gyro_rad_s) - state.gyro_bias_rad_s
        frame_rate = np.asarray(point.nav_frame_rate_enu_rad_s)
        lever_enu = rotation @ lever_arm
        rotation_velocity = rotation @ cross(rate, lever_arm)
        predicted = state.velocity_enu_mps + rotation_velocity - cross(frame_rate, lever_enu)
        jacobian = np.zeros((3, STATES.dim))
        jacobian[:, STATES.attitude] = -skew(rotation_velocity) + skew(frame_rate) @ skew(lever_enu)
        jacobian[:, STATES.velocity] = np.eye(3)
        jacobian[:, STATES.gyro_bias] = rotation @ skew(lever_arm)
        assert_same_bits(
            source.model(measurement, point),
            predicted,
            measurement.velocity_enu_mps - predicted,
            jacobian,
            numpy_floored(measurement.covariance_m2s2, floor),
        )


def test_antenna_position_model_is_the_numpy_algebra_to_the_bit(rng):
    source = GnssFixSource(CONFIG, STATES)
    lever_arm = np.array(CONFIG.primary_antenna_body_m)
    floor = CONFIG.gnss_position_variance_floor_m2
    for _ in range(CASES):
        point = random_point(rng)
        state = point.state
        measurement = source.validated(
            GnssFix(
                math.degrees(state.latitude_rad) + rng.normal(0.0, 1e-5),
                math.degrees(state.longitude_rad) + rng.normal(0.0, 1e-5),
                state.altitude_m + rng.normal(0.0, 2.0),
                random_covariance(rng, 1e-2),
            )
        )
        measured = np.array(
            earth.enu_offset_scalar(
                state.latitude_rad,
                state.longitude_rad,
                state.altitude_m,
                measurement.latitude_rad,
                measurement.longitude_rad,
                measurement.altitude_m,
            )
        )
        lever_enu = point.rotation_nb @ lever_arm
        jacobian = np.zeros((3, STATES.dim))
        jacobian[:, STATES.attitude] = -skew(lever_enu)
        jacobian[:, STATES.position] = np.eye(3)
        assert_same_bits(
            source.model(measurement, point),
            lever_enu,
            measured - lever_enu,
            jacobian,
            numpy_floored(measurement.covariance_enu_m2, floor),
        )


@pytest.mark.parametrize(
    ("source_class", "measurement_class", "body_vector"),
    [
        (
            GnssBaselineSource,
            GnssBaseline,
            np.subtract(CONFIG.secondary_antenna_body_m, CONFIG.primary_antenna_body_m),
        ),
        (
            GnssBaselineTertiarySource,
            GnssBaselineTertiary,
            np.subtract(CONFIG.tertiary_antenna_body_m, CONFIG.primary_antenna_body_m),
        ),
    ],
    ids=["baseline", "tertiary baseline"],
)
def test_baseline_vector_model_is_the_numpy_algebra_to_the_bit(
    source_class, measurement_class, body_vector, rng
):
    source = source_class(CONFIG, STATES)
    for _ in range(CASES):
        point = random_point(rng)
        predicted = point.rotation_nb @ body_vector
        measured = predicted + rng.normal(0.0, 0.01, 3)
        jacobian = np.zeros((3, STATES.dim))
        jacobian[:, STATES.attitude] = -skew(predicted)
        model = source.model(source.validated(measurement_class(measured)), point)
        assert_same_bits(model, predicted, measured - predicted, jacobian, model.covariance)
    assert np.array_equal(np.diag(model.covariance) > 0.0, [True, True, True])


def numpy_azimuth(rotation, body_vector):
    """The azimuth's prediction and Jacobian as numpy forms them."""
    east, north, up = rotation @ body_vector
    horizontal_sq = east * east + north * north
    jacobian = np.zeros((1, STATES.dim))
    jacobian[0, STATES.attitude] = (-east * up / horizontal_sq, -north * up / horizontal_sq, 1.0)
    return math.atan2(north, east), horizontal_sq, jacobian


def test_azimuth_model_is_the_numpy_algebra_to_the_bit(rng):
    """The magnetometer's and the receiver heading's shared function, for any vector."""
    for _ in range(CASES):
        rotation = Rotation.random(random_state=rng).as_matrix()
        body_vector = rng.normal(0.0, 1.0, 3) * 10.0 ** rng.uniform(-5.0, 1.0)
        vector, horizontal_sq, predicted, jacobian = azimuth_model(
            rotation, body_vector, STATES.attitude.start, STATES.dim
        )
        expected_predicted, expected_sq, expected_jacobian = numpy_azimuth(rotation, body_vector)
        assert vector.tobytes() == (rotation @ body_vector).tobytes()
        assert (predicted, horizontal_sq) == (expected_predicted, expected_sq)
        assert jacobian.tobytes() == expected_jacobian.tobytes()


def test_heading_model_is_the_numpy_algebra_to_the_bit(rng):
    source = GnssHeadingSource(CONFIG, STATES)
    body_vector = np.subtract(CONFIG.secondary_antenna_body_m, CONFIG.primary_antenna_body_m)
    floor = CONFIG.gnss_heading_variance_floor_rad2
    steep = 0
    for _ in range(CASES):
        point = random_point(rng)
        measurement = source.validated(
            GnssHeading(rng.uniform(-math.pi, math.pi), float(rng.choice([1e-6, 1e-3])))
        )
        model = source.model(measurement, point)
        if horizontal_fraction(point.rotation_nb, body_vector) < 0.2:
            assert model is None
            steep += 1
            continue
        predicted, _, jacobian = numpy_azimuth(point.rotation_nb, body_vector)
        assert_same_bits(
            model,
            np.array((predicted,)),
            np.array((wrap_angle(measurement.yaw_rad - predicted),)),
            jacobian,
            np.array([[max(measurement.variance_rad2, floor)]]),
        )
    assert 0 < steep < CASES // 10


def test_anchor_model_is_the_numpy_algebra_to_the_bit(rng):
    source = MooredSource(CONFIG, STATES)
    stated = np.diag(
        (
            CONFIG.moored_position_sigma_horizontal_m**2,
            CONFIG.moored_position_sigma_horizontal_m**2,
            CONFIG.moored_position_sigma_vertical_m**2,
        )
    )
    for _ in range(CASES):
        point = random_point(rng)
        state = point.state
        anchor = MooringAnchor(
            state.latitude_rad + rng.normal(0.0, 1e-6),
            state.longitude_rad + rng.normal(0.0, 1e-6),
            state.altitude_m + rng.normal(0.0, 1.0),
        )
        scale = float(rng.choice([1.0, rng.uniform(1.0, 5.0)]))
        source._watch._watch.status[SCALE] = scale
        offset = np.array(
            earth.enu_offset_scalar(
                state.latitude_rad, state.longitude_rad, state.altitude_m, *anchor
            )
        )
        jacobian = np.zeros((3, STATES.dim))
        jacobian[:, STATES.position] = np.eye(3)
        widened = stated.copy()
        widened[:2, :2] *= scale * scale
        assert_same_bits(source.model(anchor, point), np.zeros(3), offset, jacobian, widened)


def random_filter(rng) -> ErrorStateFilter:
    root = rng.normal(0.0, 1.0, (STATES.dim, STATES.dim)) * np.sqrt(
        rng.choice([1e-6, 1e-4, 1e-2], STATES.dim)
    )
    return ErrorStateFilter(root @ root.T + np.eye(STATES.dim) * 1e-9, 0.999)


def random_stack(rng, point):
    """The models of one GNSS epoch: fix, velocity and baseline at ``point``."""
    state = point.state
    fix = GnssFix(
        math.degrees(state.latitude_rad) + rng.normal(0.0, 2e-7),
        math.degrees(state.longitude_rad) + rng.normal(0.0, 2e-7),
        state.altitude_m + rng.normal(0.0, 0.05),
        random_covariance(rng, 1e-3),
    )
    velocity = GnssVelocity(state.velocity_enu_mps + rng.normal(0.0, 0.05, 3), np.eye(3) * 1e-3)
    baseline_vector = point.rotation_nb @ np.subtract(
        CONFIG.secondary_antenna_body_m, CONFIG.primary_antenna_body_m
    )
    pairs = (
        (GnssFixSource, fix),
        (GnssVelocitySource, velocity),
        (GnssBaselineSource, GnssBaseline(baseline_vector + rng.normal(0.0, 0.01, 3))),
    )
    chosen = [pair for pair in pairs if rng.uniform() < 0.8] or [pairs[1]]
    return [
        source_class(CONFIG, STATES).model(
            source_class(CONFIG, STATES).validated(measurement), point
        )
        for source_class, measurement in chosen
    ]


def test_the_stacked_gate_and_update_is_each_gate_then_the_update_to_the_bit(rng):
    """Every gate's NIS and S, the covariance after the update and the reset, and the correction
    equal those of the filter's own calls, for stacks of one to three measurements, gated with R
    or with a noise of their own; a stack with a measurement its gate rejects changes
    nothing."""
    outcomes = {True: 0, False: 0}
    for _ in range(CASES):
        point = random_point(rng)
        models = random_stack(rng, point)
        weighted = rng.uniform() < 0.5
        if weighted:
            models = weighted_in_the_update(rng, models)
        probability = float(rng.choice([0.9, 0.999]))
        kalman = random_filter(rng)
        before = kalman.covariance.copy()
        stacked = kalman.gated_update(
            np.concatenate([m.innovation for m in models]),
            np.vstack([m.jacobian for m in models]),
            _block_diagonal([m.covariance for m in models]),
            [m.innovation.shape[0] for m in models],
            [probability] * len(models),
            _block_diagonal([m.gated_covariance for m in models]) if weighted else None,
        )
        assert np.array_equal(kalman.covariance, before)
        gates = [
            kalman.gate(m.innovation, m.jacobian, m.gated_covariance, probability) for m in models
        ]
        for gate, expected in zip(stacked.gates, gates, strict=True):
            assert (gate.accepted, gate.nis, gate.threshold) == (
                expected.accepted,
                expected.nis,
                expected.threshold,
            )
            assert gate.innovation_covariance.tobytes() == expected.innovation_covariance.tobytes()
        outcomes[stacked.accepted] += 1
        if not stacked.accepted:
            assert not all(gate.accepted for gate in gates)
            assert np.array_equal(stacked.correction, np.zeros(STATES.dim))
            assert stacked.covariance is kalman.covariance
            continue
        correction = kalman.update(
            np.concatenate([m.innovation for m in models]),
            np.vstack([m.jacobian for m in models]),
            _block_diagonal([m.covariance for m in models]),
        )
        kalman.reset_after_injection(correction)
        assert stacked.correction.tobytes() == correction.tobytes()
        assert stacked.covariance.tobytes() == kalman.covariance.tobytes()
        assert stacked.positive_definite
    assert min(outcomes.values()) > CASES // 20, outcomes


def weighted_in_the_update(rng, models):
    """``models`` gated with their noise and updated with a multiple of it, as a sample whose
    error its neighbours share is weighted in the update."""
    return [
        dataclasses.replace(
            model,
            covariance=model.covariance * rng.uniform(2.0, 30.0),
            gate_covariance=model.covariance,
        )
        for model in models
    ]


def _block_diagonal(blocks):
    size = sum(block.shape[0] for block in blocks)
    matrix = np.zeros((size, size))
    offset = 0
    for block in blocks:
        matrix[offset : offset + block.shape[0], offset : offset + block.shape[0]] = block
        offset += block.shape[0]
    return matrix


def strapdown_vector_of(point: LinearisationPoint) -> np.ndarray:
    """The strapdown state vector of ``point``, the navigation frame's rate its last step's."""
    vector = strapdown_vector(point.state)
    frame_rate = strapdown_kernel.NAV_FRAME_RATE
    vector[frame_rate : frame_rate + 3] = point.nav_frame_rate_enu_rad_s
    return vector


def random_measurement(source, point: LinearisationPoint, rng):
    """A validated measurement of ``source`` near what ``point`` predicts."""
    state = point.state
    if isinstance(source, GnssFixSource):
        return GnssFix(
            math.degrees(state.latitude_rad) + rng.normal(0.0, 1e-5),
            math.degrees(state.longitude_rad) + rng.normal(0.0, 1e-5),
            state.altitude_m + rng.normal(0.0, 2.0),
            random_covariance(rng, 1e-2),
        )
    if isinstance(source, GnssVelocitySource):
        return GnssVelocity(rng.normal(0.0, 2.0, 3), random_covariance(rng, 1e-3))
    if isinstance(source, GnssHeadingSource):
        return GnssHeading(rng.uniform(-4.0, 4.0), rng.choice([1e-8, 1e-3]))
    if isinstance(source, AhrsAttitudeSource):
        turn = Rotation.from_rotvec(rng.normal(0.0, 0.05, 3)).as_matrix()
        return AhrsAttitude(
            turn @ point.rotation_nb,
            random_covariance(rng, 1e-4),
            float(rng.choice([math.nan, 0.1])),
            (2026.0 - 1970.0) * SECONDS_PER_JULIAN_YEAR,
        )
    vector = point.rotation_nb @ source._baseline_body_m + rng.normal(0.0, 0.01, 3)
    return source.measurement_type(vector)


def random_field(rng, point: LinearisationPoint) -> tuple[MagneticField, str]:
    """A calibrated field at ``point`` and what it is meant to be: the Earth's there seen with
    the nominal attitude and the sensor's noise (``agrees``; near the north magnetic pole so
    steep that it has no heading), or one much stronger or turned off it (``disagrees``)."""
    state = point.state
    t_s = (2026.0 - 1970.0) * SECONDS_PER_JULIAN_YEAR + rng.uniform(0.0, 2e7)
    field_enu = np.array(wmm_field_enu_t(state.latitude_rad, state.longitude_rad, t_s))
    kind = rng.choice(["agrees", "disagrees"], p=[0.7, 0.3])
    if kind == "disagrees":
        turn = Rotation.from_rotvec(rng.normal(0.0, 0.6, 3)).as_matrix()
        field_enu = turn @ field_enu * rng.choice([1.0, 1.6])
    field_body = point.rotation_nb.T @ field_enu + rng.normal(0.0, 5e-8, 3)
    interval = rng.choice([math.nan, 1.0, 0.1])
    return MagneticField(field_body, float(rng.choice([0.0, 1e-15])), t_s, interval), kind


def test_the_magnetometers_stretch_model_is_its_model_to_the_bit(rng):
    """What a compiled stretch models of a magnetometer's field, the Earth's field taken where
    the filter is, is what the source's model gives at the same point: the heading, its
    Jacobian, R and the gate's noise to the bit, a refusal both ways for a field the Earth's
    does not explain (for the source's reason), no model both ways for one too steep to head
    by, and the field left to the engine where the filter has left the cell the Earth's field
    was taken in."""
    source = MagnetometerSource(CONFIG, STATES)
    terms = source.stretch_terms()
    outcomes = Counter()
    for case in range(CASES):
        point = random_point(rng)
        if case % 10 == 0:  # beside the north magnetic pole: a field too steep to head by
            point = point._replace(
                state=dataclasses.replace(
                    point.state,
                    latitude_rad=math.radians(rng.uniform(85.0, 87.0)),
                    longitude_rad=math.radians(rng.uniform(130.0, 150.0)),
                )
            )
        field, kind = random_field(rng, point)
        measurement = source.validated(field)
        model = source.model(measurement, point)
        position = (point.state.latitude_rad, point.state.longitude_rad)
        values = np.array(source.stretch_values(measurement, position))
        vector = strapdown_vector_of(point)
        innovation, jacobian, covariance, gate_covariance, fate = source.stretch_model(
            values, vector, point.rotation_nb, np.array(point.raw_gyro_rad_s), terms
        )
        outcome = type(model).__name__
        outcomes[kind, outcome] += 1
        assert (
            fate == {"MeasurementModel": HOLDS, "NoneType": NO_GEOMETRY, "Reason": REFUSED}[outcome]
        )
        if fate == REFUSED:
            assert model == source.stretch_refusal
        if fate == HOLDS:
            for name, value, expected in (
                ("innovation", innovation, model.innovation),
                ("jacobian", jacobian, model.jacobian),
                ("covariance", covariance, model.covariance),
                ("gate covariance", gate_covariance, model.gate_covariance),
            ):
                assert value.tobytes() == np.asarray(expected).tobytes(), name
        vector[strapdown_kernel.LATITUDE] += math.radians(0.06)  # the next cell
        elsewhere = source.stretch_model(
            values, vector, point.rotation_nb, np.array(point.raw_gyro_rad_s), terms
        )
        assert elsewhere[-1] == LEFT_TO_THE_ENGINE
    assert outcomes["agrees", "MeasurementModel"] > CASES // 2, outcomes
    assert outcomes["agrees", "NoneType"] > 0, outcomes
    assert outcomes["disagrees", "Reason"] > CASES // 10, outcomes


@pytest.mark.parametrize(
    "source_class",
    [
        GnssFixSource,
        GnssVelocitySource,
        GnssHeadingSource,
        GnssBaselineSource,
        GnssBaselineTertiarySource,
        AhrsAttitudeSource,
    ],
)
def test_a_sources_stretch_model_over_arrays_is_its_model_to_the_bit(source_class, rng):
    """What a compiled stretch models of a measurement from its numbers and the strapdown state
    vector is what the source's model gives at the same point (a heading whose baseline is too
    steep: no model, both ways; a motion pack lagging, on magnetic north)."""
    source = source_class(PACK_CONFIG if source_class is AhrsAttitudeSource else CONFIG, STATES)
    terms = source.stretch_terms()
    for _ in range(CASES):
        point = random_point(rng)
        measurement = source.validated(random_measurement(source, point, rng))
        model = source.model(measurement, point)
        position = (point.state.latitude_rad, point.state.longitude_rad)
        innovation, jacobian, covariance, holds = source.stretch_model(
            np.array(source.stretch_values(measurement, position)),
            strapdown_vector_of(point),
            point.rotation_nb,
            np.array(point.raw_gyro_rad_s),
            terms,
        )
        assert holds == (model is not None)
        if model is not None:
            for name, value, expected in (
                ("innovation", innovation, model.innovation),
                ("jacobian", jacobian, model.jacobian),
                ("covariance", covariance, model.covariance),
            ):
                assert value.tobytes() == np.asarray(expected).tobytes(), name


@pytest.mark.parametrize(
    "config",
    [
        PACK_CONFIG,
        dataclasses.replace(PACK_CONFIG, magnetic_declination_deg=-7.5),
        dataclasses.replace(PACK_CONFIG, ahrs_yaw_reference="true_north"),
    ],
    ids=["model's declination", "configured declination", "true north"],
)
def test_a_packs_attitudes_made_into_rows_at_once_are_each_ones(config, rng):
    """What a stretch reads of many attitudes made at once (``stretch_values_of``) is what it
    reads of each alone, validated then made into numbers, to the bit: on magnetic north with
    the model's declination over stamps across its steps or a configured one, on true north;
    one not finite or with a variance not positive refused for the same reason; attitudes
    given as flat numbers, which do not stack, made one by one."""
    source = AhrsAttitudeSource(config, STATES)
    point = random_point(rng)
    position = (point.state.latitude_rad, point.state.longitude_rad)
    measurements = []
    for index in range(CASES):
        attitude = random_measurement(source, point, rng)._replace(
            t_s=(2026.0 - 1970.0 + rng.uniform(-1.0, 1.0)) * SECONDS_PER_JULIAN_YEAR,
            interval_s=float(rng.choice([math.nan, 0.1, 2.0, 0.0, -1.0, math.inf])),
        )
        if index % 17 == 0:
            attitude.rotation_nb[1, 2] = math.nan
        if index % 13 == 0:
            attitude.covariance_rad2[2, 2] = -1e-6
        measurements.append(attitude)
    flat = [m._replace(rotation_nb=m.rotation_nb.reshape(9).tolist()) for m in measurements[:9]]
    for given in (measurements, flat + measurements[9:]):
        validated, values = stretch_values_of(source, given, position)
        for index, measurement in enumerate(given):
            alone = source.validated(measurement)
            if isinstance(alone, str):
                assert validated[index] == alone
                continue
            assert validated[index].rotation_nb.tobytes() == alone.rotation_nb.tobytes()
            assert validated[index].covariance_rad2.tobytes() == alone.covariance_rad2.tobytes()
            assert validated[index][2:] == alone[2:]
            expected = np.array(source.stretch_values(alone, position))
            assert values[index].tobytes() == expected.tobytes(), index
    assert {reason for reason in validated if isinstance(reason, str)} == {
        Reason.NON_FINITE,
        Reason.NON_POSITIVE_VARIANCE,
    }
