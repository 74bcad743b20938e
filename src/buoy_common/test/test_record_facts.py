"""RecordFacts: the north reference and declination follow from the heading references a run
fused and its parameters; the site from the record or the parameters; an imported record's
facts survive the MCAP metadata record's strings."""

from __future__ import annotations

import math

import pytest

from buoy_common.record_facts import ImportedRecord, record_facts
from buoy_common.records.screening import FieldCounts

NAN = math.nan
PACK = ("imu/data_raw", "imu/data", "anemometer/wind")
MAGNETOMETER = ("imu/data_raw", "imu/mag", "gnss/fix", "anemometer/wind")
ANTENNAS = ("imu/data_raw", "gnss/fix", "gnss/baseline", "anemometer/wind")
COVERAGE = (10**18, 10**18 + 60 * 10**9)

RECORD = ImportedRecord(
    record="day.dat",
    column_map="map.yaml",
    description="a sonic and a motion pack",
    start_ns=1418884200 * 10**9 + 123_456_789,
    start_source="command line",
    sensors=("sonic", "imu", "ahrs"),
    yaw_reference="magnetic_north",
    site_deg=(44.64, -124.3),
    site_source="column map",
    field_counts={"anemometer.u": FieldCounts(read=10, filled=3, invalid=1, out_of_range=2)},
    temperatures_without_wind=4,
)


def test_an_imported_records_facts_survive_their_strings():
    metadata = RECORD.to_metadata()
    assert all(isinstance(v, str) for v in metadata.values())
    assert ImportedRecord.from_metadata(metadata) == RECORD
    assert RECORD.field_counts["anemometer.u"].valid == 4


@pytest.mark.parametrize(
    ("topics", "yaw_reference", "declination_deg", "north", "applied", "declination"),
    [
        # a magnetic pack: the declination turns it true, given or from the model
        (PACK, "magnetic_north", 12.5, "true_north", True, 12.5),
        (PACK, "magnetic_north", NAN, "true_north", True, None),
        # 0 given: left magnetic, as OOI's products of its FDCHP record
        (PACK, "magnetic_north", 0.0, "magnetic_north", False, None),
        (PACK, "true_north", 0.0, "true_north", False, None),
        (MAGNETOMETER, "true_north", 0.0, "magnetic_north", False, None),
        (MAGNETOMETER, "true_north", -3.0, "true_north", True, -3.0),
        # antennas give true north whatever a magnetic sensor beside them says
        (ANTENNAS, "magnetic_north", 0.0, "true_north", False, None),
        ((*ANTENNAS, "imu/mag"), "true_north", 0.0, "true_north", False, None),
    ],
)
def test_the_north_reference_follows_the_headings_fused(
    topics, yaw_reference, declination_deg, north, applied, declination
):
    facts = record_facts(None, topics, yaw_reference, declination_deg, (NAN, NAN), COVERAGE)
    assert (facts.north_reference, facts.declination_applied) == (north, applied)
    assert facts.declination_deg == declination


def test_the_site_comes_from_the_record_or_the_parameters():
    from_record = record_facts(RECORD, PACK, "magnetic_north", 0.0, RECORD.site_deg, COVERAGE)
    assert (from_record.site_deg, from_record.site_source) == (RECORD.site_deg, "record")
    overridden = record_facts(RECORD, PACK, "magnetic_north", 0.0, (45.0, -124.0), COVERAGE)
    assert (overridden.site_deg, overridden.site_source) == ((45.0, -124.0), "parameters")
    unknown = record_facts(None, PACK, "magnetic_north", 0.0, (NAN, NAN), COVERAGE)
    assert not unknown.site_known and unknown.site_source is None
    assert (
        not unknown.has_gnss
        and record_facts(None, ANTENNAS, "true_north", NAN, (NAN, NAN), COVERAGE).has_gnss
    )
    assert (unknown.coverage_start_ns, unknown.coverage_end_ns) == COVERAGE
