"""Figures and tables summarising a wind-correction run.

:func:`write_report` draws, from plain arrays:
- ``wind_time_series.png``: horizontal speed, direction and vertical wind over time, measured
  (sensor axes, uncorrected), corrected and true (when known);
- ``attitude_error.png`` (only with truth): roll, pitch and heading error of the navigation;
- ``vertical_wind_spectrum.png``: Welch power spectra of the vertical wind before and after
  correction (and of the truth);
- ``wind_products.md``: the averaged wind products and, with truth, the error statistics.

Angles are degrees in every figure and table. Figures are drawn with the Agg canvas directly
(no pyplot), so no display and no global backend state are involved. The ``wind_report``
command draws the report of a run saved with :func:`save_report_data`.
"""

import argparse
import math
from dataclasses import dataclass, field, fields
from pathlib import Path

import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure
from scipy.signal import welch
from scipy.spatial.transform import Rotation

from wind_comp.products import WindProduct, meteorological_direction_deg

_MIN_SPECTRUM_SAMPLES = 32
_MAX_SPECTRUM_SEGMENT = 1024


class ReportDataError(ValueError):
    """Report input arrays are missing or have inconsistent shapes."""


@dataclass(eq=False)
class ReportData:
    """Everything a report shows, as plain arrays.

    Attributes:
        t_s: (N,) anemometer sample stamps, s.
        measured_wind_sensor_mps: (N, 3) measured air velocity in anemometer axes, m/s.
        corrected_wind_enu_mps: (N, 3) motion-corrected wind, ENU, m/s (NaN where invalid).
        true_wind_enu_mps: (N, 3) true wind, ENU, m/s, or None when unknown.
        attitude_t_s: (M,) stamps of the attitude series, s, or None.
        nav_rpy_rad: (M, 3) estimated roll, pitch, yaw (R = Rz(yaw)·Ry(pitch)·Rx(roll)), rad.
        truth_rpy_rad: (M, 3) true roll, pitch, yaw at ``attitude_t_s``, rad, or None.
        products: averaged wind products.
        title: figure title prefix, e.g. the scenario name.
    """

    t_s: np.ndarray
    measured_wind_sensor_mps: np.ndarray
    corrected_wind_enu_mps: np.ndarray
    true_wind_enu_mps: np.ndarray | None = None
    attitude_t_s: np.ndarray | None = None
    nav_rpy_rad: np.ndarray | None = None
    truth_rpy_rad: np.ndarray | None = None
    products: list[WindProduct] = field(default_factory=list)
    title: str = ""

    def __post_init__(self):
        self.t_s = _array("t_s", self.t_s, (None,))
        n_samples = self.t_s.shape[0]
        for name in ("measured_wind_sensor_mps", "corrected_wind_enu_mps"):
            setattr(self, name, _array(name, getattr(self, name), (n_samples, 3)))
        if self.true_wind_enu_mps is not None:
            self.true_wind_enu_mps = _array(
                "true_wind_enu_mps", self.true_wind_enu_mps, (n_samples, 3)
            )
        if (self.nav_rpy_rad is None) != (self.attitude_t_s is None):
            raise ReportDataError("attitude_t_s and nav_rpy_rad must be given together")
        if self.truth_rpy_rad is not None and self.nav_rpy_rad is None:
            raise ReportDataError("truth_rpy_rad needs attitude_t_s and nav_rpy_rad")
        if self.attitude_t_s is not None:
            self.attitude_t_s = _array("attitude_t_s", self.attitude_t_s, (None,))
            n_attitudes = self.attitude_t_s.shape[0]
            for name in ("nav_rpy_rad", "truth_rpy_rad"):
                if getattr(self, name) is not None:
                    setattr(self, name, _array(name, getattr(self, name), (n_attitudes, 3)))


def _array(name: str, values, shape: tuple) -> np.ndarray:
    try:
        array = np.asarray(values, dtype=float)
    except (TypeError, ValueError) as error:
        raise ReportDataError(f"{name} must be a numeric array ({error})") from error
    expected = tuple(array.shape[0] if size is None and array.ndim else size for size in shape)
    if array.ndim != len(shape) or array.shape != expected:
        wanted = ", ".join("N" if size is None else str(size) for size in shape)
        wanted = f"({wanted},)" if len(shape) == 1 else f"({wanted})"
        raise ReportDataError(f"{name} must have shape {wanted}, got {array.shape}")
    return array


def write_report(data: ReportData, out_dir) -> list[Path]:
    """Write the report figures and table into ``out_dir`` (created); return the paths."""
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    paths = [_plot_wind_time_series(data, out_dir / "wind_time_series.png")]
    if data.truth_rpy_rad is not None:
        paths.append(_plot_attitude_error(data, out_dir / "attitude_error.png"))
    spectrum = _plot_vertical_wind_spectrum(data, out_dir / "vertical_wind_spectrum.png")
    if spectrum is not None:
        paths.append(spectrum)
    table = out_dir / "wind_products.md"
    table.write_text(_markdown_summary(data))
    paths.append(table)
    return paths


