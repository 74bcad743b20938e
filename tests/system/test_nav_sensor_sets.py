"""The sensor sets beyond RTK on the independent simulator, through the contract messages.

Each run builds the simulator's streams for a scenario, feeds their messages through
``feed_message`` (the conversion of the live node and the offline tools) and compares with the
simulator's truth: (c) IMU + magnetometer on a moored buoy, (d) IMU + a motion pack's attitude,
(e) the dual-antenna set through a GNSS outage; the magnetometer's disturbance gate; and bad
magnetometer and motion-pack input rejected, counted and never fused; and each set's normalised
errors over independent seeds (Monte-Carlo NEES), as the dual-antenna set's in
``test_nav_simulated``.
"""

from __future__ import annotations

import copy
import math

import numpy as np
import pytest
from scipy.spatial.transform import Rotation
from test_nav_simulated import attitude_nees, chi_square_mean_bounds, velocity_nees

from buoy_common.contract import AHRS_TOPIC, MAGNETOMETER_TOPIC, Reason
from buoy_nav.config import FusionConfig
from buoy_nav.engine import FusionEngine
from buoy_nav.fusion_messages import FUSION_INPUT_MSGTYPES, feed_message
from sensor_sim.scenario import load_scenario
from sensor_sim.streams import STREAMS, merged_messages
from sensor_sim.truth import TruthModel

HARD_IRON_UT = (4.0, -2.5, 1.5)
SOFT_IRON = (1.04, 0.02, -0.01, 0.02, 0.97, 0.015, -0.01, 0.015, 1.01)
MAGNETOMETER = (
    "sensors.magnetometer.fitted=true",
    f"sensors.magnetometer.hard_iron_ut={list(HARD_IRON_UT)}",
    f"sensors.magnetometer.soft_iron={list(SOFT_IRON)}",
)


def calibrated_magnetometer() -> dict:
    """Fusion parameters undoing the moored scenario's hard and soft iron exactly."""
    inverse = np.linalg.inv(np.reshape(SOFT_IRON, (3, 3)))
    return {
        "magnetometer_hard_iron_t": tuple(h * 1e-6 for h in HARD_IRON_UT),
        "magnetometer_soft_iron": tuple(float(v) for v in inverse.ravel()),
    }


def moored_config(**changes) -> FusionConfig:
    return FusionConfig(
        site_latitude_deg=35.0,
        site_longitude_deg=120.0,
        ahrs_yaw_reference="magnetic_north",
        moored=True,
        **calibrated_magnetometer(),
        **changes,
    )


def scenario_messages(name: str, duration_s: float, overrides=(), seed: int | None = None):
    """(scenario, truth model, [(topic, stamp_ns, message)]) of the scenario's sensors, with
    the scenario's seed or ``seed``."""
    scenario = load_scenario(name, [*overrides, f"duration_s={duration_s}"], seed)
    truth = TruthModel(scenario)
    streams = [STREAMS[kind].build(scenario, truth, {}) for kind in ("imu", "gnss")]
    return scenario, truth, merged_messages(streams, duration_s)


def fuse(config: FusionConfig, messages, scenario):
    """Feed the messages to an engine; (engine, solutions, their scenario times, health at
    each solution's sensor set)."""
    engine = FusionEngine(config)
    solutions, sets = [], []
    for topic, _, message in messages:
        if topic not in FUSION_INPUT_MSGTYPES:
            continue
        new, _ = feed_message(engine, topic, message)
        solutions += new
        if new and len(solutions) % 100 == 0:
            sets.append((new[-1].t_s, engine.health().sensor_set))
    solutions += engine.flush()
    start_s = scenario.start_time_ns * 1e-9
    times = np.array([s.t_s for s in solutions]) - start_s
    return engine, solutions, times, [(t - start_s, label) for t, label in sets]


def euler_errors_deg(solutions, truth, times):
    estimate = Rotation.from_quat(np.array([s.attitude_xyzw for s in solutions]))
    true = truth.evaluate(times).attitude
    difference = estimate.as_euler("ZYX")[:, ::-1] - true.as_euler("ZYX")[:, ::-1]
    return np.degrees((difference + math.pi) % (2 * math.pi) - math.pi)


