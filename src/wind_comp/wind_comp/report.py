"""Figures and tables summarising a wind-correction run.

:func:`write_report` draws, from plain arrays:
- ``wind_time_series.png``: horizontal speed, direction and vertical wind over time, measured
  (sensor axes, uncorrected), corrected and true (when known);
- ``attitude_error.png`` (only with truth): roll, pitch and heading error of the navigation,
  within the filter's own ±3σ when the navigation carries its covariance;
- ``vertical_wind_spectrum.png``: Welch power spectra of the vertical wind before and after
  correction (and of the truth);
- ``wind_products.md``: the averaged wind products and, with truth, the error statistics.

Angles are degrees in every figure and table. Figures are drawn with the Agg canvas directly
(no pyplot), so no display and no global backend state are involved.

:func:`report_data_from_bag` gathers the arrays from a bag that holds ``anemometer/wind`` and
``wind/true`` (written by ``process_bag`` or recorded from the running nodes), with the truth
and navigation topics when present. The ``wind_report`` command draws the report of such a bag,
or of a run saved with :func:`save_report_data`.
"""

import argparse
import datetime
import math
import sys
from dataclasses import dataclass, field, fields
from pathlib import Path
from typing import NamedTuple

import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure
from scipy.signal import welch
from scipy.spatial.transform import Rotation, Slerp

from buoy_common.bag_io import BagError, BagReader
from buoy_common.contract import (
    NANOSECONDS_PER_SECOND,
    NAV_ODOMETRY_TOPIC,
    TRUTH_ODOMETRY_TOPIC,
    TRUTH_WIND_TOPIC,
    WIND_MEAN_PREFIX,
    WIND_RAW_TOPIC,
    WIND_STATS_PREFIX,
    WIND_TRUE_TOPIC,
    window_label,
)
from wind_comp.compensator import CompensatorConfig
from wind_comp.nav_messages import (
    stats_values,
)
from wind_comp.products import WindAverager, WindProduct, meteorological_direction_deg

# Plots count time from the start of the minute of the first sample, so simulated runs (which
# start on a whole minute) show scenario time and the 1-minute windows start on round numbers.
_TIME_ORIGIN_STEP_S = 60

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
        nav_rpy_sigma_rad: (M, 3) the filter's 1σ of the estimated roll, pitch and yaw, rad, or
            None (see :func:`rpy_sigma_rad`).
        products: averaged wind products.
        title: figure title prefix, e.g. the scenario name.
        time_origin_s: stamp (s) that the time axes of the figures count from.
        products_source: where the products come from, stated under their table.
    """

    t_s: np.ndarray
    measured_wind_sensor_mps: np.ndarray
    corrected_wind_enu_mps: np.ndarray
    true_wind_enu_mps: np.ndarray | None = None
    attitude_t_s: np.ndarray | None = None
    nav_rpy_rad: np.ndarray | None = None
    truth_rpy_rad: np.ndarray | None = None
    nav_rpy_sigma_rad: np.ndarray | None = None
    products: list[WindProduct] = field(default_factory=list)
    title: str = ""
    time_origin_s: float = 0.0
    products_source: str = ""

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
        for name in ("truth_rpy_rad", "nav_rpy_sigma_rad"):
            if getattr(self, name) is not None and self.nav_rpy_rad is None:
                raise ReportDataError(f"{name} needs attitude_t_s and nav_rpy_rad")
        if self.attitude_t_s is not None:
            self.attitude_t_s = _array("attitude_t_s", self.attitude_t_s, (None,))
            n_attitudes = self.attitude_t_s.shape[0]
            for name in ("nav_rpy_rad", "truth_rpy_rad", "nav_rpy_sigma_rad"):
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
    t_s = data.t_s - data.time_origin_s
    for label, wind, color in _wind_series(data):
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
    speed_axis.set_title(_title(data, "wind before and after motion correction"))
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
    axes[0].set_title(_title(data, "attitude error (estimate − truth)"))
    return _save(figure, path)


def attitude_errors_deg(nav_rpy_rad: np.ndarray, truth_rpy_rad: np.ndarray) -> np.ndarray:
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


def _time_label(data: ReportData) -> str:
    if data.time_origin_s == 0.0:
        return "time (s)"
    return f"time (s) since {utc_text(data.time_origin_s)}"


def utc_text(t_s: float) -> str:
    """ISO 8601 UTC time of ``t_s`` (s since the epoch), whole seconds."""
    moment = datetime.datetime.fromtimestamp(t_s, tz=datetime.UTC)
    return moment.strftime("%Y-%m-%dT%H:%M:%SZ")


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
    for label, wind, _ in _wind_series(data)[:2]:
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


_ARRAY_FIELDS = (
    "t_s",
    "measured_wind_sensor_mps",
    "corrected_wind_enu_mps",
    "true_wind_enu_mps",
    "attitude_t_s",
    "nav_rpy_rad",
    "truth_rpy_rad",
    "nav_rpy_sigma_rad",
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
    np.savez(
        path,
        title=np.array(data.title),
        time_origin_s=np.array(data.time_origin_s),
        products_source=np.array(data.products_source),
        **arrays,
    )
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
        time_origin_s = float(stored["time_origin_s"]) if "time_origin_s" in stored else 0.0
        source = str(stored["products_source"]) if "products_source" in stored else ""
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
    return ReportData(
        **arrays,
        products=products,
        title=title,
        time_origin_s=time_origin_s,
        products_source=source,
    )


def rpy_rad_from_quaternions(quat_xyzw) -> np.ndarray:
    """(M, 3) roll, pitch, yaw (rad) of body→ENU quaternions (x, y, z, w), for ReportData."""
    yaw_pitch_roll = Rotation.from_quat(np.asarray(quat_xyzw, dtype=float)).as_euler("ZYX")
    return yaw_pitch_roll[..., ::-1]


class StampedVectors(NamedTuple):
    """The ``Vector3Stamped`` messages of one topic, in bag order."""

    stamps_ns: np.ndarray
    """(N,) int64 header stamps, ns since the epoch."""
    vectors: np.ndarray
    """(N, 3) vector components, in the topic's unit and frame."""


