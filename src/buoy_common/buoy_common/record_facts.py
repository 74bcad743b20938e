"""What is known about an imported bag's data beyond its samples: the facts of the record it was
imported from, carried in the bag.

:class:`ImportedRecord` is what ``import_records`` knows from the column map and its command
line: the north reference of the motion pack's heading, the site, the sensors the record has,
when it starts and who said so, and how each field was screened. It travels inside the bag's
MCAP file as one metadata record named :data:`RECORD_METADATA_NAME` (a map of strings, which
every MCAP reader lists: ``mcap`` library, ``mcap list metadata``, Foxglove), so it stays with
the data when the MCAP file is copied alone. :func:`read_imported_record` reads it back.

The offline tools take its parameter facts (:meth:`ImportedRecord.parameter_defaults`) as
defaults under the user's parameter files: a value given in a file wins, and nothing the map
said has to be said again.

What a processed bag's outputs say about the run (north, sensors, site, span, and this record)
is :class:`buoy_processing.output_facts.OutputFacts`.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from buoy_common.bag_io import BagError
from buoy_common.contract import seconds_to_iso8601
from buoy_common.records.screening import FieldCounts

RECORD_METADATA_NAME = "buoy_record"
"""Name of the MCAP metadata record holding an imported record's facts."""
RECORD_METADATA_VERSION = "1"
SITE_FROM_MAP = "column map"
SITE_FROM_COMMAND_LINE = "command line"
"""Where an imported record's site came from (:attr:`ImportedRecord.site_source`)."""
RECORD_SENSORS = ("sonic", "sonic_temperature", "imu", "ahrs")
"""The sensors a record may have, as ``sensors`` names them: the sonic's wind and temperature,
the motion pack's (or IMU's) rates and specific force, the motion pack's own attitude."""
SENSORS_A_RECORD_NEVER_HAS = ("gnss", "magnetometer", "dvl")
"""What ``import_records`` does not map: an imported bag has none of them."""
_COUNTS_PREFIX = "samples."


@dataclass(frozen=True)
class ImportedRecord:
    """The facts ``import_records`` stored in a bag (see the module docstring)."""

    record: str
    """The record file's name."""
    column_map: str
    """The column map's file name."""
    description: str
    start_ns: int
    """The first sample's time, ns since the Unix epoch."""
    start_source: str
    """Who said when the record starts: ``column map``, ``command line`` or ``time column``."""
    sensors: tuple[str, ...]
    """The sensors the record has, of :data:`RECORD_SENSORS`."""
    yaw_reference: str | None = None
    """``true_north`` or ``magnetic_north``: what the motion pack's heading (``imu/data``) is
    referenced to; None when the record has no attitude."""
    site_deg: tuple[float, float] | None = None
    """(latitude, longitude), deg; None: unknown."""
    site_source: str | None = None
    """``column map`` or ``command line``; None when the site is unknown."""
    field_counts: dict[str, FieldCounts] = field(default_factory=dict)
    """How each field of the map was screened, by field name (``anemometer.u``, ...)."""
    temperatures_without_wind: int = 0
    """Sonic temperatures imported invalid because their sample's wind is invalid."""

    def parameter_defaults(self) -> dict[str, Any]:
        """The nodes' parameters the record states, as defaults for the offline tools."""
        defaults: dict[str, Any] = {}
        if self.yaw_reference is not None:
            defaults["ahrs.yaw_reference"] = self.yaw_reference
        if self.site_deg is not None:
            defaults["site.latitude_deg"], defaults["site.longitude_deg"] = self.site_deg
        return defaults

    def to_metadata(self) -> dict[str, str]:
        """The facts as the strings of an MCAP metadata record."""
        metadata = {
            "version": RECORD_METADATA_VERSION,
            "record": self.record,
            "column_map": self.column_map,
            "description": self.description,
            "start": seconds_to_iso8601(self.start_ns / 1e9),
            "start_ns": str(self.start_ns),
            "start_source": self.start_source,
            "sensors": ", ".join(self.sensors),
            "sensors_absent": ", ".join(SENSORS_A_RECORD_NEVER_HAS),
            "site_source": self.site_source or "unknown",
            "temperatures_without_wind": str(self.temperatures_without_wind),
        }
        if self.yaw_reference is not None:
            metadata["yaw_reference"] = self.yaw_reference
        if self.site_deg is not None:
            metadata["site_latitude_deg"] = repr(self.site_deg[0])
            metadata["site_longitude_deg"] = repr(self.site_deg[1])
        for name, counts in self.field_counts.items():
            metadata[_COUNTS_PREFIX + name] = json.dumps(counts.as_dict())
        return metadata

    @classmethod
    def from_metadata(cls, metadata: dict[str, str]) -> ImportedRecord:
        """The facts of an MCAP metadata record written by :meth:`to_metadata`; KeyError or
        ValueError when it is not one."""
        if metadata["version"] != RECORD_METADATA_VERSION:
            raise ValueError(f"version {metadata['version']!r}, this reader reads version 1")
        site = None
        if "site_latitude_deg" in metadata:
            site = (float(metadata["site_latitude_deg"]), float(metadata["site_longitude_deg"]))
        return cls(
            record=metadata["record"],
            column_map=metadata["column_map"],
            description=metadata["description"],
            start_ns=int(metadata["start_ns"]),
            start_source=metadata["start_source"],
            sensors=tuple(s for s in metadata["sensors"].split(", ") if s),
            yaw_reference=metadata.get("yaw_reference"),
            site_deg=site,
            site_source=None if site is None else metadata["site_source"],
            field_counts={
                key.removeprefix(_COUNTS_PREFIX): FieldCounts(**json.loads(value))
                for key, value in metadata.items()
                if key.startswith(_COUNTS_PREFIX)
            },
            temperatures_without_wind=int(metadata["temperatures_without_wind"]),
        )


def read_imported_record(bag: str | Path) -> ImportedRecord | None:
    """The imported record's facts stored in ``bag`` (a bag directory or its MCAP file), None
    for a bag that holds none (a simulated or recorded one). BagError for facts that are there
    but unreadable."""
    metadata = read_metadata_record(bag, RECORD_METADATA_NAME)
    if metadata is None:
        return None
    try:
        return ImportedRecord.from_metadata(metadata)
    except (KeyError, ValueError, TypeError) as error:
        raise BagError(
            f"bag {bag}: the imported record's facts ({RECORD_METADATA_NAME}) are "
            f"unreadable: {error}"
        ) from error


def read_metadata_record(bag: str | Path, name: str) -> dict[str, str] | None:
    """The last MCAP metadata record called ``name`` in ``bag`` (a bag directory or its MCAP
    file), None when it holds none."""
    bag = Path(bag)
    files = sorted(bag.glob("*.mcap")) if bag.is_dir() else [bag]
    for mcap_file in files:
        records = [m for m in _indexed_metadata(mcap_file) if m.name == name]
        if records:
            return dict(records[-1].metadata)
    return None


def _indexed_metadata(mcap_file: Path) -> list:
    """The metadata records of a finished MCAP file, found through its summary; none for a file
    cut short (its facts, written last, are lost with its end: reading the whole file for them
    would cost as much as reading its messages)."""
    # Imported here: a tool that never reads an imported bag does without the MCAP reader.
    from mcap.exceptions import McapError
    from mcap.reader import SeekingReader

    try:
        with mcap_file.open("rb") as stream:
            reader = SeekingReader(stream)
            if reader.get_summary() is None:
                return []
            return list(reader.iter_metadata())
    except (OSError, McapError, EOFError, ValueError):
        return []