def attitude_sigma_deg(solutions):
    return np.degrees(np.sqrt([np.diag(s.attitude_covariance_rad2) for s in solutions]))


@pytest.fixture(scope="module")
def moored_run():
    scenario, truth, messages = scenario_messages("moored_motion_pack", 150.0)
    return scenario, truth, messages


def test_moored_magnetometer_set_holds_heading_and_stays_consistent(moored_run):
    """(c): heading from the calibrated magnetometer within 1° RMS, every attitude error
    within the filter's own 3σ, the set named in the health."""
    scenario, truth, messages = moored_run
    engine, solutions, times, sets = fuse(moored_config(use_ahrs=False), messages, scenario)
    converged = times >= 60.0
    errors = euler_errors_deg(solutions, truth, times)[converged]
    assert np.sqrt(np.mean(errors[:, 2] ** 2)) <= 1.0
    sigma = attitude_sigma_deg(solutions)[converged]
    horizontal = np.hypot(sigma[:, 0], sigma[:, 1])
    assert np.mean(np.abs(errors[:, :2]) <= 3 * horizontal[:, None]) > 0.99
    assert np.mean(np.abs(errors[:, 2]) <= 3 * sigma[:, 2]) > 0.99
    assert sets[-1][1] == "c: magnetometer, no GNSS"
    health = engine.health()
    assert health.counters["moored"].accepted > 100
    assert health.covariance_repairs == 0


def test_motion_pack_set_follows_the_pack_without_its_lag(moored_run):
    """(d): the pack's attitude (magnetic north, 0.2 s lag) as the only reference: heading
    within 1° RMS, roll and pitch closer to the truth than the pack's own lagging output."""
    scenario, truth, messages = moored_run
    engine, solutions, times, sets = fuse(
        moored_config(use_magnetometer=False, ahrs_lag_s=0.2), messages, scenario
    )
    converged = times >= 60.0
    errors = euler_errors_deg(solutions, truth, times)[converged]
    assert np.sqrt(np.mean(errors[:, 2] ** 2)) <= 1.0
    pack = [(stamp, m) for topic, stamp, m in messages if topic == AHRS_TOPIC]
    pack_times = np.array([stamp for stamp, _ in pack]) * 1e-9 - scenario.start_time_ns * 1e-9
    quaternions = [
        (m.orientation.x, m.orientation.y, m.orientation.z, m.orientation.w) for _, m in pack
    ]
    pack_euler = Rotation.from_quat(quaternions).as_euler("ZYX")[:, ::-1]
    pack_errors = np.degrees(
        pack_euler - truth.evaluate(pack_times).attitude.as_euler("ZYX")[:, ::-1]
    )
    pack_rms = np.sqrt(np.mean(pack_errors[pack_times >= 60.0, :2] ** 2, axis=0))
    fused_rms = np.sqrt(np.mean(errors[:, :2] ** 2, axis=0))
    assert np.all(fused_rms < pack_rms)
    assert sets[-1][1] == "d: motion pack"
    assert engine.health().counters["magnetometer"].accepted == 0


def test_a_passing_hull_is_rejected_by_the_gate_and_counted():
    """20 s of a 30° heading bias in the magnetometer (a steel hull passing): the gate rejects
    the disturbed samples, counts them, and the heading stays within 1° of the truth."""
    scenario, truth, messages = scenario_messages(
        "moored_motion_pack",
        150.0,
        ("sensors.magnetometer.disturbances_s=[[100, 120]]", "sensors.ahrs.fitted=false"),
    )
    engine, solutions, times, _ = fuse(moored_config(), messages, scenario)
    disturbed_samples = 20.0 * 10.0  # 10 Hz magnetometer
    # A disturbance this long suspends the magnetometer until it agrees again.
    rejected = sum(
        engine.health().counters["magnetometer"].rejected.get(reason, 0)
        for reason in (Reason.GATE, Reason.SUSPENDED)
    )
    assert rejected >= 0.9 * disturbed_samples
    assert engine.health().counters["magnetometer"].resets == 0
    during = (times >= 100.0) & (times < 125.0)
    errors = euler_errors_deg(solutions, truth, times)
    assert np.abs(errors[during, 2]).max() < 1.0


