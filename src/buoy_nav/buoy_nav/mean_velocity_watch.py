"""A moored buoy's mean velocity over minutes as the witness of the gyro's drift.

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
"""

from __future__ import annotations

import math
from collections import deque

import numpy as np

from buoy_nav.chi_square import chi_square_quantile

BLOCK_S = 30.0
"""Length of a block (s): long against the waves (their velocity averages out) and short
against the gyro's wander (minutes), so the block's mean is the slow velocity error."""
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


class MeanVelocityWatch:
    """The blocks' mean horizontal velocity of a moored buoy against its stated σ, and the factor
    on the gyro's drift σ it asks for (see the module docstring).

    ``window_s``: span of the blocks judged together (s); ``excursion_sigma_m``: the mooring's
    horizontal 1-σ wave excursion (m); ``scale_limit``: the largest factor on the drift's σ
    (1: never widened)."""

    def __init__(self, window_s: float, excursion_sigma_m: float, scale_limit: float):
        self._blocks_in_window = max(MIN_BLOCKS, round(window_s / BLOCK_S))
        self._excursion_variance_m2s2 = 2.0 * excursion_sigma_m**2 / BLOCK_S**2
        self._scale_limit = scale_limit
        self._block_start_s = math.nan
        self._velocity_sum_mps = np.zeros(2)
        self._covariance_sum_m2s2 = np.zeros((2, 2))
        self._samples = 0
        self._normalised_squared: deque[float] = deque(maxlen=self._blocks_in_window)
        self.scale = 1.0
        """Factor (≥ 1) on the σ of the gyro's drift (``fusion.gyro_bias_instability_deg_h``)."""
        self.warning = ""
        """What the watch says while the drift is widened, else ``""``."""
        self._covariance_factor = 1.0

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
        if t_s - self._block_start_s >= BLOCK_S and self._samples:
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
            self.warning = (
                f"the moored buoy's mean velocity over {BLOCK_S:.0f}-s blocks is {ratio:.1f}× "
                f"its stated σ: the gyro wanders more than fusion.gyro_bias_instability_deg_h "
                f"says; its drift widened {self.scale:.1f}× (at most "
                f"fusion.moored_gyro_drift_scale_limit, {self._scale_limit:g}); run "
                f"assess_motion_pack"
            )
            return True
        full = len(self._normalised_squared) == self._blocks_in_window
        if full and ratio < NARROW_RATIO and self.scale > 1.0:
            self.scale = max(1.0, self.scale / NARROWING_PER_WINDOW)
            self._normalised_squared.clear()
            self.warning = (
                f"the gyro's drift (fusion.gyro_bias_instability_deg_h) held widened "
                f"{self.scale:.1f}×, narrowing as the moored buoy's mean velocity stays within "
                f"its σ ({ratio:.1f}×); run assess_motion_pack"
                if self.scale > 1.0
                else ""
            )
            return True
        return False
