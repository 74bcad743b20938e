"""``wind_report``: draw the figures and tables of a wind-correction run and of its current.

    wind_report SOURCE [--out FOLDER] [--namespace NS] [--remap FROM:=TO ...]

SOURCE is a bag holding ``anemometer/wind`` and ``wind/true``, ``current/velocity``, or both
(written by ``process_bag`` or recorded from the running nodes; its truth and navigation topics
are shown when present), or a wind report data file (``.npz``) saved with
:func:`buoy_processing.report.data.save_report_data`. The report goes to FOLDER, by default
``<SOURCE>_report``: see :mod:`buoy_processing.report`. A bag recorded or processed under a
namespace is read in it; a bag of several buoys gives one report per namespace,
``FOLDER/buoy1``, ``FOLDER/buoy2`` (:mod:`buoy_common.namespaces`).
"""

from pathlib import Path

from buoy_common.bag_io import BagError, BagReader
from buoy_common.cli import INTERRUPTIBLE_EXIT_CODES, command_parser, interruptible
from buoy_common.contract import CURRENT_TOPIC, WIND_RAW_TOPIC, WIND_TRUE_TOPIC
from buoy_common.namespaces import (
    NamespaceError,
    TopicView,
    add_namespace_arguments,
    output_for,
    views_of_bag,
)
from buoy_processing.report.current import CurrentData, current_report_data
from buoy_processing.report.data import (
    ReportData,
    ReportDataError,
    has_messages,
    load_report_data,
    report_data_from_bag,
)
from buoy_processing.report.folder import write_report

EXIT_CODES = INTERRUPTIBLE_EXIT_CODES


@interruptible("wind_report")
def main(argv=None) -> int:
    """Command line: draw the report of a bag, or of a run saved with :func:`save_report_data`."""
    parser = command_parser("wind_report", __doc__, EXIT_CODES)
    parser.add_argument(
        "source",
        type=Path,
        help="bag directory holding anemometer/wind and wind/true, current/velocity or both "
        "(written by process_bag or recorded from the nodes), or a report data file (.npz)",
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
            data = load_report_data(source)
            reports = [(data, None, data.title, arguments.out or default_out)]
        else:
            reports = _bag_reports(arguments, source)
    except (ReportDataError, NamespaceError, BagError) as error:
        message = str(error)
        if "a wind report needs" in message:
            message += f"; a current report needs {CURRENT_TOPIC}"
        parser.exit(2, f"wind_report: {message}\n")
    for data, current, title, out in reports:
        try:
            written = write_report(data, out, current, title)
        except OSError as error:
            parser.exit(2, f"wind_report: cannot write the report: {error}\n")
        for path in written:
            print(path)
    return 0


def _bag_reports(
    arguments, bag: Path
) -> list[tuple[ReportData | None, CurrentData | None, str, Path]]:
    """(wind data, current data, title, output folder) of each namespace of ``bag`` to report
    on; a namespace that holds only a current is reported for its current."""
    views = views_of_bag(arguments, bag, WIND_RAW_TOPIC, CURRENT_TOPIC)
    out = arguments.out or bag.with_name(bag.name + "_report")
    several = len(views) > 1
    reports = []
    for view in views:
        title = f"{bag.name} {view.label}" if several else bag.name
        current = current_report_data(bag, view)
        wind = None
        if current is None or _has_wind(bag, view):
            wind = report_data_from_bag(bag, title, view)
        reports.append((wind, current, title, output_for(out, view, several)))
    return reports


def _has_wind(bag: Path, view: TopicView) -> bool:
    """Whether the bag holds, in ``view``'s namespace, the wind topics a wind report needs."""
    with BagReader(bag, view) as reader:
        return any(has_messages(reader, t) for t in (WIND_RAW_TOPIC, WIND_TRUE_TOPIC))


if __name__ == "__main__":
    raise SystemExit(main())
