"""The fusion engine on the independent simulator: accuracy and statistical consistency.

sensor_sim shares no navigation code with buoy_nav; its IMU and GNSS carry the default error
budget the filter is configured for. Consistency follows pyins: normalised estimation errors
(NEES) over Monte-Carlo runs and normalised innovations (NIS) per measurement kind must be
chi-square distributed with the right number of degrees of freedom.
"""

import dataclasses
import math

import numpy as np
import pytest
from scipy.spatial.transform import Rotation
from scipy.stats import chi2

from buoy_nav.aiding import (
    GnssBaseline,
    GnssBaselineTertiary,
    GnssFix,
    GnssHeading,
    GnssVelocity,
)
from buoy_nav.config import FusionConfig
from buoy_nav.engine import FusionEngine
from buoy_nav.smoothed_solutions import FixedIntervalSmoother
from error_budget import gyro_bias_limit_rad_s
from sensor_sim.scenario import load_scenario
from sensor_sim.sensor_models import GnssSimulator, ImuSimulator
from sensor_sim.truth import TruthModel

IMU_RATE_HZ = 100.0
GNSS_RATE_HZ = 10.0
# Two-sided probability of the chi-square acceptance regions.
CONSISTENCY_PROBABILITY = 0.999


def simulate(
    name,
    duration_s=None,
    seed=None,
    record_innovations=False,
    baseline_until_s=math.inf,
    imu_errors=None,
    tertiary_antenna_body_m=(math.nan, math.nan, math.nan),
):
    """Run the engine on a scenario; return truth and solutions at the solution stamps.

    The receiver's heading is fed throughout, its baseline vector up to ``baseline_until_s``
    (never: the filter is configured without it), and with a ``tertiary_antenna_body_m`` the
    third antenna's baseline. ``imu_errors`` replaces the scenario's IMU error budget.
    """
    config = FusionConfig(
        record_innovations=record_innovations,
        use_gnss_baseline=baseline_until_s > 0.0,
        tertiary_antenna_body_m=tertiary_antenna_body_m,
    )
    engine = FusionEngine(config)
    solutions, truth = run_engine(engine, name, duration_s, seed, baseline_until_s, imu_errors)
    return engine, solutions, truth


def simulate_smoothed(name, duration_s=None, seed=None):
    """Run the engine with the fixed-interval smoother on a scenario; return the engine, the
    forward and the smoothed solutions, and truth at the solution stamps."""
    engine = FusionEngine(FusionConfig(realtime_output=False))
    with FixedIntervalSmoother(engine) as smoother:
        solutions, truth = run_engine(engine, name, duration_s, seed, math.inf)
        for solution in solutions:
            smoother.add(solution, 0, 0, 0)
        smoothed = [pair.smoothed for pair in smoother.smoothed()]
    return engine, solutions, smoothed, truth


def run_engine(engine, name, duration_s, seed, baseline_until_s, imu_errors=None):
    """Feed ``engine`` the simulated IMU and GNSS of a scenario (baseline vectors up to
    ``baseline_until_s``; ``imu_errors`` in place of the scenario's IMU error budget); return
    its solutions and truth at their stamps."""
    scenario = load_scenario(name, seed=seed)
    duration = duration_s or scenario.duration_s
    truth = TruthModel(scenario)
    config = engine.config
    imu = ImuSimulator(truth, imu_errors or scenario.sensors.imu, scenario.seed)
    gnss = GnssSimulator(
        truth,
        scenario.sensors.gnss,
        config.primary_antenna_body_m,
        config.secondary_antenna_body_m,
        scenario.seed,
        config.tertiary_antenna_body_m,
    )
    t_imu = np.arange(0.0, duration, 1.0 / IMU_RATE_HZ)
    t_gnss = np.arange(0.0, duration, 1.0 / GNSS_RATE_HZ)
    gyro, force = imu.measure(t_imu)
    sample = gnss.measure(t_gnss)
    solutions = []
    next_gnss = 0
    for k, t in enumerate(t_imu):
        while next_gnss < t_gnss.size and t_gnss[next_gnss] <= t:
            i = next_gnss
            if sample.fix_valid[i]:
                engine.add_measurement(
                    t_gnss[i],
                    GnssFix(
                        sample.latitude_deg[i],
                        sample.longitude_deg[i],
                        sample.altitude_m[i],
                        sample.position_covariance_enu_m2[i],
                    ),
                )
                engine.add_measurement(
                    t_gnss[i],
                    GnssVelocity(
                        sample.velocity_enu_mps[i], sample.velocity_covariance_enu_m2s2[i]
                    ),
                )
            if sample.heading_valid[i]:
                engine.add_measurement(
                    t_gnss[i],
                    GnssHeading(sample.heading_yaw_rad[i], sample.heading_variance_rad2[i]),
                )
                if t_gnss[i] < baseline_until_s:
                    engine.add_measurement(t_gnss[i], GnssBaseline(sample.baseline_enu_m[i]))
                if sample.tertiary_baseline_enu_m is not None:
                    engine.add_measurement(
                        t_gnss[i], GnssBaselineTertiary(sample.tertiary_baseline_enu_m[i])
                    )
            next_gnss += 1
        solutions += engine.add_imu(t, gyro[k], force[k])
    solutions += engine.flush()
    stamps = np.array([s.t_s for s in solutions])
    return solutions, truth.evaluate(stamps)


