"""Aiding sources that keep disagreeing are suspended, not followed, on the simulator's imperfect
sensors: an uncalibrated magnetometer on a moored buoy with one GNSS antenna, the same
magnetometer calibrated, and a GNSS velocity off by a constant bias beside dual antennas. The
truth is the simulator's, never the fusion's."""

import math

import numpy as np
from gnss_faults import biased_velocity
from test_nav_sensor_sets import (
    attitude_sigma_deg,
    euler_errors_deg,
    fuse,
    scenario_messages,
)

from buoy_common.contract import Reason
from buoy_nav.config import FusionConfig
from buoy_nav.source_health import HealthChange

MAST_ANTENNA_M = (0.1, 0.2, 1.9)
"""Where the imperfect single-antenna scenarios put their GNSS antenna (base_link)."""
HARD_IRON_UT = (18.0, -27.5, 12.0)
SOFT_IRON = (1.08, 0.05, -0.03, 0.05, 0.93, 0.07, -0.03, 0.07, 1.02)
"""The magnetometer's iron in set_b_imperfect and measured_moored_single_gnss."""


def single_antenna_config(**changes) -> FusionConfig:
    return FusionConfig(
        primary_antenna_body_m=MAST_ANTENNA_M,
        secondary_antenna_body_m=(1.6, 0.2, 1.9),
        site_latitude_deg=35.0,
        site_longitude_deg=120.0,
        **changes,
    )


def transitions_of(engine, kind: str):
    return [t for t in engine.take_source_transitions() if t.kind == kind]


def test_an_uncalibrated_magnetometer_never_gives_the_filter_its_heading():
    """The measured moored case: the uncalibrated magnetometer's field disagrees with the
    Earth's most of the time, and agrees now and then, at some headings. It is refused for the
    alignment with its reason, and no field that happens to agree completes the alignment,
    since the fields before it did not: with no other heading reference the fusion publishes
    nothing, rather than a heading 100° off with a σ of a degree."""
    scenario, _, messages = scenario_messages("measured_moored_single_gnss", 300.0)
    engine, solutions, _, _ = fuse(single_antenna_config(moored=True), messages, scenario)
    health = engine.health()
    counters = health.counters["magnetometer"]
    assert counters.rejected[Reason.MAGNETIC_FIELD_INCONSISTENT] > 1000
    assert counters.accepted == 0
    assert not health.aligned
    assert solutions == []


def test_an_uncalibrated_magnetometer_is_not_trusted_for_agreeing_in_strength_alone():
    """Set (e) uncalibrated: the levelling of a drifting buoy starts again while the GNSS
    velocity settles, and in between only the field's strength can be judged, which this
    sensor's iron leaves within tolerance. Those fields must not vouch for its heading (70° off
    here): no solution's yaw is beyond five of its stated σ, and the alignment waits for fields
    judged in strength and dip."""
    scenario, truth, messages = scenario_messages("set_e_imperfect", 60.0)
    engine, solutions, times, _ = fuse(single_antenna_config(), messages, scenario)
    assert engine.health().counters["magnetometer"].rejected[Reason.MAGNETIC_FIELD_INCONSISTENT]
    if solutions:
        yaw_errors = np.abs(euler_errors_deg(solutions, truth, times)[:, 2])
        assert np.all(yaw_errors <= 5.0 * attitude_sigma_deg(solutions)[:, 2])


