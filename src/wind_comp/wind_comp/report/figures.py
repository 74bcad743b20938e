"""The report's figures, drawn with the Agg canvas directly (no pyplot), so no display and no
global backend state are involved:

- ``wind_time_series.png``: horizontal speed, direction and vertical wind over time, measured
  (sensor axes, uncorrected), corrected and true (when known);
- ``attitude_error.png`` (only with truth): roll, pitch and heading error of the navigation,
  within the filter's own ±3σ when the navigation carries its covariance;
- ``vertical_wind_spectrum.png``: Welch power spectra of the vertical wind before and after
  correction (and of the truth).

Angles are degrees in every figure.
"""

from pathlib import Path

import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure
from scipy.signal import welch

from wind_comp.products import meteorological_direction_deg
from wind_comp.report.attitude import attitude_errors_deg
from wind_comp.report.data import ReportData, titled, utc_text, wind_series

_MIN_SPECTRUM_SAMPLES = 32
_MAX_SPECTRUM_SEGMENT = 1024


def write_figures(data: ReportData, out_dir: Path) -> list[Path]:
    """Draw the figures ``data`` allows into the folder ``out_dir``; return their paths."""
    paths = [_plot_wind_time_series(data, out_dir / "wind_time_series.png")]
    if data.truth_rpy_rad is not None:
        paths.append(_plot_attitude_error(data, out_dir / "attitude_error.png"))
    spectrum = _plot_vertical_wind_spectrum(data, out_dir / "vertical_wind_spectrum.png")
    if spectrum is not None:
        paths.append(spectrum)
    return paths


def _plot_wind_time_series(data: ReportData, path: Path) -> Path:
    figure = Figure(figsize=(10, 8))
    speed_axis, direction_axis, vertical_axis = figure.subplots(3, 1, sharex=True)
    t_s = data.t_s - data.time_origin_s
    for label, wind, color in wind_series(data):
        speed_axis.plot(t_s, np.hypot(wind[:, 0], wind[:, 1]), color=color, label=label)
        direction_axis.plot(
            t_s,
            meteorological_direction_deg(wind[:, 0], wind[:, 1]),
            ".",
            markersize=2,
            color=color,
            label=label,
        )
        vertical_axis.plot(t_s, wind[:, 2], color=color, label=label)
    speed_axis.set_ylabel("horizontal speed (m/s)")
    direction_axis.set_ylabel("direction from (deg)")
    direction_axis.set_ylim(0, 360)
    direction_axis.set_yticks(range(0, 361, 90))
    vertical_axis.set_ylabel("vertical wind w (m/s)")
    vertical_axis.set_xlabel(_time_label(data))
    speed_axis.legend(loc="upper right")
    speed_axis.set_title(titled(data, "wind before and after motion correction"))
    for axis in (speed_axis, direction_axis, vertical_axis):
        axis.grid(alpha=0.3)
    return _save(figure, path)


def _plot_attitude_error(data: ReportData, path: Path) -> Path:
    errors_deg = attitude_errors_deg(data.nav_rpy_rad, data.truth_rpy_rad)
    t_s = data.attitude_t_s - data.time_origin_s
    figure = Figure(figsize=(10, 7))
    axes = figure.subplots(3, 1, sharex=True)
    for k, (axis, label) in enumerate(zip(axes, ("roll", "pitch", "heading"), strict=True)):
        if data.nav_rpy_sigma_rad is not None:
            # A consistent filter keeps its error inside this band but for rare moments.
            bound_deg = 3.0 * np.degrees(data.nav_rpy_sigma_rad[:, k])
            axis.fill_between(
                t_s, -bound_deg, bound_deg, color="0.85", linewidth=0, label="filter ±3σ"
            )
        axis.plot(t_s, errors_deg[:, k], color="tab:red", label="estimate − truth")
        if data.nav_rpy_sigma_rad is not None:
            # Scaled to the error: the band of the first seconds after alignment is far wider.
            largest_deg = np.nanmax(np.abs(errors_deg[:, k]), initial=0.0)
            axis.set_ylim(-1.2 * largest_deg - 1e-3, 1.2 * largest_deg + 1e-3)
        axis.set_ylabel(f"{label} error (deg)")
        axis.grid(alpha=0.3)
    if data.nav_rpy_sigma_rad is not None:
        axes[0].legend(loc="upper right")
    axes[-1].set_xlabel(_time_label(data))
    axes[0].set_title(titled(data, "attitude error (estimate − truth)"))
    return _save(figure, path)


def _plot_vertical_wind_spectrum(data: ReportData, path: Path) -> Path | None:
    series = wind_series(data)
    finite = np.all([np.isfinite(wind[:, 2]) for _, wind, _ in series], axis=0)
    run = _longest_true_run(finite)
    if run.stop - run.start < _MIN_SPECTRUM_SAMPLES:
        return None
    sample_rate_hz = 1.0 / float(np.median(np.diff(data.t_s[run])))
    segment = min(run.stop - run.start, _MAX_SPECTRUM_SEGMENT)
    figure = Figure(figsize=(8, 5))
    axis = figure.subplots()
    for label, wind, color in series:
        frequency_hz, density = welch(wind[run, 2], fs=sample_rate_hz, nperseg=segment)
        axis.loglog(frequency_hz[1:], density[1:], color=color, label=label)
    axis.set_xlabel("frequency (Hz)")
    axis.set_ylabel("PSD of w (m²/s² per Hz)")
    axis.set_title(titled(data, "vertical wind spectrum"))
    axis.grid(alpha=0.3, which="both")
    axis.legend()
    return _save(figure, path)


def _longest_true_run(mask: np.ndarray) -> slice:
    """Slice of the longest run of consecutive True values (empty slice when none)."""
    padded = np.concatenate(([False], mask, [False])).astype(np.int8)
    edges = np.flatnonzero(np.diff(padded))
    if edges.size == 0:
        return slice(0, 0)
    starts, stops = edges[0::2], edges[1::2]
    longest = int(np.argmax(stops - starts))
    return slice(int(starts[longest]), int(stops[longest]))


def _time_label(data: ReportData) -> str:
    if data.time_origin_s == 0.0:
        return "time (s)"
    return f"time (s) since {utc_text(data.time_origin_s)}"


def _save(figure: Figure, path: Path) -> Path:
    FigureCanvasAgg(figure)
    figure.tight_layout()
    figure.savefig(path, dpi=120)
    return path
