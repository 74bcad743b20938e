"""``wind_report``: draw the figures and tables of a wind-correction run.

    wind_report SOURCE [--out FOLDER] [--namespace NS] [--remap FROM:=TO ...]

SOURCE is a bag holding ``anemometer/wind`` and ``wind/true`` (written by ``process_bag`` or
recorded from the running nodes; its truth and navigation topics are shown when present), or a
report data file (``.npz``) saved with :func:`wind_comp.report.data.save_report_data`. The
report goes to FOLDER, by default ``<SOURCE>_report``: see :mod:`wind_comp.report`. A bag
recorded or processed under a namespace is read in it; a bag of several buoys gives one report
per namespace, ``FOLDER/buoy1``, ``FOLDER/buoy2`` (:mod:`buoy_common.namespaces`).
"""

import argparse
from pathlib import Path

from buoy_common.bag_io import BagError
from buoy_common.contract import WIND_RAW_TOPIC
from buoy_common.namespaces import (
    NamespaceError,
    add_namespace_arguments,
    output_for,
    views_of_bag,
)
from wind_comp.report import write_report
from wind_comp.report.data import (
    ReportData,
    ReportDataError,
    load_report_data,
    report_data_from_bag,
)


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
    add_namespace_arguments(parser)
    arguments = parser.parse_args(argv)
    source = arguments.source
    try:
        if source.is_file():
            default_out = source.with_name(source.stem + "_report")
            reports = [(load_report_data(source), arguments.out or default_out)]
        else:
            reports = _bag_reports(arguments, source)
    except (ReportDataError, NamespaceError, BagError) as error:
        parser.exit(2, f"wind_report: {error}\n")
    for data, out in reports:
        for path in write_report(data, out):
            print(path)
    return 0


def _bag_reports(arguments, bag: Path) -> list[tuple[ReportData, Path]]:
    """(data, output folder) of each namespace of ``bag`` to report on."""
    views = views_of_bag(arguments, bag, WIND_RAW_TOPIC)
    out = arguments.out or bag.with_name(bag.name + "_report")
    several = len(views) > 1
    return [
        (
            report_data_from_bag(bag, f"{bag.name} {view.label}" if several else None, view),
            output_for(out, view, several),
        )
        for view in views
    ]


if __name__ == "__main__":
    raise SystemExit(main())
