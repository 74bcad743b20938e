"""``wind_report``: draw the figures and tables of a wind-correction run.

    wind_report SOURCE [--out FOLDER]

SOURCE is a bag holding ``anemometer/wind`` and ``wind/true`` (written by ``process_bag`` or
recorded from the running nodes; its truth and navigation topics are shown when present), or a
report data file (``.npz``) saved with :func:`wind_comp.report.data.save_report_data`. The
report goes to FOLDER, by default ``<SOURCE>_report``: see :mod:`wind_comp.report`.
"""

import argparse
from pathlib import Path

from buoy_common.cli import interruptible
from wind_comp.report import write_report
from wind_comp.report.data import ReportDataError, load_report_data, report_data_from_bag


@interruptible("wind_report")
def main(argv=None) -> int:
    """Command line: draw the report of a bag, or of a run saved with :func:`save_report_data`."""
    parser = argparse.ArgumentParser(
        prog="wind_report", description="Draw wind-correction figures and tables."
    )
    parser.add_argument(
        "source",
        type=Path,
        help="bag directory holding anemometer/wind and wind/true (written by process_bag or "
        "recorded from the nodes), or a report data file (.npz)",
    )
    parser.add_argument(
        "--out", type=Path, default=None, help="output folder (default: <source>_report)"
    )
    arguments = parser.parse_args(argv)
    source = arguments.source
    try:
        if source.is_file():
            data = load_report_data(source)
            default_out = source.with_name(source.stem + "_report")
        else:
            data = report_data_from_bag(source)
            default_out = source.with_name(source.name + "_report")
    except ReportDataError as error:
        parser.exit(2, f"wind_report: {error}\n")
    try:
        written = write_report(data, arguments.out or default_out)
    except OSError as error:
        parser.exit(2, f"wind_report: cannot write the report: {error}\n")
    for path in written:
        print(path)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
