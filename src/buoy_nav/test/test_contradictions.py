"""The receiver's motion set against the sources without the filter: the velocities against the
fixes, the mooring against the drift, and the suspensions they cause. Analytic motions with
noise drawn at the stated σ: the statistics are held against their chi-square laws."""

import math

import numpy as np
import pytest

from buoy_nav import earth
from buoy_nav.aiding.gnss_fix import GnssFix
from buoy_nav.aiding.gnss_velocity import GnssVelocity
from buoy_nav.aiding.moored import MooredSource
from buoy_nav.chi_square import chi_square_quantile
from buoy_nav.config import FusionConfig
from buoy_nav.contradictions import Contradictions
from buoy_nav.error_state_filter import ERROR_STATES
from buoy_nav.gnss_motion import GnssMotion
from buoy_nav.source_health import HealthChange, SourceHealth, SourceHealthRule

LATITUDE_DEG, LONGITUDE_DEG = 35.0, 120.0
POSITION_SIGMA_M = 0.5
VELOCITY_SIGMA_MPS = 0.05
WAVE_AMPLITUDE_MPS, WAVE_PERIOD_S = 0.3, 7.0


def antenna_motion(t_s, drift_enu_mps):
    """Position (m, ENU from the start) and velocity (m/s) of an antenna drifting at
    ``drift_enu_mps`` while the waves move it east and north with 0.3 m/s at 7 s."""
    omega = 2.0 * math.pi / WAVE_PERIOD_S
    t = np.asarray(t_s, dtype=float)[:, None]
    wave_direction = np.array([0.6, 0.8, 0.0])
    drift = np.asarray(drift_enu_mps, dtype=float)
    velocity = drift + WAVE_AMPLITUDE_MPS * np.cos(omega * t) * wave_direction
    position = drift * t + WAVE_AMPLITUDE_MPS / omega * np.sin(omega * t) * wave_direction
    return position, velocity


def measurements(stamps_s, drift_enu_mps, rng, velocity_bias_mps=(0.0, 0.0, 0.0)):
    """(stamp, GnssFix) and (stamp, GnssVelocity) pairs of the motion, with noise at the
    stated σ (the velocities also off by ``velocity_bias_mps``), in stamp order."""
    position, velocity = antenna_motion(stamps_s, drift_enu_mps)
    position = position + rng.normal(0.0, POSITION_SIGMA_M, position.shape)
    velocity = velocity + rng.normal(0.0, VELOCITY_SIGMA_MPS, velocity.shape)
    velocity = velocity + np.asarray(velocity_bias_mps)
    origin = (math.radians(LATITUDE_DEG), math.radians(LONGITUDE_DEG), 0.0)
    pairs = []
    for t, p, v in zip(stamps_s, position, velocity, strict=True):
        latitude, longitude, altitude = earth.geodetic_offset(*origin, p)
        fix = GnssFix(math.degrees(latitude), math.degrees(longitude), altitude, np.eye(3) * 0.25)
        pairs.append((t, fix))
        pairs.append((t, GnssVelocity(v, np.eye(3) * VELOCITY_SIGMA_MPS**2)))
    return pairs


def motion_of(pairs, keep_s=600.0) -> GnssMotion:
    motion = GnssMotion(keep_s, 1e-6, 1e-6)
    for t, measurement in pairs:
        motion.add(t, measurement)
    return motion


def normalised_squared(mean) -> float:
    vector = mean.velocity_enu_mps
    return float(vector @ np.linalg.solve(mean.covariance_m2s2, vector))


@pytest.mark.parametrize("rate_hz", [1.0, 10.0])
def test_velocities_and_fixes_of_one_motion_agree_within_their_noise(rate_hz):
    """Velocities integrated between fixes equal the fixes' displacement: over 200 windows of
    10 s the normalised difference is never beyond the gate's quantile, and no larger on
    average than a chi-square of three degrees of freedom (the trapezoidal rule's allowance
    only makes it smaller)."""
    rng = np.random.default_rng(3)
    statistics = []
    for window in range(200):
        stamps = 1000.0 + window * 10.0 + np.arange(0.0, 10.0 + 1e-9, 1.0 / rate_hz)
        motion = motion_of(measurements(stamps, (0.2, -0.1, 0.0), rng))
        statistics.append(normalised_squared(motion.velocity_against_fixes(0.0, 1e9)))
    assert max(statistics) < chi_square_quantile(3, 0.9999)
    assert 1.0 < np.mean(statistics) < 3.0 * 1.3