def stored_topic(reader: BagReader, topic: str) -> str | None:
    """The name under which ``reader`` stores relative ``topic`` (with or without "/"), or None."""
    for candidate in (topic, "/" + topic.lstrip("/")):
        if candidate in reader.topics:
            return candidate
    return None


def _has_messages(reader: BagReader, topic: str) -> bool:
    name = stored_topic(reader, topic)
    return name is not None and reader.topics[name].count > 0


def _stamp_ns(header) -> int:
    return int(header.stamp.sec) * NANOSECONDS_PER_SECOND + int(header.stamp.nanosec)


def stamped_vectors(reader: BagReader, topic: str) -> StampedVectors:
    """Header stamps and vectors of every ``Vector3Stamped`` message of ``topic``."""
    stamps, vectors = [], []
    for message in reader.messages([topic]):
        decoded = reader.decode(message)
        stamps.append(_stamp_ns(decoded.header))
        vectors.append((decoded.vector.x, decoded.vector.y, decoded.vector.z))
    return StampedVectors(
        np.array(stamps, dtype=np.int64), np.array(vectors, dtype=float).reshape(-1, 3)
    )


def stamped_orientations(
    reader: BagReader, topic: str
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(M,) int64 header stamps (ns), (M, 4) body→ENU quaternions (x, y, z, w) and (M, 3, 3)
    attitude covariances (the pose covariance's rotation block: the ENU rotation-vector error,
    rad²) of an ``Odometry`` topic."""
    stamps, quats, covariances = [], [], []
    for message in reader.messages([topic]):
        decoded = reader.decode(message)
        orientation = decoded.pose.pose.orientation
        stamps.append(_stamp_ns(decoded.header))
        quats.append((orientation.x, orientation.y, orientation.z, orientation.w))
        covariances.append(np.reshape(decoded.pose.covariance, (6, 6))[3:, 3:])
    return (
        np.array(stamps, dtype=np.int64),
        np.array(quats, dtype=float).reshape(-1, 4),
        np.array(covariances, dtype=float).reshape(-1, 3, 3),
    )


def rpy_sigma_rad(rpy_rad, attitude_covariance_enu_rad2) -> np.ndarray:
    """(M, 3) 1σ (rad) of roll, pitch and yaw (R = Rz(yaw)·Ry(pitch)·Rx(roll)) at attitudes
    ``rpy_rad`` (M, 3) whose error is the ENU rotation vector φ (R_true = Exp(φ)·R) with
    covariance ``attitude_covariance_enu_rad2`` (M, 3, 3).

    To first order the Euler errors are J·φ with J the inverse of the map from Euler increments
    to the rotation they make in ENU, [Rz·Ry·x̂ | Rz·ŷ | ẑ]; their covariance is J·P·Jᵀ.
    """
    _, pitch, yaw = np.moveaxis(np.asarray(rpy_rad, dtype=float), -1, 0)
    cos_yaw, sin_yaw, cos_pitch = np.cos(yaw), np.sin(yaw), np.cos(pitch)
    zeros, ones = np.zeros_like(yaw), np.ones_like(yaw)
    jacobian = np.stack(
        [
            np.stack([cos_yaw / cos_pitch, sin_yaw / cos_pitch, zeros], axis=-1),
            np.stack([-sin_yaw, cos_yaw, zeros], axis=-1),
            np.stack([cos_yaw * np.tan(pitch), sin_yaw * np.tan(pitch), ones], axis=-1),
        ],
        axis=-2,
    )
    covariance = jacobian @ np.asarray(attitude_covariance_enu_rad2, dtype=float)
    variances = np.einsum("...ij,...ij->...i", covariance, jacobian)
    return np.sqrt(np.maximum(variances, 0.0))


def vectors_at_stamps(stamps_ns: np.ndarray, source: StampedVectors) -> np.ndarray:
    """(N, 3): for each stamp (ns), the vector of the ``source`` message carrying exactly that
    header stamp; NaN where no message does."""
    order = np.argsort(source.stamps_ns, kind="stable")
    sorted_stamps = source.stamps_ns[order]
    matched = np.full((len(stamps_ns), 3), np.nan)
    if sorted_stamps.size == 0:
        return matched
    index = np.minimum(np.searchsorted(sorted_stamps, stamps_ns), sorted_stamps.size - 1)
    found = sorted_stamps[index] == stamps_ns
    matched[found] = source.vectors[order[index[found]]]
    return matched


def interpolate_vectors(stamps_ns: np.ndarray, source: StampedVectors) -> np.ndarray:
    """(N, 3) ``source`` vectors linearly interpolated at ``stamps_ns`` (ns); NaN outside the
    span of the source stamps."""
    interpolated = np.full((len(stamps_ns), 3), np.nan)
    if source.stamps_ns.size == 0:
        return interpolated
    order = np.argsort(source.stamps_ns, kind="stable")
    # Relative seconds keep nanosecond resolution that epoch seconds in float64 would lose.
    origin_ns = source.stamps_ns[order[0]]
    source_t_s = (source.stamps_ns[order] - origin_ns) * 1e-9
    t_s = (np.asarray(stamps_ns, dtype=np.int64) - origin_ns) * 1e-9
    for axis in range(3):
        interpolated[:, axis] = np.interp(
            t_s, source_t_s, source.vectors[order, axis], left=np.nan, right=np.nan
        )
    return interpolated


def interpolate_rpy_rad(stamps_ns: np.ndarray, source_stamps_ns, source_quat_xyzw) -> np.ndarray:
    """(N, 3) roll, pitch, yaw (rad) of the source attitudes slerped to ``stamps_ns`` (ns);
    NaN outside the span of the source stamps or when fewer than two source samples exist."""
    rpy = np.full((len(stamps_ns), 3), np.nan)
    unique_stamps, first = np.unique(
        np.asarray(source_stamps_ns, dtype=np.int64), return_index=True
    )
    if unique_stamps.size < 2:
        return rpy
    origin_ns = unique_stamps[0]
    slerp = Slerp((unique_stamps - origin_ns) * 1e-9, Rotation.from_quat(source_quat_xyzw[first]))
    t_s = (np.asarray(stamps_ns, dtype=np.int64) - origin_ns) * 1e-9
    inside = (t_s >= 0.0) & (t_s <= (unique_stamps[-1] - origin_ns) * 1e-9)
    if np.any(inside):
        rpy[inside] = rpy_rad_from_quaternions(slerp(t_s[inside]).as_quat())
    return rpy


def report_data_from_bag(bag, title: str | None = None) -> ReportData:
    """The :class:`ReportData` of a bag holding ``anemometer/wind`` and ``wind/true``.

    - ``t_s`` and the measured wind: every ``anemometer/wind`` message (header stamps).
    - corrected wind: the ``wind/true`` message with the same header stamp, NaN when none.
    - true wind (with ``truth/wind``): interpolated linearly to the anemometer stamps.
    - attitude (with ``nav/odometry``): at the navigation stamps, with ``truth/odometry``
      slerped to them.
    - products: the ``wind/stats_<window>`` messages (mean vectors from ``wind/mean_<window>``)
      when the bag has them, otherwise recomputed from the corrected wind with the default
      windows of the compensation.

    Raises :class:`ReportDataError` (one line) for a missing or unreadable bag or one without
    the two wind topics.
    """
    try:
        with BagReader(bag) as reader:
            if reader.recovery is not None:
                print(f"wind_report: warning: {reader.recovery.describe(bag)}", file=sys.stderr)
            return _report_data(reader, Path(bag).name if title is None else title)
    except BagError as error:
        raise ReportDataError(str(error)) from error


def _report_data(reader: BagReader, title: str) -> ReportData:
    required = (WIND_RAW_TOPIC, WIND_TRUE_TOPIC)
    missing = [topic for topic in required if not _has_messages(reader, topic)]
    if missing:
        raise ReportDataError(
            f"bag {reader.path} has no {' and no '.join(missing)} messages; a wind report needs "
            f"{' and '.join(required)} (a bag written by process_bag, or recorded with "
            "compensation_node running)"
        )
    measured = stamped_vectors(reader, WIND_RAW_TOPIC)
    corrected = vectors_at_stamps(measured.stamps_ns, stamped_vectors(reader, WIND_TRUE_TOPIC))
    t_s = measured.stamps_ns / NANOSECONDS_PER_SECOND
    true_wind = None
    if _has_messages(reader, TRUTH_WIND_TOPIC):
        true_wind = interpolate_vectors(
            measured.stamps_ns, stamped_vectors(reader, TRUTH_WIND_TOPIC)
        )
    attitude_t_s = nav_rpy = truth_rpy = nav_rpy_sigma = None
    if _has_messages(reader, NAV_ODOMETRY_TOPIC):
        nav_stamps_ns, nav_quats, nav_covariances = stamped_orientations(reader, NAV_ODOMETRY_TOPIC)
        attitude_t_s = nav_stamps_ns / NANOSECONDS_PER_SECOND
        nav_rpy = rpy_rad_from_quaternions(nav_quats)
        nav_rpy_sigma = rpy_sigma_rad(nav_rpy, nav_covariances)
        if _has_messages(reader, TRUTH_ODOMETRY_TOPIC):
            truth_stamps_ns, truth_quats, _ = stamped_orientations(reader, TRUTH_ODOMETRY_TOPIC)
            truth_rpy = interpolate_rpy_rad(nav_stamps_ns, truth_stamps_ns, truth_quats)
    products, products_source = _products(reader, t_s, corrected)
    minute_ns = _TIME_ORIGIN_STEP_S * NANOSECONDS_PER_SECOND
    return ReportData(
        t_s=t_s,
        measured_wind_sensor_mps=measured.vectors,
        corrected_wind_enu_mps=corrected,
        true_wind_enu_mps=true_wind,
        attitude_t_s=attitude_t_s,
        nav_rpy_rad=nav_rpy,
        truth_rpy_rad=truth_rpy,
        nav_rpy_sigma_rad=nav_rpy_sigma,
        products=products,
        title=title,
        time_origin_s=float(measured.stamps_ns[0] // minute_ns * _TIME_ORIGIN_STEP_S),
        products_source=products_source,
    )


def _products(
    reader: BagReader, t_s: np.ndarray, corrected_wind_enu_mps: np.ndarray
) -> tuple[list[WindProduct], str]:
    """The bag's published wind products, or products recomputed from the corrected wind; and a
    sentence saying which."""
    stats_topics = sorted(
        name for name in reader.topics if name.lstrip("/").startswith(WIND_STATS_PREFIX)
    )
    if stats_topics:
        per_topic = {topic: _published_products(reader, topic) for topic in stats_topics}
        products = sorted(
            (product for topic_products in per_topic.values() for product in topic_products),
            key=lambda product: (product.window_s, product.window_start_s),
        )
        by_window = sorted(
            per_topic, key=lambda topic: min((p.window_s for p in per_topic[topic]), default=0.0)
        )
        return products, "published on " + ", ".join(name.lstrip("/") for name in by_window)
    defaults = {field.name: field.default for field in fields(CompensatorConfig)}
    windows_s = defaults["product_windows_s"]
    gust_window_s = defaults["gust_window_s"]
    products = []
    for window_s in windows_s:
        averager = WindAverager(window_s, gust_window_s)
        products += averager.add_batch(t_s, corrected_wind_enu_mps) + averager.flush()
    labels = " and ".join(window_label(window_s) for window_s in windows_s)
    return products, (
        f"recomputed from {WIND_TRUE_TOPIC}, {labels} windows, {gust_window_s:g} s gust "
        f"(the bag has no {WIND_STATS_PREFIX}* topic)"
    )


def _published_products(reader: BagReader, stats_topic: str) -> list[WindProduct]:
    """Products from the ``wind/stats_<window>`` messages of ``stats_topic``, each with the mean
    vector of the ``wind/mean_<window>`` message stamped at the window end (when recorded; else
    u and v from speed and direction, and w NaN). The gust window is not published: NaN."""
    mean_topic = stored_topic(
        reader, WIND_MEAN_PREFIX + stats_topic.lstrip("/").removeprefix(WIND_STATS_PREFIX)
    )
    means = (
        stamped_vectors(reader, mean_topic)
        if mean_topic
        else StampedVectors(np.empty(0, dtype=np.int64), np.empty((0, 3)))
    )
    products = []
    for message in reader.messages([stats_topic]):
        try:
            values = stats_values(reader.decode(message))
            product = _product_from_stats(values, means)
        except (KeyError, ValueError) as error:
            raise ReportDataError(
                f"bag {reader.path}: {stats_topic} message at log time {message.log_time_ns} ns "
                f"is not a wind statistics layout ({error})"
            ) from error
        products.append(product)
    return products


def _product_from_stats(values: dict[str, float], means: StampedVectors) -> WindProduct:
    end_ns = round(values["window_end_s"] * NANOSECONDS_PER_SECOND)
    mean = vectors_at_stamps(np.array([end_ns], dtype=np.int64), means)[0]
    if np.isnan(mean[0]):
        speed = values["vector_mean_speed_mps"]
        from_rad = math.radians(values["vector_mean_direction_deg"])
        mean = np.array([-speed * math.sin(from_rad), -speed * math.cos(from_rad), math.nan])
    return WindProduct(
        window_s=values["window_end_s"] - values["window_start_s"],
        window_start_s=values["window_start_s"],
        window_end_s=values["window_end_s"],
        first_sample_s=values["first_sample_s"],
        last_sample_s=values["last_sample_s"],
        n_valid=int(values["n_valid"]),
        n_invalid=int(values["n_invalid"]),
        mean_u_enu_mps=float(mean[0]),
        mean_v_enu_mps=float(mean[1]),
        mean_w_enu_mps=float(mean[2]),
        vector_mean_speed_mps=values["vector_mean_speed_mps"],
        vector_mean_direction_deg=values["vector_mean_direction_deg"],
        scalar_mean_speed_mps=values["scalar_mean_speed_mps"],
        gust_mps=values["gust_mps"],
        gust_window_s=math.nan,
        std_u_mps=values["std_u_mps"],
        std_v_mps=values["std_v_mps"],
        std_w_mps=values["std_w_mps"],
    )


def main(argv=None) -> int:
    """Command line: draw the report of a bag, or of a run saved with :func:`save_report_data`."""
    parser = argparse.ArgumentParser(
        prog="wind_report", description="Draw wind-correction figures and tables."
    )
    parser.add_argument(
        "source",
        type=Path,
        help="bag directory holding anemometer/wind and wind/true (written by process_bag or "
        "recorded from the nodes), or a report data file (.npz)",
    )
    parser.add_argument(
        "--out", type=Path, default=None, help="output folder (default: <source>_report)"
    )
    arguments = parser.parse_args(argv)
    source = arguments.source
    try:
        if source.is_file():
            data = load_report_data(source)
            default_out = source.with_name(source.stem + "_report")
        else:
            data = report_data_from_bag(source)
            default_out = source.with_name(source.name + "_report")
    except ReportDataError as error:
        parser.exit(2, f"wind_report: {error}\n")
    for path in write_report(data, arguments.out or default_out):
        print(path)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
