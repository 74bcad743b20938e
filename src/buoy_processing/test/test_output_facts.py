"""What the outputs say about a run follows from what the run had: the north of the heading the
fusion used and the declination actually applied, the sensors it accepted (a suspended one said
so), a site only when one was given or measured (and where it came from), the span of the
samples and the imported record; the facts survive the MCAP metadata record's strings."""

from __future__ import annotations

import dataclasses
import math

import pytest

from buoy_common.record_facts import ImportedRecord
from buoy_common.records.screening import FieldCounts
from buoy_nav.config import ConfigError, FusionConfig
from buoy_processing.output_facts import (
    MAGNETIC_NORTH,
    SITE_FROM_PARAMETERS,
    SITE_FROM_RECORD,
    TRUE_NORTH,
    UNKNOWN_NORTH,
    OutputFacts,
    SourceUse,
    output_facts,
)

# Valid samples of the flow sensors' topics
MOTION_PACK_TOPICS = {"anemometer/wind": 12_000, "anemometer/temperature": 12_000}
GNSS_TOPICS = {"anemometer/wind": 600}


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
    [(math.nan, "World Magnetic Model at 41.50000, -70.70000 deg"), (-12.5, "-12.5 deg")],
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


def test_the_models_declination_is_said_to_be_taken_at_the_gnss_fixes():
    config = _config(ahrs_yaw_reference="magnetic_north")
    uses = {"gnss_fix": SourceUse(600), "ahrs": SourceUse(6000)}
    facts = output_facts(config, GNSS_TOPICS, uses, [])
    assert facts.north == TRUE_NORTH
    assert "World Magnetic Model at the positions of the GNSS fixes" in facts.north_basis


def test_a_fusion_that_never_aligned_states_no_heading_and_no_navigation_sensor():
    config = _config(ahrs_yaw_reference="magnetic_north")
    # the motion pack's samples fed an alignment that never completed
    uses = {"imu": SourceUse(3000), "ahrs": SourceUse(3000)}
    facts = output_facts(config, MOTION_PACK_TOPICS, uses, [], aligned=False)
    assert facts.north == UNKNOWN_NORTH
    assert "never aligned" in facts.north_sentence()
    assert "World Magnetic Model" not in facts.north_sentence()
    assert "true north" not in facts.north_sentence()
    assert facts.sensors == ("sonic anemometer with temperature",)
    assert facts.declination_deg is None and not facts.position_known


@pytest.mark.parametrize(
    ("valid_flow_samples", "words"),
    [
        (
            {"anemometer/wind": 0, "anemometer/temperature": 0},
            "sonic anemometer (no valid wind sample)",
        ),
        (
            {"anemometer/wind": 0, "anemometer/temperature": 50},
            "sonic anemometer (no valid wind sample)",
        ),
        ({"anemometer/wind": 50, "anemometer/temperature": 0}, "sonic anemometer"),
        ({"anemometer/wind": 50}, "sonic anemometer"),
        (
            {"anemometer/wind": 50, "anemometer/temperature": 50},
            "sonic anemometer with temperature",
        ),
        ({"dvl/velocity": 0}, "DVL (no valid sample)"),
        ({"dvl/velocity": 10}, "DVL"),
    ],
)
def test_a_flow_sensor_is_named_with_what_it_delivered(valid_flow_samples, words):
    facts = output_facts(FusionConfig(), valid_flow_samples, {"gnss_heading": SourceUse(9)}, [])
    assert facts.sensors[-1] == words


def test_a_run_without_any_heading_states_no_north():
    facts = output_facts(FusionConfig(), GNSS_TOPICS, {"gnss_heading": SourceUse(0)}, [])
    assert facts.north == UNKNOWN_NORTH
    assert facts.north_token == "unknown_north"


def test_a_true_and_an_uncorrected_magnetic_heading_fused_together_are_said_to_be_biased():
    config = _config(ahrs_yaw_reference="magnetic_north", magnetic_declination_deg=0.0)
    uses = {"gnss_fix": SourceUse(600), "gnss_heading": SourceUse(600), "ahrs": SourceUse(6000)}
    facts = output_facts(config, GNSS_TOPICS, uses, [])
    assert facts.north == TRUE_NORTH
    assert "biased toward magnetic north" in facts.north_basis


RECORD = ImportedRecord(
    record="day.dat",
    column_map="map.yaml",
    description="a sonic and a motion pack",
    start_ns=1418884200 * 10**9,
    start_source="command line",
    sensors=("sonic", "imu", "ahrs"),
    yaw_reference="magnetic_north",
    site_deg=(44.64, -124.3),
    site_source="column map",
    field_counts={"anemometer.u": FieldCounts(read=10, filled=3, invalid=1, out_of_range=2)},
)