def _wind_series(data: ReportData) -> list[tuple[str, np.ndarray, str]]:
    """(label, (N, 3) wind, style) of each series; the measured one is in sensor axes."""
    series = [
        ("measured (sensor axes)", data.measured_wind_sensor_mps, "tab:gray"),
        ("corrected", data.corrected_wind_enu_mps, "tab:blue"),
    ]
    if data.true_wind_enu_mps is not None:
        series.append(("true", data.true_wind_enu_mps, "tab:green"))
    return series


def _plot_wind_time_series(data: ReportData, path: Path) -> Path:
    figure = Figure(figsize=(10, 8))
    speed_axis, direction_axis, vertical_axis = figure.subplots(3, 1, sharex=True)
    for label, wind, color in _wind_series(data):
        speed_axis.plot(data.t_s, np.hypot(wind[:, 0], wind[:, 1]), color=color, label=label)
        direction_axis.plot(
            data.t_s,
            meteorological_direction_deg(wind[:, 0], wind[:, 1]),
            ".",
            markersize=2,
            color=color,
            label=label,
        )
        vertical_axis.plot(data.t_s, wind[:, 2], color=color, label=label)
    speed_axis.set_ylabel("horizontal speed (m/s)")
    direction_axis.set_ylabel("direction from (deg)")
    direction_axis.set_ylim(0, 360)
    direction_axis.set_yticks(range(0, 361, 90))
    vertical_axis.set_ylabel("vertical wind w (m/s)")
    vertical_axis.set_xlabel("time (s)")
    speed_axis.legend(loc="upper right")
    speed_axis.set_title(_title(data, "wind before and after motion correction"))
    for axis in (speed_axis, direction_axis, vertical_axis):
        axis.grid(alpha=0.3)
    return _save(figure, path)


def _plot_attitude_error(data: ReportData, path: Path) -> Path:
    errors_deg = _attitude_errors_deg(data.nav_rpy_rad, data.truth_rpy_rad)
    figure = Figure(figsize=(10, 7))
    axes = figure.subplots(3, 1, sharex=True)
    for axis, label, error in zip(axes, ("roll", "pitch", "heading"), errors_deg.T, strict=True):
        axis.plot(data.attitude_t_s, error, color="tab:red")
        axis.set_ylabel(f"{label} error (deg)")
        axis.grid(alpha=0.3)
    axes[-1].set_xlabel("time (s)")
    axes[0].set_title(_title(data, "attitude error (estimate − truth)"))
    return _save(figure, path)


def _attitude_errors_deg(nav_rpy_rad: np.ndarray, truth_rpy_rad: np.ndarray) -> np.ndarray:
    """(M, 3) roll, pitch and heading errors, deg, wrapped to [-180, 180).

    Heading is measured clockwise from North, so its error is the negated yaw error.
    """
    errors = np.degrees(nav_rpy_rad - truth_rpy_rad)
    errors[:, 2] = -errors[:, 2]
    return (errors + 180.0) % 360.0 - 180.0


def _plot_vertical_wind_spectrum(data: ReportData, path: Path) -> Path | None:
    series = _wind_series(data)
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
    axis.set_title(_title(data, "vertical wind spectrum"))
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


def _title(data: ReportData, what: str) -> str:
    return f"{data.title}: {what}" if data.title else what


def _save(figure: Figure, path: Path) -> Path:
    FigureCanvasAgg(figure)
    figure.tight_layout()
    figure.savefig(path, dpi=120)
    return path


def _markdown_summary(data: ReportData) -> str:
    lines = [f"# {_title(data, 'wind products')}", ""]
    if data.true_wind_enu_mps is not None:
        lines += [*_accuracy_table(data), ""]
    lines += _products_table(data.products)
    return "\n".join(lines) + "\n"


def _accuracy_table(data: ReportData) -> list[str]:
    """Bias and RMS of the measured and corrected wind against the truth (valid samples)."""
    true_wind = data.true_wind_enu_mps
    true_speed = np.hypot(true_wind[:, 0], true_wind[:, 1])
    true_direction = meteorological_direction_deg(true_wind[:, 0], true_wind[:, 1])
    lines = [
        "## Error against truth",
        "",
        "| series | quantity | bias | RMS | samples |",
        "|---|---|---|---|---|",
    ]
    for label, wind, _ in _wind_series(data)[:2]:
        speed_error = np.hypot(wind[:, 0], wind[:, 1]) - true_speed
        vertical_error = wind[:, 2] - true_wind[:, 2]
        quantities = [("horizontal speed (m/s)", speed_error), ("w (m/s)", vertical_error)]
        if label == "corrected":
            direction = meteorological_direction_deg(wind[:, 0], wind[:, 1])
            direction_error = (direction - true_direction + 180.0) % 360.0 - 180.0
            quantities.append(("direction (deg)", direction_error))
        for quantity, error in quantities:
            error = error[np.isfinite(error)]
            if error.size:
                bias, rms = float(error.mean()), float(np.sqrt(np.mean(error**2)))
            else:
                bias = rms = math.nan
            lines.append(f"| {label} | {quantity} | {bias:.3f} | {rms:.3f} | {error.size} |")
    return lines


