"""The mooring's innovation watch (:mod:`buoy_nav.aiding.moored`): the normalised RMS of its
horizontal innovations over a sliding window, the factor its σ is widened by, and the warning
beyond :data:`WARNING_RATIO`.

Each innovation ν (m, ENU east and north) is kept with the part of its covariance that is the
filter's, C = H P Hᵀ (m²), as its squared components along the eigenvectors of C and C's
eigenvalues, so that the normalised RMS is known for any σ of the mooring::

    ratio(k)² = Σ νᵀ (C + k² σ² I)⁻¹ ν / Σ 2.

Beyond :data:`WARNING_RATIO` at the stated σ (k = 1) the σ is widened by the k that makes the
window consistent, ratio(k) = 1, at most the scale limit: at once when k grows, with the window
as time constant when it shrinks, and back toward 1 the same way once the innovations are no
larger than stated, ratio(1) ≤ 1. Starting only beyond the warning keeps a consistent filter's
scatter from widening it.

The watch is compiled, one function over arrays (:func:`watched`), so that the engine's epochs
(through :class:`InnovationWatch`) and the compiled stretches' (:mod:`buoy_nav.mooring_epoch`)
judge the same innovations to the same bit. The window's sum is NumPy's pairwise sum
(:func:`pairwise_sum`) and k is found by Brent's method with SciPy's ``brentq`` steps and
tolerances (:func:`consistent_scale`): the figures are those of the vectorised formulation.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numba
import numpy as np

MIN_SPAN_OF_WINDOW = 0.2
"""Share of the window the innovations must span before the σ may be widened by them (and of
``moored_check_window_s`` the measurements must span before the mooring is judged against
GNSS)."""
WARNING_RATIO = 1.3
"""Normalised RMS of the mooring's innovations over a window beyond which it warns and starts
widening its σ: a variance 1.7 times the stated one. Consecutive innovations are correlated
over the anchor's minutes, so a window holds only a few independent samples and a consistent
filter's ratio scatters by a tenth or two about 1."""

# The watch's terms: its window (s), the stated horizontal variance (m²), the largest factor
# on the σ.
WINDOW, STATED_VARIANCE, SCALE_LIMIT = range(3)
TERMS_SIZE = 3
# What it moves besides the window (``status``): the factor (≥ 1) on the stated σ the mooring
# is fused with, whether it is being widened (1.0), the stamp it was last followed at (s),
# whether a warning holds (1.0) and the stamp of the last one said (s).
SCALE, WIDENING, SCALED_AT, WARNING, WARNED_AT = range(5)
STATUS_SIZE = 5
# What an innovation makes the watch say: nothing, a warning (once a window while one holds),
# or that the warning no longer holds.
SAYS_NOTHING, SAYS_WARNING, SAYS_CLEARED = range(3)

ROOT_ABSOLUTE_TOLERANCE = 2e-12
ROOT_RELATIVE_TOLERANCE = 4.0 * np.finfo(float).eps
ROOT_ITERATIONS = 100
"""Brent's tolerances on k and its largest number of steps (SciPy's ``brentq`` defaults)."""
PAIRWISE_BLOCK = 128
"""Length up to which :func:`pairwise_sum` sums in eight interleaved lanes (NumPy's block)."""
PAIRWISE_DEPTH = 64
"""Depth of :func:`pairwise_sum`'s halving it has room for: beyond any array's length."""


class WatchArrays(NamedTuple):
    """The watch as arrays (laid out above): its terms and status, and per innovation of the
    window its stamp (s), its squared components along the eigenvectors of C (m², 2 a row)
    and C's eigenvalues (m², 2 a row), with room after the window's end."""

    terms: np.ndarray
    status: np.ndarray
    stamps: np.ndarray
    projected: np.ndarray
    eigenvalues: np.ndarray


