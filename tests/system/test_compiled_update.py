"""The motion pack's compiled update against the interpreted one, on the simulator.

The engine applies a stamp of one measurement of the pack's attitude through the source's
compiled update (model, gate, Joseph update and reset in one call) and books it as the gate
books it; a measurement the compiled gate rejects goes the interpreted way. Run with the
compiled update and without it, the same messages must give the same solutions, counters and
source health to the bit: for a pack that agrees with the IMU (every update compiled) and for
a pack whose noise is twenty times the tenth of a degree it claims, each sample weighted as
independent (its gate rejects many, the rejections are booked the interpreted way, and the
integrity monitor realigns the filter).
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from test_nav_sensor_sets import fuse, moored_config, scenario_messages

from buoy_common.contract import Reason
from buoy_nav.aiding.ahrs_attitude import AhrsAttitudeSource

WRONG_PACK = ("sensors.ahrs.noise_deg=2.0", "sensors.ahrs.claimed_sigma_deg=[0.1, 0.1, 0.1]")
SAMPLES_INDEPENDENT = {"ahrs_error_correlation_time_s": 0.1}


def runs(overrides, monkeypatch):
    """The engine and its solutions on 200 s of the moored motion-pack scenario, with the
    compiled update and without it."""
    scenario, _, messages = scenario_messages("moored_motion_pack", 200.0, overrides)
    config = moored_config(use_magnetometer=False, ahrs_lag_s=0.2, **SAMPLES_INDEPENDENT)
    compiled = fuse(config, messages, scenario)
    with monkeypatch.context() as patch:
        patch.setattr(AhrsAttitudeSource, "has_compiled_update", False)
        interpreted = fuse(config, messages, scenario)
    return compiled, interpreted


def assert_same_solutions(first, second):
    assert len(first) == len(second)
    for a, b in zip(first, second, strict=True):
        for field in dataclasses.fields(a):
            value, other = getattr(a, field.name), getattr(b, field.name)
            assert np.array_equal(value, other), field.name


@pytest.mark.parametrize("overrides", [(), WRONG_PACK], ids=["agreeing pack", "wrong pack"])
def test_compiled_and_interpreted_updates_give_the_same_filter(overrides, monkeypatch):
    (engine, solutions, _, _), (reference, expected, _, _) = runs(overrides, monkeypatch)
    assert len(solutions) > 1000
    assert_same_solutions(solutions, expected)
    health, expected_health = engine.health(), reference.health()
    assert health.counters == expected_health.counters
    assert health.source_health == expected_health.source_health
    pack = health.counters[AhrsAttitudeSource.kind]
    assert pack.accepted > 100
    if overrides:
        assert pack.rejected[Reason.GATE] > 100
        assert engine.health().realignments > 0
