"""The mooring's innovation watch: silent and unwidened on innovations as large as stated, a
warning once a window and a σ widened by what the innovations show on innovations larger,
both undone when they shrink again; its compiled sums and roots those of NumPy and SciPy."""

import math

import numpy as np
import pytest
from scipy.optimize import brentq

from buoy_nav.innovation_watch import (
    WARNING_RATIO,
    InnovationWatch,
    consistent_scale,
    pairwise_sum,
    window_ratio,
)

WINDOW_S = 300.0
STATED_SIGMA_M = 0.2
SCALE_LIMIT = 3.0


def feed(
    watch: InnovationWatch,
    start_s: float,
    duration_s: float,
    true_sigma_m: float,
    seed: int,
    filter_variance_m2: float = 0.0,
):
    """One horizontal innovation a second, normal with variance C + true_sigma_m² per axis
    where the filter's part is C = filter_variance_m2 · I; the answers."""
    rng = np.random.default_rng(seed)
    filter_covariance = filter_variance_m2 * np.eye(2)
    spread = math.sqrt(filter_variance_m2 + true_sigma_m**2)
    return [
        watch.add(float(t_s), spread * rng.standard_normal(2), filter_covariance)
        for t_s in np.arange(start_s, start_s + duration_s)
    ]


def test_innovations_as_stated_give_no_warning_and_no_widening():
    watch = InnovationWatch(WINDOW_S, STATED_SIGMA_M, SCALE_LIMIT)
    assert all(answer is None for answer in feed(watch, 0.0, 1200.0, STATED_SIGMA_M, 1))
    assert abs(watch.ratio() - 1.0) < 0.15
    assert watch.scale == 1.0


def test_larger_innovations_warn_once_a_window_and_clear():
    watch = InnovationWatch(WINDOW_S, STATED_SIGMA_M, SCALE_LIMIT)
    answers = feed(watch, 0.0, 1200.0, 1.5 * WARNING_RATIO * STATED_SIGMA_M, 2)
    warnings = [answer for answer in answers if answer]
    # The first once the window is four-fifths full (240 s), then once each 300 s.
    assert len(warnings) == 4
    assert all("run assess_motion_pack" in warning for warning in warnings)
    assert all("σ widened" in warning for warning in warnings)
    answers = feed(watch, 1200.0, 600.0, STATED_SIGMA_M, 3)
    assert answers.count("") == 1 and not any(answers)


@pytest.mark.parametrize("filter_variance_m2", [0.0, 0.02])
def test_the_sigma_is_widened_to_what_the_innovations_show(filter_variance_m2):
    """Innovations of variance v = C + (2σ)² per axis: the watch widens σ by the k that makes
    C + (kσ)² their variance, 2, with the filter's own C counted, not attributed to σ. The
    window's 600 components know v to √(2/600) of itself, so k to v √(2/600) / (2 (2σ)²);
    three of that allowed."""
    watch = InnovationWatch(WINDOW_S, STATED_SIGMA_M, SCALE_LIMIT)
    feed(watch, 0.0, 600.0, 2.0 * STATED_SIGMA_M, 4, filter_variance_m2)
    widened_variance = (2.0 * STATED_SIGMA_M) ** 2
    innovation_variance = filter_variance_m2 + widened_variance
    relative_scale_sigma = innovation_variance * math.sqrt(2.0 / 600) / (2.0 * widened_variance)
    assert abs(watch.scale / 2.0 - 1.0) < 3.0 * relative_scale_sigma
    # Narrowed only over the window: never narrower than consistent.
    assert watch.ratio(watch.scale) <= 1.0 + 1e-9


def test_the_widening_is_bounded_and_narrows_over_the_window():
    watch = InnovationWatch(WINDOW_S, STATED_SIGMA_M, SCALE_LIMIT)
    feed(watch, 0.0, 600.0, 10.0 * STATED_SIGMA_M, 5)
    assert watch.scale == SCALE_LIMIT
    # Innovations as stated again: once the window holds only those (300 s), the widening
    # decays with the window as time constant, so within another 300 s by at least 1 − 1/e.
    feed(watch, 600.0, 600.0, STATED_SIGMA_M, 6)
    assert 1.0 < watch.scale < 1.0 + (SCALE_LIMIT - 1.0) / math.e
    feed(watch, 1200.0, 1800.0, STATED_SIGMA_M, 7)
    assert watch.scale == pytest.approx(1.0, abs=0.01)


def test_a_limit_of_one_never_widens():
    watch = InnovationWatch(WINDOW_S, STATED_SIGMA_M, 1.0)
    answers = feed(watch, 0.0, 600.0, 3.0 * STATED_SIGMA_M, 7)
    assert watch.scale == 1.0 and any(answers)


@pytest.mark.parametrize("first", [0, 3])
def test_the_window_is_summed_as_numpy_sums(first):
    """The compiled pairwise sum against NumPy's on every length up to several blocks and
    on long windows: the ratio is the vectorised formulation's to the bit."""
    rng = np.random.default_rng(8)
    lengths = [*range(600), *rng.integers(600, 20_000, 20)]
    for length in lengths:
        values = rng.exponential(size=first + length) * 10.0 ** rng.uniform(-5, 5, first + length)
        assert pairwise_sum(values, first, length) == np.sum(values[first:]), length


def test_the_widened_sigma_is_the_root_scipy_finds():
    """While the window's innovations are larger than stated, the factor found by the compiled
    Brent's method is the one SciPy's brentq finds on the same ratio, to the bit."""
    watch = InnovationWatch(WINDOW_S, STATED_SIGMA_M, SCALE_LIMIT)
    rng = np.random.default_rng(9)
    checked = 0
    for t_s in np.arange(0.0, 900.0):
        spread = STATED_SIGMA_M * (1.0 + 2.0 * t_s / 900.0)
        root = rng.normal(0.0, STATED_SIGMA_M, (2, 2))
        watch.add(float(t_s), spread * rng.standard_normal(2), root @ root.T)
        if watch.ratio(1.0) <= 1.0 or watch.ratio(SCALE_LIMIT) >= 1.0:
            continue
        arrays = watch.arrays(0)
        bounds = np.array((0, arrays.stamps.size))

        def excess(scale, arrays=arrays, bounds=bounds):
            return window_ratio(arrays, bounds, scale) - 1.0

        assert consistent_scale(arrays, bounds) == brentq(excess, 1.0, SCALE_LIMIT)
        checked += 1
    assert checked > 300