def test_a_calibrated_magnetometer_is_never_suspended():
    """Set (b) with the simulated iron undone by the fusion's calibration: the field agrees
    with the Earth's and the magnetometer with the filter; it is never suspended."""
    scenario, truth, messages = scenario_messages("set_b_imperfect", 300.0)
    inverse = np.linalg.inv(np.reshape(SOFT_IRON, (3, 3)))
    config = single_antenna_config(
        magnetometer_hard_iron_t=tuple(h * 1e-6 for h in HARD_IRON_UT),
        magnetometer_soft_iron=tuple(float(v) for v in inverse.ravel()),
    )
    engine, solutions, times, _ = fuse(config, messages, scenario)
    health = engine.health()
    assert health.source_health["magnetometer"].suspensions == 0
    counters = health.counters["magnetometer"]
    inconsistent = counters.rejected.get(Reason.MAGNETIC_FIELD_INCONSISTENT, 0)
    assert counters.accepted > 1000
    assert inconsistent <= 0.01 * counters.accepted
    converged = times >= 120.0
    yaw_error = euler_errors_deg(solutions, truth, times)[converged, 2]
    assert np.sqrt(np.mean(yaw_error**2)) <= 2.0


def test_a_biased_gnss_velocity_is_suspended_while_the_antennas_hold_the_heading():
    """Sea state with dual antennas; from 60 s the receiver's velocity is 1 m/s off to the
    East: the velocity is suspended with its reason, and the heading stays within its 3σ."""
    scenario, truth, messages = scenario_messages("sea_state", 180.0)
    faulty = list(biased_velocity(messages, 60.0, scenario.start_time_ns, 1.0))
    engine, solutions, times, _ = fuse(FusionConfig(), faulty, scenario)
    suspensions = [
        t for t in transitions_of(engine, "gnss_velocity") if t.change is HealthChange.SUSPENDED
    ]
    assert suspensions, "the biased velocity was never suspended"
    assert "check the antenna lever arm and the receiver" in suspensions[0].message
    suspended_s = suspensions[0].t_s - scenario.start_time_ns * 1e-9
    assert 60.0 < suspended_s <= 90.0
    health = engine.health()
    assert health.source_health["gnss_velocity"].suspended
    assert not health.source_health["gnss_baseline"].suspended
    after = times > suspended_s + 5.0
    errors = euler_errors_deg(solutions, truth, times)[after]
    sigma = attitude_sigma_deg(solutions)[after]
    assert np.mean(np.abs(errors[:, 2]) <= 3.0 * sigma[:, 2]) >= 0.99
    assert math.sqrt(np.mean(errors[:, 2] ** 2)) <= 1.0


def calibrated_single_antenna_config(**changes) -> FusionConfig:
    """The single-antenna buoy with its magnetometer's iron undone."""
    inverse = np.linalg.inv(np.reshape(SOFT_IRON, (3, 3)))
    return single_antenna_config(
        magnetometer_hard_iron_t=tuple(h * 1e-6 for h in HARD_IRON_UT),
        magnetometer_soft_iron=tuple(float(v) for v in inverse.ravel()),
        **changes,
    )


def horizontal_velocity_normalised_errors(solutions, truth, times):
    """|error| / stated σ of the east and north velocity of each solution, against the truth
    (base_link, the solution's own point)."""
    error = (
        np.array([s.velocity_enu_mps for s in solutions]) - truth.evaluate(times).velocity_enu_mps
    )
    sigma = np.sqrt([np.diag(s.velocity_covariance_m2s2) for s in solutions])
    return np.abs(error[:, :2]) / sigma[:, :2]


def test_a_mooring_the_gnss_shows_drifting_is_suspended_and_the_velocity_stays_honest():
    """Set (e): the buoy drifts with a 0.15 m/s current and a 0.25 m/s tide, and
    ``fusion.moored`` is set on it. The GNSS's fixes show the drift before the receiver's first
    silent minute (120-180 s): the mooring is suspended with the drift named, so in that minute
    the velocity coasts on the IMU instead of being held near zero, within its stated σ."""
    scenario, truth, messages = scenario_messages("set_e_imperfect", 200.0)
    engine, solutions, times, _ = fuse(
        calibrated_single_antenna_config(moored=True), messages, scenario
    )
    start_s = scenario.start_time_ns * 1e-9
    (suspension,) = transitions_of(engine, "moored")
    assert suspension.change is HealthChange.SUSPENDED
    assert suspension.t_s - start_s < 120.0
    assert "mean drift" in suspension.message
    assert "fusion.moored is wrong for this buoy" in suspension.message
    health = engine.health()
    assert health.source_health["moored"].suspended
    assert "mean drift" in health.source_health["moored"].reason
    assert health.counters["moored"].accepted == 0
    outage = (times >= 125.0) & (times < 180.0)
    normalised = horizontal_velocity_normalised_errors(solutions, truth, times)[outage]
    assert outage.sum() > 1000
    assert np.mean(normalised <= 3.0, axis=0).min() >= 0.99
    assert normalised.max() <= 5.0