@numba.njit(cache=True)
def pairwise_sum(values, first, count) -> float:
    """The sum of ``count`` of ``values`` from ``first``, added as NumPy's ``sum`` adds a
    contiguous array: halved (on a multiple of eight) down to blocks of at most
    :data:`PAIRWISE_BLOCK` (:func:`_block_sum`), each half's sum added to the other's. The
    halving is walked with a stack of its own: a recursive function's compiled code cannot be
    cached."""
    firsts = np.empty(PAIRWISE_DEPTH, dtype=np.int64)
    counts = np.empty(PAIRWISE_DEPTH, dtype=np.int64)
    left_sums = np.empty(PAIRWISE_DEPTH)
    right_pending = np.zeros(PAIRWISE_DEPTH, dtype=np.bool_)
    top = 0
    firsts[0], counts[0] = first, count
    while True:
        if counts[top] > PAIRWISE_BLOCK:
            half = _pairwise_half(counts[top])
            firsts[top + 1], counts[top + 1] = firsts[top], half
            right_pending[top] = True
            top += 1
            continue
        total = _block_sum(values, firsts[top], counts[top])
        top -= 1
        while top >= 0 and not right_pending[top]:
            total = left_sums[top] + total
            top -= 1
        if top < 0:
            return total
        left_sums[top], right_pending[top] = total, False
        half = _pairwise_half(counts[top])
        firsts[top + 1], counts[top + 1] = firsts[top] + half, counts[top] - half
        top += 1


@numba.njit(cache=True)
def _pairwise_half(count) -> int:
    half = count // 2
    return half - half % 8


@numba.njit(cache=True)
def _block_sum(values, first, count) -> float:
    """A block's sum: straight below eight, in eight interleaved lanes above."""
    if count < 8:
        total = 0.0
        for i in range(first, first + count):
            total += values[i]
        return total
    lanes = values[first : first + 8].copy()
    whole = count - count % 8
    for i in range(8, whole, 8):
        for lane in range(8):
            lanes[lane] += values[first + i + lane]
    total = ((lanes[0] + lanes[1]) + (lanes[2] + lanes[3])) + (
        (lanes[4] + lanes[5]) + (lanes[6] + lanes[7])
    )
    for i in range(whole, count):
        total += values[first + i]
    return total


@numba.njit(cache=True)
def window_ratio(watch, bounds, scale) -> float:
    """Normalised RMS of the innovations of the window (``bounds``: its first and past-last
    index in ``watch``) with the stated σ widened by ``scale``."""
    first, end = bounds[0], bounds[1]
    variance = scale * scale * watch.terms[STATED_VARIANCE]
    normalised = np.empty(2 * (end - first))
    for i in range(first, end):
        for axis in range(2):
            normalised[2 * (i - first) + axis] = watch.projected[i, axis] / (
                watch.eigenvalues[i, axis] + variance
            )
    return math.sqrt(pairwise_sum(normalised, 0, normalised.size) / normalised.size)


@numba.njit(cache=True)
def watched(watch, bounds, t_s, innovation_m, filter_covariance_m2) -> int:
    """Take one horizontal innovation (stamp s, ν m ENU east and north, C = H P Hᵀ m² 2×2)
    into the window at its end (``bounds``, moved), update the ``watch``'s status, and say
    what it makes the watch say (:data:`SAYS_NOTHING`, ...)."""
    terms, status = watch.terms, watch.status
    eigenvalues, eigenvectors = np.linalg.eigh(filter_covariance_m2)
    end = bounds[1]
    watch.stamps[end] = t_s
    for axis in range(2):
        along = eigenvectors[0, axis] * innovation_m[0] + eigenvectors[1, axis] * innovation_m[1]
        watch.projected[end, axis] = along * along
    watch.eigenvalues[end] = np.maximum(eigenvalues, 0.0)
    bounds[1] = end + 1
    window_s = terms[WINDOW]
    while watch.stamps[bounds[0]] < t_s - window_s:
        bounds[0] += 1
    span_s = t_s - watch.stamps[bounds[0]]
    if span_s < MIN_SPAN_OF_WINDOW * window_s:
        return SAYS_NOTHING
    ratio = window_ratio(watch, bounds, 1.0)
    # Started beyond the warning, kept until the innovations are no larger than stated.
    if ratio > WARNING_RATIO:
        status[WIDENING] = 1.0
    elif ratio <= 1.0:
        status[WIDENING] = 0.0
    consistent = consistent_scale(watch, bounds) if status[WIDENING] == 1.0 else 1.0
    _follow(status, window_s, t_s, consistent)
    if span_s < (1.0 - MIN_SPAN_OF_WINDOW) * window_s:
        return SAYS_NOTHING
    if ratio <= WARNING_RATIO:
        was_warning = status[WARNING] == 1.0
        status[WARNING] = 0.0
        return SAYS_CLEARED if was_warning else SAYS_NOTHING
    status[WARNING] = 1.0
    if t_s - status[WARNED_AT] < window_s:
        return SAYS_NOTHING
    status[WARNED_AT] = t_s
    return SAYS_WARNING