@pytest.mark.parametrize(
    ("sources", "yaw_reference", "declination_deg", "north", "applied_deg"),
    [
        # a magnetic pack: the declination turns it true; only a number is stated as one
        ({"ahrs": SourceUse(10)}, "magnetic_north", 12.5, TRUE_NORTH, 12.5),
        ({"ahrs": SourceUse(10)}, "magnetic_north", math.nan, TRUE_NORTH, None),
        # 0 given: left magnetic, as OOI's products of its FDCHP record
        ({"ahrs": SourceUse(10)}, "magnetic_north", 0.0, MAGNETIC_NORTH, None),
        # a true-north pack turns nothing, whatever the declination
        ({"ahrs": SourceUse(10)}, "true_north", 7.0, TRUE_NORTH, None),
        ({"magnetometer": SourceUse(10)}, "true_north", -3.0, TRUE_NORTH, -3.0),
        # antennas alone: the declination enters nothing
        ({"gnss_heading": SourceUse(10)}, "magnetic_north", 5.0, TRUE_NORTH, None),
    ],
)
def test_the_declination_is_stated_only_when_it_turned_a_magnetic_heading(
    sources, yaw_reference, declination_deg, north, applied_deg
):
    config = _config(ahrs_yaw_reference=yaw_reference, magnetic_declination_deg=declination_deg)
    facts = output_facts(config, MOTION_PACK_TOPICS, sources, [])
    assert (facts.north, facts.declination_deg) == (north, applied_deg)


def test_the_site_says_whether_it_is_the_records_or_the_parameters():
    pack = {"ahrs": SourceUse(10)}
    record_site = _config(site_latitude_deg=44.64, site_longitude_deg=-124.3)
    facts = output_facts(record_site, MOTION_PACK_TOPICS, pack, [], RECORD)
    assert (facts.site_deg, facts.site_source) == ((44.64, -124.3), SITE_FROM_RECORD)
    other_site = _config(site_latitude_deg=45.0, site_longitude_deg=-124.0)
    facts = output_facts(other_site, MOTION_PACK_TOPICS, pack, [], RECORD)
    assert (facts.site_deg, facts.site_source) == ((45.0, -124.0), SITE_FROM_PARAMETERS)
    assert "the parameters, 45.00000, -124.00000 deg (not measured)" in facts.site_text()
    facts = output_facts(FusionConfig(), MOTION_PACK_TOPICS, pack, [], RECORD)
    assert (facts.site_deg, facts.site_source, facts.site_text()) == (
        None,
        None,
        "position unknown",
    )


def test_the_record_its_start_and_its_screening_are_stated():
    facts = output_facts(FusionConfig(), MOTION_PACK_TOPICS, {"ahrs": SourceUse(1)}, [], RECORD)
    assert "day.dat" in facts.record_text() and "map.yaml" in facts.record_text()
    assert "2014-12-18T06:30:00.000Z (start from the command line)" in facts.record_text()
    assert "anemometer.u 10/3/1/2" in facts.screening_text()
    plain = output_facts(FusionConfig(), MOTION_PACK_TOPICS, {"ahrs": SourceUse(1)}, [])
    assert (plain.record_text(), plain.screening_text()) == ("", "")


@pytest.mark.parametrize("with_record", [False, True])
def test_the_facts_survive_their_strings(with_record):
    config = _config(
        ahrs_yaw_reference="magnetic_north",
        magnetic_declination_deg=-12.5,
        site_latitude_deg=41.5,
        site_longitude_deg=-70.7,
    )
    uses = {"ahrs": SourceUse(10), "magnetometer": SourceUse(3, suspended_at_end=True)}
    record = RECORD if with_record else None
    facts = output_facts(config, MOTION_PACK_TOPICS, uses, [(100.25, 1300.5)], record)
    metadata = facts.to_metadata()
    assert all(isinstance(value, str) for value in metadata.values())
    assert OutputFacts.from_metadata(metadata, record) == facts


def test_a_latitude_alone_serves_gravity_and_is_no_position():
    config = _config(
        ahrs_yaw_reference="magnetic_north", magnetic_declination_deg=0.0, site_latitude_deg=38.5
    )
    facts = output_facts(config, MOTION_PACK_TOPICS, {"ahrs": SourceUse(10)}, [])
    assert (facts.site_deg, facts.latitude_only_deg) == (None, 38.5)
    assert not facts.position_known
    assert facts.site_text() == "latitude 38.50000 deg given for gravity; position unknown"


def test_a_latitude_alone_with_the_declination_from_the_model_is_refused_by_name():
    with pytest.raises(ConfigError, match=r"'site\.longitude_deg'.*magnetic\.declination_deg"):
        _config(site_latitude_deg=38.5)
    with pytest.raises(ConfigError, match=r"'site\.latitude_deg'"):
        _config(site_longitude_deg=-70.0, magnetic_declination_deg=0.0)
    # the map origin's longitude completes the site
    config = _config(
        site_latitude_deg=38.5,
        origin_latitude_deg=38.0,
        origin_longitude_deg=-70.0,
        origin_altitude_m=0.0,
    )
    assert config.site_position_deg == (38.5, -70.0)
