"""Suspension and resumption of an aiding source from its gate outcomes."""

import copy
import dataclasses

import numpy as np
import pytest
from engine_scenario import RockingBuoy, engine_config, make_events, run

from buoy_nav.config import ConfigError, FusionConfig
from buoy_nav.health import diagnostic_values, health_status
from buoy_nav.source_health import HealthChange, SourceHealth, SourceHealthRule, SourceStatus

RULE = SourceHealthRule(window=200, min_samples=100, suspend_share=0.5, resume_share=0.05)


def _feed(health, outcomes):
    return [health.record(failed) for failed in outcomes]


def test_a_source_that_agrees_is_never_suspended():
    # A consistent source fails a 0.9999 gate about once in 10,000 samples; here far more often.
    rng = np.random.default_rng(1)
    health = SourceHealth(RULE)
    changes = _feed(health, rng.random(20_000) < 0.02)
    assert HealthChange.SUSPENDED not in changes
    assert not health.suspended


def test_a_source_that_keeps_disagreeing_is_suspended_with_its_share_named():
    rng = np.random.default_rng(2)
    health = SourceHealth(RULE)
    changes = _feed(health, rng.random(400) < 0.62)
    first = changes.index(HealthChange.SUSPENDED)
    assert first == RULE.min_samples - 1
    assert health.suspended and health.suspensions == 1
    share = int(health.reason.split(" %")[0])
    assert 50 <= share <= 75
    assert health.reason.endswith(f"of the last {RULE.min_samples} samples failed the gate")


def test_a_burst_shorter_than_the_judged_span_suspends_nothing():
    # A filter fault that the source's reset mends: rejections in a row, then agreement.
    health = SourceHealth(RULE)
    changes = _feed(health, [True] * 49 + [False] * 1000)
    assert HealthChange.SUSPENDED not in changes


def test_a_suspended_source_resumes_once_it_agrees_again():
    health = SourceHealth(RULE)
    _feed(health, [True] * RULE.min_samples)
    assert health.suspended
    # Still failing one sample in ten: held out.
    every_tenth = [k % 10 == 0 for k in range(RULE.min_samples)]
    assert HealthChange.RESUMED not in _feed(health, every_tenth * 3)
    changes = _feed(health, [False] * RULE.min_samples)
    # The last 100 outcomes hold 5 failures (at most 5 %) after 41 clean ones.
    assert changes.index(HealthChange.RESUMED) == 40
    assert changes.count(HealthChange.RESUMED) == 1
    assert not health.suspended and health.reason == ""


def test_the_outcomes_that_cannot_resume_a_source_are_as_many_as_fail_to_resume_it():
    """From suspensions of every kind (fresh, after a few outcomes, after many with failures
    among them): that many outcomes, passing or failing, leave the source suspended, and one
    more passing outcome than that resumes it."""
    rng = np.random.default_rng(3)
    counts = []
    for _ in range(300):
        health = SourceHealth(RULE)
        _feed(health, [True] * RULE.min_samples)
        _feed(health, rng.random(int(rng.integers(0, 2 * RULE.window))) < rng.uniform(0.0, 0.2))
        if not health.suspended:
            continue
        count = health.outcomes_that_cannot_resume()
        counts.append(count)
        for failing in (False, True):
            trial = copy.deepcopy(health)
            outcomes = [failing or bool(rng.random() < 0.5) for _ in range(count)]
            assert HealthChange.RESUMED not in _feed(trial, outcomes)
        trial = copy.deepcopy(health)
        assert _feed(trial, [False] * (count + 1))[-1] is HealthChange.RESUMED
    assert len(counts) > 100 and min(counts) <= 5 and max(counts) >= 90


