"""The report's tables, as Markdown: the wind's error against the truth, the averaged wind
products and the eddy-covariance fluxes, each window with its coverage and quality flag
(``wind_products.md``), the current's error against the truth and the averaged current
(``current_products.md``), and the summary page (``summary.md``) with the figures, the quality
control of the samples and the filter's health."""

import math
from pathlib import Path

import numpy as np

from buoy_common.contract import QualityFlag
from buoy_processing.output_facts import clockwise_from_north_text
from buoy_processing.report.attitude import attitude_errors_deg
from buoy_processing.report.current import CurrentData, window_errors
from buoy_processing.report.data import ReportData, titled, utc_text, wind_series
from wind_comp.flux_products import FluxProduct
from wind_comp.products import WindProduct, meteorological_direction_deg

MIN_CURRENT_FOR_DIRECTION_MPS = 0.2
"""Windows whose true current is slower than this leave out of the direction error: the
direction of a slack current is not defined."""
_ANGLES = ("roll", "pitch", "heading")


def wind_products_markdown(data: ReportData) -> str:
    """The table of ``wind_products.md``: with truth, the error of the measured and corrected
    wind against it; then the averaged wind products."""
    lines = [f"# {titled(data, 'wind products')}", ""]
    if data.true_wind_enu_mps is not None:
        lines += [*_accuracy_table(data), ""]
    lines += _products_table(data.products, data.products_source, data.north_text)
    if data.fluxes:
        lines += ["", *_fluxes_table(data.fluxes)]
    return "\n".join(lines) + "\n"


def flag_text(flag: int) -> str:
    """A QARTOD flag as the tables show it: its number and meaning, in bold unless good, so
    that a flagged window stands out."""
    try:
        meaning = QualityFlag(flag).name.lower().replace("_", " ")
    except ValueError:
        meaning = "unknown"
    text = f"{flag} {meaning}"
    return text if flag == QualityFlag.GOOD else f"**{text}**"


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


def _products_table(products: list[WindProduct], source: str, north_text: str) -> list[str]:
    lines = [
        "## Averaged wind",
        "",
        f"Direction: degrees {north_text}, where the wind blows from. "
        "Vectors ENU. Gust: maximum running mean of horizontal speed. The last window of each "
        "length may be partial: it was closed at the end of the data. Coverage: the share of a "
        "full window's samples the window holds valid; flag: IOOS QARTOD (1 good, 2 not "
        "evaluated, 3 suspect, 4 bad, 9 missing), from the coverage.",
        "",
    ]
    if source:
        lines += [f"Source: {source}.", ""]
    if not products:
        return [*lines, "No averaging window completed."]
    lines += [
        "| window start (UTC) | length (s) | valid | invalid | vector mean speed (m/s) "
        "| direction (deg) | scalar mean speed (m/s) | gust (m/s) | mean w (m/s) "
        "| std u (m/s) | std v (m/s) | std w (m/s) | coverage | flag |",
        "|" + "---|" * 14,
    ]
    for product in products:
        lines.append(
            f"| {utc_text(product.window_start_s)} | {product.window_s:.0f} | {product.n_valid} "
            f"| {product.n_invalid} | {product.vector_mean_speed_mps:.2f} "
            f"| {product.vector_mean_direction_deg:.1f} | {product.scalar_mean_speed_mps:.2f} "
            f"| {product.gust_mps:.2f} | {product.mean_w_enu_mps:.3f} "
            f"| {product.std_u_mps:.2f} | {product.std_v_mps:.2f} | {product.std_w_mps:.2f} "
            f"| {product.coverage:.4f} | {flag_text(product.quality_flag)} |"
        )
    return lines


