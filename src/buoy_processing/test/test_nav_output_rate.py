"""The rate of the written navigation: which solutions it keeps, how the commands take it, and
how the processed bag's facts and an archive's digest carry it."""

from __future__ import annotations

import math
from types import SimpleNamespace

import numpy as np
import pytest

from buoy_nav.config import FusionConfig
from buoy_processing import fuse_bag, process_archive, process_bag
from buoy_processing.archive import parameters_digest
from buoy_processing.nav_output_rate import NavOutputRate
from buoy_processing.output_facts import OutputFacts, SourceUse, output_facts
from wind_comp.config import CompensatorConfig

IMU_RATE_HZ = 100.0
START_NS = 1_767_225_600_000_000_000


def solutions_at(stamps_s) -> list[SimpleNamespace]:
    """Solutions as the rate sees them: header stamps (sec, nanosec) of times after START."""
    solutions = []
    for t_s in stamps_s:
        stamp_ns = START_NS + round(t_s * 1e9)
        solutions.append(SimpleNamespace(sec=stamp_ns // 10**9, nanosec=stamp_ns % 10**9))
    return solutions


def kept_stamps_s(rate: NavOutputRate, stamps_s) -> np.ndarray:
    kept = [t for t, s in zip(stamps_s, solutions_at(stamps_s), strict=True) if rate.due(s)]
    return np.array(kept)


@pytest.mark.parametrize("nav_rate_hz", [1.0, 10.0, 30.0, 50.0])
def test_one_solution_per_period_of_jittered_imu_samples(nav_rate_hz):
    jitter_s = np.random.default_rng(7).uniform(-1e-3, 1e-3, 2000)
    stamps_s = np.arange(2000) / IMU_RATE_HZ + jitter_s
    kept = kept_stamps_s(NavOutputRate(nav_rate_hz), stamps_s)
    period_s = 1.0 / nav_rate_hz
    half_step_s = 0.5 / IMU_RATE_HZ
    assert kept[0] == stamps_s[0]
    assert np.diff(kept).min() >= period_s - half_step_s - 2e-3
    assert abs(len(kept) - (stamps_s[-1] - stamps_s[0]) * nav_rate_hz) <= 1


def test_rate_zero_keeps_every_solution():
    stamps_s = np.arange(500) / IMU_RATE_HZ
    np.testing.assert_array_equal(kept_stamps_s(NavOutputRate(0.0), stamps_s), stamps_s)


def test_the_first_solution_after_a_gap_is_kept_and_the_grid_goes_on_from_it():
    stamps_s = np.concatenate([np.arange(100), 537 + np.arange(100)]) / IMU_RATE_HZ
    kept = kept_stamps_s(NavOutputRate(10.0), stamps_s)
    assert 5.37 in kept
    after_gap = kept[kept >= 5.37]
    np.testing.assert_allclose(np.diff(after_gap), 0.1, atol=1e-9)


@pytest.mark.parametrize("rate", [-1.0, math.nan, math.inf])
def test_a_rate_that_is_no_rate_is_refused(rate):
    with pytest.raises(ValueError, match="≥ 0 Hz"):
        NavOutputRate(rate)


@pytest.mark.parametrize("command", [fuse_bag, process_bag, process_archive])
@pytest.mark.parametrize("text", ["-1", "nan", "fast"])
def test_the_commands_refuse_a_bad_rate_as_a_usage_error(command, text, capsys):
    with pytest.raises(SystemExit) as ended:
        command.parse_arguments(["in", "out", "--nav-rate-hz", text])
    assert ended.value.code == 2
    assert "--nav-rate-hz: expected a number of Hz ≥ 0" in capsys.readouterr().err


@pytest.mark.parametrize("command", [fuse_bag, process_bag, process_archive])
def test_the_commands_write_every_solution_unless_asked(command):
    assert command.parse_arguments(["in", "out"]).nav_rate_hz == 0.0
    assert command.parse_arguments(["in", "out", "--nav-rate-hz", "2.5"]).nav_rate_hz == 2.5


def test_the_facts_carry_the_rate_and_read_it_as_every_solution_when_absent():
    valid_flow_samples = {"anemometer/wind": 100}
    uses = {"gnss_heading": SourceUse(10)}
    facts = output_facts(FusionConfig(), valid_flow_samples, uses, [(1.0, 2.0)], nav_rate_hz=5.0)
    metadata = facts.to_metadata()
    assert OutputFacts.from_metadata(metadata) == facts
    written_before = {name: value for name, value in metadata.items() if name != "nav_rate_hz"}
    assert OutputFacts.from_metadata(written_before).nav_rate_hz == 0.0


def test_an_archive_redoes_its_bags_for_another_rate_only():
    configs = (FusionConfig(), CompensatorConfig(), None, ())
    assert parameters_digest(*configs, 0.0) == parameters_digest(*configs)
    assert parameters_digest(*configs, 10.0) != parameters_digest(*configs)
    assert parameters_digest(*configs, 10.0) != parameters_digest(*configs, 5.0)
