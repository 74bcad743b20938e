"""A moored buoy's mean velocity over blocks of seconds as the witness of the gyro's drift and
of the velocity's noise.

Without GNSS the mooring (:mod:`buoy_nav.aiding.moored`) bounds the inertial velocity, but what
it cannot hold is a slow tilt error: a gyro that wanders more than
``fusion.gyro_bias_instability_deg_h`` says leaves a tilt error of a degree or two at periods of
minutes, and ``g δθ`` drives the velocity by tenths of a metre per second to a metre per second
at those periods, while the filter, trusting its gyro model, states a few tenths. The mooring's
own innovations (the position against its 600-s mean) barely see it: a velocity error at a
minute's period moves the position by a few metres, within the wave excursion it allows.

What does see it is the velocity's mean over half a minute: on a mooring the buoy's true mean
velocity over a block of T seconds is its displacement over T, at most the wave excursion at
both ends, ``2 σ_h² / T²`` in variance; the filter's own mean over the block is its error plus
that. So over the blocks of the last ``window_s`` the normalised RMS

    ratio² = Σ v̄ᵀ (C̄ + 2 σ_h² / T² I)⁻¹ v̄ / Σ 2

(v̄: the block's mean horizontal velocity, m/s ENU; C̄: the mean of the filter's horizontal
velocity covariance over the block, m²/s²) is 1 or less for a filter whose velocity σ is
honest. Beyond :data:`WANDER_RATIO`, or when one block alone is beyond :data:`BLOCK_QUANTILE`,
the gyro's drift is widened (:attr:`MeanVelocityWatch.scale`, a factor on its σ the engine
applies to the drift's process noise): by ``ratio²`` at once, at most ``scale_limit``, and the
blocks judged at the narrower drift are dropped, so the next verdict is on the widened filter's
own blocks. A wider drift lets the filter's attitude follow the motion pack, whose slow
attitude is then worth more than the gyro's, and its velocity's σ grow with what the tilt error
leaves; the attitude and velocity variances are raised at once by ``ratio²``, which the drift
alone would take minutes to do. Once the ratio over a whole window falls below
:data:`NARROW_RATIO` the drift is narrowed again, a factor of √2 a window: the hysteresis keeps
a filter that is consistent only because it was widened from narrowing back into the error it
left.

Learning takes a few blocks: until the first verdict the velocity's error is what the stated
gyro model allows it to be (``tests/system/test_moored_gyro_wander.py``: within σ from the
mooring's check window on).

The same judgement over 10-s blocks (:data:`SHORT_BLOCK_S`) sees a velocity error at periods of
10 to 50 s, shorter than the gyro's wander and longer than the waves': what a motion pack's own
tilt error at those periods leaves (OOI's FDCHP record, ``docs/real-records.md``). That one
widens the velocity's own process noise (``fusion.accel_noise_mps_sqrt_h``), so the mooring
holds the velocity harder and its σ grows with what it cannot hold; widening the gyro's drift
would only let the filter follow the pack's tilt more closely.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numba
import numpy as np

from buoy_nav.chi_square import chi_square_quantile

BLOCK_S = 30.0
"""Length of the gyro drift's blocks (s): long against the waves (their velocity averages out)
and short against the gyro's wander (minutes), so the block's mean is the slow velocity
error."""
SHORT_BLOCK_S = 10.0
"""Length of the velocity noise's blocks (s): still longer than most waves' periods, whose
displacement the excursion term covers."""
MIN_BLOCKS = 3
"""Blocks the window's verdict needs."""
BLOCK_QUANTILE = chi_square_quantile(2, 0.999)
"""Normalised square of a single block's mean beyond which the drift is widened at once, by
its half (the block's own ratio²): a consistent filter's block passes it once in a thousand."""
WANDER_RATIO = 1.5
"""Normalised RMS of the blocks' mean velocity beyond which the gyro's drift is widened: a
window of 300 s holds five blocks, whose ratio for a consistent filter scatters by about a
third about 1 (ten degrees of freedom)."""
NARROW_RATIO = 0.5
"""Normalised RMS below which a widened drift is narrowed."""
NARROWING_PER_WINDOW = math.sqrt(2.0)

# A watch's terms (``terms``): its block's length (s), the variance the wave excursion leaves
# in a block's mean (m²/s² an axis), the blocks its window holds, the factor it has widened its
# σ by and the largest it may.
BLOCK_LENGTH, EXCURSION_VARIANCE, BLOCKS_IN_WINDOW, SCALE, SCALE_LIMIT = range(5)
TERMS_SIZE = 5
# Its block in progress and window (``block``): the block's start (s, NaN: none), its samples,
# their velocities' sum (m/s, east and north) and their covariances' (m²/s², 2×2 row-major), and
# how many blocks' normalised squares the window holds (``squares``, oldest first).
BLOCK_START, SAMPLES, VELOCITY_SUM, COVARIANCE_SUM, SQUARES = 0, 1, 2, 4, 8
BLOCK_SIZE = 9
# A closed block's verdict: nothing changes, the σ is to be widened, or narrowed.
KEEPS, WIDENS, NARROWS = range(3)


