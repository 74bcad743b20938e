"""Averaged wind products over fixed windows (WMO practice).

Conventions:
- Windows are aligned to multiples of their length in sensor time: a window of length W
  covers stamps [k·W, (k+1)·W). A window is reported when the first sample of a later window
  arrives, or at :meth:`WindAverager.flush`; windows that received no sample are not reported.
- Vectors are ENU (u east, v north, w up), m/s. Horizontal speed is hypot(u, v).
- Direction is meteorological: degrees clockwise from true North of the direction the wind
  blows FROM, in [0, 360). Wind moving toward East (u > 0, v = 0) comes from 270°.
- Vector mean: the components are averaged, then speed and direction are taken from the mean
  vector. Scalar mean: the horizontal speeds are averaged. Vector mean ≤ scalar mean, equal
  only when the direction is steady.
- Gust: the maximum over the window of the running mean of horizontal speed over the previous
  ``gust_window_s`` (WMO: 3 s), evaluated at every valid sample. The running mean may reach
  back into the previous window, never to before the first sample the averager received, and
  counts only where at least half of its samples are valid.
- Standard deviations are population standard deviations (about the window mean) of the valid
  samples.
- Invalid samples (any non-finite component) count in ``n_invalid`` and nowhere else. Samples
  whose stamp is not later than the previous one are ignored and counted in
  :attr:`WindAverager.n_rejected_stamps`.
"""

import itertools
import math
from dataclasses import dataclass

import numpy as np

_MIN_GUST_VALID_FRACTION = 0.5
_STAMP_TOLERANCE_S = 1e-6


class ProductsError(ValueError):
    """A wind product setting or input is malformed."""


def meteorological_direction_deg(u_east_mps, v_north_mps):
    """Direction the wind blows FROM, degrees clockwise from true North, in [0, 360).

    Args:
        u_east_mps: eastward component(s) of the wind velocity, m/s.
        v_north_mps: northward component(s), m/s.

    Returns NaN for a calm (zero) or non-finite vector; a float for scalar input.
    """
    u = np.asarray(u_east_mps, dtype=float)
    v = np.asarray(v_north_mps, dtype=float)
    direction = np.degrees(np.arctan2(-u, -v)) % 360.0
    direction = np.where(direction >= 360.0, direction - 360.0, direction)
    direction = np.where((u == 0) & (v == 0), np.nan, direction)
    return float(direction) if direction.ndim == 0 else direction


@dataclass(frozen=True)
class WindProduct:
    """Statistics of one averaging window (see the module docstring for conventions)."""

    window_s: float
    window_start_s: float
    """Start of the window, s (a multiple of ``window_s``)."""
    window_end_s: float
    """End of the window (exclusive), s."""
    first_sample_s: float
    """Stamp of the first sample in the window, s."""
    last_sample_s: float
    """Stamp of the last sample in the window, s."""
    n_valid: int
    n_invalid: int
    mean_u_enu_mps: float
    mean_v_enu_mps: float
    mean_w_enu_mps: float
    vector_mean_speed_mps: float
    vector_mean_direction_deg: float
    scalar_mean_speed_mps: float
    gust_mps: float
    gust_window_s: float
    std_u_mps: float
    std_v_mps: float
    std_w_mps: float


