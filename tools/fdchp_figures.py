"""Figures of the FDCHP comparisons (``bench_fdchp.py``, ``fdchp_simulated.py``), drawn with the
Agg canvas directly (no pyplot, no display):

- ``fdchp_wave_band.png``: the real record's vertical wind, uncorrected, Edson's and ours: its
  spectrum, its coherence with the buoy's heave, and the share of the platform's vertical
  velocity each correction leaves in it (in phase), per frequency, the wave band shaded;
- ``fdchp_simulated.png``: on each simulated sea, the spectrum of the vertical wind's error
  against the truth, Edson's and ours, beside the uncorrected w's, the wave band shaded.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure
from scipy import signal

from wind_comp.motion_residual import SEGMENT_S, gaps_filled

HIGHEST_HZ = 2.0
COLOURS = {"uncorrected": "tab:gray", "Edson": "tab:blue", "ours": "tab:red"}


def _spectra(series: dict, reference, rate_hz: float):
    """Per series: frequency, its density, its coherence with ``reference``, and the real part
    of its cross-spectrum with ``reference`` over the reference's spectrum."""
    segment = int(SEGMENT_S * rate_hz)
    x = gaps_filled(reference)
    frequency, reference_density = signal.welch(x, fs=rate_hz, nperseg=segment)
    result = {}
    for label, values in series.items():
        y = gaps_filled(values)
        _, density = signal.welch(y, fs=rate_hz, nperseg=segment)
        _, coherence = signal.coherence(x, y, fs=rate_hz, nperseg=segment)
        _, cross = signal.csd(x, y, fs=rate_hz, nperseg=segment)
        result[label] = (density, coherence, cross.real / reference_density)
    return frequency, result


def _shade(axis, band_hz, label=None) -> None:
    axis.axvspan(*band_hz, color="tab:orange", alpha=0.12, zorder=0, label=label)


def _save(figure: Figure, path: Path) -> Path:
    FigureCanvasAgg(figure)
    figure.tight_layout()
    figure.savefig(path, dpi=110)
    return path


def draw_wave_band(
    path: Path,
    vertical_wind_mps: dict,
    heave_mps2,
    platform_up_mps,
    band_hz: tuple[float, float],
    rate_hz: float,
) -> Path:
    """``fdchp_wave_band.png`` from the vertical wind series by label (m/s), the heave
    acceleration (m/s²) and our platform vertical velocity (m/s, ENU up)."""
    frequency, by_heave = _spectra(vertical_wind_mps, heave_mps2, rate_hz)
    _, by_platform = _spectra(vertical_wind_mps, platform_up_mps, rate_hz)
    shown = (frequency > 0) & (frequency <= HIGHEST_HZ)
    figure = Figure(figsize=(9, 9))
    density_axis, coherence_axis, left_axis = figure.subplots(3, 1, sharex=True)
    for label in vertical_wind_mps:
        colour = COLOURS.get(label)
        density, coherence, _ = by_heave[label]
        density_axis.semilogy(frequency[shown], density[shown], color=colour, label=label)
        coherence_axis.plot(frequency[shown], coherence[shown], color=colour, label=label)
        if label != "uncorrected":
            left = by_platform[label][2]
            left_axis.plot(frequency[shown], left[shown], color=colour, label=label)
    for axis in (density_axis, coherence_axis, left_axis):
        _shade(axis, band_hz, "wave band" if axis is density_axis else None)
        axis.grid(alpha=0.3)
    left_axis.axhline(0.0, color="black", linewidth=0.8)
    # Away from the waves the platform hardly moves and the ratio is noise.
    left_axis.set_ylim(-0.5, 1.0)
    density_axis.set_ylabel("S(f) of w (m²/s² per Hz)")
    coherence_axis.set_ylabel("coherence with the heave")
    left_axis.set_ylabel("platform w left, in phase")
    left_axis.set_xlabel("frequency (Hz)")
    density_axis.set_title(
        f"OOI FDCHP record: vertical wind, uncorrected and corrected ({SEGMENT_S:.0f} s segments)"
    )
    density_axis.legend(loc="upper right", fontsize="small")
    return _save(figure, path)


def draw_simulated_errors(path: Path, seas: dict, rate_hz: float) -> Path:
    """``fdchp_simulated.png`` from, per sea, a dict with ``band_hz``, ``uncorrected`` (m/s) and
    the error of each correction against the truth (m/s) by label."""
    figure = Figure(figsize=(9, 3.2 * len(seas)))
    axes = np.atleast_1d(figure.subplots(len(seas), 1))
    for axis, (sea, series) in zip(axes, seas.items(), strict=True):
        for label in ("uncorrected", "Edson", "ours"):
            if label not in series:
                continue
            frequency, density = signal.welch(
                gaps_filled(series[label]), fs=rate_hz, nperseg=int(SEGMENT_S * rate_hz)
            )
            shown = (frequency > 0) & (frequency <= HIGHEST_HZ)
            name = "uncorrected w" if label == "uncorrected" else f"{label}: error of w"
            axis.semilogy(frequency[shown], density[shown], color=COLOURS[label], label=name)
        _shade(axis, series["band_hz"], "wave band")
        axis.set_title(f"simulated FDCHP, {sea.replace('_', ' ')}")
        axis.set_ylabel("S(f) (m²/s² per Hz)")
        axis.grid(alpha=0.3)
        axis.legend(loc="upper right", fontsize="small")
    axes[-1].set_xlabel("frequency (Hz)")
    return _save(figure, path)