def test_bad_magnetometer_and_motion_pack_input_is_rejected_and_never_fused(moored_run):
    """NaN and saturated fields, a zero and a non-unit quaternion, a pack stamp out of order:
    each rejected with its reason, and the solutions exactly those of the clean input."""
    scenario, _, messages = moored_run
    messages = [m for m in messages if m[1] < scenario.start_time_ns + 40e9]
    config = moored_config(ahrs_lag_s=0.2)
    _, clean, _, _ = fuse(config, messages, scenario)

    def spoiled(topic, index, change):
        positions = [i for i, m in enumerate(messages) if m[0] == topic]
        original = messages[positions[index]]
        message = copy.deepcopy(original[2])
        change(message)
        return positions[index], (topic, original[1], message)

    def nan_field(m):
        m.magnetic_field.x = math.nan

    def saturated(m):
        m.magnetic_field.z = 1e-3

    def zero_quaternion(m):
        m.orientation.x = m.orientation.y = m.orientation.z = m.orientation.w = 0.0

    def non_unit(m):
        m.orientation.w *= 1.1

    def older_stamp(m):
        m.header.stamp.sec -= 1

    cases = [
        (MAGNETOMETER_TOPIC, 50, nan_field, "magnetometer", Reason.NON_FINITE),
        (MAGNETOMETER_TOPIC, 250, saturated, "magnetometer", Reason.OUT_OF_RANGE),
        (AHRS_TOPIC, 60, zero_quaternion, "ahrs", Reason.ZERO_QUATERNION),
        (AHRS_TOPIC, 260, non_unit, "ahrs", Reason.NON_UNIT_QUATERNION),
        (AHRS_TOPIC, 300, older_stamp, "ahrs", Reason.STAMP_NOT_INCREASING),
    ]
    inserted = dict(spoiled(topic, index, change) for topic, index, change, _, _ in cases)
    dirty = []
    for i, message in enumerate(messages):
        dirty.append(message)
        if i in inserted:
            dirty.append(inserted[i])
    engine, solutions, _, _ = fuse(config, dirty, scenario)
    counters = engine.health().counters
    for _, _, _, kind, reason in cases:
        assert counters[kind].rejected.get(reason, 0) == 1, (kind, reason)
    assert len(solutions) == len(clean)
    for a, b in zip(solutions, clean, strict=True):
        np.testing.assert_array_equal(a.attitude_xyzw, b.attitude_xyzw)
        np.testing.assert_array_equal(a.velocity_enu_mps, b.velocity_enu_mps)


def test_dual_antenna_set_through_a_minute_without_gnss():
    """(e): 60 s without any GNSS topic: the set reports the outage, the attitude stays within
    twice the RTK targets (0.2°/0.2°/0.3°), and when GNSS returns the correction of what the
    outage let grow moves the attitude by less than the roll/pitch bound of the outage, 0.2°
    (measured: 0.13°, in one update: the filter does not blend corrections in)."""
    scenario, truth, messages = scenario_messages(
        "sea_state", 170.0, ("sensors.gnss.fix_outages_s=[[100, 160]]",)
    )
    _, solutions, times, sets = fuse(FusionConfig(), messages, scenario)
    errors = euler_errors_deg(solutions, truth, times)
    converged = times >= 60.0
    assert np.all(np.abs(errors[converged]).max(axis=0) <= (0.2, 0.2, 0.3))
    labels = {label for t, label in sets if 105.0 <= t < 160.0}
    assert labels and all("e: outage" in label for label in labels)
    assert sets[-1][1] == "a: dual-antenna GNSS"
    step = np.abs(np.diff(errors, axis=0)).max(axis=1)
    around_return = (times[1:] >= 159.0) & (times[1:] < 162.0)
    assert step[around_return].max() < 0.2


