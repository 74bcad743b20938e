"""The report's figures, drawn with the Agg canvas directly (no pyplot), so no display and no
global backend state are involved:

- ``wind_time_series.png``: horizontal speed, direction and vertical wind over time, measured
  (sensor axes, uncorrected), corrected and true (when known), with the 1- and 10-minute means
  of the products; the truth a broad pale band under the corrected line, so that both show;
  the direction unwrapped (no jumps at 360/0); the legend above the panels, off the data;
- ``attitude_error.png`` (only with truth): roll, pitch and heading error of the navigation,
  within the filter's own ±3σ when the navigation carries its covariance;
- ``vertical_wind_spectrum.png``: Welch power spectra of the vertical wind before and after
  correction (and of the truth), averaged over segments and then over log-spaced frequency
  bands so that they read as lines; the wave band (where the buoy's tilt has its energy)
  shaded; a −5/3 reference slope (the inertial subrange); and, below, the variance-preserving
  f·S(f), whose area shows where the variance lies.

Angles are degrees in every figure.
"""

from pathlib import Path

import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure
from matplotlib.ticker import FuncFormatter
from scipy.signal import welch

from wind_comp.products import meteorological_direction_deg
from wind_comp.report.attitude import attitude_errors_deg
from wind_comp.report.data import ReportData, titled, utc_text, wind_series

_MIN_SPECTRUM_SAMPLES = 32
_MIN_SEGMENTS = 15
_LONGEST_SEGMENT_S = 60.0
_BANDS_PER_DECADE = 20


def write_figures(data: ReportData, out_dir: Path) -> list[Path]:
    """Draw the figures ``data`` allows into the folder ``out_dir``; return their paths."""
    paths = [_plot_wind_time_series(data, out_dir / "wind_time_series.png")]
    if data.truth_rpy_rad is not None:
        paths.append(_plot_attitude_error(data, out_dir / "attitude_error.png"))
    spectrum = _plot_vertical_wind_spectrum(data, out_dir / "vertical_wind_spectrum.png")
    if spectrum is not None:
        paths.append(spectrum)
    return paths


# Drawing order and weight of each series: the truth broad and pale underneath, the corrected
# wind thin and dark on top of it, the measured wind thin and grey behind both.
_SERIES_STYLE = {
    "measured (sensor axes)": {"linewidth": 0.6, "alpha": 0.8, "zorder": 1},
    "true": {"linewidth": 3.0, "alpha": 0.45, "zorder": 2},
    "corrected": {"linewidth": 0.7, "alpha": 1.0, "zorder": 3},
}
_MEAN_STYLE = {60.0: ("1-min mean", "--", 1.2), 600.0: ("10-min mean", "-", 2.2)}


def _plot_wind_time_series(data: ReportData, path: Path) -> Path:
    figure = Figure(figsize=(11, 9))
    speed_axis, direction_axis, vertical_axis = figure.subplots(3, 1, sharex=True)
    t_s = data.t_s - data.time_origin_s
    reference_direction_deg = None
    for label, wind, color in wind_series(data):
        style = _SERIES_STYLE.get(label, {})
        speed_axis.plot(t_s, np.hypot(wind[:, 0], wind[:, 1]), color=color, label=label, **style)
        direction = _unwrapped_deg(meteorological_direction_deg(wind[:, 0], wind[:, 1]))
        if label != "measured (sensor axes)":
            reference_direction_deg = reference_direction_deg or _level_deg(direction)
            direction = _near_deg(direction, reference_direction_deg)
        direction_axis.plot(t_s, direction, color=color, **style)
        vertical_axis.plot(t_s, wind[:, 2], color=color, **style)
    for window_s, (label, linestyle, width) in _MEAN_STYLE.items():
        products = [p for p in data.products if p.window_s == window_s]
        if not products:
            continue
        # Over the samples each window holds: a window the record cuts short is drawn short.
        starts = np.array([p.first_sample_s for p in products]) - data.time_origin_s
        ends = np.array([p.last_sample_s for p in products]) - data.time_origin_s
        speeds = np.array([p.vector_mean_speed_mps for p in products])
        directions = np.array([p.vector_mean_direction_deg for p in products])
        if reference_direction_deg is not None:
            directions = _near_deg(directions, reference_direction_deg)
        for axis, values in ((speed_axis, speeds), (direction_axis, directions)):
            axis.hlines(
                values,
                starts,
                ends,
                colors="black",
                linestyles=linestyle,
                linewidth=width,
                zorder=4,
                label=label if axis is speed_axis else None,
            )
    speed_axis.set_ylabel("horizontal speed (m/s)")
    direction_axis.set_ylabel("direction from (deg)")
    direction_axis.yaxis.set_major_formatter(FuncFormatter(lambda value, _: f"{value % 360:.0f}"))
    vertical_axis.set_ylabel("vertical wind w (m/s)")
    vertical_axis.set_xlabel(_time_label(data))
    figure.suptitle(titled(data, "wind before and after motion correction"))
    handles, labels = speed_axis.get_legend_handles_labels()
    figure.legend(
        handles,
        labels,
        loc="upper center",
        ncol=len(labels),
        frameon=False,
        bbox_to_anchor=(0.5, 0.955),
    )
    for axis in (speed_axis, direction_axis, vertical_axis):
        axis.grid(alpha=0.3)
    figure.tight_layout(rect=(0, 0, 1, 0.93))
    return _save(figure, path, layout_done=True)


def _unwrapped_deg(direction_deg: np.ndarray) -> np.ndarray:
    """A direction series without its jumps at 360/0 (NaN samples kept NaN)."""
    unwrapped = np.full_like(direction_deg, np.nan)
    finite = np.isfinite(direction_deg)
    unwrapped[finite] = np.unwrap(direction_deg[finite], period=360.0)
    return unwrapped


