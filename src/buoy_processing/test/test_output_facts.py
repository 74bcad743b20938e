"""What the outputs say about a run follows from what the run had: the north of the heading the
fusion used and the declination actually applied, the sensors it accepted (a suspended one said
so), a site only when one was given or measured, and the span of the samples."""

from __future__ import annotations

import dataclasses
import math

import pytest

from buoy_nav.config import FusionConfig
from buoy_processing.output_facts import (
    MAGNETIC_NORTH,
    TRUE_NORTH,
    UNKNOWN_NORTH,
    SourceUse,
    output_facts,
)

MOTION_PACK_TOPICS = ("imu/data_raw", "imu/data", "anemometer/wind", "anemometer/temperature")
GNSS_TOPICS = ("imu/data_raw", "gnss/fix", "gnss/vel", "gnss/heading", "anemometer/wind")


def _config(**changes) -> FusionConfig:
    return dataclasses.replace(FusionConfig(), **changes)


def test_a_magnetic_motion_pack_without_declination_gives_magnetic_north():
    config = _config(ahrs_yaw_reference="magnetic_north", magnetic_declination_deg=0.0)
    uses = {"ahrs": SourceUse(12_000), "moored": SourceUse(1_200), "gnss_fix": SourceUse(0)}
    facts = output_facts(config, MOTION_PACK_TOPICS, uses, [(100.0, 1300.8), (100.5, 1300.0)])
    assert facts.north == MAGNETIC_NORTH
    assert "no declination applied" in facts.clockwise_from()
    assert facts.north_token == "magnetic_north"
    assert "GNSS" not in facts.sensor_text()
    assert "motion pack" in facts.sensor_text()
    assert "sonic anemometer with temperature" in facts.sensor_text()
    assert facts.site_deg is None and not facts.position_known
    assert (facts.first_sample_s, facts.last_sample_s) == (100.0, 1300.8)


@pytest.mark.parametrize(
    ("declination_deg", "basis"),
    [(math.nan, "World Magnetic Model"), (-12.5, "-12.5 deg")],
)
def test_a_magnetic_heading_with_a_declination_applied_gives_true_north(declination_deg, basis):
    config = _config(
        ahrs_yaw_reference="magnetic_north",
        magnetic_declination_deg=declination_deg,
        site_latitude_deg=41.5,
        site_longitude_deg=-70.7,
    )
    facts = output_facts(config, MOTION_PACK_TOPICS, {"ahrs": SourceUse(10)}, [])
    assert facts.north == TRUE_NORTH
    assert basis in facts.north_basis
    assert facts.site_deg == (41.5, -70.7) and facts.position_known
    assert facts.first_sample_s is None


def test_gnss_headings_give_true_north_and_a_measured_position():
    uses = {
        "gnss_fix": SourceUse(600),
        "gnss_velocity": SourceUse(600),
        "gnss_heading": SourceUse(600),
        "magnetometer": SourceUse(0),
    }
    facts = output_facts(FusionConfig(), GNSS_TOPICS, uses, [(0.0, 60.0)])
    assert facts.north == TRUE_NORTH
    assert facts.position_from_gnss and facts.site_deg is None and facts.position_known
    assert "dual-antenna GNSS" in facts.sensor_text()
    # a source the bag carried but the fusion never used is not claimed
    assert "magnetometer" not in facts.sensor_text()


def test_a_suspended_source_is_named_as_suspended():
    uses = {
        "gnss_fix": SourceUse(600),
        "gnss_heading": SourceUse(600),
        "magnetometer": SourceUse(40, suspended_at_end=True),
    }
    facts = output_facts(FusionConfig(), GNSS_TOPICS, uses, [])
    assert "magnetometer (heading), suspended by the end" in facts.sensors


def test_a_run_without_any_heading_states_no_north():
    facts = output_facts(FusionConfig(), GNSS_TOPICS, {"gnss_heading": SourceUse(0)}, [])
    assert facts.north == UNKNOWN_NORTH
    assert facts.north_token == "unknown_north"


def test_a_true_and_an_uncorrected_magnetic_heading_fused_together_are_said_to_be_biased():
    config = _config(ahrs_yaw_reference="magnetic_north", magnetic_declination_deg=0.0)
    uses = {"gnss_fix": SourceUse(600), "gnss_heading": SourceUse(600), "ahrs": SourceUse(6000)}
    facts = output_facts(config, (*GNSS_TOPICS, "imu/data"), uses, [])
    assert facts.north == TRUE_NORTH
    assert "biased toward magnetic north" in facts.north_basis
