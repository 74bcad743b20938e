"""The covariance blocks a solution carries: the filter's own, read-only, widened while the
filter is distrusted, and shared by consecutive solutions until the covariance changes; its
vectors; and its numbers written as a row."""

import numpy as np
import pytest

from buoy_nav import earth
from buoy_nav import solution_rows as row
from buoy_nav.error_state_filter import ERROR_STATES, ErrorStateFilter
from buoy_nav.mechanization import StrapdownIntegrator
from buoy_nav.solution import NavSolution, SolutionBuilder
from buoy_nav.solution_rows import SolutionRows
from buoy_nav.strapdown_kernel import STATE_SIZE

BLOCK_OF_FIELD = {
    "attitude_covariance_rad2": "attitude",
    "velocity_covariance_m2s2": "velocity",
    "position_covariance_m2": "position",
    "gyro_bias_covariance_rad2_s2": "gyro_bias",
}
LATITUDE_RAD, LONGITUDE_RAD = 0.7, -1.2


def _random_filter(seed: int) -> ErrorStateFilter:
    factor = np.random.default_rng(seed).normal(size=(ERROR_STATES.dim, ERROR_STATES.dim))
    return ErrorStateFilter(factor @ factor.T, 0.99)


def _solution(builder: SolutionBuilder, kalman: ErrorStateFilter) -> NavSolution:
    integrator = StrapdownIntegrator(
        (0.0, 0.0, 0.0, 1.0), (0.0, 0.0, 0.0), LATITUDE_RAD, LONGITUDE_RAD, 3.0
    )
    return builder.solution(
        integrator, kalman, 1.0, (0.0, 0.0, 0.0), (0.0, 0.0, 9.8), (False, False, False)
    )


def _builder() -> SolutionBuilder:
    return SolutionBuilder(earth.LocalTangentPlane(LATITUDE_RAD, LONGITUDE_RAD, 0.0))


@pytest.mark.parametrize("variances", [None, (1e-4, 2e-3)])
def test_blocks_are_the_filters_read_only_and_widened_while_distrusted(variances):
    kalman = _random_filter(3)
    builder = _builder()
    builder.distrust(variances)
    solution = _solution(builder, kalman)
    widening = (
        {} if variances is None else dict(zip(("attitude", "velocity"), variances, strict=True))
    )
    for field, name in BLOCK_OF_FIELD.items():
        states = getattr(ERROR_STATES, name)
        expected = kalman.covariance[states, states].copy()
        if name in widening:
            expected[np.diag_indices(3)] += widening[name]
        block = getattr(solution, field)
        assert block.shape == (3, 3) and block.dtype == np.float64
        assert block.tobytes() == expected.tobytes(), field
        assert not block.flags.writeable, field


def test_solutions_share_the_blocks_until_the_covariance_changes():
    kalman = _random_filter(4)
    builder = _builder()
    first = _solution(builder, kalman)
    kalman.covariance = _random_filter(5).covariance
    second = _solution(builder, kalman)
    builder.covariance_changed()
    third = _solution(builder, kalman)
    for field, name in BLOCK_OF_FIELD.items():
        states = getattr(ERROR_STATES, name)
        assert getattr(second, field) is getattr(first, field)
        np.testing.assert_array_equal(getattr(third, field), kalman.covariance[states, states])


def _turning_integrator(rng) -> StrapdownIntegrator:
    """A nominal state away from the origin: tilted, moving, biased, at another place."""
    attitude = rng.normal(size=4)
    return StrapdownIntegrator(
        tuple(attitude / np.linalg.norm(attitude)),
        tuple(rng.normal(scale=3.0, size=3)),
        LATITUDE_RAD + rng.normal(scale=1e-3),
        LONGITUDE_RAD + rng.normal(scale=1e-3),
        rng.normal(scale=20.0),
        tuple(rng.normal(scale=1e-3, size=3)),
        tuple(rng.normal(scale=1e-2, size=3)),
    )


def test_a_solutions_vectors_are_the_interpreters_arithmetic_to_the_bit():
    """The compiled solution against the same sums written out for the interpreter: ω_ib
    and the force less their biases, ω_nb = ω_ib − R_nbᵀ ω_in, and the ``map`` position of
    the plane's own scalar conversion."""
    rng = np.random.default_rng(11)
    builder = _builder()
    kalman = _random_filter(6)
    for _ in range(200):
        integrator = _turning_integrator(rng)
        gyro = tuple(rng.normal(scale=0.3, size=3).tolist())
        force = tuple(rng.normal(loc=(0.0, 0.0, 9.8), scale=2.0).tolist())
        solution = builder.solution(integrator, kalman, 1.0, gyro, force, (False,) * 3)
        rate = np.array(gyro) - np.array(integrator.gyro_bias_rad_s)
        r = integrator.rotation_elements
        ie, in_, iu = integrator.nav_frame_rate_enu_rad_s
        rate_nb = [rate[i] - (r[i] * ie + r[3 + i] * in_ + r[6 + i] * iu) for i in range(3)]
        position = builder.map_plane.enu_from_geodetic_scalar(
            integrator.latitude_rad, integrator.longitude_rad, integrator.altitude_m
        )
        expected = {
            "attitude_xyzw": integrator.attitude_xyzw,
            "angular_rate_body_rad_s": rate,
            "angular_rate_nb_body_rad_s": rate_nb,
            "specific_force_body_mps2": np.array(force) - np.array(integrator.accel_bias_mps2),
            "velocity_enu_mps": integrator.velocity_enu_mps,
            "position_map_m": position,
        }
        for field, values in expected.items():
            array = getattr(solution, field)
            assert array.tobytes() == np.array(values, dtype=float).tobytes(), field