def test_a_moored_buoy_keeps_its_mooring():
    """The measured moored buoy, which does not drift, through a silent minute of its
    receiver: the GNSS never contradicts the mooring, which holds the velocity in that minute
    within its stated σ."""
    scenario, truth, messages = scenario_messages(
        "measured_moored_single_gnss", 240.0, ("sensors.gnss.silent_outages_s=[[150, 210]]",)
    )
    engine, solutions, times, _ = fuse(
        calibrated_single_antenna_config(moored=True), messages, scenario
    )
    assert transitions_of(engine, "moored") == []
    health = engine.health()
    assert health.source_health["moored"].suspensions == 0
    assert health.counters["moored"].accepted > 50
    outage = (times >= 150.0) & (times < 210.0)
    normalised = horizontal_velocity_normalised_errors(solutions, truth, times)[outage]
    assert np.mean(normalised <= 3.0, axis=0).min() >= 0.99


def test_a_biased_velocity_beside_noisy_fixes_does_not_drive_a_loop_of_realignments():
    """As above with fixes good to 2 m only: a realignment is due before the fixes can tell a
    metre per second of bias, and the filter realigned to the biased velocity drifts from the
    fixes, which fail next. The periods of distrust that keep coming back are judged together,
    so the velocity is suspended at the first or second realignment and stays suspended,
    rather than the filter being realigned to it again and again."""
    scenario, truth, messages = scenario_messages(
        "sea_state",
        240.0,
        (
            "sensors.gnss.position_noise_horizontal_m=2.0",
            "sensors.gnss.position_noise_vertical_m=4.0",
        ),
    )
    faulty = list(biased_velocity(messages, 60.0, scenario.start_time_ns, 1.0))
    engine, solutions, times, _ = fuse(FusionConfig(), faulty, scenario)
    health = engine.health()
    assert health.realignments <= 2
    velocity = health.source_health["gnss_velocity"]
    assert velocity.suspended and velocity.suspensions == 1
    assert "differs from the fixes' displacement" in velocity.reason
    assert not health.source_health["gnss_fix"].suspended
    after = times > 180.0
    errors = euler_errors_deg(solutions, truth, times)[after]
    sigma = attitude_sigma_deg(solutions)[after]
    assert np.mean(np.abs(errors[:, 2]) <= 3.0 * sigma[:, 2]) >= 0.99


def test_a_biased_gnss_velocity_is_suspended_rather_than_reset_to():
    """The same bias with the integrity monitor out of the way (it would realign first): after
    ``gate_reset_count`` rejections in a row the velocity is set against the fixes instead of
    the filter's velocity being reset to it, and suspended; the horizontal velocity stays within
    its σ."""
    scenario, truth, messages = scenario_messages("sea_state", 120.0)
    faulty = list(biased_velocity(messages, 60.0, scenario.start_time_ns, 1.0))
    engine, solutions, times, _ = fuse(
        FusionConfig(integrity_rejection_count=1000), faulty, scenario
    )
    health = engine.health()
    assert health.counters["gnss_velocity"].resets == 0
    assert health.source_health["gnss_velocity"].suspended
    assert "differs from the fixes' displacement" in health.source_health["gnss_velocity"].reason
    after = times > 70.0
    normalised = horizontal_velocity_normalised_errors(solutions, truth, times)[after]
    assert np.mean(normalised <= 3.0, axis=0).min() >= 0.99