MONTE_CARLO_SEEDS = range(100, 108)
MONTE_CARLO_DURATION_S = 100.0
# After the magnetometer's heading has converged; the outage of (e) spans 50-90 s.
MONTE_CARLO_CHECKPOINTS_S = (60.0, 80.0, 95.0)
MONTE_CARLO_SETS = {
    "b_single_antenna_magnetometer": (
        "sea_state",
        ("sensors.gnss.receiver=single_antenna", *MAGNETOMETER),
        lambda: FusionConfig(
            site_latitude_deg=35.0, site_longitude_deg=120.0, **calibrated_magnetometer()
        ),
    ),
    "c_magnetometer_moored": (
        "moored_motion_pack",
        ("sensors.ahrs.fitted=false",),
        lambda: moored_config(use_ahrs=False),
    ),
    "d_motion_pack_moored": (
        "moored_motion_pack",
        (),
        lambda: moored_config(use_magnetometer=False, ahrs_lag_s=0.2),
    ),
    "e_dual_antenna_outage": (
        "sea_state",
        ("sensors.gnss.fix_outages_s=[[50, 90]]",),
        FusionConfig,
    ),
}


@pytest.mark.parametrize("set_name", MONTE_CARLO_SETS)
def test_monte_carlo_nees_of_each_sensor_set(set_name):
    """Over independent seeds, the normalised attitude error at fixed times is chi-square with
    3 dof per run in every set, and so is the velocity error where GNSS velocity or its outage
    sets it. A moored buoy's velocity is held by the zero-mean constraint, whose noise is the
    whole wave excursion taken as white: its covariance is conservative (measured mean NEES
    0.26-0.52 against 3), so there the velocity is held only to never being overconfident."""
    scenario_name, overrides, config = MONTE_CARLO_SETS[set_name]
    nees = []  # per run: (attitude NEES, velocity NEES) at the checkpoints
    for seed in MONTE_CARLO_SEEDS:
        scenario, truth, messages = scenario_messages(
            scenario_name, MONTE_CARLO_DURATION_S, overrides, seed
        )
        _, solutions, times, _ = fuse(config(), messages, scenario)
        at = [int(np.argmin(np.abs(times - t))) for t in MONTE_CARLO_CHECKPOINTS_S]
        true = truth.evaluate(times[at])
        chosen = [solutions[i] for i in at]
        nees.append((attitude_nees(chosen, true), velocity_nees(chosen, true)))
    attitude, velocity = np.mean(nees, axis=0)
    low, high = chi_square_mean_bounds(3, len(MONTE_CARLO_SEEDS))
    figures = f"attitude {np.round(attitude, 2)}, velocity {np.round(velocity, 2)}"
    assert np.all((low <= attitude) & (attitude <= high)), figures
    if "moored" in set_name:
        assert np.all(velocity <= high), figures
    else:
        assert np.all((low <= velocity) & (velocity <= high)), figures


def test_a_magnetometer_a_few_degrees_off_is_suspended_not_followed():
    """(d) at an FDCHP's rates (10 Hz IMU; the pack and the magnetometer at 1 Hz) with the moored
    scenario's magnetometer left uncalibrated: its small iron (4 µT) keeps the field within the
    Earth's strength and dip, and turns its heading by a few degrees, beyond the 1° its
    calibration claims. Each sample is gated at that 1° and fails; the
    magnetometer is suspended, the heading follows the pack, and no attitude error leaves three
    of its σ (fused as white noise, a minute of such samples claimed a tenth of a degree and
    pulled the heading 5 to 11° off, the pitch with it)."""
    scenario, truth, messages = scenario_messages(
        "moored_motion_pack", 300.0, ("sensors.rates.imu_hz=10.0",)
    )
    uncalibrated = FusionConfig(
        site_latitude_deg=35.0,
        site_longitude_deg=120.0,
        ahrs_yaw_reference="magnetic_north",
        moored=True,
        ahrs_lag_s=0.2,
    )
    engine, solutions, times, _ = fuse(uncalibrated, messages, scenario)
    converged = times >= 60.0
    errors = euler_errors_deg(solutions, truth, times)[converged]
    sigma = attitude_sigma_deg(solutions)[converged]
    assert np.mean(np.abs(errors) <= 3 * sigma, axis=0).min() > 0.99
    assert np.sqrt(np.mean(errors[:, 2] ** 2)) <= 1.0
    health = engine.health()
    assert health.source_health["magnetometer"].suspended
    assert health.counters["magnetometer"].rejected[Reason.GATE] > 0