class WindAverager:
    """Streaming and batch averaging of ENU wind samples over one window length."""

    def __init__(self, window_s: float = 600.0, gust_window_s: float = 3.0):
        """Args:
        window_s: window length, s (WMO: 600 s for the mean wind, 60 s also common).
        gust_window_s: running-mean length for the gust, s (WMO: 3 s).
        """
        if not (math.isfinite(window_s) and window_s > 0):
            raise ProductsError(f"window_s must be positive, got {window_s}")
        if not (math.isfinite(gust_window_s) and 0 < gust_window_s < window_s):
            raise ProductsError(
                f"gust_window_s must be positive and shorter than window_s ({window_s}), "
                f"got {gust_window_s}"
            )
        self.window_s = float(window_s)
        self.gust_window_s = float(gust_window_s)
        self.n_rejected_stamps = 0
        self._first_stamp_s = math.nan
        self._latest_stamp_s = -math.inf
        self._window_index: int | None = None
        self._stamps: list[float] = []
        self._winds: list[np.ndarray] = []
        self._tail_stamps = np.empty(0)
        self._tail_speeds = np.empty(0)
        self._tail_valid = np.empty(0, dtype=bool)

    def add(self, t_s: float, wind_enu_mps) -> list[WindProduct]:
        """Add one sample (stamp s, ENU wind m/s, NaN when invalid); return completed windows."""
        wind = np.asarray(wind_enu_mps, dtype=float)
        if wind.shape != (3,):
            raise ProductsError(f"wind_enu_mps must have shape (3,), got {wind.shape}")
        t_s = float(t_s)
        if not (math.isfinite(t_s) and t_s > self._latest_stamp_s):
            self.n_rejected_stamps += 1
            return []
        if math.isnan(self._first_stamp_s):
            self._first_stamp_s = t_s
        self._latest_stamp_s = t_s
        index = math.floor(t_s / self.window_s)
        completed = []
        if self._window_index is not None and index != self._window_index:
            completed.append(self._close_window())
        self._window_index = index
        self._stamps.append(t_s)
        self._winds.append(wind)
        return completed

    def add_batch(self, t_s, wind_enu_mps) -> list[WindProduct]:
        """Add (N,) stamps and (N, 3) winds in order; identical to calling :meth:`add` on each."""
        stamps = np.asarray(t_s, dtype=float)
        winds = np.asarray(wind_enu_mps, dtype=float)
        if stamps.ndim != 1 or winds.shape != (stamps.shape[0], 3):
            raise ProductsError(
                f"t_s must be (N,) and wind_enu_mps (N, 3), got {stamps.shape} and {winds.shape}"
            )
        finite = np.isfinite(stamps)
        latest_before = np.maximum.accumulate(
            np.concatenate(([self._latest_stamp_s], np.where(finite, stamps, -np.inf)))
        )[:-1]
        accepted = finite & (stamps > latest_before)
        self.n_rejected_stamps += int(np.count_nonzero(~accepted))
        stamps, winds = stamps[accepted], winds[accepted]
        if not stamps.shape[0]:
            return []
        if math.isnan(self._first_stamp_s):
            self._first_stamp_s = float(stamps[0])
        self._latest_stamp_s = float(stamps[-1])
        indices = np.floor(stamps / self.window_s)
        bounds = [0, *(np.flatnonzero(np.diff(indices)) + 1).tolist(), stamps.shape[0]]
        completed = []
        for start, stop in itertools.pairwise(bounds):
            index = int(indices[start])
            if self._window_index is not None and index != self._window_index:
                completed.append(self._close_window())
            self._window_index = index
            self._stamps.extend(stamps[start:stop].tolist())
            self._winds.extend(winds[start:stop])
        return completed

    def flush(self) -> list[WindProduct]:
        """Close the current (possibly partial) window at end of data."""
        if self._window_index is None:
            return []
        product = self._close_window()
        self._window_index = None
        return [product]

    def _close_window(self) -> WindProduct:
        stamps = np.array(self._stamps)
        winds = np.array(self._winds)
        valid = np.all(np.isfinite(winds), axis=1)
        speeds = np.hypot(winds[:, 0], winds[:, 1])
        gust = self._gust(stamps, speeds, valid)

        all_stamps = np.concatenate((self._tail_stamps, stamps))
        keep = all_stamps > stamps[-1] - self.gust_window_s
        self._tail_stamps = all_stamps[keep]
        self._tail_speeds = np.concatenate((self._tail_speeds, speeds))[keep]
        self._tail_valid = np.concatenate((self._tail_valid, valid))[keep]
        self._stamps, self._winds = [], []

        n_valid = int(np.count_nonzero(valid))
        if n_valid:
            mean = winds[valid].mean(axis=0)
            std = winds[valid].std(axis=0)
            scalar_mean_speed = float(speeds[valid].mean())
        else:
            mean = std = np.full(3, np.nan)
            scalar_mean_speed = math.nan
        start = self._window_index * self.window_s
        return WindProduct(
            window_s=self.window_s,
            window_start_s=start,
            window_end_s=start + self.window_s,
            first_sample_s=float(stamps[0]),
            last_sample_s=float(stamps[-1]),
            n_valid=n_valid,
            n_invalid=int(stamps.shape[0] - n_valid),
            mean_u_enu_mps=float(mean[0]),
            mean_v_enu_mps=float(mean[1]),
            mean_w_enu_mps=float(mean[2]),
            vector_mean_speed_mps=float(np.hypot(mean[0], mean[1])),
            vector_mean_direction_deg=meteorological_direction_deg(mean[0], mean[1]),
            scalar_mean_speed_mps=scalar_mean_speed,
            gust_mps=gust,
            gust_window_s=self.gust_window_s,
            std_u_mps=float(std[0]),
            std_v_mps=float(std[1]),
            std_w_mps=float(std[2]),
        )

    def _gust(self, stamps: np.ndarray, speeds: np.ndarray, valid: np.ndarray) -> float:
        """Maximum running mean of horizontal speed at the window's valid samples, m/s."""
        all_stamps = np.concatenate((self._tail_stamps, stamps))
        all_valid = np.concatenate((self._tail_valid, valid))
        all_speeds = np.where(all_valid, np.concatenate((self._tail_speeds, speeds)), 0.0)
        speed_sums = np.concatenate(([0.0], np.cumsum(all_speeds)))
        valid_counts = np.concatenate(([0], np.cumsum(all_valid)))

        ends = np.arange(self._tail_stamps.shape[0], all_stamps.shape[0])[valid]
        span_starts = all_stamps[ends] - self.gust_window_s
        firsts = np.searchsorted(all_stamps, span_starts, side="right")
        n_valid_in_span = valid_counts[ends + 1] - valid_counts[firsts]
        n_in_span = ends + 1 - firsts
        qualifies = (span_starts >= self._first_stamp_s - _STAMP_TOLERANCE_S) & (
            n_valid_in_span >= _MIN_GUST_VALID_FRACTION * n_in_span
        )
        if not np.any(qualifies):
            return math.nan
        running_means = (speed_sums[ends + 1] - speed_sums[firsts])[qualifies] / n_valid_in_span[
            qualifies
        ]
        return float(running_means.max())
