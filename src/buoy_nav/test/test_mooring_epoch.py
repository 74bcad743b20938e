"""The compiled stretch's judgement of the mooring's innovations against the watch's own: the
stretch stops making the mooring's epochs no later than the epoch after which the watch widens
its σ (it never applies one at a σ the watch would have widened), and no earlier than the
rounding of the two formulations allows; the normalised squares it keeps are the watch's."""

import math

import numpy as np
import pytest

from buoy_nav.aiding.moored import MIN_SPAN_OF_WINDOW, WARNING_RATIO, InnovationWatch
from buoy_nav.mooring_epoch import (
    HORIZONTAL_VARIANCE,
    MARGIN,
    MIN_SPAN,
    QUIET,
    RATIO_SQ_LIMIT,
    STATE_SIZE,
    TERMS_SIZE,
    VARIANCE_SCALE,
    WINDOW,
    MooringArguments,
    judged,
)

WINDOW_S = 300.0
STATED_SIGMA_M = 3.0


def stretch_mooring(capacity: int) -> MooringArguments:
    """The mooring's arguments as a stretch gets them for a quiet watch of an empty window."""
    terms = np.zeros(TERMS_SIZE)
    terms[HORIZONTAL_VARIANCE], terms[VARIANCE_SCALE] = STATED_SIGMA_M**2, 1.0
    terms[WINDOW], terms[MIN_SPAN] = WINDOW_S, MIN_SPAN_OF_WINDOW * WINDOW_S
    terms[RATIO_SQ_LIMIT] = WARNING_RATIO**2 * (1.0 - MARGIN)
    state = np.zeros(STATE_SIZE)
    state[QUIET] = 1.0
    return MooringArguments(
        terms, np.eye(3), state, np.zeros(capacity), np.zeros(capacity), np.zeros((0, 29))
    )


def innovations(seed: int, duration_s: float, first_spread: float, last_spread: float):
    """A horizontal innovation a second (stamp s, ν m, the filter's part C m², S m² 3×3), its
    spread from ``first_spread`` to ``last_spread`` times the stated one."""
    rng = np.random.default_rng(seed)
    for t_s in np.arange(duration_s):
        root = rng.normal(0.0, 1.0, (2, 2))
        filter_part = 0.5 * root @ root.T
        horizontal = filter_part + STATED_SIGMA_M**2 * np.eye(2)
        spread = first_spread + (last_spread - first_spread) * t_s / duration_s
        nu = spread * np.linalg.cholesky(horizontal) @ rng.standard_normal(2)
        innovation_covariance = np.eye(3)
        innovation_covariance[:2, :2] = horizontal
        yield float(t_s), nu, filter_part, innovation_covariance


# The window's RMS crossing WARNING_RATIO on its way up, between the checks; or beyond it from
# the start, when the window first spans enough to be judged.
SPREADS = {"growing": (0.9, 2.0), "too large from the start": (1.6, 1.6)}


@pytest.mark.parametrize("seed", range(4))
@pytest.mark.parametrize("spreads", SPREADS)
def test_the_stretch_stops_with_the_epoch_after_which_the_watch_widens(spreads, seed):
    watch = InnovationWatch(WINDOW_S, STATED_SIGMA_M, 3.0)
    duration_s = 900.0
    mooring = stretch_mooring(int(duration_s))
    window = np.zeros(2, dtype=np.int64)
    for t_s, nu, filter_part, innovation_covariance in innovations(
        seed, duration_s, *SPREADS[spreads]
    ):
        judged(mooring, window, t_s, np.array((*nu, 0.0)), innovation_covariance)
        watch.add(t_s, nu, filter_part)
        if not watch.quiet or mooring.state[QUIET] == 0.0:
            break
    # Both at the same epoch: the first to judge it so stopped the loop.
    assert not watch.quiet, f"the stretch stopped at {t_s} s, the watch did not widen"
    assert mooring.state[QUIET] == 0.0, f"the watch widened at {t_s} s, the stretch went on"


def test_the_stretch_keeps_the_watch_s_normalised_squares():
    watch = InnovationWatch(WINDOW_S, STATED_SIGMA_M, 3.0)
    mooring = stretch_mooring(400)
    window = np.zeros(2, dtype=np.int64)
    for t_s, nu, filter_part, innovation_covariance in innovations(7, 400.0, 1.0, 1.0):
        judged(mooring, window, t_s, np.array((*nu, 0.0)), innovation_covariance)
        watch.add(t_s, nu, filter_part)
    stamps, squares = watch.window_squares()
    first, end = window
    np.testing.assert_array_equal(mooring.window_stamps[first:end], stamps)
    np.testing.assert_allclose(mooring.window_squares[first:end], squares, rtol=1e-12)
    assert math.isclose(
        math.sqrt(np.sum(squares) / (2 * squares.size)), watch.ratio(), rel_tol=1e-12
    )