@numba.njit(cache=True)
def _follow(status, window_s, t_s, consistent) -> None:
    """Follow the ``consistent`` factor at ``t_s`` (s): at once when it widens, over the
    window (``window_s``, s) when it narrows. The filter's covariance grows with the widening,
    so the innovations judged at a narrower σ look consistent before the mooring is."""
    if consistent >= status[SCALE]:
        status[SCALE] = consistent
    else:
        share = -math.expm1(-(t_s - status[SCALED_AT]) / window_s)
        status[SCALE] += share * (consistent - status[SCALE])
    status[SCALED_AT] = t_s


@numba.njit(cache=True)
def consistent_scale(watch, bounds) -> float:
    """The k of ratio(k) = 1 within [1, scale limit], the window's ratio at k = 1 beyond 1."""
    limit = watch.terms[SCALE_LIMIT]
    if window_ratio(watch, bounds, limit) >= 1.0:
        return limit
    return _brent_root(watch, bounds, 1.0, limit)


@numba.njit(cache=True)
def _excess(watch, bounds, scale) -> float:
    return window_ratio(watch, bounds, scale) - 1.0


@numba.njit(cache=True)
def _brent_root(watch, bounds, low, high) -> float:
    """The scale in [``low``, ``high``] where the window's ratio is 1, bracketed at both ends,
    by Brent's method: inverse quadratic or secant steps that stay well inside the bracket,
    bisection otherwise, to within :data:`ROOT_ABSOLUTE_TOLERANCE` and
    :data:`ROOT_RELATIVE_TOLERANCE` of the root."""
    x_before, x = low, high
    f_before, f = _excess(watch, bounds, x_before), _excess(watch, bounds, x)
    if f_before == 0.0:
        return x_before
    x_far = f_far = step_before = step = 0.0
    for _ in range(ROOT_ITERATIONS):
        if f_before * f < 0.0:
            x_far, f_far = x_before, f_before
            step_before = step = x - x_before
        if abs(f_far) < abs(f):
            x_before, x, x_far = x, x_far, x
            f_before, f, f_far = f, f_far, f
        tolerance = (ROOT_ABSOLUTE_TOLERANCE + ROOT_RELATIVE_TOLERANCE * abs(x)) / 2.0
        halfway = (x_far - x) / 2.0
        if f == 0.0 or abs(halfway) < tolerance:
            return x
        step_before, step = _next_steps(
            x_before, f_before, x, f, x_far, f_far, step_before, step, halfway, tolerance
        )
        x_before, f_before = x, f
        if abs(step) > tolerance:
            x += step
        else:
            x += tolerance if halfway > 0.0 else -tolerance
        f = _excess(watch, bounds, x)
    return x


@numba.njit(cache=True)
def _next_steps(x_before, f_before, x, f, x_far, f_far, step_before, step, halfway, tolerance):
    """The step before and the step of Brent's next move from ``x``: interpolated (secant
    when the previous point is the bracket's far end, inverse quadratic otherwise) when the
    last steps shrank the function and the interpolation stays short, else bisection."""
    if abs(step_before) > tolerance and abs(f) < abs(f_before):
        if x_before == x_far:
            trial = -f * (x - x_before) / (f - f_before)
        else:
            slope_before = (f_before - f) / (x_before - x)
            slope_far = (f_far - f) / (x_far - x)
            trial = (
                -f
                * (f_far * slope_far - f_before * slope_before)
                / (slope_far * slope_before * (f_far - f_before))
            )
        if 2.0 * abs(trial) < min(abs(step_before), 3.0 * abs(halfway) - tolerance):
            return step, trial
    return halfway, halfway


def initial_status() -> np.ndarray:
    """The status of a watch that has seen nothing: σ as stated, never followed or warned."""
    status = np.zeros(STATUS_SIZE)
    status[SCALE] = 1.0
    status[SCALED_AT] = status[WARNED_AT] = -math.inf
    return status