def test_a_biased_velocity_differs_from_the_fixes_by_its_bias():
    """A velocity off by 1 m/s east differs from the fixes' displacement by that, within the
    stated σ of the difference (0.14 m/s over 5 s of fixes good to 0.5 m), and is named
    contradicted by the fixes; the same velocity without its bias is not."""
    rng = np.random.default_rng(4)
    stamps = np.arange(0.0, 5.0 + 1e-9, 0.1)
    pairs = measurements(stamps, (0.2, -0.1, 0.0), rng, velocity_bias_mps=(1.0, 0.0, 0.0))
    motion = motion_of(pairs)
    difference = motion.velocity_against_fixes(0.0, 5.0)
    error = difference.velocity_enu_mps - (1.0, 0.0, 0.0)
    assert np.all(np.abs(error) <= 4.0 * np.sqrt(np.diag(difference.covariance_m2s2)))
    contradictions = Contradictions(FusionConfig())
    for t, measurement in pairs:
        contradictions.observe(t, measurement)
    verdict = contradictions.velocity_verdict(0.0, 5.0)
    assert verdict.contradicted and "m/s over 5.0 s" in verdict.reason
    unbiased = Contradictions(FusionConfig())
    for t, measurement in measurements(stamps, (0.2, -0.1, 0.0), rng):
        unbiased.observe(t, measurement)
    assert not unbiased.velocity_verdict(0.0, 5.0).contradicted


def test_too_few_measurements_say_nothing():
    motion = GnssMotion(600.0, 1e-6, 1e-6)
    assert motion.velocity_against_fixes(0.0, 10.0) is None
    assert motion.mean_velocity(1.0) is None


@pytest.mark.parametrize("measured_by", ["fixes", "velocities"])
def test_the_mean_velocity_is_the_drift_within_its_stated_noise(measured_by):
    """Over 300 s the mean velocity is the drift, whichever the receiver sends."""
    rng = np.random.default_rng(5)
    drift = np.array([0.25, -0.1, 0.0])
    pairs = measurements(np.arange(0.0, 300.0 + 1e-9, 1.0), drift, rng)
    kept = GnssFix if measured_by == "fixes" else GnssVelocity
    motion = motion_of([(t, m) for t, m in pairs if isinstance(m, kept)])
    mean = motion.mean_velocity(60.0)
    assert mean.measured_by == measured_by
    assert mean.span_s == pytest.approx(300.0)
    wave_mean_bound = WAVE_AMPLITUDE_MPS * WAVE_PERIOD_S / (math.pi * mean.span_s)
    sigma = np.sqrt(np.diag(mean.covariance_m2s2)) + wave_mean_bound
    assert np.all(np.abs(mean.velocity_enu_mps - drift) <= 4.0 * sigma)


def mooring(**changes) -> MooredSource:
    return MooredSource(FusionConfig(moored=True, **changes), ERROR_STATES)


def test_a_drifting_buoy_contradicts_its_mooring_and_a_moored_one_does_not():
    """0.25 m/s of drift over 300 s is far beyond a mooring's 3 m of wave excursion; waves
    alone are not. Before the fixes span a fifth of the window nothing is said."""
    rng = np.random.default_rng(6)
    stamps = np.arange(0.0, 300.0 + 1e-9, 1.0)
    drifting = motion_of(measurements(stamps, (0.25, 0.0, 0.0), rng), keep_s=300.0)
    verdict = mooring().judged_by(drifting)
    assert verdict.contradicted
    assert "mean drift of 0.25 m/s over 300 s" in verdict.reason
    assert "fusion.moored is wrong for this buoy" in mooring().suspension_hint
    moored = motion_of(measurements(stamps, (0.0, 0.0, 0.0), rng), keep_s=300.0)
    assert not mooring().judged_by(moored).contradicted
    early = motion_of(measurements(np.arange(0.0, 50.0, 1.0), (0.25, 0.0, 0.0), rng))
    assert mooring().judged_by(early) is None


def test_the_mooring_s_own_sigma_sets_what_counts_as_drift():
    """A mooring stated with a wide excursion (a long slack mooring) allows the same drift."""
    rng = np.random.default_rng(7)
    stamps = np.arange(0.0, 300.0 + 1e-9, 1.0)
    drifting = motion_of(measurements(stamps, (0.1, 0.0, 0.0), rng), keep_s=300.0)
    assert mooring().judged_by(drifting).contradicted
    slack = mooring(moored_position_sigma_horizontal_m=30.0).judged_by(drifting)
    assert slack is not None and not slack.contradicted


RULE = SourceHealthRule(window=200, min_samples=100, suspend_share=0.5, resume_share=0.05)


def test_a_contradiction_holds_whatever_the_gate_says_until_it_is_lifted():
    health = SourceHealth(RULE)
    assert health.contradict("drifts") is HealthChange.SUSPENDED
    assert all(health.record(False) is HealthChange.NONE for _ in range(300))
    assert health.suspended and health.reason == "drifts"
    health.forget()
    assert health.suspended
    assert health.no_longer_contradicted() is HealthChange.RESUMED
    assert not health.suspended and health.reason == "" and health.suspensions == 1
