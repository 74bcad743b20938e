"""Sources and assumptions that the GNSS's own measurements contradict, judged without the filter.

The gate judges each measurement against the filter, so it cannot tell a filter that has lost
its way from a source that has pulled the filter along. What the receiver measured of the
buoy's motion (:class:`~buoy_nav.gnss_motion.GnssMotion`) can, since it does not pass through
the filter:

- **a velocity that disagrees with the fixes.** When the integrity monitor is about to realign
  (or a source to reset the velocity to its measurement) because a velocity source failed its
  gate while the fixes agreed with the filter, the velocities integrated over that time are set
  against the displacement between the fixes. A difference beyond the chi-square quantile of
  ``gate_probability`` (three degrees of freedom) against the noise of both says the velocity
  is wrong, not the filter: it is suspended instead of followed
  (:meth:`~buoy_nav.source_health.SourceHealth.contradict`), and the new alignment goes without
  it. Its gate cannot lift that (a filter just realigned without it has a velocity σ wide
  enough to let a biased velocity pass): it is judged against the fixes again every second,
  over the last :data:`VELOCITY_CHECK_SPAN_S`, and resumes once the difference is below the
  quantile of :data:`~buoy_nav.chi_square.AGREEMENT_PROBABILITY`. A position source is not
  judged so: a fix that jumps is followed (reset), as before.
- **an assumption the motion disproves**: a constraint judges itself against the mean velocity
  the receiver measured (:meth:`~buoy_nav.aiding.base.AidingSource.judged_by`), such as the
  mooring's zero mean velocity on a buoy that drifts
  (:meth:`~buoy_nav.source_health.SourceHealth.contradict`).

Every validated fix and velocity feeds the motion, suspended or not: a suspended velocity must
be seen to agree again.
"""

from __future__ import annotations

import math

import numpy as np

from buoy_nav.aiding.base import AidingSource, Verdict
from buoy_nav.chi_square import AGREEMENT_PROBABILITY, chi_square_quantile
from buoy_nav.config import FusionConfig
from buoy_nav.gnss_motion import GnssMotion

VELOCITY_CHECK_SPAN_S = 60.0
"""Longest span (s) over which a velocity is set against the fixes: the time it has failed."""


class Contradictions:
    """The receiver's motion of the last minutes and what it contradicts (see the module
    docstring), for ``config``'s gate probability and the constraints' windows."""

    def __init__(self, config: FusionConfig):
        keep_s = max(VELOCITY_CHECK_SPAN_S, config.moored_check_window_s if config.moored else 0.0)
        self.motion = GnssMotion(
            keep_s, config.gnss_position_variance_floor_m2, config.gnss_velocity_variance_floor_m2s2
        )
        """What the receiver measured of the buoy's motion."""
        self._velocity_contradiction = chi_square_quantile(3, config.gate_probability)
        self._velocity_agreement = chi_square_quantile(3, AGREEMENT_PROBABILITY)

    def observe(self, t_s: float, measurement) -> None:
        """A validated measurement stamped ``t_s`` (s) of any source, suspended or not (only
        fixes and velocities are kept)."""
        self.motion.add(t_s, measurement)

    def velocity_verdict(self, from_s: float, to_s: float) -> Verdict | None:
        """The velocities of [``from_s``, ``to_s``] (s, at most the last
        :data:`VELOCITY_CHECK_SPAN_S` of it) against the fixes of that time; None when too few
        measurements say, or the difference is between the two quantiles."""
        from_s = max(from_s, to_s - VELOCITY_CHECK_SPAN_S)
        difference = self.motion.velocity_against_fixes(from_s, to_s)
        if difference is None:
            return None
        vector = difference.velocity_enu_mps
        normalised_squared = float(vector @ np.linalg.solve(difference.covariance_m2s2, vector))
        difference_text = (
            f"{np.linalg.norm(vector):.2f} m/s over {difference.span_s:.1f} s "
            f"({math.sqrt(normalised_squared):.1f}σ)"
        )
        if normalised_squared > self._velocity_contradiction:
            return Verdict(
                True,
                f"its velocity differs from the fixes' displacement by {difference_text}; it "
                "began to fail while the fixes agreed with the filter",
            )
        if normalised_squared < self._velocity_agreement:
            return Verdict(
                False, f"its velocity agrees with the fixes' displacement to {difference_text}"
            )
        return None

    def judge(self, source: AidingSource) -> Verdict | None:
        """What the receiver's motion says of ``source``'s assumption
        (:meth:`AidingSource.judged_by`)."""
        return source.judged_by(self.motion)
