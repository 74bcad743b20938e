"""The current of a run: its series and products, its accuracy against the simulator's truth,
and what averaging over a window leaves of the waves.

A single ``current/velocity`` sample is the water's velocity at the DVL: the current plus the
waves' orbital velocity at the DVL's depth, plus the estimate's own error (navigation, DVL).
The mean over a window of length T keeps of the orbital velocity its displacement over the
window divided by T: (ξ(t + T) − ξ(t)) / T, whose RMS is about √2·σ_ξ / T with σ_ξ the RMS
orbital excursion of the water at that depth. The residual therefore falls as 1/T once T is
several wave periods, not as 1/√T like white noise. :func:`error_by_window_length` measures
it: the means of the estimate against the current's (what a user gets), of the true water
velocity against the current's (the waves' part alone) and of the estimate against the true
water velocity (the estimate's own part).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from buoy_common.bag_io import BagError, BagReader
from buoy_common.contract import (
    CURRENT_STATS_PREFIX,
    CURRENT_TOPIC,
    NANOSECONDS_PER_SECOND,
    TRUTH_CURRENT_TOPIC,
    TRUTH_WATER_VELOCITY_TOPIC,
    QualityFlag,
)
from buoy_common.namespaces import TopicView
from buoy_processing.bag_processing import CURRENT_PRODUCTS_CSV_SUFFIX
from buoy_processing.output_facts import north_token_of_bag
from buoy_processing.report.data import (
    ReportDataError,
    has_messages,
    interpolate_vectors,
    stamped_vectors,
    stored_topic,
)
from wind_comp.compensation_messages import stats_values
from wind_comp.products import CurrentProduct, oceanographic_direction_deg

WINDOW_LENGTHS_S = (10.0, 30.0, 60.0, 120.0, 300.0, 600.0, 1200.0)
"""Window lengths of :func:`error_by_window_length` by default, s."""
MIN_WINDOW_FRACTION = 0.9
"""A window counts in the accuracy figures when its samples span this share of it and this
share of them are valid."""


@dataclass
class CurrentData:
    """The current of a run as plain arrays.

    Attributes:
        t_s: (N,) header stamps of the DVL samples (``current/velocity``), s since the epoch.
        current_enu_mps: (N, 3) the estimated current, ENU, m/s; NaN where invalid.
        products: the averaged products stored in the bag (``current/stats_<window>``).
        truth_current_enu_mps: (N, 3) ``truth/current`` at the stamps, or None.
        truth_water_enu_mps: (N, 3) ``truth/water_velocity`` at the stamps, or None.
        north: the north the directions are referenced to, as
            :attr:`~buoy_processing.output_facts.OutputFacts.north_token`; empty when the bag
            does not record it.
    """

    t_s: np.ndarray
    current_enu_mps: np.ndarray
    products: list[CurrentProduct]
    truth_current_enu_mps: np.ndarray | None = None
    truth_water_enu_mps: np.ndarray | None = None
    north: str = ""


def current_report_data(bag, view: TopicView | None = None) -> CurrentData | None:
    """:func:`current_data_from_bag` of the bag at path ``bag``, its topics read in ``view``'s
    namespace (the root when None); :class:`ReportDataError` (one line) for a missing or
    unreadable bag."""
    try:
        with BagReader(bag, view) as reader:
            return current_data_from_bag(reader)
    except BagError as error:
        raise ReportDataError(str(error)) from error


def current_data_from_bag(reader: BagReader) -> CurrentData | None:
    """The :class:`CurrentData` of a bag holding ``current/velocity`` (None without it); the
    truth topics are interpolated to the DVL stamps."""
    topic = stored_topic(reader, CURRENT_TOPIC)
    if topic is None or not has_messages(reader, CURRENT_TOPIC):
        return None
    current = stamped_vectors(reader, topic)
    t_s = current.stamps_ns / NANOSECONDS_PER_SECOND
    truths = []
    for truth_topic in (TRUTH_CURRENT_TOPIC, TRUTH_WATER_VELOCITY_TOPIC):
        stored = stored_topic(reader, truth_topic)
        if stored is None or not has_messages(reader, truth_topic):
            truths.append(None)
            continue
        truths.append(interpolate_vectors(current.stamps_ns, stamped_vectors(reader, stored)))
    north = north_token_of_bag(reader.path, CURRENT_PRODUCTS_CSV_SUFFIX)
    return CurrentData(t_s, current.vectors, _stored_products(reader), *truths, north=north)


def _stored_products(reader: BagReader) -> list[CurrentProduct]:
    products = []
    for name in sorted(reader.topics):
        if not name.lstrip("/").startswith(CURRENT_STATS_PREFIX):
            continue
        mean_topic = stored_topic(reader, name.replace("stats_", "mean_"))
        means = {}
        if mean_topic is not None:
            vectors = stamped_vectors(reader, mean_topic)
            means = dict(zip(vectors.stamps_ns.tolist(), vectors.vectors, strict=True))
        for message in reader.messages([name]):
            values = stats_values(reader.decode(message))
            end_ns = round(values["window_end_s"] * NANOSECONDS_PER_SECOND)
            mean = means.get(end_ns, np.full(3, np.nan))
            window_s = values["window_end_s"] - values["window_start_s"]
            products.append(
                CurrentProduct(
                    window_s=window_s,
                    window_start_s=values["window_start_s"],
                    window_end_s=values["window_end_s"],
                    first_sample_s=values["first_sample_s"],
                    last_sample_s=values["last_sample_s"],
                    n_valid=int(values["n_valid"]),
                    n_invalid=int(values["n_invalid"]),
                    mean_u_enu_mps=float(mean[0]),
                    mean_v_enu_mps=float(mean[1]),
                    mean_w_enu_mps=float(mean[2]),
                    speed_mps=values["speed_mps"],
                    direction_deg=values["direction_deg"],
                    std_u_mps=values["std_u_mps"],
                    std_v_mps=values["std_v_mps"],
                    std_w_mps=values["std_w_mps"],
                    # Bags written before coverage was published carry neither: not evaluated.
                    coverage=values.get("coverage", math.nan),
                    quality_flag=int(values.get("quality_flag", QualityFlag.NOT_EVALUATED)),
                    # Bags written before the standard errors were published carry none: unknown.
                    mean_u_standard_error_mps=values.get("mean_u_standard_error_mps", math.nan),
                    mean_v_standard_error_mps=values.get("mean_v_standard_error_mps", math.nan),
                    mean_w_standard_error_mps=values.get("mean_w_standard_error_mps", math.nan),
                )
            )
    return sorted(products, key=lambda product: (product.window_s, product.window_start_s))


class WindowErrors(NamedTuple):
    """The window means of an estimate against those of a reference over the same samples;
    one entry per window that counts (see :data:`MIN_WINDOW_FRACTION`)."""

    window_start_s: np.ndarray
    """(W,) start of each window, s (a multiple of the window length)."""
    reference_speed_mps: np.ndarray
    """(W,) horizontal speed of the reference's mean, m/s."""
    vector_error_mps: np.ndarray
    """(W,) horizontal length of the difference of the means, m/s."""
    speed_error_mps: np.ndarray
    """(W,) speed of the estimate's mean minus the reference's, m/s."""
    direction_error_deg: np.ndarray
    """(W,) direction of the estimate's mean minus the reference's, wrapped to ±180°."""


