"""``wind_report``: draw the figures and tables of a wind-correction run and of its current.

    wind_report SOURCE [--out FOLDER]

SOURCE is a bag holding ``anemometer/wind`` and ``wind/true``, ``current/velocity``, or both
(written by ``process_bag`` or recorded from the running nodes; its truth and navigation topics
are shown when present), or a wind report data file (``.npz``) saved with
:func:`wind_comp.report.data.save_report_data`. The report goes to FOLDER, by default
``<SOURCE>_report``: see :mod:`wind_comp.report`.
"""

import argparse
from pathlib import Path

from buoy_common.bag_io import BagError, BagReader
from buoy_common.contract import CURRENT_TOPIC, WIND_RAW_TOPIC, WIND_TRUE_TOPIC
from wind_comp.report import write_report
from wind_comp.report.current import current_report_data
from wind_comp.report.data import (
    ReportDataError,
    has_messages,
    load_report_data,
    report_data_from_bag,
)


def main(argv=None) -> int:
    """Command line: draw the report of a bag, or of a run saved with :func:`save_report_data`."""
    parser = argparse.ArgumentParser(
        prog="wind_report", description="Draw wind-correction and current figures and tables."
    )
    parser.add_argument(
        "source",
        type=Path,
        help="bag directory holding anemometer/wind and wind/true, current/velocity or both "
        "(written by process_bag or recorded from the nodes), or a report data file (.npz)",
    )
    parser.add_argument(
        "--out", type=Path, default=None, help="output folder (default: <source>_report)"
    )
    arguments = parser.parse_args(argv)
    source = arguments.source
    current = None
    try:
        if source.is_file():
            data = load_report_data(source)
            default_out = source.with_name(source.stem + "_report")
        else:
            default_out = source.with_name(source.name + "_report")
            current = current_report_data(source)
            data = report_data_from_bag(source) if current is None or _has_wind(source) else None
    except ReportDataError as error:
        message = str(error)
        if "a wind report needs" in message:
            message += f"; a current report needs {CURRENT_TOPIC}"
        parser.exit(2, f"wind_report: {message}\n")
    title = source.stem if source.is_file() else source.name
    for path in write_report(data, arguments.out or default_out, current, title):
        print(path)
    return 0


def _has_wind(bag: Path) -> bool:
    """Whether the bag holds the wind topics a wind report needs (a bag that holds only a
    current is reported for its current)."""
    try:
        with BagReader(bag) as reader:
            return any(has_messages(reader, t) for t in (WIND_RAW_TOPIC, WIND_TRUE_TOPIC))
    except BagError as error:
        raise ReportDataError(str(error)) from error


if __name__ == "__main__":
    raise SystemExit(main())
