"""Averaged wind and current products over fixed windows (WMO practice).

Conventions:
- Windows are aligned to multiples of their length in sensor time: a window of length W
  covers stamps [k·W, (k+1)·W). A window is reported when the first sample of a later window
  arrives, or at :meth:`WindAverager.flush`; windows that received no sample are not reported.
- Vectors are ENU (u east, v north, w up), m/s. Horizontal speed is hypot(u, v).
- Wind direction is meteorological: degrees clockwise from true North of the direction the
  wind blows FROM, in [0, 360). Wind moving toward East (u > 0, v = 0) comes from 270°.
- Current direction is oceanographic: degrees clockwise from true North of the direction the
  water flows TOWARD, in [0, 360). A current toward East (u > 0, v = 0) is 90°.
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
  :attr:`WindowAverager.n_rejected_stamps`.
- Coverage: the share of the samples a full window holds that the window holds valid,
  n_valid / (window_s / Δt), at most 1, where Δt is the sensor's sampling interval: the median
  of the intervals between the latest :data:`RATE_MEMORY_INTERVALS` stamps up to the window's
  last sample (invalid samples included: a sensor that reports every sample, as the
  corrections do, keeps its interval through a stretch of invalid output). A gap in the data,
  a window cut by the start or the end of a record, or a stretch of invalid samples lowers
  it; a window of a single sample after a full one has a coverage of one sample's share.
- Quality flag: the IOOS QARTOD flag of the window, from its coverage (:func:`quality_flag`):
  1 good (coverage ≥ :data:`GOOD_COVERAGE`), 3 suspect (≥ :data:`MIN_COVERAGE`), 4 bad (below,
  with at least one valid sample), 9 missing (no valid sample), 2 not evaluated (the sampling
  interval is not known yet: fewer than :data:`MIN_RATE_INTERVALS` intervals seen).
- Standard deviations need two valid samples (NaN with fewer): one sample has no spread to
  report, and a standard deviation of 0 would read as a steady wind.
- Standard errors of the mean: the 1σ of each component of the vector mean, from the valid
  samples' covariances (:func:`wind_comp.flow_uncertainty.window_mean_covariance_enu`): the
  navigation's part of the samples' errors is alike from sample to sample over the filter's
  time constants and does not average down as σ/√N would; the sensor's noise does. NaN
  without valid samples or where the samples came without covariances.
- The current has no gust and no scalar mean speed: its products are the vector mean, its speed
  and direction and the standard deviations, which over a window of several wave periods hold
  the waves' orbital motion the mean has averaged away.
"""

import itertools
import math
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from buoy_common.contract import QualityFlag
from wind_comp.flow_uncertainty import FlowCovariance, window_mean_covariance_enu

_MIN_GUST_VALID_FRACTION = 0.5
_STAMP_TOLERANCE_S = 1e-6

GOOD_COVERAGE = 0.9
"""A window holding at least this share of a full window's samples valid is good (flag 1)."""
MIN_COVERAGE = 0.5
"""Below this share a window is bad (flag 4); between it and :data:`GOOD_COVERAGE`, suspect
(flag 3)."""
RATE_MEMORY_INTERVALS = 1000
"""Stamp intervals whose median is the sampling interval: 50 s at 20 Hz, long enough that a
gap does not move the median, short enough to follow a sensor reconfigured to another rate."""
MIN_RATE_INTERVALS = 10
"""Fewer intervals than this since the first sample: the sampling interval is not known."""


def window_coverage(n_valid: int, interval_s: float, window_s: float) -> float:
    """The share of a full window of ``window_s`` (s) that ``n_valid`` samples of a sensor
    sampling every ``interval_s`` (s, NaN when unknown) cover, at most 1, to 1e-4: epoch
    stamps in float64 seconds resolve 0.24 µs, which moves the interval of a 10 Hz sensor by a
    part in a million, and a full window must read 1, a window holding exactly 90 % 0.9."""
    return round(min(n_valid * interval_s / window_s, 1.0), 4)


def quality_flag(coverage: float, n_valid: int) -> QualityFlag:
    """The flag of a window of ``coverage`` (share of a full window's samples held valid, NaN
    when the sampling interval is unknown) with ``n_valid`` valid samples."""
    if n_valid == 0:
        return QualityFlag.MISSING
    if math.isnan(coverage):
        return QualityFlag.NOT_EVALUATED
    if coverage >= GOOD_COVERAGE:
        return QualityFlag.GOOD
    if coverage >= MIN_COVERAGE:
        return QualityFlag.SUSPECT
    return QualityFlag.BAD