def euler_errors_deg(solutions, truth):
    estimate = Rotation.from_quat(np.array([s.attitude_xyzw for s in solutions]))
    difference = estimate.as_euler("ZYX")[:, ::-1] - truth.attitude.as_euler("ZYX")[:, ::-1]
    return np.degrees((difference + math.pi) % (2 * math.pi) - math.pi)


def attitude_nees(solutions, truth):
    phi = truth.attitude * Rotation.from_quat([s.attitude_xyzw for s in solutions]).inv()
    phi = phi.as_rotvec()
    covariance = np.array([s.attitude_covariance_rad2 for s in solutions])
    return np.einsum("ni,ni->n", phi, np.linalg.solve(covariance, phi[..., None])[..., 0])


def velocity_nees(solutions, truth):
    error = np.array([s.velocity_enu_mps for s in solutions]) - truth.velocity_enu_mps
    covariance = np.array([s.velocity_covariance_m2s2 for s in solutions])
    return np.einsum("ni,ni->n", error, np.linalg.solve(covariance, error[..., None])[..., 0])


def chi_square_mean_bounds(dof, count):
    """Acceptance region of the mean of ``count`` independent chi-square(dof) samples."""
    tail = (1.0 - CONSISTENCY_PROBABILITY) / 2
    total = dof * count
    return chi2.ppf(tail, total) / count, chi2.ppf(1.0 - tail, total) / count


def test_sea_state_accuracy_meets_the_targets():
    """Paper-002 sway (10/5/5°) with mooring yaw and drift: after 60 s of convergence the
    attitude stays within 0.1° (roll, pitch) and 0.15° (yaw), RMS 0.05/0.05/0.08°."""
    engine, solutions, truth = simulate("sea_state", duration_s=200.0)
    stamps = np.array([s.t_s for s in solutions])
    converged = stamps >= 60.0
    errors = euler_errors_deg(solutions, truth)[converged]
    assert np.all(np.abs(errors).max(axis=0) <= (0.1, 0.1, 0.15))
    assert np.all(np.sqrt(np.mean(errors**2, axis=0)) <= (0.05, 0.05, 0.08))
    velocity_error = np.array([s.velocity_enu_mps for s in solutions]) - truth.velocity_enu_mps
    assert np.sqrt(np.mean(velocity_error[converged] ** 2)) < 0.02
    health = engine.health()
    assert health.covariance_repairs == 0
    assert health.counters["gnss_baseline"].accepted > 1800
    # The heading is the baseline's azimuth: fusing it too would count it twice.
    heading = health.counters["gnss_heading"]
    assert heading.accepted == 0
    assert heading.superseded == heading_epochs(200.0)
    assert heading.rejected == {}


def heading_epochs(duration_s):
    return math.ceil(duration_s * GNSS_RATE_HZ)


