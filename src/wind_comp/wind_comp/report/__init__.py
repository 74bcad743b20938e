"""The report of a wind-correction run: figures and tables in a folder.

- :mod:`wind_comp.report.data`: everything a report shows, as plain arrays (:class:`ReportData`),
  gathered from a bag or a saved ``.npz`` file;
- :mod:`wind_comp.report.attitude`: Euler angles, their 1σ and their errors;
- :mod:`wind_comp.report.figures` and :mod:`wind_comp.report.tables`: what is drawn and tabulated;
- :func:`write_report`: all of it into one folder. The ``wind_report`` command
  (:mod:`wind_comp.wind_report`) runs it on a bag or a saved file.
"""

from pathlib import Path

from wind_comp.report.data import ReportData
from wind_comp.report.figures import write_figures
from wind_comp.report.tables import summary_markdown, wind_products_markdown


def write_report(data: ReportData, out_dir) -> list[Path]:
    """Write the report figures, the products table and the summary page that shows them all
    (``summary.md``) into ``out_dir`` (created); return the paths."""
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    paths = write_figures(data, out_dir)
    table = out_dir / "wind_products.md"
    table.write_text(wind_products_markdown(data))
    summary = out_dir / "summary.md"
    summary.write_text(summary_markdown(data, [path.name for path in paths]))
    return [*paths, table, summary]
