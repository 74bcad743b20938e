"""The screening of a stream's stamps for a second stream on its topic."""

import numpy as np
import pytest

from buoy_nav.stream_sequence import CONFIRMING_SPAN_S, SEQUENCE_INTERVALS, StreamSequence

INTERVAL_S = 0.1


def screen_all(stamps_s) -> tuple[list, list, list]:
    """(stamps taken, stamps given up, held flags) of a StreamSequence fed ``stamps_s``."""
    sequence = StreamSequence()
    taken, given_up, held = [], [], []
    for t in stamps_s:
        screening = sequence.screen(t, t)
        taken += screening.taken
        given_up += screening.given_up
        held.append(screening.held)
    return taken, given_up, held


@pytest.mark.parametrize("lead_s", [0.3, 40.0])
def test_a_second_stream_ahead_is_given_up_and_the_own_one_taken(lead_s):
    """Each of the second stream's samples comes just before one of the stream's own, once
    the stream's rate is known (two samples)."""
    own = np.arange(0.0, 10.0, INTERVAL_S)
    stamps = list(own[:2])
    for t in own[2:]:
        stamps += [t - INTERVAL_S + lead_s, t]
    taken, given_up, held = screen_all(stamps)
    assert taken == list(own)
    assert given_up == stamps[2::2]
    assert held == [False, False] + [True, False] * (len(own) - 2)


def test_the_sequence_goes_on_through_a_lost_sample():
    stamps = [0.0, 0.1, 0.2, 0.4, 0.5]
    taken, given_up, _ = screen_all(stamps)
    assert taken == stamps and given_up == []


def test_a_lost_sample_does_not_widen_what_follows():
    """The interval is the median of the recent ones: after a lost sample, a stamp ahead by more
    than SEQUENCE_INTERVALS of the stream's own interval is still held."""
    sequence = StreamSequence()
    for t in (0.0, 0.1, 0.2, 0.4):
        sequence.screen(t, t)
    assert sequence.interval_s == pytest.approx(INTERVAL_S)
    assert sequence.screen(0.4 + (SEQUENCE_INTERVALS + 0.1) * INTERVAL_S, None).held


@pytest.mark.parametrize("off_grid_share", [0.3, 0.4, 0.6])
def test_a_stamp_off_the_grid_before_an_outage_costs_no_sample(off_grid_share):
    """A stamp off the stream's grid (a driver's jitter) makes two short intervals: the stream's
    interval stays its own, so after an outage that follows at once the held samples still
    follow each other and become the sequence; none is lost."""
    own = list(np.arange(0.0, 5.0, INTERVAL_S))
    off_grid = own[-1] + off_grid_share * INTERVAL_S
    after = list(5.0 + 1.0 + np.arange(0.0, 5.0, INTERVAL_S))
    taken, given_up, _ = screen_all([*own, off_grid, *after])
    assert given_up == []
    assert taken == [*own, off_grid, *after]


def test_after_an_outage_the_held_samples_become_the_sequence_once_they_span_the_confirming_span():
    before = list(np.arange(0.0, 5.0, INTERVAL_S))
    after = list(5.0 + 10.0 + np.arange(0.0, 5.0, INTERVAL_S))
    taken, given_up, held = screen_all(before + after)
    assert given_up == []
    assert taken == before + after  # released in order, none lost
    n_held = round(CONFIRMING_SPAN_S / INTERVAL_S) + 1
    assert held == [False] * len(before) + [True] * n_held + [False] * (len(after) - n_held)


def test_a_stamp_behind_the_sequence_is_left_to_the_callers_order_checks():
    sequence = StreamSequence()
    for t in (0.0, 0.1, 0.2):
        sequence.screen(t, t)
    screening = sequence.screen(0.15, "late")
    assert screening == (False, ["late"], [])
    assert sequence.latest_s == 0.2


def test_held_samples_given_up_are_counted_with_their_lead():
    sequence = StreamSequence()
    for t in (0.0, 0.1, 0.2):
        sequence.screen(t, t)
    assert sequence.screen(1.0, "stray").held
    assert sequence.screen(0.3, 0.3) == (False, [0.3], ["stray"])
    assert sequence.second_stream_samples == 1
    assert sequence.second_stream_lead_s == pytest.approx(0.8)


@pytest.mark.parametrize(
    ("t_s", "on_grid"),
    [(0.5, True), (0.2, True), (10.0 + 0.0005, True), (0.53, False), (0.3 + 0.002, False)],
)
def test_a_stamp_on_the_grid_is_a_whole_number_of_intervals_from_the_sequence(t_s, on_grid):
    sequence = StreamSequence()
    for t in (0.0, 0.1, 0.2):
        sequence.screen(t, t)
    assert sequence.on_grid(t_s) == on_grid