class ProductsError(ValueError):
    """A wind product setting or input is malformed."""


def meteorological_direction_deg(u_east_mps, v_north_mps):
    """Direction the wind blows FROM, degrees clockwise from true North, in [0, 360).

    Args:
        u_east_mps: eastward component(s) of the wind velocity, m/s.
        v_north_mps: northward component(s), m/s.

    Returns NaN for a calm (zero) or non-finite vector; a float for scalar input.
    """
    return _azimuth_deg(-np.asarray(u_east_mps, dtype=float), -np.asarray(v_north_mps, dtype=float))


def oceanographic_direction_deg(u_east_mps, v_north_mps):
    """Direction the water flows TOWARD, degrees clockwise from true North, in [0, 360).

    Args:
        u_east_mps: eastward component(s) of the current, m/s.
        v_north_mps: northward component(s), m/s.

    Returns NaN for slack water (a zero vector) or a non-finite one; a float for scalar input.
    """
    return _azimuth_deg(np.asarray(u_east_mps, dtype=float), np.asarray(v_north_mps, dtype=float))


def _azimuth_deg(east, north):
    """Azimuth of the vector (east, north), degrees clockwise from North in [0, 360); NaN for
    a zero vector."""
    direction = np.degrees(np.arctan2(east, north)) % 360.0
    direction = np.where(direction >= 360.0, direction - 360.0, direction)
    direction = np.where((east == 0) & (north == 0), np.nan, direction)
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
    coverage: float
    """Share of a full window's samples the window holds valid, in [0, 1]; NaN while the
    sampling interval is unknown."""
    quality_flag: int
    """:class:`QualityFlag` of the window (1 good, 2 not evaluated, 3 suspect, 4 bad,
    9 missing)."""
    mean_u_standard_error_mps: float
    """1σ of ``mean_u_enu_mps``, m/s (see the module docstring)."""
    mean_v_standard_error_mps: float
    """1σ of ``mean_v_enu_mps``, m/s."""
    mean_w_standard_error_mps: float
    """1σ of ``mean_w_enu_mps``, m/s."""


def _standard_errors(covariances: np.ndarray, valid: np.ndarray) -> dict[str, float]:
    """The product fields of the standard errors of a window's mean (m/s), from its samples'
    (n, 2, 3, 3) covariances (navigation part, sensor part; ENU m²/s²) and (n,) valid mask."""
    if not np.any(valid):
        sigmas = np.full(3, np.nan)
    else:
        kept = covariances[valid]
        mean = window_mean_covariance_enu(FlowCovariance(kept[:, 0], kept[:, 1]))
        sigmas = np.sqrt(np.diagonal(mean))
    # math.nan itself where not known: products compare equal field by field, NaN included.
    return {
        f"mean_{axis}_standard_error_mps": float(sigma) if np.isfinite(sigma) else math.nan
        for axis, sigma in zip("uvw", sigmas, strict=True)
    }