def test_passes_recorded_at_once_leave_the_health_one_at_a_time_leaves():
    """From histories of every length and share failed that passes cannot move (none failed,
    or the judged count reached), a run of passes of any length recorded at once: the same
    outcomes, stamps and count as recorded one by one, and the same changes after them."""
    rng = np.random.default_rng(4)
    compared = 0
    for _ in range(400):
        health = SourceHealth(RULE)
        history = int(rng.integers(0, 2 * RULE.window))
        share = rng.choice([0.0, rng.uniform(0.0, 0.4)])
        stamps = np.cumsum(rng.uniform(0.01, 2.0, history + 3 * RULE.window)).tolist()
        for t_s in stamps[:history]:
            health.record(bool(rng.random() < share), t_s)
        if not health.unmoved_by_passes:
            continue
        passes = stamps[history : history + int(rng.integers(1, 2 * RULE.window))]
        at_once, one_by_one = copy.deepcopy(health), copy.deepcopy(health)
        at_once.record_passes(passes)
        changes = [one_by_one.record(False, t_s) for t_s in passes]
        assert set(changes) == {HealthChange.NONE}
        assert vars(at_once) == vars(one_by_one)
        after = rng.random(RULE.window) < 0.7
        assert _feed(at_once, after) == _feed(one_by_one, after)
        compared += 1
    assert compared > 200


def test_passes_are_not_recorded_at_once_where_one_could_move_the_source():
    suspended, judging = SourceHealth(RULE), SourceHealth(RULE)
    _feed(suspended, [True] * RULE.min_samples)
    _feed(judging, [True, False])
    for health in (suspended, judging):
        with pytest.raises(ValueError, match="could move it"):
            health.record_passes([1.0, 2.0])


def test_forget_starts_the_judgement_again():
    health = SourceHealth(RULE)
    _feed(health, [True] * RULE.min_samples)
    health.forget()
    assert not health.suspended
    assert np.isnan(health.failed_share())


@pytest.mark.parametrize(
    "fields",
    [
        {"window": 50, "min_samples": 100},
        {"min_samples": 0},
        {"suspend_share": 0.05, "resume_share": 0.05},
        {"suspend_share": 1.5},
    ],
)
def test_an_impossible_rule_is_refused(fields):
    with pytest.raises(ValueError, match="source health"):
        SourceHealthRule(**fields)


def test_the_fusion_parameters_give_the_rule_and_are_checked_together():
    assert FusionConfig().source_health_rule == RULE
    with pytest.raises(ConfigError, match="min_samples"):
        FusionConfig(source_health_window=50)
    with pytest.raises(ConfigError, match="shares"):
        FusionConfig(source_health_resume_share=0.6)


def test_the_diagnostics_say_per_source_whether_it_is_suspended_and_why():
    engine, _ = run(make_events(RockingBuoy(), 20.0), engine_config())
    health = engine.health()
    values = diagnostic_values(health)
    assert values["gnss_velocity.suspended"] is False
    assert values["gnss_velocity.suspensions"] == 0
    assert values["gnss_velocity.suspension_reason"] == ""
    suspended = SourceStatus(True, "62 % of the last 200 samples failed the gate", 1)
    health = dataclasses.replace(
        health, source_health={**health.source_health, "gnss_velocity": suspended}
    )
    values = diagnostic_values(health)
    assert values["gnss_velocity.suspended"] is True
    assert values["gnss_velocity.suspension_reason"].startswith("62 %")
    level, message = health_status(health, "imu/data_raw", 100, 10)
    assert level == "warn" and "suspended: gnss_velocity" in message


@pytest.mark.parametrize(("rate_hz", "suspended_after_s"), [(1.0, 60.0), (0.2, 95.0), (10.0, 9.9)])
def test_a_slow_source_is_judged_after_a_span_of_time_a_fast_one_after_its_count(
    rate_hz, suspended_after_s
):
    """Failing every other sample: a 1-Hz source is suspended once its outcomes span the
    minute (not after a hundred of them), a 0.2-Hz one once twenty are in, a 10-Hz one after
    its hundred outcomes, as before."""
    health = SourceHealth(RULE)
    stamps = np.arange(400) / rate_hz
    changes = [health.record(i % 2 == 0, t) for i, t in enumerate(stamps)]
    first = changes.index(HealthChange.SUSPENDED)
    assert stamps[first] == pytest.approx(suspended_after_s)
    assert health.reason == (
        f"{round(100 * (first // 2 + 1) / (first + 1))} % of the last {first + 1} samples failed "
        "the gate"
    )
