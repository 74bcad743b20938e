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
from collections import deque
from typing import NamedTuple

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
        self._block_s = widened.block_s
        self._blocks_in_window = max(MIN_BLOCKS, round(window_s / self._block_s))
        self._excursion_variance_m2s2 = 2.0 * excursion_sigma_m**2 / self._block_s**2
        self._scale_limit = scale_limit
        self._block_start_s = math.nan
        self._velocity_sum_mps = np.zeros(2)
        self._covariance_sum_m2s2 = np.zeros((2, 2))
        self._samples = 0
        self._normalised_squared: deque[float] = deque(maxlen=self._blocks_in_window)
        self.scale = 1.0
        """Factor (≥ 1) on the σ of the noise it widens (``widened.parameter``)."""
        self.warning = ""
        """What the watch says while the drift is widened, else ``""``."""
        self._covariance_factor = 1.0

    @property
    def block(self) -> tuple[float, float]:
        """The block in progress: its start (s; NaN before its first sample) and length (s)."""
        return self._block_start_s, self._block_s

    def restart(self) -> None:
        """Forget the block in progress (the velocity was not held by the mooring between)."""
        self._block_start_s = math.nan
        self._velocity_sum_mps[:] = 0.0
        self._covariance_sum_m2s2[:] = 0.0
        self._samples = 0

    def add(self, t_s: float, velocity_enu_mps, velocity_covariance_m2s2) -> bool:
        """Take the filter's horizontal velocity (m/s ENU, its first two components) and its
        covariance (m²/s², the upper-left 2×2) at stamp ``t_s`` (s); returns whether
        :attr:`scale` changed."""
        if math.isnan(self._block_start_s):
            self._block_start_s = t_s
        if t_s - self._block_start_s >= self._block_s and self._samples:
            changed = self._close_block()
            self.restart()
            self._block_start_s = t_s
        else:
            changed = False
        self._velocity_sum_mps += np.asarray(velocity_enu_mps, dtype=float)[:2]
        self._covariance_sum_m2s2 += np.asarray(velocity_covariance_m2s2, dtype=float)[:2, :2]
        self._samples += 1
        return changed

    def take_covariance_factor(self) -> float:
        """The variance factor the blocks showed when the drift was last widened, once: the
        filter's attitude and velocity variances are raised by it at once, since a wider drift
        alone would take minutes to cover the error already there."""
        factor, self._covariance_factor = self._covariance_factor, 1.0
        return factor

    def ratio(self) -> float:
        """Normalised RMS of the window's blocks (NaN before any)."""
        if not self._normalised_squared:
            return math.nan
        return math.sqrt(sum(self._normalised_squared) / (2.0 * len(self._normalised_squared)))

    def _close_block(self) -> bool:
        mean = self._velocity_sum_mps / self._samples
        covariance = self._covariance_sum_m2s2 / self._samples
        covariance = covariance + self._excursion_variance_m2s2 * np.eye(2)
        block = float(mean @ np.linalg.solve(covariance, mean))
        self._normalised_squared.append(block)
        ratio = self.ratio()
        if block > BLOCK_QUANTILE:
            ratio = max(ratio, math.sqrt(block / 2.0))
        elif len(self._normalised_squared) < MIN_BLOCKS:
            return False
        if ratio > WANDER_RATIO and self.scale < self._scale_limit:
            self.scale = min(self._scale_limit, self.scale * ratio**2)
            self._covariance_factor = ratio**2
            self._normalised_squared.clear()
            widened = self._widened
            self.warning = (
                f"the moored buoy's mean velocity over {self._block_s:.0f}-s blocks is "
                f"{ratio:.1f}× its stated σ: {widened.cause} (fusion.{widened.parameter}); "
                f"{widened.name} widened {self.scale:.1f}× (at most "
                f"fusion.{widened.limit_parameter}, {self._scale_limit:g}); run "
                f"assess_motion_pack"
            )
            return True
        full = len(self._normalised_squared) == self._blocks_in_window
        if full and ratio < NARROW_RATIO and self.scale > 1.0:
            self.scale = max(1.0, self.scale / NARROWING_PER_WINDOW)
            self._normalised_squared.clear()
            self.warning = (
                f"{self._widened.name} (fusion.{self._widened.parameter}) held widened "
                f"{self.scale:.1f}×, narrowing as the moored buoy's mean velocity over "
                f"{self._block_s:.0f}-s blocks stays within its σ ({ratio:.1f}×); run "
                f"assess_motion_pack"
                if self.scale > 1.0
                else ""
            )
            return True
        return False