class WindowAverager:
    """Streaming and batch averaging of ENU vectors over windows of one length: the window
    bookkeeping every product shares. A subclass summarises each closed window
    (:meth:`_summarise`) into its product."""

    def __init__(self, window_s: float):
        """window_s: window length, s (WMO: 600 s for the mean wind, 60 s also common)."""
        if not (math.isfinite(window_s) and window_s > 0):
            raise ProductsError(f"window_s must be positive, got {window_s}")
        self.window_s = float(window_s)
        self.n_rejected_stamps = 0
        self._first_stamp_s = math.nan
        self._latest_stamp_s = -math.inf
        self._window_index: int | None = None
        self._stamps: list[float] = []
        # The open window's vectors and covariances, a stretch of rows per batch.
        self._vectors: list[np.ndarray] = []
        self._covariances: list[np.ndarray] = []
        # The latest stamps before the open window: with its own, they give the sampling
        # interval of its coverage.
        self._earlier_stamps = np.empty(0)

    def add(self, t_s: float, vector_enu_mps) -> list:
        """Add one sample (stamp s, ENU vector m/s, NaN when invalid); return completed windows:
        :meth:`add_batch` of one sample."""
        vector = np.asarray(vector_enu_mps, dtype=float)
        if vector.shape != (3,):
            raise ProductsError(f"vector_enu_mps must have shape (3,), got {vector.shape}")
        return self.add_batch([t_s], vector[None, :])

    def add_batch(self, t_s, vectors_enu_mps, covariance: FlowCovariance | None = None) -> list:
        """Add (N,) stamps (s) and (N, 3) ENU vectors (m/s, NaN when invalid) in order, with
        their (N, 3, 3) covariances (None: not known); return the windows they complete. A
        stamp not later than every earlier one is rejected and counted."""
        stamps = np.asarray(t_s, dtype=float)
        vectors = np.asarray(vectors_enu_mps, dtype=float)
        if stamps.ndim != 1 or vectors.shape != (stamps.shape[0], 3):
            raise ProductsError(
                f"t_s must be (N,) and vectors_enu_mps (N, 3), got {stamps.shape} and "
                f"{vectors.shape}"
            )
        finite = np.isfinite(stamps)
        latest_before = np.maximum.accumulate(
            np.concatenate(([self._latest_stamp_s], np.where(finite, stamps, -np.inf)))
        )[:-1]
        accepted = finite & (stamps > latest_before)
        self.n_rejected_stamps += int(np.count_nonzero(~accepted))
        if covariance is None:
            covariances = np.full((stamps.shape[0], 2, 3, 3), np.nan)
        else:
            covariances = np.stack((covariance.navigation, covariance.sensor), axis=1)
        stamps, vectors, covariances = stamps[accepted], vectors[accepted], covariances[accepted]
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
            self._vectors.append(vectors[start:stop])
            self._covariances.append(covariances[start:stop])
        return completed

    def flush(self) -> list:
        """Close the current (possibly partial) window at end of data."""
        if self._window_index is None:
            return []
        product = self._close_window()
        self._window_index = None
        return [product]

    def _close_window(self):
        stamps = np.array(self._stamps)
        vectors = np.concatenate(self._vectors)
        covariances = np.concatenate(self._covariances)
        self._stamps, self._vectors, self._covariances = [], [], []
        recent = np.concatenate((self._earlier_stamps, stamps))[-(RATE_MEMORY_INTERVALS + 1) :]
        self._earlier_stamps = recent
        intervals = np.diff(recent)
        interval_s = (
            float(np.median(intervals)) if intervals.size >= MIN_RATE_INTERVALS else math.nan
        )
        return self._summarise(
            self._window_index * self.window_s, stamps, vectors, covariances, interval_s
        )

    def _summarise(
        self,
        window_start_s: float,
        stamps: np.ndarray,
        vectors: np.ndarray,
        covariances: np.ndarray,
        interval_s: float,
    ):
        """The product of one window: its start (s), its (n,) stamps, (n, 3) vectors and
        (n, 2, 3, 3) covariances (navigation part, sensor part), and the sensor's sampling
        interval (s, NaN when unknown)."""
        raise NotImplementedError

    def _coverage(self, n_valid: int, interval_s: float) -> tuple[float, int]:
        """Coverage and quality flag of a window of ``n_valid`` valid samples of a sensor
        sampling every ``interval_s`` seconds."""
        coverage = window_coverage(n_valid, interval_s, self.window_s)
        return coverage, int(quality_flag(coverage, n_valid))


class _WindowStatistics(NamedTuple):
    valid: np.ndarray
    n_valid: int
    mean: np.ndarray
    std: np.ndarray


def _statistics(vectors: np.ndarray) -> _WindowStatistics:
    """Valid rows (every component finite), their number, mean (NaN without valid rows) and
    population standard deviation (NaN with fewer than two)."""
    valid = np.all(np.isfinite(vectors), axis=1)
    n_valid = int(np.count_nonzero(valid))
    mean = vectors[valid].mean(axis=0) if n_valid else np.full(3, np.nan)
    std = vectors[valid].std(axis=0) if n_valid >= 2 else np.full(3, np.nan)
    return _WindowStatistics(valid, n_valid, mean, std)


