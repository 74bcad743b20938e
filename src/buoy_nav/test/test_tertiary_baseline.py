"""The third antenna's baseline vector: its model, its layout check and its rejections."""

import math

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from buoy_common.contract import Reason
from buoy_nav.aiding import GnssBaseline, GnssBaselineSource, GnssBaselineTertiary
from buoy_nav.aiding.base import LinearisationPoint
from buoy_nav.aiding.gnss_baseline_tertiary import GnssBaselineTertiarySource
from buoy_nav.config import ConfigError, FusionConfig
from buoy_nav.engine import FusionEngine
from buoy_nav.error_state_filter import ERROR_STATES, NavState, inject_error_state

STATES = ERROR_STATES
PRIMARY = (-0.75, 0.0, 1.0)
SECONDARY = (0.75, 0.0, 1.0)
TERTIARY = (0.0, 0.9, 1.1)
CONFIG = FusionConfig(
    primary_antenna_body_m=PRIMARY,
    secondary_antenna_body_m=SECONDARY,
    tertiary_antenna_body_m=TERTIARY,
)
TERTIARY_BASELINE = np.subtract(TERTIARY, PRIMARY)


def state_at(roll_deg, pitch_deg, yaw_deg) -> NavState:
    rotation = Rotation.from_euler("ZYX", np.radians([yaw_deg, pitch_deg, roll_deg]))
    return NavState(tuple(rotation.as_quat()), np.zeros(3), 0.6, 2.1, 3.0, np.zeros(3), np.zeros(3))


def point_at(state: NavState) -> LinearisationPoint:
    return LinearisationPoint(state, state.rotation_nb, (0.0, 0.0, 0.0), (0.0, 0.0, 0.0))


@pytest.mark.parametrize("attitude_deg", [(0, 0, 30), (35, -20, 120), (-60, 45, -170)])
def test_jacobian_matches_finite_differences_and_prediction_is_the_rotated_lever(attitude_deg):
    source = GnssBaselineTertiarySource(CONFIG, STATES)
    state = state_at(*attitude_deg)
    measurement = GnssBaselineTertiary(np.zeros(3))
    model = source.model(measurement, point_at(state))
    np.testing.assert_allclose(model.predicted, state.rotation_nb @ TERTIARY_BASELINE)
    step = 1e-6
    columns = []
    for index in range(STATES.dim):
        delta = np.zeros(STATES.dim)
        delta[index] = step
        plus = source.model(measurement, point_at(inject_error_state(state, delta))).predicted
        minus = source.model(measurement, point_at(inject_error_state(state, -delta))).predicted
        columns.append((plus - minus) / (2 * step))
    np.testing.assert_allclose(model.jacobian, np.column_stack(columns), atol=1e-7)


def attitude_rank(config) -> int:
    """Rank of the attitude columns of the two baselines' stacked Jacobians."""
    point = point_at(state_at(3.0, -2.0, 40.0))
    first = GnssBaselineSource(config, STATES).model(GnssBaseline(np.zeros(3)), point)
    second = GnssBaselineTertiarySource(config, STATES).model(
        GnssBaselineTertiary(np.zeros(3)), point
    )
    stacked = np.vstack((first.jacobian, second.jacobian))[:, STATES.attitude]
    return int(np.linalg.matrix_rank(stacked, tol=1e-6))


def test_two_baselines_observe_all_three_angles_and_one_leaves_the_rotation_about_it():
    assert attitude_rank(CONFIG) == 3
    collinear = FusionConfig(
        primary_antenna_body_m=PRIMARY,
        secondary_antenna_body_m=SECONDARY,
        tertiary_antenna_body_m=(1.5, 0.0, 1.0),
    )
    assert attitude_rank(collinear) == 2


def test_near_collinear_layout_is_reported_and_its_baselines_not_fused():
    """A third antenna 5° off the first baseline's line: a valid configuration, reported by the
    source and rejected as geometry, message by message."""
    off_line = (0.75 + 1.5 * math.cos(math.radians(5)), 1.5 * math.sin(math.radians(5)), 1.0)
    config = FusionConfig(
        primary_antenna_body_m=PRIMARY,
        secondary_antenna_body_m=SECONDARY,
        tertiary_antenna_body_m=off_line,
    )
    source = GnssBaselineTertiarySource(config, STATES)
    assert "near-collinear" in source.configuration_problem
    assert source.validated(GnssBaselineTertiary(np.subtract(off_line, PRIMARY))) == (
        Reason.GEOMETRY
    )
    assert GnssBaselineTertiarySource(CONFIG, STATES).configuration_problem is None


def test_length_disagreeing_with_the_antennas_is_rejected_and_counted():
    engine = FusionEngine(CONFIG)
    length = np.linalg.norm(TERTIARY_BASELINE)
    direction = TERTIARY_BASELINE / length
    tolerance = CONFIG.gnss_tertiary_length_tolerance_m
    engine.add_imu(0.0, np.zeros(3), np.array((0.0, 0.0, 9.8)))
    engine.add_measurement(0.1, GnssBaselineTertiary(direction * (length + 0.5 * tolerance)))
    engine.add_measurement(0.2, GnssBaselineTertiary(direction * (length + 2.0 * tolerance)))
    engine.add_measurement(0.3, GnssBaselineTertiary(direction * (length - 2.0 * tolerance)))
    counters = engine.health().counters["gnss_baseline_tertiary"]
    assert counters.rejected == {Reason.OUT_OF_RANGE: 2}


def test_without_a_tertiary_antenna_the_source_is_off_and_a_close_one_is_refused():
    assert not GnssBaselineTertiarySource.enabled_by(FusionConfig())
    assert not GnssBaselineTertiarySource.enabled_by(
        FusionConfig(tertiary_antenna_body_m=TERTIARY, use_gnss_baseline_tertiary=False)
    )
    engine = FusionEngine(FusionConfig())
    engine.add_measurement(0.1, GnssBaselineTertiary(TERTIARY_BASELINE))
    assert engine.health().counters["gnss_baseline_tertiary"].rejected == {Reason.DISABLED: 1}
    with pytest.raises(ConfigError, match=r"gnss\.tertiary_antenna"):
        FusionConfig(tertiary_antenna_body_m=(-0.7, 0.0, 1.0))
    with pytest.raises(ConfigError, match=r"gnss\.tertiary_antenna"):
        FusionConfig(tertiary_antenna_body_m=(0.0, math.nan, 1.0))