def test_heading_takes_over_when_the_baselines_stop():
    """A receiver that stops sending baselines leaves the heading: superseded at the epochs
    with a baseline, fused from the first epoch without, with no coasting gap and the attitude
    still within the targets."""
    engine, solutions, truth = simulate("sea_state", duration_s=160.0, baseline_until_s=100.0)
    heading = engine.health().counters["gnss_heading"]
    assert heading.superseded == heading_epochs(100.0)
    assert heading.rejected == {}
    assert heading.accepted == heading_epochs(160.0) - heading_epochs(100.0)
    stamps = np.array([s.t_s for s in solutions])
    assert not any(s.coasting_heading for s in solutions)
    errors = euler_errors_deg(solutions, truth)[stamps >= 60.0]
    assert np.all(np.abs(errors).max(axis=0) <= (0.1, 0.1, 0.15))


def test_tilt_table_accuracy_and_the_unobservable_pitch():
    """Paper-000 tilt table, heading only: 60 s still, then ±15° roll swings at 5°/s.

    While the table is still, both horizontal accelerometer biases look like tilt (error ≈ b/g);
    once it rolls about body x, the y accelerometer turns out of the horizontal and roll
    becomes observable, but the x accelerometer never does, so pitch keeps an error ≈ b_x / g.
    The filter must say so: the tilt errors stay within their own 3σ throughout, and roll (after
    20 s of swinging) and yaw meet the targets.
    """
    _, solutions, truth = simulate("tilt_table", baseline_until_s=0.0)
    stamps = np.array([s.t_s for s in solutions])
    errors = euler_errors_deg(solutions, truth)
    swinging = stamps >= 80.0
    assert np.abs(errors[swinging, 0]).max() <= 0.1
    assert np.abs(errors[stamps >= 30.0, 2]).max() <= 0.15
    sigma_deg = np.degrees(np.sqrt([np.diag(s.attitude_covariance_rad2) for s in solutions]))
    horizontal_sigma = np.hypot(sigma_deg[:, 0], sigma_deg[:, 1])
    converged = stamps >= 30.0
    assert np.all(np.abs(errors[converged, :2]) <= 3 * horizontal_sigma[converged, None])
    assert np.degrees(np.sqrt(solutions[-1].attitude_covariance_rad2[1, 1])) > 0.1


def test_the_baseline_vector_observes_pitch_even_at_rest():
    """Paper 001: the baseline vector's vertical component is the tilt of the antenna axis
    (body x), which no accelerometer bias can imitate. On the tilt table the pitch σ drops
    below 0.03° while the table is still and the pitch error stays within 3σ and the target."""
    _, solutions, truth = simulate("tilt_table")
    stamps = np.array([s.t_s for s in solutions])
    errors = euler_errors_deg(solutions, truth)
    sigma_deg = np.degrees(np.sqrt([np.diag(s.attitude_covariance_rad2) for s in solutions]))
    still = (stamps >= 40.0) & (stamps < 60.0)
    # Yaw 30° on the table: pitch is the tilt about the axis 30° from north toward west.
    axis = np.array((-math.sin(math.radians(30.0)), math.cos(math.radians(30.0)), 0.0))
    pitch_sigma = np.degrees(np.sqrt([axis @ s.attitude_covariance_rad2 @ axis for s in solutions]))
    assert pitch_sigma[still].max() < 0.03
    converged = stamps >= 30.0
    assert np.all(np.abs(errors[converged, 1]) <= 3 * pitch_sigma[converged])
    assert np.abs(errors[converged, 1]).max() <= 0.1
    assert np.abs(errors[stamps >= 80.0, 0]).max() <= 0.1
    assert sigma_deg[-1].max() < 0.05


def test_gyro_bias_estimate_finds_the_true_bias():
    """With an IMU whose biases stay what they were at switch-on, the filter's gyro bias
    estimate after two and a half minutes at sea is within the limit of :mod:`error_budget` of
    the simulator's bias on every axis. A rate the mechanization gets wrong (the Earth's, say)
    would be taken up as a bias of that size."""
    name = "sea_state"
    scenario = load_scenario(name)
    constant_biases = dataclasses.replace(
        scenario.sensors.imu,
        gyro_bias_instability_deg_h=0.0,
        accel_bias_instability_mg=0.0,
        scale_factor_error_percent=0.0,
    )
    engine, _, _ = simulate(name, duration_s=160.0, imu_errors=constant_biases)
    true_bias = ImuSimulator(
        TruthModel(scenario), constant_biases, scenario.seed
    ).gyro_turn_on_bias_rad_s
    error_deg_h = np.degrees(engine.nav_state.gyro_bias_rad_s - true_bias) * 3600.0
    limit_deg_h = math.degrees(gyro_bias_limit_rad_s()) * 3600.0
    figures = (
        f"{name}: gyro bias error x, y, z {np.round(error_deg_h, 2)} deg/h, "
        f"limit {limit_deg_h:g} deg/h (true bias {np.round(np.degrees(true_bias) * 3600, 1)})"
    )
    assert np.all(np.abs(error_deg_h) <= limit_deg_h), figures
    print(figures)