def _fluxes_table(fluxes: list[FluxProduct]) -> list[str]:
    """The published eddy-covariance fluxes per window with their quality control; w'Ts' and
    its tests only when a window has a sonic temperature."""
    with_temperature = any(flux.n_temperature > 0 for flux in fluxes)
    header = ["window start (UTC)", "length (s)", "valid", "u* (m/s)", "u'w' (m²/s²)"]
    header += ["v'w' (m²/s²)"] + (["w'Ts' (K m/s)"] if with_temperature else [])
    header += ["tilt (deg)", "spikes u/v/w" + ("/Ts" if with_temperature else "")]
    header += ["non-stationarity u'w' (%)"]
    header += ["non-stationarity w'Ts' (%)"] if with_temperature else []
    header += ["coverage", "flag"]
    lines = [
        "## Eddy-covariance fluxes",
        "",
        "In the frame of the mean wind (u along it, w up), linearly detrended, as published on "
        "wind/fluxes_*. Spikes: Vickers–Mahrt counts per component; non-stationarity: "
        "Foken–Wichura (< 30 % stationary). Flag: from the coverage, then suspect for a "
        "non-stationarity above 30 % or spikes above 1 % of a component's samples, bad above "
        "100 %. Bold flags mark the windows not to trust as they are.",
        "",
        "| " + " | ".join(header) + " |",
        "|" + "---|" * len(header),
    ]
    for flux in fluxes:
        spikes = [flux.spikes_u, flux.spikes_v, flux.spikes_w]
        spikes += [flux.spikes_ts] if with_temperature else []
        cells = [utc_text(flux.window_start_s), f"{flux.window_s:.0f}", f"{flux.n_valid}"]
        cells += [f"{flux.friction_velocity_mps:.4g}", f"{flux.u_w_m2_s2:.4g}"]
        cells += [f"{flux.v_w_m2_s2:.4g}"]
        cells += [f"{flux.w_ts_k_mps:.4g}"] if with_temperature else []
        cells += [f"{flux.tilt_deg:.2f}", "/".join(str(count) for count in spikes)]
        cells += [f"{flux.stationarity_u_w_percent:.1f}"]
        cells += [f"{flux.stationarity_w_ts_percent:.1f}"] if with_temperature else []
        cells += [f"{flux.coverage:.4f}", flag_text(flux.quality_flag)]
        lines.append("| " + " | ".join(cells) + " |")
    return lines


def current_markdown(current: CurrentData, title: str) -> str:
    """The table of ``current_products.md``: with truth, the error of the single samples and of
    the window means against it; then the averaged current."""
    lines = [f"# {title}: current", ""]
    if current.truth_current_enu_mps is not None:
        lines += [*_current_accuracy(current), ""]
    lines += [
        "## Averaged current",
        "",
        f"Direction: degrees {clockwise_from_north_text(current.north)}, where the water "
        "flows toward. Vectors ENU. The standard deviations of a window hold the waves' orbital "
        "motion its mean averaged away. The last window of each length may be partial.",
        "",
    ]
    if not current.products:
        return "\n".join([*lines, "No averaging window completed."]) + "\n"
    lines += [
        "| window start (UTC) | length (s) | valid | invalid | speed (m/s) | toward (deg) "
        "| mean u (m/s) | mean v (m/s) | mean w (m/s) | std u (m/s) | std v (m/s) "
        "| std w (m/s) |",
        "|" + "---|" * 12,
    ]
    for product in current.products:
        lines.append(
            f"| {utc_text(product.window_start_s)} | {product.window_s:.0f} | {product.n_valid} "
            f"| {product.n_invalid} | {product.speed_mps:.4f} | {product.direction_deg:.2f} "
            f"| {product.mean_u_enu_mps:.4f} | {product.mean_v_enu_mps:.4f} "
            f"| {product.mean_w_enu_mps:.4f} | {product.std_u_mps:.3f} "
            f"| {product.std_v_mps:.3f} | {product.std_w_mps:.3f} |"
        )
    return "\n".join(lines) + "\n"


def _current_accuracy(current: CurrentData) -> list[str]:
    lines = [
        "## Error against truth",
        "",
        "Single samples against the water's velocity at the DVL (the estimate's own error) and "
        "against the current (which the waves' orbital velocity is not part of); window means "
        "against the current's mean over the same samples. Horizontal errors; the direction "
        f"only over windows whose current is {MIN_CURRENT_FOR_DIRECTION_MPS} m/s or faster.",
        "",
        "| series | against | windows | RMS error (m/s) | max error (m/s) "
        "| max direction error (deg) |",
        "|---|---|---|---|---|---|",
    ]
    valid = np.all(np.isfinite(current.current_enu_mps), axis=1)
    references = [("current", current.truth_current_enu_mps)]
    if current.truth_water_enu_mps is not None:
        references.insert(0, ("water at the DVL", current.truth_water_enu_mps))
    for name, reference in references:
        error = np.hypot(*(current.current_enu_mps[valid] - reference[valid])[:, :2].T)
        lines.append(
            f"| single samples | {name} | {error.size} | {_rms(error):.4f} "
            f"| {_largest(error):.4f} | |"
        )
    for window_s in sorted({product.window_s for product in current.products}):
        errors = window_errors(
            current.t_s, current.current_enu_mps, current.truth_current_enu_mps, window_s
        )
        fast = errors.reference_speed_mps >= MIN_CURRENT_FOR_DIRECTION_MPS
        direction = np.abs(errors.direction_error_deg[fast])
        lines.append(
            f"| {window_s:g} s means | current | {errors.vector_error_mps.size} "
            f"| {_rms(errors.vector_error_mps):.4f} "
            f"| {_largest(errors.vector_error_mps):.4f} | {_largest(direction):.2f} |"
        )
    return lines