def window_errors(
    t_s: np.ndarray, estimate_enu: np.ndarray, reference_enu: np.ndarray, window_s: float
) -> WindowErrors:
    """Compare the means of ``estimate_enu`` and ``reference_enu`` ((N, 3), m/s, at the stamps
    ``t_s``, s) over windows aligned to multiples of ``window_s`` (s), as the products are; both
    means are taken over the samples where both are finite."""
    usable = np.all(np.isfinite(estimate_enu), axis=1) & np.all(np.isfinite(reference_enu), axis=1)
    index = np.floor(t_s / window_s).astype(np.int64)
    rows = []
    for window in np.unique(index):
        inside = index == window
        valid = inside & usable
        span_s = t_s[inside].max() - t_s[inside].min()
        if span_s < MIN_WINDOW_FRACTION * window_s - 1.0 / _rate_hz(t_s) or np.count_nonzero(
            valid
        ) < MIN_WINDOW_FRACTION * np.count_nonzero(inside):
            continue
        estimate = estimate_enu[valid].mean(axis=0)
        reference = reference_enu[valid].mean(axis=0)
        rows.append(
            (
                window * window_s,
                np.hypot(reference[0], reference[1]),
                np.hypot(*(estimate - reference)[:2]),
                np.hypot(estimate[0], estimate[1]) - np.hypot(reference[0], reference[1]),
                _wrapped_deg(
                    oceanographic_direction_deg(estimate[0], estimate[1])
                    - oceanographic_direction_deg(reference[0], reference[1])
                ),
            )
        )
    columns = np.array(rows, dtype=float).reshape(-1, 5).T
    return WindowErrors(*columns)


def _rate_hz(t_s: np.ndarray) -> float:
    steps = np.diff(t_s)
    return 1.0 / float(np.median(steps)) if steps.size else 1.0


def _wrapped_deg(angle_deg):
    return (np.asarray(angle_deg) + 180.0) % 360.0 - 180.0


class WindowLengthRow(NamedTuple):
    """RMS over the windows of one length of the horizontal difference of window means, m/s."""

    window_s: float
    """0 for single samples."""
    n_windows: int
    estimate_vs_current_mps: float
    """What a user gets: the estimate's means against the current's."""
    water_vs_current_mps: float
    """The waves' part alone: the true water velocity's means against the current's."""
    estimate_vs_water_mps: float
    """The estimate's own part (navigation, DVL): its means against the true water's."""


def error_by_window_length(
    data: CurrentData, windows_s: tuple[float, ...] = WINDOW_LENGTHS_S
) -> list[WindowLengthRow]:
    """The error of the window means against the window length (single samples first); needs
    both truth topics."""
    if data.truth_current_enu_mps is None or data.truth_water_enu_mps is None:
        raise ValueError("the error by window length needs truth/current and truth/water_velocity")
    pairs = (
        (data.current_enu_mps, data.truth_current_enu_mps),
        (data.truth_water_enu_mps, data.truth_current_enu_mps),
        (data.current_enu_mps, data.truth_water_enu_mps),
    )
    usable = np.all(np.isfinite(data.current_enu_mps), axis=1)
    rows = [
        WindowLengthRow(
            0.0,
            int(np.count_nonzero(usable)),
            *(_rms(np.hypot(*(a[usable] - b[usable])[:, :2].T)) for a, b in pairs),
        )
    ]
    for window_s in windows_s:
        # The same windows for the three pairs: those where the estimate is valid.
        errors = [
            window_errors(data.t_s, np.where(usable[:, None], a, np.nan), b, window_s)
            for a, b in pairs
        ]
        rows.append(
            WindowLengthRow(
                window_s,
                len(errors[0].window_start_s),
                *(_rms(error.vector_error_mps) for error in errors),
            )
        )
    return rows


def _rms(values: np.ndarray) -> float:
    return float(np.sqrt(np.mean(np.square(values)))) if len(values) else float("nan")
