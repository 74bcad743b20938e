"""The report of a wind-correction run, or of a current estimate, written into one folder."""

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