def _rms(values: np.ndarray) -> float:
    return float(np.sqrt(np.mean(np.square(values)))) if values.size else math.nan


def _largest(values: np.ndarray) -> float:
    return float(np.max(values)) if values.size else math.nan


def summary_markdown(
    data: ReportData | None,
    figures: list[str],
    current: CurrentData | None = None,
    title: str = "",
) -> str:
    """The summary page: span, figures (file names beside the page), quality control, filter
    health, then the tables of ``wind_products.md`` and ``current_products.md`` (the wind's
    parts with ``data``, the current's with ``current``)."""
    if data is not None:
        heading = titled(data, "summary")
    else:
        heading = f"{title}: summary" if title else "summary"
    lines = [f"# {heading}", ""]
    for series, what in ((data, "anemometer"), (current, "DVL")):
        if series is not None and series.t_s.size:
            lines += [
                f"{series.t_s.size} {what} samples from {utc_text(float(series.t_s[0]))} to "
                f"{utc_text(float(series.t_s[-1]))} ({series.t_s[-1] - series.t_s[0]:.0f} s).",
                "",
            ]
    if data is not None:
        lines += [f"Wind directions in degrees {data.north_text}. {data.sensors_sentence}", ""]
        lines += _no_valid_wind_lines(data)
    lines += [f"![{Path(name).stem.replace('_', ' ')}]({name})" for name in figures]
    if data is not None:
        lines += ["", *_quality_table(data), "", *_filter_health_table(data), ""]
        lines += wind_products_markdown(data).splitlines()[2:]
    if current is not None:
        lines += ["", *_current_quality_table(current), ""]
        lines += current_markdown(current, title).splitlines()[2:]
    return "\n".join(lines) + "\n"


def _no_valid_wind_lines(data: ReportData) -> list[str]:
    """A paragraph saying that the run gave no valid wind, and why as far as the data show;
    none when it gave some."""
    if np.isfinite(data.corrected_wind_enu_mps).all(axis=1).any():
        return []
    samples = data.t_s.size
    if not np.isfinite(data.measured_wind_sensor_mps).all(axis=1).any():
        why = "the anemometer delivered no valid sample"
    else:
        why = "none could be corrected (see the quality control below)"
    return [
        f"**No valid wind**: none of the {samples} anemometer samples gave a wind: {why}. "
        "No window below holds a wind value.",
        "",
    ]


def _current_quality_table(current: CurrentData) -> list[str]:
    """How many DVL samples gave a current."""
    computed = np.isfinite(current.current_enu_mps).all(axis=1)
    total = max(computed.size, 1)
    return [
        "## Quality control of the current",
        "",
        "| what | count | share |",
        "|---|---|---|",
        f"| DVL samples | {computed.size} | 100 % |",
        f"| current computed | {int(computed.sum())} | {100 * computed.sum() / total:.1f} % |",
        f"| not computed (NaN: before alignment, lost pings, rejected) | "
        f"{int((~computed).sum())} | {100 * (~computed).sum() / total:.1f} % |",
    ]


def _quality_table(data: ReportData) -> list[str]:
    """How many samples were corrected, how many windows of each length lacked samples, and
    how many were flagged."""
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
    for what, windows in (("", data.products), ("flux ", data.fluxes)):
        for window_s in sorted({w.window_s for w in windows}):
            of_length = [w for w in windows if w.window_s == window_s]
            flagged = sum(1 for w in of_length if w.quality_flag != QualityFlag.GOOD)
            lines.append(
                f"| {window_s:g} s {what}windows flagged other than good | {flagged} of "
                f"{len(of_length)} | {100 * flagged / len(of_length):.0f} % |"
            )
    return lines


def _filter_health_table(data: ReportData) -> list[str]:
    """The filter's own 1σ of each angle and, with truth, whether its errors stay inside it."""
    if data.nav_rpy_rad is None:
        return ["## Filter health", "", "(the source holds no navigation solution)"]
    if data.nav_rpy_sigma_rad is None:
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
