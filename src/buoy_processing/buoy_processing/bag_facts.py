"""An imported record's facts in an offline run: defaults under the user's parameters.

An imported bag says what its column map knew (``ahrs.yaw_reference``, the site;
:mod:`buoy_common.record_facts`): the run takes those values unless a parameter file gives
another, and says so, so that nothing the map said has to be repeated and a contradiction is
seen.
"""

from __future__ import annotations

from collections.abc import Iterable
from pathlib import Path

from buoy_common.contract import seconds_to_iso8601
from buoy_common.parameters import load_parameter_files
from buoy_common.record_facts import ImportedRecord, read_imported_record
from buoy_nav.config import FUSION_NODE_NAME, FusionConfig, fusion_config_from_files


def describe_record(record: ImportedRecord) -> str:
    """The imported record in one line: its file, map, start and who gave the start."""
    return (
        f"{record.record} imported with {record.column_map}, from "
        f"{seconds_to_iso8601(record.start_ns / 1e9)} (start from the {record.start_source}), "
        f"sensors {', '.join(record.sensors)}"
    )


def record_defaults_lines(
    record: ImportedRecord, parameter_files: Iterable[str | Path]
) -> list[str]:
    """One line per parameter the record states: used from the record, or overridden by a
    parameter file that gives another value."""
    given = load_parameter_files(parameter_files, FUSION_NODE_NAME)
    lines = []
    for name, value in record.parameter_defaults().items():
        if name in given and given[name] != value:
            lines.append(f"{name}={given[name]} from the parameters, over the record's {value}")
        elif name not in given:
            lines.append(f"{name}={value} from the record")
    return lines


def fusion_config_for_bag(
    in_bag: str | Path, parameter_files: list[str]
) -> tuple[FusionConfig, list[str]]:
    """The fusion's configuration for ``in_bag``: the parameter files over the facts of the
    record the bag was imported from (if it was); and what the tool says of the record, one
    line each (none for a bag that was not imported)."""
    record = read_imported_record(in_bag)
    if record is None:
        return fusion_config_from_files(parameter_files), []
    config = fusion_config_from_files(parameter_files, record.parameter_defaults())
    return config, [describe_record(record), *record_defaults_lines(record, parameter_files)]