def _products_table(products: list[WindProduct]) -> list[str]:
    lines = [
        "## Averaged wind",
        "",
        "Direction: degrees clockwise from true North, where the wind blows from. "
        "Vectors ENU. Gust: maximum running mean of horizontal speed.",
        "",
    ]
    if not products:
        return [*lines, "No averaging window completed."]
    lines += [
        "| window start (s) | length (s) | valid | invalid | vector mean speed (m/s) "
        "| direction (deg) | scalar mean speed (m/s) | gust (m/s) | mean w (m/s) "
        "| std u (m/s) | std v (m/s) | std w (m/s) |",
        "|" + "---|" * 12,
    ]
    for product in products:
        lines.append(
            f"| {product.window_start_s:.1f} | {product.window_s:.0f} | {product.n_valid} "
            f"| {product.n_invalid} | {product.vector_mean_speed_mps:.2f} "
            f"| {product.vector_mean_direction_deg:.1f} | {product.scalar_mean_speed_mps:.2f} "
            f"| {product.gust_mps:.2f} | {product.mean_w_enu_mps:.3f} "
            f"| {product.std_u_mps:.2f} | {product.std_v_mps:.2f} | {product.std_w_mps:.2f} |"
        )
    return lines


_ARRAY_FIELDS = (
    "t_s",
    "measured_wind_sensor_mps",
    "corrected_wind_enu_mps",
    "true_wind_enu_mps",
    "attitude_t_s",
    "nav_rpy_rad",
    "truth_rpy_rad",
)
_PRODUCT_PREFIX = "product_"


def save_report_data(data: ReportData, path) -> Path:
    """Store ``data`` as a NumPy ``.npz`` file readable by :func:`load_report_data`."""
    arrays = {
        name: getattr(data, name) for name in _ARRAY_FIELDS if getattr(data, name) is not None
    }
    for product_field in fields(WindProduct):
        arrays[_PRODUCT_PREFIX + product_field.name] = np.array(
            [getattr(product, product_field.name) for product in data.products], dtype=float
        )
    path = Path(path)
    np.savez(path, title=np.array(data.title), **arrays)
    return path


def load_report_data(path) -> ReportData:
    """Read a file written by :func:`save_report_data`."""
    try:
        stored = np.load(path)
    except (OSError, ValueError) as error:
        raise ReportDataError(f"{path}: not a readable report data file ({error})") from error
    with stored:
        missing = [name for name in _ARRAY_FIELDS[:3] if name not in stored]
        if missing:
            raise ReportDataError(f"{path}: missing array(s) {missing}")
        arrays = {name: stored[name] for name in _ARRAY_FIELDS if name in stored}
        columns = {
            product_field: stored[_PRODUCT_PREFIX + product_field.name]
            for product_field in fields(WindProduct)
            if _PRODUCT_PREFIX + product_field.name in stored
        }
        title = str(stored["title"]) if "title" in stored else ""
    n_products = min((len(column) for column in columns.values()), default=0)
    products = [
        WindProduct(
            **{
                product_field.name: (
                    int(column[i]) if product_field.type is int else float(column[i])
                )
                for product_field, column in columns.items()
            }
        )
        for i in range(n_products)
    ]
    return ReportData(**arrays, products=products, title=title)


def rpy_rad_from_quaternions(quat_xyzw) -> np.ndarray:
    """(M, 3) roll, pitch, yaw (rad) of body→ENU quaternions (x, y, z, w), for ReportData."""
    yaw_pitch_roll = Rotation.from_quat(np.asarray(quat_xyzw, dtype=float)).as_euler("ZYX")
    return yaw_pitch_roll[..., ::-1]


def main(argv=None) -> int:
    """Command line: draw the report of a run saved with :func:`save_report_data`."""
    parser = argparse.ArgumentParser(
        prog="wind_report", description="Draw wind-correction figures and tables."
    )
    parser.add_argument("data", type=Path, help="report data file (.npz)")
    parser.add_argument(
        "--out", type=Path, default=None, help="output folder (default: <data>_report)"
    )
    arguments = parser.parse_args(argv)
    out_dir = arguments.out or arguments.data.with_name(arguments.data.stem + "_report")
    try:
        data = load_report_data(arguments.data)
    except ReportDataError as error:
        parser.exit(2, f"wind_report: {error}\n")
    for path in write_report(data, out_dir):
        print(path)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