def unwatched() -> WatchArrays:
    """A watch of no window and no room, for a stretch that takes no innovation."""
    return WatchArrays(np.zeros(TERMS_SIZE), initial_status(), *_empty_rows(0))


class InnovationWatch:
    """The mooring's horizontal innovations over the last ``window_s`` (s) at its stated
    horizontal σ (m), widened at most ``scale_limit`` times (see the module docstring)."""

    def __init__(self, window_s: float, stated_sigma_m: float, scale_limit: float):
        self.window_s = window_s
        """The window's length (s)."""
        self._scale_limit = scale_limit
        terms = np.empty(TERMS_SIZE)
        terms[WINDOW], terms[STATED_VARIANCE], terms[SCALE_LIMIT] = (
            window_s,
            stated_sigma_m**2,
            scale_limit,
        )
        self._watch = _with_room(WatchArrays(terms, initial_status(), *_empty_rows(0)), 64)
        self._bounds = np.zeros(2, dtype=np.int64)

    @property
    def scale(self) -> float:
        """Factor (≥ 1) on the stated horizontal σ the mooring is fused with."""
        return float(self._watch.status[SCALE])

    def ratio(self, scale: float = 1.0) -> float:
        """Normalised RMS of the window's innovations with the σ widened by ``scale``."""
        return window_ratio(self._watch, self._bounds, scale)

    def add(
        self, t_s: float, innovation_m: np.ndarray, filter_covariance_m2: np.ndarray
    ) -> str | None:
        """Take one horizontal innovation (stamp s, ν m, C = H P Hᵀ m²) and update
        :attr:`scale`: a new warning, ``""`` when one no longer holds, None when nothing
        changed."""
        self._make_room()
        says = watched(
            self._watch,
            self._bounds,
            t_s,
            np.ascontiguousarray(innovation_m, dtype=float),
            np.ascontiguousarray(filter_covariance_m2, dtype=float),
        )
        if says == SAYS_NOTHING:
            return None
        if says == SAYS_CLEARED:
            return ""
        return (
            f"mooring innovations {self.ratio():.1f}× their stated σ over the last "
            f"{self.window_s:.0f} s: the gyro's wander (fusion.gyro_bias_instability_deg_h) or "
            f"the mooring's σ (fusion.moored_position_sigma_horizontal_m) is stated too small; "
            f"its σ widened {self.scale:.1f}× (at most fusion.moored_sigma_scale_limit, "
            f"{self._scale_limit:g}); run assess_motion_pack"
        )

    def load_compiled_code(self) -> None:
        """Compile the watch, or load it from the cache, now, on a copy of it."""
        watch = self.arrays(1)
        bounds = np.array((0, watch.stamps.size - 1))
        watched(watch, bounds, 0.0, np.zeros(2), np.eye(2))
        window_ratio(watch, bounds, 1.0)

    def arrays(self, room: int) -> WatchArrays:
        """A copy of the watch, its window from index 0, with room for ``room`` innovations."""
        return _with_room(self.window(), room)

    def window(self) -> WatchArrays:
        """A copy of the watch with its window's rows alone."""
        first, end = self._bounds
        watch = self._watch
        return WatchArrays(
            watch.terms.copy(),
            watch.status.copy(),
            watch.stamps[first:end].copy(),
            watch.projected[first:end].copy(),
            watch.eigenvalues[first:end].copy(),
        )

    def _make_room(self) -> None:
        """Room for one more innovation: the window moved back to the front when the arrays
        end, into arrays twice as long when it fills more than half of them."""
        first, end = self._bounds
        capacity = self._watch.stamps.size
        if end < capacity:
            return
        live = end - first
        new_capacity = capacity if 2 * live <= capacity else 2 * capacity
        self._watch = _with_room(self.window(), new_capacity - live)
        self._bounds[:] = 0, live


def _empty_rows(count: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    return np.zeros(count), np.zeros((count, 2)), np.zeros((count, 2))


def _with_room(watch: WatchArrays, room: int) -> WatchArrays:
    """``watch`` with room for ``room`` more innovations after its rows."""
    stamps, projected, eigenvalues = _empty_rows(room)
    return WatchArrays(
        watch.terms,
        watch.status,
        np.concatenate((watch.stamps, stamps)),
        np.concatenate((watch.projected, projected)),
        np.concatenate((watch.eigenvalues, eigenvalues)),
    )