class WindAverager(WindowAverager):
    """The wind products (:class:`WindProduct`) of one window length."""

    def __init__(self, window_s: float = 600.0, gust_window_s: float = 3.0):
        """Args:
        window_s: window length, s (WMO: 600 s for the mean wind, 60 s also common).
        gust_window_s: running-mean length for the gust, s (WMO: 3 s).
        """
        super().__init__(window_s)
        if not (math.isfinite(gust_window_s) and 0 < gust_window_s < window_s):
            raise ProductsError(
                f"gust_window_s must be positive and shorter than window_s ({window_s}), "
                f"got {gust_window_s}"
            )
        self.gust_window_s = float(gust_window_s)
        self._tail_stamps = np.empty(0)
        self._tail_speeds = np.empty(0)
        self._tail_valid = np.empty(0, dtype=bool)

    def _summarise(
        self,
        window_start_s: float,
        stamps: np.ndarray,
        winds: np.ndarray,
        covariances: np.ndarray,
        interval_s: float,
    ):
        statistics = _statistics(winds)
        valid = statistics.valid
        speeds = np.hypot(winds[:, 0], winds[:, 1])
        gust = self._gust(stamps, speeds, valid)

        all_stamps = np.concatenate((self._tail_stamps, stamps))
        keep = all_stamps > stamps[-1] - self.gust_window_s
        self._tail_stamps = all_stamps[keep]
        self._tail_speeds = np.concatenate((self._tail_speeds, speeds))[keep]
        self._tail_valid = np.concatenate((self._tail_valid, valid))[keep]

        mean, std = statistics.mean, statistics.std
        scalar_mean_speed = float(speeds[valid].mean()) if statistics.n_valid else math.nan
        coverage, flag = self._coverage(statistics.n_valid, interval_s)
        return WindProduct(
            window_s=self.window_s,
            window_start_s=window_start_s,
            window_end_s=window_start_s + self.window_s,
            first_sample_s=float(stamps[0]),
            last_sample_s=float(stamps[-1]),
            n_valid=statistics.n_valid,
            n_invalid=int(stamps.shape[0] - statistics.n_valid),
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
            coverage=coverage,
            quality_flag=flag,
            **_standard_errors(covariances, valid),
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


@dataclass(frozen=True)
class CurrentProduct:
    """Statistics of one averaging window of the current (see the module docstring)."""

    window_s: float
    window_start_s: float
    """Start of the window, s (a multiple of ``window_s``)."""
    window_end_s: float
    """End of the window (exclusive), s."""
    first_sample_s: float
    last_sample_s: float
    n_valid: int
    n_invalid: int
    mean_u_enu_mps: float
    mean_v_enu_mps: float
    mean_w_enu_mps: float
    speed_mps: float
    """Horizontal speed of the vector mean, m/s."""
    direction_deg: float
    """Oceanographic direction of the vector mean (toward, clockwise from true North), deg."""
    std_u_mps: float
    std_v_mps: float
    std_w_mps: float
    coverage: float
    """As :attr:`WindProduct.coverage`."""
    quality_flag: int
    """As :attr:`WindProduct.quality_flag`."""
    mean_u_standard_error_mps: float
    """As :attr:`WindProduct.mean_u_standard_error_mps`."""
    mean_v_standard_error_mps: float
    mean_w_standard_error_mps: float


class CurrentAverager(WindowAverager):
    """The current products (:class:`CurrentProduct`) of one window length."""

    def _summarise(
        self,
        window_start_s: float,
        stamps: np.ndarray,
        currents: np.ndarray,
        covariances: np.ndarray,
        interval_s: float,
    ):
        statistics = _statistics(currents)
        mean, std = statistics.mean, statistics.std
        coverage, flag = self._coverage(statistics.n_valid, interval_s)
        return CurrentProduct(
            window_s=self.window_s,
            window_start_s=window_start_s,
            window_end_s=window_start_s + self.window_s,
            first_sample_s=float(stamps[0]),
            last_sample_s=float(stamps[-1]),
            n_valid=statistics.n_valid,
            n_invalid=int(stamps.shape[0] - statistics.n_valid),
            mean_u_enu_mps=float(mean[0]),
            mean_v_enu_mps=float(mean[1]),
            mean_w_enu_mps=float(mean[2]),
            speed_mps=float(np.hypot(mean[0], mean[1])),
            direction_deg=oceanographic_direction_deg(mean[0], mean[1]),
            std_u_mps=float(std[0]),
            std_v_mps=float(std[1]),
            std_w_mps=float(std[2]),
            coverage=coverage,
            quality_flag=flag,
            **_standard_errors(covariances, statistics.valid),
        )