class BlockArrays(NamedTuple):
    """A watch as arrays (laid out above), one row a watch when the stretches take several
    (``squares`` then as wide as the widest window)."""

    terms: np.ndarray
    block: np.ndarray
    squares: np.ndarray


def unwatched_blocks() -> BlockArrays:
    """No watch's arrays, for a stretch that takes no velocity."""
    return BlockArrays(np.zeros((0, TERMS_SIZE)), np.zeros((0, BLOCK_SIZE)), np.zeros((0, 1)))


def stacked(watches: list[BlockArrays]) -> BlockArrays:
    """Several watches' arrays, a row each."""
    squares = np.zeros((len(watches), max(watch.squares.size for watch in watches)))
    for row, watch in zip(squares, watches, strict=True):
        row[: watch.squares.size] = watch.squares
    return BlockArrays(
        np.stack([watch.terms for watch in watches]),
        np.stack([watch.block for watch in watches]),
        squares,
    )


@numba.njit(cache=True)
def velocity_added(terms, block, squares, t_s, velocity_enu_mps, velocity_covariance_m2s2):
    """Take the filter's horizontal velocity (m/s ENU, east and north) and its covariance
    (m²/s², 2×2) at stamp ``t_s`` (s) into the block in progress, closing it first when it
    is over (its normalised square added to the window, :func:`_closed`): the verdict
    (:data:`KEEPS`, ...) and the window's ratio it is on (NaN when no block closed). The
    caller widens or narrows the σ (:attr:`terms`' :data:`SCALE`) as the verdict says."""
    verdict, ratio = KEEPS, math.nan
    if math.isnan(block[BLOCK_START]):
        block[BLOCK_START] = t_s
    if t_s - block[BLOCK_START] >= terms[BLOCK_LENGTH] and block[SAMPLES] > 0.0:
        verdict, ratio = _closed(terms, block, squares)
        block[BLOCK_START:SQUARES] = 0.0
        block[BLOCK_START] = t_s
    for i in range(2):
        block[VELOCITY_SUM + i] += velocity_enu_mps[i]
        for j in range(2):
            block[COVARIANCE_SUM + 2 * i + j] += velocity_covariance_m2s2[i, j]
    block[SAMPLES] += 1.0
    return verdict, ratio


@numba.njit(cache=True)
def _closed(terms, block, squares):
    """The block in progress closed: its mean's normalised square added to the window (the
    oldest dropped when it is full), and the verdict on the window (see the module
    docstring) with the ratio it is on."""
    samples = block[SAMPLES]
    mean = np.empty(2)
    covariance = np.empty((2, 2))
    for i in range(2):
        mean[i] = block[VELOCITY_SUM + i] / samples
        for j in range(2):
            identity = 1.0 if i == j else 0.0
            covariance[i, j] = (
                block[COVARIANCE_SUM + 2 * i + j] / samples + terms[EXCURSION_VARIANCE] * identity
            )
    square = mean @ np.linalg.solve(covariance, mean)
    count = int(block[SQUARES])
    if count == int(terms[BLOCKS_IN_WINDOW]):
        squares[: count - 1] = squares[1:count]
        count -= 1
    squares[count] = square
    count += 1
    block[SQUARES] = count
    total = 0.0
    for i in range(count):
        total += squares[i]
    ratio = math.sqrt(total / (2.0 * count))
    if square > BLOCK_QUANTILE:
        root = math.sqrt(square / 2.0)
        ratio = root if root > ratio else ratio
    elif count < MIN_BLOCKS:
        return KEEPS, ratio
    if ratio > WANDER_RATIO and terms[SCALE] < terms[SCALE_LIMIT]:
        return WIDENS, ratio
    full = count == terms[BLOCKS_IN_WINDOW]
    if full and ratio < NARROW_RATIO and terms[SCALE] > 1.0:
        return NARROWS, ratio
    return KEEPS, ratio


class WidenedNoise(NamedTuple):
    """What a watch widens, over which blocks, and how it says so."""

    name: str
    parameter: str
    """The fusion parameter of the σ widened."""
    limit_parameter: str
    """The fusion parameter bounding the widening."""
    block_s: float
    cause: str


GYRO_DRIFT = WidenedNoise(
    "the gyro's drift",
    "gyro_bias_instability_deg_h",
    "moored_gyro_drift_scale_limit",
    BLOCK_S,
    "the gyro wanders more than its stated model says",
)
VELOCITY_NOISE = WidenedNoise(
    "the velocity's noise",
    "accel_noise_mps_sqrt_h",
    "moored_velocity_noise_scale_limit",
    SHORT_BLOCK_S,
    "the velocity errs at tens of seconds more than its stated noise allows",
)


