"""What the fusion engine tells a recorder of its filter: the hooks a smoother stores from.

The engine (:class:`buoy_nav.engine.FusionEngine`) calls these methods of its ``recorder`` at
every change of the error-state filter, so a backward pass can replay the forward one:

- :meth:`EpochRecorder.propagated`: the covariance was propagated to a new *epoch* (every
  ``covariance_propagation_interval_s`` and at each measurement stamp);
- :meth:`EpochRecorder.corrected`: an update's correction was injected into the nominal state
  and the error mean reset to zero (at the current epoch);
- :meth:`EpochRecorder.noise_added`: the covariance was widened without a change of the state
  (the integrity monitor's inflation), which is process noise at the current stamp;
- :meth:`EpochRecorder.end_segment` and :meth:`EpochRecorder.begin_segment`: the nominal state
  was set other than by a correction (the alignment, a source's reset of the states it observes
  such as the yaw reset, a realignment after an IMU gap or a loss of integrity, the end of the
  data), across which nothing is smoothed.

This base class does nothing: the engine's default, live and in forward-only processing.
:class:`buoy_nav.smoother.SmootherRecorder` stores the epochs.
"""

from __future__ import annotations

import numpy as np


class EpochRecorder:
    """Receives the filter's epochs and resets (see the module docstring); records nothing."""

    def begin_segment(self, t_s: float, covariance: np.ndarray) -> None:
        """The filter starts (alignment) or restarts (state reset) at stamp ``t_s`` (s) with
        ``covariance``."""

    def propagated(
        self,
        t_s: float,
        transition: np.ndarray,
        prior_covariance: np.ndarray,
        previous_posterior: np.ndarray,
    ) -> None:
        """The covariance was propagated to stamp ``t_s`` (s) by ``transition`` from
        ``previous_posterior`` (P⁺ of the previous epoch) to ``prior_covariance``."""

    def corrected(self, correction: np.ndarray) -> None:
        """The error-state ``correction`` was injected into the nominal state at the current
        epoch."""

    def noise_added(
        self, t_s: float, covariance_before: np.ndarray, covariance: np.ndarray
    ) -> None:
        """The covariance was widened at stamp ``t_s`` (s) from ``covariance_before`` to
        ``covariance``, the state unchanged."""

    def end_segment(self, covariance: np.ndarray | None) -> None:
        """The filter stops with ``covariance`` (None: there is no filter): its nominal state
        is about to be set, or the data end."""