def test_monte_carlo_nees_of_attitude_and_velocity_is_chi_square():
    """Over independent seeds (sensor noise, biases and motion phases), the normalised
    attitude and velocity errors at fixed times are chi-square with 3 dof per run."""
    runs = [simulate("sea_state", duration_s=80.0, seed=seed) for seed in range(100, 108)]
    checkpoints = (30.0, 50.0, 70.0)
    low, high = chi_square_mean_bounds(3, len(runs))
    for checkpoint in checkpoints:
        nees_attitude, nees_velocity = [], []
        for _, solutions, truth in runs:
            stamps = np.array([s.t_s for s in solutions])
            index = int(np.argmin(np.abs(stamps - checkpoint)))
            nees_attitude.append(attitude_nees(solutions, truth)[index])
            nees_velocity.append(velocity_nees(solutions, truth)[index])
        assert low <= np.mean(nees_attitude) <= high, (checkpoint, nees_attitude)
        assert low <= np.mean(nees_velocity) <= high, (checkpoint, nees_velocity)


def test_nis_of_each_measurement_kind_is_chi_square():
    """Innovations of accepted updates, normalised by their predicted covariance, average to
    the measurement dimension (3 for fix, velocity and baseline, 1 for heading), with the
    baseline vector and with the heading alone."""
    with_baseline, _, _ = simulate("sea_state", duration_s=150.0, seed=3, record_innovations=True)
    heading_only, _, _ = simulate(
        "sea_state", duration_s=150.0, seed=3, record_innovations=True, baseline_until_s=0.0
    )
    for engine, kind, dof in (
        (with_baseline, "gnss_fix", 3),
        (with_baseline, "gnss_velocity", 3),
        (with_baseline, "gnss_baseline", 3),
        (heading_only, "gnss_fix", 3),
        (heading_only, "gnss_velocity", 3),
        (heading_only, "gnss_heading", 1),
    ):
        nis = np.array([r.nis for r in engine.innovation_log if r.kind == kind and r.accepted])
        assert nis.size > 1000, kind
        low, high = chi_square_mean_bounds(dof, nis.size)
        assert low <= nis.mean() <= high, (kind, nis.mean(), low, high)
        assert engine.health().counters[kind].mean_nis == pytest.approx(nis.mean())


def test_three_antennas_observe_roll_at_rest():
    """Paper 001: at rest, two antennas along body x leave roll to the accelerometer, where a
    y bias looks like a tilt; a third antenna off that line observes it. On the static buoy
    the roll error stays within 0.05° from 60 s after the alignment, with the filter's own
    roll σ below 0.03°, where the dual-antenna filter keeps σ above 0.05°."""
    tertiary = (0.0, 0.75, 1.0)
    _, dual, _ = simulate("static", duration_s=120.0)
    _, triple, truth = simulate("static", duration_s=120.0, tertiary_antenna_body_m=tertiary)
    stamps = np.array([s.t_s for s in triple])
    converged = stamps >= stamps[0] + 60.0
    roll_error = euler_errors_deg(triple, truth)[converged, 0]
    assert np.abs(roll_error).max() <= 0.05
    # The static buoy's body x points along its heading; roll is about that axis.
    heading = Rotation.from_quat(triple[-1].attitude_xyzw).apply((1.0, 0.0, 0.0))
    roll_sigma_deg = np.degrees(
        np.sqrt([heading @ s.attitude_covariance_rad2 @ heading for s in (triple[-1], dual[-1])])
    )
    assert roll_sigma_deg[0] < 0.03 < 0.05 < roll_sigma_deg[1]
