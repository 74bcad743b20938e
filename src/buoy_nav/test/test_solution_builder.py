"""The covariance blocks a solution carries: the filter's own, read-only, widened while the
filter is distrusted, and shared by consecutive solutions until the covariance changes."""

import numpy as np
import pytest

from buoy_nav import earth
from buoy_nav.error_state_filter import ERROR_STATES, ErrorStateFilter
from buoy_nav.mechanization import StrapdownIntegrator
from buoy_nav.solution import NavSolution, SolutionBuilder

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