def _level_deg(direction_deg: np.ndarray) -> float:
    """The median of an unwrapped direction, brought into [0, 360)."""
    return float(np.nanmedian(direction_deg) % 360.0) if np.isfinite(direction_deg).any() else 0.0


def _near_deg(direction_deg, reference_deg: float):
    """Directions shifted by whole turns to lie within ±180° of ``reference_deg``."""
    return reference_deg + (np.asarray(direction_deg) - reference_deg + 180.0) % 360.0 - 180.0


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
    segment = _segment_samples(run.stop - run.start, sample_rate_hz)
    figure = Figure(figsize=(9, 8))
    density_axis, preserving_axis = figure.subplots(2, 1, sharex=True, height_ratios=(3, 2))
    wave_band = _wave_band_hz(data)
    corrected_density = None
    for label, wind, color in series:
        frequency_hz, density = welch(wind[run, 2], fs=sample_rate_hz, nperseg=segment)
        frequency_hz, density = _log_band_average(frequency_hz[1:], density[1:])
        style = _SERIES_STYLE.get(label, {})
        density_axis.loglog(frequency_hz, density, color=color, label=label, **style)
        preserving_axis.semilogx(frequency_hz, frequency_hz * density, color=color, **style)
        if label == "corrected":
            corrected_density = (frequency_hz, density)
    if corrected_density is not None:
        _draw_five_thirds(density_axis, *corrected_density)
    if wave_band is not None:
        for axis in (density_axis, preserving_axis):
            axis.axvspan(
                *wave_band,
                color="tab:orange",
                alpha=0.12,
                zorder=0,
                label="wave band (buoy tilt)" if axis is density_axis else None,
            )
    density_axis.set_ylabel("S(f) of w (m²/s² per Hz)")
    preserving_axis.set_ylabel("f·S(f) (m²/s²)")
    preserving_axis.set_xlabel("frequency (Hz)")
    density_axis.set_title(
        titled(
            data,
            f"vertical wind spectrum ({segment / sample_rate_hz:.0f} s "
            "segments, log-band averaged)",
        )
    )
    for axis in (density_axis, preserving_axis):
        axis.grid(alpha=0.3, which="both")
    density_axis.legend(loc="lower left", fontsize="small")
    return _save(figure, path)


def _segment_samples(samples: int, sample_rate_hz: float) -> int:
    """Welch segment length: at least ``_MIN_SEGMENTS`` half-overlapping segments, and no longer
    than ``_LONGEST_SEGMENT_S`` (which resolves wave periods of 20 s)."""
    by_count = 2 * samples // (_MIN_SEGMENTS + 1)
    return int(max(_MIN_SPECTRUM_SAMPLES, min(by_count, _LONGEST_SEGMENT_S * sample_rate_hz)))


def _log_band_average(frequency_hz: np.ndarray, density: np.ndarray):
    """The spectrum averaged over bands of equal width in log frequency (``_BANDS_PER_DECADE``
    per decade); bands holding no estimate are left out."""
    edges = np.logspace(
        np.log10(frequency_hz[0]),
        np.log10(frequency_hz[-1]) + 1e-9,
        int(np.ceil(np.log10(frequency_hz[-1] / frequency_hz[0]) * _BANDS_PER_DECADE)) + 1,
    )
    band = np.digitize(frequency_hz, edges) - 1
    counts = np.bincount(band, minlength=edges.size)
    occupied = counts > 0
    mean_f = np.bincount(band, weights=frequency_hz, minlength=edges.size)[occupied]
    mean_s = np.bincount(band, weights=density, minlength=edges.size)[occupied]
    return mean_f / counts[occupied], mean_s / counts[occupied]


def _draw_five_thirds(axis, frequency_hz: np.ndarray, density: np.ndarray) -> None:
    """A f^(−5/3) line through the corrected spectrum at 1 Hz (or its middle frequency)."""
    anchor = float(np.clip(1.0, frequency_hz[0], frequency_hz[-1]))
    level = float(np.interp(np.log10(anchor), np.log10(frequency_hz), density))
    span = frequency_hz[(frequency_hz >= anchor / 5) & (frequency_hz <= anchor * 5)]
    if span.size >= 2:
        axis.loglog(
            span,
            3.0 * level * (span / anchor) ** (-5.0 / 3.0),
            color="black",
            linestyle=":",
            linewidth=1.2,
            label="f^(−5/3)",
        )


def _wave_band_hz(data: ReportData) -> tuple[float, float] | None:
    """The frequencies where the estimated tilt (roll and pitch) holds its energy: where its
    spectrum exceeds a tenth of its peak; None without attitude."""
    if data.attitude_t_s is None or data.attitude_t_s.size < 4 * _MIN_SPECTRUM_SAMPLES:
        return None
    rate_hz = 1.0 / float(np.median(np.diff(data.attitude_t_s)))
    tilt = data.nav_rpy_rad[:, :2]
    if not np.isfinite(tilt).all():
        return None
    segment = _segment_samples(tilt.shape[0], rate_hz)
    frequency_hz, density = welch(tilt, fs=rate_hz, nperseg=segment, axis=0)
    total = density.sum(axis=1)[1:]
    frequency_hz = frequency_hz[1:]
    strong = frequency_hz[total >= 0.1 * total.max()]
    return float(strong.min()), float(strong.max())


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


def _save(figure: Figure, path: Path, layout_done: bool = False) -> Path:
    FigureCanvasAgg(figure)
    if not layout_done:
        figure.tight_layout()
    figure.savefig(path, dpi=120)
    return path
