"""The report's tables, as Markdown: the wind's error against the truth and the averaged wind
products (``wind_products.md``), and the summary page (``summary.md``) with the figures, the
quality control of the samples and the filter's health."""

import math
from pathlib import Path

import numpy as np

from wind_comp.products import WindProduct, meteorological_direction_deg
from wind_comp.report.attitude import attitude_errors_deg
from wind_comp.report.data import ReportData, titled, utc_text, wind_series

_ANGLES = ("roll", "pitch", "heading")


def wind_products_markdown(data: ReportData) -> str:
    """The table of ``wind_products.md``: with truth, the error of the measured and corrected
    wind against it; then the averaged wind products."""
    lines = [f"# {titled(data, 'wind products')}", ""]
    if data.true_wind_enu_mps is not None:
        lines += [*_accuracy_table(data), ""]
    lines += _products_table(data.products, data.products_source)
    return "\n".join(lines) + "\n"


def _accuracy_table(data: ReportData) -> list[str]:
    """Bias and RMS of the measured and corrected wind against the truth.

    Each row counts the samples where both the series and the truth are finite. The measured
    wind is in sensor axes, so only its horizontal speed and w are compared; the corrected wind
    is ENU like the truth and is also compared per component and in direction.
    """
    true_wind = data.true_wind_enu_mps
    true_speed = np.hypot(true_wind[:, 0], true_wind[:, 1])
    true_direction = meteorological_direction_deg(true_wind[:, 0], true_wind[:, 1])
    lines = [
        "## Error against truth",
        "",
        "| series | quantity | bias | RMS | samples |",
        "|---|---|---|---|---|",
    ]
    for label, wind, _ in wind_series(data)[:2]:
        speed_error = np.hypot(wind[:, 0], wind[:, 1]) - true_speed
        vertical_error = wind[:, 2] - true_wind[:, 2]
        quantities = [("horizontal speed (m/s)", speed_error), ("w (m/s)", vertical_error)]
        if label == "corrected":
            direction = meteorological_direction_deg(wind[:, 0], wind[:, 1])
            direction_error = (direction - true_direction + 180.0) % 360.0 - 180.0
            quantities += [
                ("u (m/s)", wind[:, 0] - true_wind[:, 0]),
                ("v (m/s)", wind[:, 1] - true_wind[:, 1]),
                ("direction (deg)", direction_error),
            ]
        for quantity, error in quantities:
            error = error[np.isfinite(error)]
            if error.size:
                bias, rms = float(error.mean()), float(np.sqrt(np.mean(error**2)))
            else:
                bias = rms = math.nan
            lines.append(f"| {label} | {quantity} | {bias:.4f} | {rms:.4f} | {error.size} |")
    return lines


def _products_table(products: list[WindProduct], source: str) -> list[str]:
    lines = [
        "## Averaged wind",
        "",
        "Direction: degrees clockwise from true North, where the wind blows from. "
        "Vectors ENU. Gust: maximum running mean of horizontal speed. The last window of each "
        "length may be partial: it was closed at the end of the data.",
        "",
    ]
    if source:
        lines += [f"Source: {source}.", ""]
    if not products:
        return [*lines, "No averaging window completed."]
    lines += [
        "| window start (UTC) | length (s) | valid | invalid | vector mean speed (m/s) "
        "| direction (deg) | scalar mean speed (m/s) | gust (m/s) | mean w (m/s) "
        "| std u (m/s) | std v (m/s) | std w (m/s) |",
        "|" + "---|" * 12,
    ]
    for product in products:
        lines.append(
            f"| {utc_text(product.window_start_s)} | {product.window_s:.0f} | {product.n_valid} "
            f"| {product.n_invalid} | {product.vector_mean_speed_mps:.2f} "
            f"| {product.vector_mean_direction_deg:.1f} | {product.scalar_mean_speed_mps:.2f} "
            f"| {product.gust_mps:.2f} | {product.mean_w_enu_mps:.3f} "
            f"| {product.std_u_mps:.2f} | {product.std_v_mps:.2f} | {product.std_w_mps:.2f} |"
        )
    return lines


def summary_markdown(data: ReportData, figures: list[str]) -> str:
    """The summary page: span, figures (file names beside the page), quality control, filter
    health, then the tables of ``wind_products.md``."""
    lines = [f"# {titled(data, 'summary')}", ""]
    if data.t_s.size:
        lines += [
            f"{data.t_s.size} anemometer samples from {utc_text(float(data.t_s[0]))} to "
            f"{utc_text(float(data.t_s[-1]))} ({data.t_s[-1] - data.t_s[0]:.0f} s).",
            "",
        ]
    lines += [f"![{Path(name).stem.replace('_', ' ')}]({name})" for name in figures]
    lines += ["", *_quality_table(data), "", *_filter_health_table(data), ""]
    lines += wind_products_markdown(data).splitlines()[2:]
    return "\n".join(lines) + "\n"


def _quality_table(data: ReportData) -> list[str]:
    """How many samples were corrected, and how many each product window lacked."""
    corrected = np.isfinite(data.corrected_wind_enu_mps).all(axis=1)
    total = max(corrected.size, 1)
    lines = [
        "## Quality control",
        "",
        "| what | count | share |",
        "|---|---|---|",
        f"| anemometer samples | {corrected.size} | 100 % |",
        f"| corrected | {int(corrected.sum())} | {100 * corrected.sum() / total:.1f} % |",
        f"| not corrected (NaN: before alignment, gaps, rejected) | {int((~corrected).sum())} | "
        f"{100 * (~corrected).sum() / total:.1f} % |",
    ]
    for window_s in sorted({p.window_s for p in data.products}):
        windows = [p for p in data.products if p.window_s == window_s]
        incomplete = sum(1 for p in windows if p.n_invalid > 0)
        lines.append(
            f"| {window_s:g} s windows with invalid samples | {incomplete} of {len(windows)} | "
            f"{100 * incomplete / len(windows):.0f} % |"
        )
    return lines


def _filter_health_table(data: ReportData) -> list[str]:
    """The filter's own 1σ of each angle and, with truth, whether its errors stay inside it."""
    if data.nav_rpy_rad is None or data.nav_rpy_sigma_rad is None:
        return ["## Filter health", "", "(the source carries no navigation covariance)"]
    sigma_deg = np.degrees(data.nav_rpy_sigma_rad)
    header = "| angle | 1σ at the end (deg) | median 1σ (deg) |"
    rule = "|---|---|---|"
    errors_deg = None
    if data.truth_rpy_rad is not None:
        errors_deg = attitude_errors_deg(data.nav_rpy_rad, data.truth_rpy_rad)
        header += " RMS error (deg) | errors inside ±3σ |"
        rule += "---|---|"
    lines = ["## Filter health", "", header, rule]
    for k, angle in enumerate(_ANGLES):
        row = f"| {angle} | {sigma_deg[-1, k]:.3f} | {np.nanmedian(sigma_deg[:, k]):.3f} |"
        if errors_deg is not None:
            error, sigma = errors_deg[:, k], sigma_deg[:, k]
            finite = np.isfinite(error) & np.isfinite(sigma)
            rms = float(np.sqrt(np.mean(error[finite] ** 2))) if finite.any() else math.nan
            inside = (
                float(np.mean(np.abs(error[finite]) <= 3 * sigma[finite]))
                if finite.any()
                else math.nan
            )
            row += f" {rms:.3f} | {100 * inside:.1f} % |"
        lines.append(row)
    return lines
