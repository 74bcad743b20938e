"""An imported record's facts survive the MCAP metadata record's strings."""

from __future__ import annotations

from buoy_common.record_facts import ImportedRecord
from buoy_common.records.screening import FieldCounts

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
