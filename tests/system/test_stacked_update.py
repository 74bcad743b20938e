"""A GNSS epoch's compiled gates and stacked update against the interpreted ones, on the simulator.

When every measurement of a stamp comes from a source whose model is one compiled call (the
position, velocity and antenna vectors, the magnetometer's field), the engine gates them and applies
them in one compiled call and books them as the gates book them; a stamp with a measurement its gate
rejects, or of a suspended source, goes the interpreted way. Run with the compiled models' path and
without it, the same messages must give the same solutions, counters and source health to the bit:
for a three-antenna buoy in a sea whose every epoch passes, for a receiver's heading, for a moored
buoy without GNSS, for a single antenna with a magnetometer that a passing hull gets suspended, and
for a filter told that its antennas are 1.5 m from where they are, whose positions are rejected,
whose velocity is suspended and which realigns.
"""

from __future__ import annotations

import numpy as np
from test_compiled_update import assert_same_solutions
from test_nav_sensor_sets import (
    MAGNETOMETER,
    calibrated_magnetometer,
    fuse,
    moored_config,
    scenario_messages,
)
from test_nav_simulated import simulate

from buoy_common.contract import Reason
from buoy_nav.aiding import (
    GnssBaselineSource,
    GnssBaselineTertiarySource,
    GnssFixSource,
    GnssHeadingSource,
    GnssVelocitySource,
    MagnetometerSource,
    MooredSource,
)
from buoy_nav.config import FusionConfig

COMPILED_MODEL_SOURCES = (
    GnssFixSource,
    GnssVelocitySource,
    GnssBaselineSource,
    GnssBaselineTertiarySource,
    GnssHeadingSource,
    MooredSource,
    MagnetometerSource,
)


def with_and_without_the_compiled_path(run, monkeypatch):
    """``run()`` as the engine runs, then with every source's compiled model path off."""
    compiled = run()
    with monkeypatch.context() as patch:
        for source_class in COMPILED_MODEL_SOURCES:
            patch.setattr(source_class, "has_compiled_model", False)
        interpreted = run()
    return compiled, interpreted


def assert_same_engine(engine, reference):
    health, expected = engine.health(), reference.health()
    assert health.counters == expected.counters
    assert health.source_health == expected.source_health
    assert health.realignments == expected.realignments


def test_three_antennas_in_a_sea_give_the_same_filter(monkeypatch):
    def run():
        return simulate("sea_state", duration_s=90.0, tertiary_antenna_body_m=(0.0, 0.75, 1.0))

    (engine, solutions, _), (reference, expected, _) = with_and_without_the_compiled_path(
        run, monkeypatch
    )
    assert len(solutions) > 5000
    assert_same_solutions(solutions, expected)
    assert_same_engine(engine, reference)
    counters = engine.health().counters
    for source_class in COMPILED_MODEL_SOURCES[:4]:  # the heading is superseded by the vector
        assert counters[source_class.kind].accepted > 500, source_class.kind


def test_a_receivers_heading_gives_the_same_filter(monkeypatch):
    """The heading (an azimuth, not the vector) with the position and velocity."""

    def run():
        return simulate("sea_state", duration_s=60.0, baseline_until_s=0.0)

    (engine, solutions, _), (reference, expected, _) = with_and_without_the_compiled_path(
        run, monkeypatch
    )
    assert_same_solutions(solutions, expected)
    assert_same_engine(engine, reference)
    assert engine.health().counters[GnssHeadingSource.kind].accepted > 300


def test_a_mooring_without_gnss_gives_the_same_filter(monkeypatch):
    """The mooring's anchor, once a second, beside the motion pack's attitude (whose own
    compiled update is used either way)."""
    scenario, _, messages = scenario_messages("moored_motion_pack", 200.0)
    config = moored_config(use_magnetometer=False, ahrs_lag_s=0.2)

    (engine, solutions, _, _), (reference, expected, _, _) = with_and_without_the_compiled_path(
        lambda: fuse(config, messages, scenario), monkeypatch
    )
    assert_same_solutions(solutions, expected)
    assert_same_engine(engine, reference)
    assert engine.health().counters[MooredSource.kind].accepted > 100


def test_a_single_antenna_and_a_magnetometer_give_the_same_filter(monkeypatch):
    """The magnetometer's field (gated with one sample's noise, updated with its share of the
    calibration's) stacked with the position and velocity, and a steel hull passing that gets
    the magnetometer suspended for a while."""
    scenario, _, messages = scenario_messages(
        "sea_state",
        120.0,
        (
            "sensors.gnss.receiver=single_antenna",
            *MAGNETOMETER,
            "sensors.magnetometer.disturbances_s=[[60, 70]]",
        ),
    )
    config = FusionConfig(
        site_latitude_deg=35.0, site_longitude_deg=120.0, **calibrated_magnetometer()
    )
    (engine, solutions, _, _), (reference, expected, _, _) = with_and_without_the_compiled_path(
        lambda: fuse(config, messages, scenario), monkeypatch
    )
    assert_same_solutions(solutions, expected)
    assert_same_engine(engine, reference)
    counters = engine.health().counters[MagnetometerSource.kind]
    assert counters.accepted > 500 and counters.rejected.get(Reason.SUSPENDED, 0) > 0


def test_a_wrong_lever_arm_gives_the_same_rejections_and_filter(monkeypatch):
    """Both antennas 1.5 m off where they are: the baseline is right, the position and velocity
    are not, and each suspension, realignment and rejection must be the same."""
    scenario, _, messages = scenario_messages("sea_state", 120.0)
    right = FusionConfig()
    offset = np.array((0.0, 1.5, 0.0))
    config = FusionConfig(
        primary_antenna_body_m=tuple(np.add(right.primary_antenna_body_m, offset)),
        secondary_antenna_body_m=tuple(np.add(right.secondary_antenna_body_m, offset)),
    )

    (engine, solutions, _, _), (reference, expected, _, _) = with_and_without_the_compiled_path(
        lambda: fuse(config, messages, scenario), monkeypatch
    )
    assert_same_solutions(solutions, expected)
    assert_same_engine(engine, reference)
    health = engine.health()
    counters = health.counters
    assert counters["gnss_fix"].rejected[Reason.GATE] > 50
    assert health.source_health["gnss_velocity"].suspensions > 0
    assert health.realignments > 0
    assert counters["gnss_baseline"].accepted > 300
