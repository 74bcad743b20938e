"""The mooring's innovation watch: silent on innovations as large as stated, a warning once a
window on innovations larger, cleared when they shrink again."""

import numpy as np

from buoy_nav.aiding.moored import WARNING_RATIO, InnovationWatch

WINDOW_S = 300.0
DIMENSION = 2


def feed(watch: InnovationWatch, start_s: float, duration_s: float, scale: float, seed: int):
    """One NIS a second of normal innovations ``scale`` times their stated σ; the answers."""
    rng = np.random.default_rng(seed)
    answers = []
    for t_s in np.arange(start_s, start_s + duration_s):
        innovation = scale * rng.standard_normal(DIMENSION)
        answers.append(watch.add(float(t_s), float(innovation @ innovation), DIMENSION))
    return answers


def test_innovations_as_stated_give_no_warning():
    watch = InnovationWatch(WINDOW_S)
    assert all(answer is None for answer in feed(watch, 0.0, 1200.0, 1.0, 1))
    assert abs(watch.ratio() - 1.0) < 0.15


def test_larger_innovations_warn_once_a_window_and_clear():
    watch = InnovationWatch(WINDOW_S)
    answers = feed(watch, 0.0, 1200.0, 1.5 * WARNING_RATIO, 2)
    warnings = [answer for answer in answers if answer]
    # The first once the window is four-fifths full (240 s), then once each 300 s.
    assert len(warnings) == 4
    assert all("run assess_motion_pack" in warning for warning in warnings)
    answers = feed(watch, 1200.0, 600.0, 1.0, 3)
    assert answers.count("") == 1 and not any(answers)