class MeanVelocityWatch:
    """The blocks' mean horizontal velocity of a moored buoy against its stated σ, and the factor
    on the σ of the noise it widens that it asks for (see the module docstring).

    ``window_s``: span of the blocks judged together (s); ``excursion_sigma_m``: the mooring's
    horizontal 1-σ wave excursion (m); ``widened``: what it widens (:data:`GYRO_DRIFT` over
    :data:`BLOCK_S`, :data:`VELOCITY_NOISE` over :data:`SHORT_BLOCK_S`); ``scale_limit``: the
    largest factor on that σ (1: never widened)."""

    def __init__(
        self,
        window_s: float,
        excursion_sigma_m: float,
        widened: WidenedNoise,
        scale_limit: float,
    ):
        self._widened = widened
        blocks_in_window = max(MIN_BLOCKS, round(window_s / widened.block_s))
        terms = np.zeros(TERMS_SIZE)
        terms[BLOCK_LENGTH] = widened.block_s
        terms[EXCURSION_VARIANCE] = 2.0 * excursion_sigma_m**2 / widened.block_s**2
        terms[BLOCKS_IN_WINDOW] = blocks_in_window
        terms[SCALE], terms[SCALE_LIMIT] = 1.0, scale_limit
        self._arrays = BlockArrays(terms, np.zeros(BLOCK_SIZE), np.zeros(blocks_in_window))
        self.restart()
        self.warning = ""
        """What the watch says while the drift is widened, else ``""``."""
        self._covariance_factor = 1.0

    @property
    def scale(self) -> float:
        """Factor (≥ 1) on the σ of the noise it widens (``widened.parameter``)."""
        return float(self._arrays.terms[SCALE])

    @property
    def arrays(self) -> BlockArrays:
        """A copy of the watch as arrays."""
        return BlockArrays(*(array.copy() for array in self._arrays))

    def restart(self) -> None:
        """Forget the block in progress (the velocity was not held by the mooring between)."""
        block = self._arrays.block
        block[BLOCK_START:SQUARES] = 0.0
        block[BLOCK_START] = math.nan

    def add(self, t_s: float, velocity_enu_mps, velocity_covariance_m2s2) -> bool:
        """Take the filter's horizontal velocity (m/s ENU, its first two components) and its
        covariance (m²/s², the upper-left 2×2) at stamp ``t_s`` (s); returns whether
        :attr:`scale` changed."""
        verdict, ratio = velocity_added(
            *self._arrays,
            t_s,
            np.asarray(velocity_enu_mps, dtype=float),
            np.ascontiguousarray(np.asarray(velocity_covariance_m2s2, dtype=float)[:2, :2]),
        )
        if verdict == WIDENS:
            self._widen(ratio)
        elif verdict == NARROWS:
            self._narrow(ratio)
        return verdict != KEEPS

    def load_compiled_code(self) -> None:
        """Compile the watch, or load it from the cache, now, on a copy of it."""
        velocity_added(*self.arrays, 0.0, np.zeros(3), np.eye(2))

    def take_covariance_factor(self) -> float:
        """The variance factor the blocks showed when the drift was last widened, once: the
        filter's attitude and velocity variances are raised by it at once, since a wider drift
        alone would take minutes to cover the error already there."""
        factor, self._covariance_factor = self._covariance_factor, 1.0
        return factor

    def ratio(self) -> float:
        """Normalised RMS of the window's blocks (NaN before any)."""
        count = int(self._arrays.block[SQUARES])
        if not count:
            return math.nan
        return math.sqrt(sum(self._arrays.squares[:count].tolist()) / (2.0 * count))

    def _widen(self, ratio: float) -> None:
        """Widen the σ by the variance ``ratio``² the blocks show, at most to the limit; judge
        the widened filter's own blocks from now on."""
        terms, widened = self._arrays.terms, self._widened
        limit = terms[SCALE_LIMIT]
        terms[SCALE] = min(limit, terms[SCALE] * ratio**2)
        self._covariance_factor = ratio**2
        self._arrays.block[SQUARES] = 0.0
        self.warning = (
            f"the moored buoy's mean velocity over {widened.block_s:.0f}-s blocks is "
            f"{ratio:.1f}× its stated σ: {widened.cause} (fusion.{widened.parameter}); "
            f"{widened.name} widened {self.scale:.1f}× (at most "
            f"fusion.{widened.limit_parameter}, {limit:g}); run "
            f"assess_motion_pack"
        )

    def _narrow(self, ratio: float) -> None:
        """Narrow a widened σ by :data:`NARROWING_PER_WINDOW`, the window's ``ratio`` well
        within it."""
        terms, widened = self._arrays.terms, self._widened
        terms[SCALE] = max(1.0, terms[SCALE] / NARROWING_PER_WINDOW)
        self._arrays.block[SQUARES] = 0.0
        self.warning = (
            f"{widened.name} (fusion.{widened.parameter}) held widened "
            f"{self.scale:.1f}×, narrowing as the moored buoy's mean velocity over "
            f"{widened.block_s:.0f}-s blocks stays within its σ ({ratio:.1f}×); run "
            f"assess_motion_pack"
            if self.scale > 1.0
            else ""
        )
