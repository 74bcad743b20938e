"""The report of a wind-correction run, and of a current estimate: figures and tables in a folder.

- :mod:`buoy_processing.report.data`: everything a report shows, as plain arrays
  (:class:`ReportData`), gathered from a bag or a saved ``.npz`` file;
- :mod:`buoy_processing.report.attitude`: Euler angles, their 1σ and their errors;
- :mod:`buoy_processing.report.current`: the current of a bag (:class:`CurrentData`), its
  accuracy by window and against the window length;
- :mod:`buoy_processing.report.figures` and :mod:`buoy_processing.report.tables`: what is drawn
  and tabulated;
- :func:`write_report`: all of it into one folder. The ``wind_report`` command
  (:mod:`buoy_processing.wind_report`) runs it on a bag or a saved file.
"""

from pathlib import Path

from buoy_processing.report.current import CurrentData
from buoy_processing.report.data import ReportData
from buoy_processing.report.figures import write_current_figures, write_figures
from buoy_processing.report.tables import current_markdown, summary_markdown, wind_products_markdown


def write_report(
    data: ReportData | None, out_dir, current: CurrentData | None = None, title: str = ""
) -> list[Path]:
    """Write the report figures and tables into ``out_dir`` (created): the wind's of ``data``,
    the current's of ``current``, whichever is given, and the summary page that shows them all
    (``summary.md``); return the paths."""
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    title = title or (data.title if data is not None else "")
    figures, tables = [], []
    if data is not None:
        figures += write_figures(data, out_dir)
        table = out_dir / "wind_products.md"
        table.write_text(wind_products_markdown(data))
        tables.append(table)
    if current is not None:
        figures += write_current_figures(current, out_dir)
        table = out_dir / "current_products.md"
        table.write_text(current_markdown(current, title))
        tables.append(table)
    summary = out_dir / "summary.md"
    summary.write_text(summary_markdown(data, [path.name for path in figures], current, title))
    return [*figures, *tables, summary]
