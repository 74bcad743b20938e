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
  bands so that they read as lines; the record's wave band (from the spectrum of the
  platform's vertical motion, as each flux window's: :mod:`wind_comp.wave_motion_left`)
  shaded; a −5/3 reference slope (the inertial subrange); and, below, the variance-preserving
  f·S(f), whose area shows where the variance lies;
- ``wind_fluxes.png`` (bags with ``wind/fluxes_*``): the friction velocity u* (and the buoyancy
  flux w'Ts' with a sonic temperature) of each flux window as published, drawn over the
  window's span; windows whose QARTOD flag is not good drawn as open red markers labelled with
  their flag;
- ``wave_motion_left.png`` (bags with ``wind/fluxes_*``): per flux window, the share of the
  platform's vertical velocity left in the corrected w and its coherence with w over the
  window's wave band, against the "motion left" test's default thresholds, each window marked
  with that test's flag;
- ``current_time_series.png`` (bags with ``current/velocity``): the current's single samples,
  its window means and the truth;
- ``current_averaging.png`` (with the simulator's truth): the error of the window means against
  the window length.

Angles are degrees in every figure.
"""

from pathlib import Path

import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure
from matplotlib.ticker import FuncFormatter, MultipleLocator
from scipy.signal import welch

from buoy_common.contract import QualityFlag
from buoy_processing.report.attitude import attitude_errors_deg
from buoy_processing.report.current import CurrentData, error_by_window_length
from buoy_processing.report.data import ReportData, titled, utc_text, wind_series
from wind_comp.products import meteorological_direction_deg, oceanographic_direction_deg
from wind_comp.wave_motion_left import DEFAULT_THRESHOLDS, platform_wave_band_hz

_MIN_SPECTRUM_SAMPLES = 32
_MIN_SEGMENTS = 15
_LONGEST_SEGMENT_S = 60.0
_BANDS_PER_DECADE = 20


def write_figures(data: ReportData, out_dir: Path) -> list[Path]:
    """Draw the figures ``data`` allows into the folder ``out_dir``; return their paths. A
    figure none of whose values is finite is not drawn: an empty frame is no data."""
    paths = []
    if any(np.isfinite(wind).any() for _, wind, _ in wind_series(data)):
        paths.append(_plot_wind_time_series(data, out_dir / "wind_time_series.png"))
    if data.truth_rpy_rad is not None:
        paths.append(_plot_attitude_error(data, out_dir / "attitude_error.png"))
    spectrum = _plot_vertical_wind_spectrum(data, out_dir / "vertical_wind_spectrum.png")
    if spectrum is not None:
        paths.append(spectrum)
    if _any_finite(data.fluxes, "friction_velocity_mps", "w_ts_k_mps"):
        paths.append(_plot_fluxes(data, out_dir / "wind_fluxes.png"))
    if _any_finite(data.fluxes, "motion_left_share", "motion_left_coherence"):
        paths.append(_save(wave_motion_left_figure(data), out_dir / "wave_motion_left.png"))
    return paths


def _any_finite(windows: list, *names: str) -> bool:
    """Whether any of ``windows`` has a finite value of any of the fields ``names``."""
    return any(np.isfinite(getattr(window, name)) for window in windows for name in names)


# Drawing order and weight of each series: the truth broad and pale underneath, the corrected
# wind thin and dark on top of it, the measured wind thin and grey behind both.
_SERIES_STYLE = {
    "measured (sensor axes)": {"linewidth": 0.6, "alpha": 0.8, "zorder": 1},
    "true": {"linewidth": 3.0, "alpha": 0.45, "zorder": 2},
    "corrected": {"linewidth": 0.7, "alpha": 1.0, "zorder": 3},
}
_MEAN_STYLE = {60.0: ("1-min mean", "--", 1.2), 600.0: ("10-min mean", "-", 2.2)}


def _plot_wind_time_series(data: ReportData, path: Path) -> Path:
    return _save(wind_time_series_figure(data), path, layout_done=True)


def wind_time_series_figure(data: ReportData) -> Figure:
    """The figure of ``wind_time_series.png`` (see the module docstring)."""
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
        direction_axis.plot(t_s, direction, color=color, label=label, **style)
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
    _shift_lines_near(direction_axis, reference_direction_deg)
    speed_axis.set_ylabel("horizontal speed (m/s)")
    direction_axis.set_ylabel("direction from (deg)")
    direction_axis.set_title(
        f"where the wind blows from, degrees {data.north_text}", loc="left", fontsize="small"
    )
    _set_direction_ticks(direction_axis)
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
    return figure


def _plot_fluxes(data: ReportData, path: Path) -> Path:
    return _save(fluxes_figure(data), path)


def fluxes_figure(data: ReportData) -> Figure:
    """The figure of ``wind_fluxes.png`` (see the module docstring)."""
    fluxes = data.fluxes
    quantities = [("friction_velocity_mps", "u* (m/s)")]
    if any(flux.n_temperature > 0 for flux in fluxes):
        quantities.append(("w_ts_k_mps", "w'Ts' (K m/s)"))
    figure = Figure(figsize=(11, 2.0 + 2.6 * len(quantities)))
    axes = figure.subplots(len(quantities), 1, sharex=True, squeeze=False)[:, 0]
    starts, ends = _flux_spans_s(data)
    middles = 0.5 * (starts + ends)
    flagged = np.array([flux.quality_flag != QualityFlag.GOOD for flux in fluxes], dtype=bool)
    for axis, (name, label) in zip(axes, quantities, strict=True):
        values = np.array([getattr(flux, name) for flux in fluxes])
        for marked, colour, marker_face, legend in (
            (~flagged, "tab:blue", "tab:blue", "flag 1 (good)"),
            (flagged, "tab:red", "none", "flagged (2 not evaluated, 3 suspect, 4 bad)"),
        ):
            if not marked.any():
                continue
            axis.hlines(values[marked], starts[marked], ends[marked], colors=colour, alpha=0.5)
            axis.plot(
                middles[marked],
                values[marked],
                linestyle="none",
                marker="o",
                markersize=7,
                color=colour,
                markerfacecolor=marker_face,
                label=legend,
            )
        for index in np.flatnonzero(flagged & np.isfinite(values)):
            axis.annotate(
                str(fluxes[index].quality_flag),
                (middles[index], values[index]),
                textcoords="offset points",
                xytext=(6, 4),
                color="tab:red",
            )
        if name == "w_ts_k_mps":
            axis.axhline(0.0, color="grey", linewidth=0.8)
        axis.set_ylabel(label)
        axis.grid(alpha=0.3)
    axes[0].legend(loc="best", frameon=False)
    axes[-1].set_xlabel(_time_label(data))
    missing = sum(1 for flux in fluxes if flux.quality_flag == QualityFlag.MISSING)
    note = f" ({missing} missing window(s) without fluxes not drawn)" if missing else ""
    figure.suptitle(titled(data, f"eddy-covariance fluxes per window{note}"))
    return figure


def _flux_spans_s(data: ReportData) -> tuple[np.ndarray, np.ndarray]:
    """Where each flux window is drawn, s from the time origin: over the samples it holds (a
    window the record cuts short is drawn short), its bounds clipped to the data's span when
    the product does not say which samples it holds."""
    first_s = np.array([flux.first_sample_s for flux in data.fluxes])
    last_s = np.array([flux.last_sample_s for flux in data.fluxes])
    data_span_s = (data.t_s[0], data.t_s[-1]) if data.t_s.size else (-np.inf, np.inf)
    bounds_start_s = np.maximum([flux.window_start_s for flux in data.fluxes], data_span_s[0])
    bounds_end_s = np.minimum([flux.window_end_s for flux in data.fluxes], data_span_s[1])
    starts = np.where(np.isfinite(first_s), first_s, bounds_start_s)
    ends = np.where(np.isfinite(last_s), last_s, bounds_end_s)
    return starts - data.time_origin_s, ends - data.time_origin_s


def _shift_lines_near(axis, reference_deg: float | None) -> None:
    """Shift each direction line drawn on ``axis`` by whole turns, as one piece, so that its
    median lies within ±180° of ``reference_deg`` (the corrected wind's): every line stays
    continuous, and the sensor-axes direction is drawn beside the corrected one."""
    if reference_deg is None:
        return
    for line in axis.get_lines():
        values = np.asarray(line.get_ydata(), dtype=float)
        if not np.isfinite(values).any():
            continue
        median = float(np.nanmedian(values))
        line.set_ydata(values + (_near_deg(median, reference_deg) - median))


_DIRECTION_TICK_STEPS_DEG = (90.0, 45.0, 30.0, 15.0, 10.0, 5.0, 1.0)
"""Tick spacings of a direction axis: divisors of 360, so a label read modulo 360 repeats
the same ticks on every turn."""


def _set_direction_ticks(axis) -> None:
    """Ticks at multiples of the largest divisor of 360 that gives three or more within the
    drawn range, labelled in [0, 360] (a turn shows 0, 90, 180, 270, 360)."""
    low, high = axis.get_ylim()
    step = next(
        (s for s in _DIRECTION_TICK_STEPS_DEG if np.floor(high / s) - np.ceil(low / s) >= 2),
        _DIRECTION_TICK_STEPS_DEG[-1],
    )
    axis.yaxis.set_major_locator(MultipleLocator(step))
    axis.yaxis.set_major_formatter(FuncFormatter(_direction_label))


def _direction_label(value_deg: float, _position=None) -> str:
    """A direction tick's label in [0, 360]: north is 0 at the turn's start, 360 at its end."""
    wrapped = round(value_deg) % 360
    return "360" if wrapped == 0 and round(value_deg) > 0 else f"{wrapped:.0f}"


_MOTION_LEFT_STYLE = {
    QualityFlag.GOOD: ("tab:blue", "o", "pass"),
    QualityFlag.SUSPECT: ("tab:orange", "s", "suspect"),
    QualityFlag.BAD: ("tab:red", "X", "fail"),
}
"""Colour, marker and name of each flag of the "motion left" test."""


def wave_motion_left_figure(data: ReportData) -> Figure:
    """Per flux window, at its middle: the share of the platform's vertical velocity left in
    the corrected w and the coherence of w with it over the window's wave band, marked by the
    "motion left" flag, against the test's default share thresholds (the parameters
    ``compensation.motion_left_*``) and each window's coherence threshold; the windows it
    could not evaluate counted in the title."""
    fluxes = data.fluxes
    middles = np.array([0.5 * (f.window_start_s + f.window_end_s) for f in fluxes])
    middles -= data.time_origin_s
    flags = np.array([flux.motion_left_flag for flux in fluxes])
    figure = Figure(figsize=(11, 6.5))
    share_axis, coherence_axis = figure.subplots(2, 1, sharex=True)
    for axis, name in (
        (share_axis, "motion_left_share"),
        (coherence_axis, "motion_left_coherence"),
    ):
        values = np.array([getattr(flux, name) for flux in fluxes])
        for flag, (colour, marker, meaning) in _MOTION_LEFT_STYLE.items():
            marked = flags == flag
            if marked.any():
                axis.plot(
                    middles[marked],
                    values[marked],
                    linestyle="none",
                    marker=marker,
                    markersize=8,
                    color=colour,
                    label=f"flag {int(flag)} ({meaning})",
                )
        axis.set_ylim(bottom=0.0)
        axis.grid(alpha=0.3)
    thresholds = DEFAULT_THRESHOLDS
    for share, colour, meaning in (
        (thresholds.suspect_share, "tab:orange", "suspect"),
        (thresholds.fail_share, "tab:red", "fail"),
    ):
        share_axis.axhline(
            share, color=colour, linestyle="--", label=f"{meaning} from {share:g} (default)"
        )
    coherence_axis.plot(
        middles,
        [flux.motion_left_coherence_threshold for flux in fluxes],
        linestyle="none",
        marker="_",
        markersize=30,
        color="grey",
        label="counts above (unrelated series' coherence + "
        f"{thresholds.coherence_sigmas:g}σ, default)",
    )
    share_axis.set_ylabel("platform w left in w (share)")
    coherence_axis.set_ylabel("coherence of w with platform w")
    coherence_axis.set_xlabel(_time_label(data))
    for axis in (share_axis, coherence_axis):
        axis.legend(loc="upper right", fontsize="small")
    unjudged = int(np.count_nonzero(flags == QualityFlag.NOT_EVALUATED))
    note = f" ({unjudged} window(s) too short or broken to judge)" if unjudged else ""
    figure.suptitle(titled(data, f"wave motion left in the corrected w per flux window{note}"))
    return figure


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
    figure = vertical_wind_spectrum_figure(data)
    return None if figure is None else _save(figure, path)


def vertical_wind_spectrum_figure(data: ReportData) -> Figure | None:
    """The figure of ``vertical_wind_spectrum.png`` (see the module docstring); None when the
    record holds no run of samples long enough."""
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
                label="wave band (platform heave)" if axis is density_axis else None,
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
    return figure


def _segment_samples(samples: int, sample_rate_hz: float) -> int:
    """Welch segment length: at least ``_MIN_SEGMENTS`` half-overlapping segments, and no longer
    than ``_LONGEST_SEGMENT_S`` (which resolves wave periods of 20 s)."""
    by_count = 2 * samples // (_MIN_SEGMENTS + 1)
    return int(max(_MIN_SPECTRUM_SAMPLES, min(by_count, _LONGEST_SEGMENT_S * sample_rate_hz)))


def _log_band_average(frequency_hz: np.ndarray, density: np.ndarray):
    """The spectrum averaged over bands of equal width in log frequency (``_BANDS_PER_DECADE``
    per decade); bands holding no estimate are left out."""
    edges = np.logspace(
        np.log10(frequency_hz[0]) - 1e-9,
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
    """A f^(−5/3) line over the corrected spectrum's upper decade, where a sonic at sea sees
    the inertial subrange, through the median of S(f)·f^(5/3) there: it lies on the spectrum
    where the spectrum follows the slope."""
    upper = (frequency_hz >= frequency_hz[-1] / 10.0) & np.isfinite(density) & (density > 0)
    if np.count_nonzero(upper) < 2:
        return
    span = frequency_hz[upper]
    level = float(np.median(density[upper] * span ** (5.0 / 3.0)))
    axis.loglog(
        span,
        level * span ** (-5.0 / 3.0),
        color="black",
        linestyle=":",
        linewidth=1.2,
        label="f^(−5/3)",
    )


def _wave_band_hz(data: ReportData) -> tuple[float, float] | None:
    """The record's wave band, Hz, from the navigation's vertical velocity as each flux
    window's (:func:`wind_comp.wave_motion_left.platform_wave_band_hz`); None without it."""
    if data.nav_up_velocity_mps is None or data.attitude_t_s.size < 2:
        return None
    interval_s = float(np.median(np.diff(data.attitude_t_s)))
    return platform_wave_band_hz(data.attitude_t_s, data.nav_up_velocity_mps, interval_s)


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


def write_current_figures(current: CurrentData, out_dir: Path) -> list[Path]:
    """Draw the current's figures into ``out_dir``: ``current_time_series.png`` always,
    ``current_averaging.png`` when the bag carries both truth topics; return their paths."""
    paths = [_plot_current_time_series(current, out_dir / "current_time_series.png")]
    if current.truth_current_enu_mps is not None and current.truth_water_enu_mps is not None:
        paths.append(_plot_current_averaging(current, out_dir / "current_averaging.png"))
    return paths


def _plot_current_time_series(current: CurrentData, path: Path) -> Path:
    """East and north components: the single samples (waves and all), the window means, and
    the truth; then speed and direction (toward) of the means."""
    origin_s = _minute_origin_s(current.t_s)
    t_s = current.t_s - origin_s
    figure = Figure(figsize=(10, 9))
    east_axis, north_axis, speed_axis, direction_axis = figure.subplots(4, 1, sharex=True)
    for axis, k, name in ((east_axis, 0, "east"), (north_axis, 1, "north")):
        axis.plot(
            t_s,
            current.current_enu_mps[:, k],
            ".",
            markersize=2,
            color="0.6",
            label="current/velocity (single samples)",
        )
        if current.truth_water_enu_mps is not None:
            axis.plot(
                t_s,
                current.truth_water_enu_mps[:, k],
                color="tab:cyan",
                linewidth=0.6,
                label="water at the DVL (truth)",
            )
        if current.truth_current_enu_mps is not None:
            axis.plot(
                t_s, current.truth_current_enu_mps[:, k], color="tab:green", label="current (truth)"
            )
        axis.set_ylabel(f"{name} (m/s)")
    for product, color in _window_colours(current.products):
        # Over the samples the window holds: a window closed at the end of the data is short.
        start, end = product.first_sample_s - origin_s, product.last_sample_s - origin_s
        label = f"{product.window_s:g} s mean"
        east_axis.hlines(product.mean_u_enu_mps, start, end, color=color, label=label)
        north_axis.hlines(product.mean_v_enu_mps, start, end, color=color, label=label)
        speed_axis.hlines(product.speed_mps, start, end, color=color, label=label)
        direction_axis.hlines(product.direction_deg, start, end, color=color, label=label)
    if current.truth_current_enu_mps is not None:
        truth = current.truth_current_enu_mps
        speed_axis.plot(
            t_s, np.hypot(truth[:, 0], truth[:, 1]), color="tab:green", label="current (truth)"
        )
        direction_axis.plot(
            t_s,
            oceanographic_direction_deg(truth[:, 0], truth[:, 1]),
            color="tab:green",
            label="current (truth)",
        )
    speed_axis.set_ylabel("speed of the mean (m/s)")
    direction_axis.set_ylabel("toward (deg)")
    direction_axis.set_xlabel(
        "time (s)" if origin_s == 0.0 else f"time (s) since {utc_text(origin_s)}"
    )
    for axis in (east_axis, north_axis, speed_axis, direction_axis):
        axis.grid(alpha=0.3)
        handles, labels = axis.get_legend_handles_labels()
        unique = dict(zip(labels, handles, strict=True))
        axis.legend(unique.values(), unique.keys(), loc="upper right", fontsize="small")
    east_axis.set_title("current: single DVL samples and window means (ENU, toward)")
    return _save(figure, path)


def _plot_current_averaging(current: CurrentData, path: Path) -> Path:
    rows = [row for row in error_by_window_length(current) if row.n_windows > 0]
    windows = np.array([row.window_s for row in rows[1:]])
    figure = Figure(figsize=(8, 5))
    axis = figure.subplots()
    for field, label, color in (
        ("estimate_vs_current_mps", "estimate − current (what a user gets)", "tab:red"),
        ("water_vs_current_mps", "water at the DVL − current (the waves' part)", "tab:cyan"),
        ("estimate_vs_water_mps", "estimate − water at the DVL (navigation, DVL)", "tab:gray"),
    ):
        values = np.array([getattr(row, field) for row in rows])
        axis.loglog(windows, values[1:], "o-", color=color, label=label)
        axis.axhline(values[0], color=color, linestyle=":", linewidth=0.8)
    axis.set_xlabel("averaging window (s); dotted: single samples")
    axis.set_ylabel("RMS horizontal error of the window mean (m/s)")
    axis.set_title("what averaging removes: the waves fall as 1/T, noise as 1/√T")
    axis.grid(alpha=0.3, which="both")
    axis.legend(fontsize="small")
    return _save(figure, path)


def _window_colours(products):
    colours = {60.0: "tab:orange", 600.0: "tab:red"}
    for product in products:
        yield product, colours.get(product.window_s, "tab:purple")


def _minute_origin_s(t_s: np.ndarray) -> float:
    return float(np.floor(t_s[0] / 60.0) * 60.0) if t_s.size else 0.0