def test_a_solutions_rate_relative_to_enu_and_its_place_follow_the_frames():
    """Physics, not arithmetic: ω_nb turned into ENU is ω_ib turned there less ω_in, and the
    position in the ``map`` plane goes back to the integrator's latitude, longitude and height."""
    rng = np.random.default_rng(12)
    builder = _builder()
    integrator = _turning_integrator(rng)
    gyro = (0.2, -0.1, 0.3)
    solution = builder.solution(
        integrator, _random_filter(7), 1.0, gyro, (0.0, 0.0, 9.8), (False,) * 3
    )
    rotation_nb = integrator.rotation_nb
    np.testing.assert_allclose(
        rotation_nb @ solution.angular_rate_nb_body_rad_s,
        rotation_nb @ solution.angular_rate_body_rad_s
        - np.array(integrator.nav_frame_rate_enu_rad_s),
        atol=1e-15,
    )
    latitude, longitude, altitude = builder.map_plane.geodetic_from_enu(solution.position_map_m)
    assert latitude == pytest.approx(integrator.latitude_rad, abs=1e-12)
    assert longitude == pytest.approx(integrator.longitude_rad, abs=1e-12)
    assert altitude == pytest.approx(integrator.altitude_m, abs=1e-6)


@pytest.mark.parametrize("variances", [None, (1e-4, 2e-3)])
def test_a_solutions_row_is_its_own_numbers_to_the_bit(variances):
    """Written as rows (a run that makes no message of them), the solutions keep the numbers
    the built ones carry, column by column, distrusted or not; taken, the oldest rows leave
    and the rest stay in order."""
    rng = np.random.default_rng(13)
    built, written = _builder(), SolutionBuilder(_builder().map_plane, SolutionRows())
    solutions = []
    for index in range(300):
        kalman = _random_filter(100 + index)
        for builder in (built, written):
            builder.distrust(variances)
            builder.covariance_changed()
            builder.biases_changed()
        integrator = _turning_integrator(rng)
        gyro = tuple(rng.normal(scale=0.3, size=3).tolist())
        force = tuple(rng.normal(loc=(0.0, 0.0, 9.8), scale=2.0).tolist())
        arguments = (integrator, kalman, 10.0 + index, gyro, force, (False,) * 3)
        solutions.append(built.emit(*arguments))
        assert written.emit(*arguments) == 10.0 + index
    first = written.rows.take(100)
    rows = np.concatenate((first, written.rows.take(200)))
    assert written.rows.count == 0
    for solution, values in zip(solutions, rows, strict=True):
        expected = [
            (row.STAMP, [solution.t_s]),
            (row.ATTITUDE_XYZW, solution.attitude_xyzw),
            (row.ANGULAR_RATE, solution.angular_rate_body_rad_s),
            (row.VELOCITY_ENU, solution.velocity_enu_mps),
            (
                row.GEODETIC,
                [solution.latitude_deg, solution.longitude_deg, solution.altitude_m],
            ),
            (row.ATTITUDE_COVARIANCE, solution.attitude_covariance_rad2.ravel()),
            (row.VELOCITY_COVARIANCE, solution.velocity_covariance_m2s2.ravel()),
            (row.POSITION_COVARIANCE, solution.position_covariance_m2.ravel()),
            (row.GYRO_BIAS_COVARIANCE, solution.gyro_bias_covariance_rad2_s2.ravel()),
            (row.POSITION_MAP, solution.position_map_m),
            (row.SPECIFIC_FORCE, solution.specific_force_body_mps2),
        ]
        for columns, numbers in expected:
            kept = np.atleast_1d(values[columns])
            assert kept.tobytes() == np.asarray(numbers, dtype=float).tobytes(), columns


def test_more_rows_are_taken_than_written_is_an_error():
    rows = SolutionRows()
    with pytest.raises(ValueError, match="1 rows asked for, 0 written"):
        rows.take(1)


def test_the_block_grows_and_keeps_its_rows_in_order():
    """More rows than the first block holds, taken in parts while more are written: every
    stamp comes out once, in the order written."""
    rows = SolutionRows()
    state = np.zeros(STATE_SIZE)
    covariance = _random_filter(8).covariance
    indices = np.arange(36, dtype=np.int64).reshape(4, 3, 3)

    def write(stamps):
        for t_s in stamps:
            rows.append(
                float(t_s),
                state,
                (0.0,) * 3,
                (0.0, 0.0, 9.8),
                np.zeros(12),
                covariance,
                indices,
                None,
            )

    write(range(10_000))
    taken = [rows.take(3_000)]
    write(range(10_000, 12_000))
    taken.append(rows.take(rows.count))
    stamps = np.concatenate(taken)[:, row.STAMP]
    np.testing.assert_array_equal(stamps, np.arange(12_000, dtype=float))
    assert rows.count == 0
