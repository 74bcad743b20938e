"""Fusion engine: ordering, interpolation at stamps, input validation, gating, outages."""

import dataclasses
import math

import numpy as np
import pytest
from engine_scenario import (
    HEADING_VAR,
    LATITUDE,
    LATITUDE_DEG,
    LONGITUDE_DEG,
    POSITION_COV,
    VELOCITY_COV,
    RockingBuoy,
    attitude_errors_rad,
    deliver,
    engine_config,
    make_events,
    run,
    solution_matrix,
)

from buoy_nav import earth
from buoy_nav.aiding import GnssHeading
from buoy_nav.alignment import AlignmentState
from buoy_nav.config import ConfigError, FusionConfig
from buoy_nav.engine import MAX_MEASUREMENT_LEAD_S, FusionEngine
from buoy_nav.health import diagnostic_values, health_status


def test_exact_data_keeps_the_rocking_buoy_on_its_truth(rocking_run):
    buoy, _, engine, solutions = rocking_run
    health = engine.health()
    assert health.aligned and health.alignment_state is AlignmentState.ALIGNED
    assert health.alignment.t_s == pytest.approx(10.0, abs=0.011)
    assert solutions[0].t_s >= health.alignment.t_s
    errors = attitude_errors_rad(buoy, solutions)
    assert errors.max() < math.radians(0.01)
    last = solutions[-1]
    np.testing.assert_allclose(last.velocity_enu_mps, 0.0, atol=2e-3)
    np.testing.assert_allclose(last.position_map_m, 0.0, atol=5e-3)
    for kind in ("gnss_fix", "gnss_velocity", "gnss_heading"):
        counters = health.counters[kind]
        assert counters.rejected == {}
        assert counters.accepted + counters.used_for_alignment == 600
    assert health.counters["imu"].accepted == 6000
    # One solution per IMU sample after the alignment, bias-corrected body rate reported.
    assert len(solutions) == sum(1 for t in np.arange(0, 60, 0.01) if t >= health.alignment.t_s)
    np.testing.assert_allclose(
        last.angular_rate_nb_body_rad_s, buoy.body_rate(last.t_s)[0], atol=1e-3
    )


def test_measurements_between_imu_samples_are_applied_at_their_stamps():
    """GNSS stamps 3.7 ms after the IMU grid: the engine integrates to each stamp with
    interpolated samples; with exact data the result stays on the truth."""
    buoy = RockingBuoy(roll_deg=12.0, pitch_deg=7.0, yaw_swing_deg=6.0)
    engine, solutions = run(make_events(buoy, 40.0, gnss_offset_s=0.0037))
    assert attitude_errors_rad(buoy, solutions).max() < math.radians(0.01)
    np.testing.assert_allclose(solutions[-1].velocity_enu_mps, 0.0, atol=2e-3)
    assert engine.health().counters["gnss_heading"].rejected == {}


def test_out_of_order_arrival_within_the_delay_gives_the_in_order_result(rocking_run):
    _, events, _, solutions = rocking_run
    rng = np.random.default_rng(11)
    # GNSS messages arrive up to 0.25 s late (delay budget 0.3 s), shuffled among themselves.
    arrivals = [
        (e[0] + (rng.uniform(0.0, 0.25) if e[2] != "imu" else 0.0), rng.uniform(), e)
        for e in events
    ]
    arrivals.sort(key=lambda a: (a[0], a[1]))
    _, shuffled = run([a[2] for a in arrivals])
    np.testing.assert_array_equal(solution_matrix(shuffled), solution_matrix(solutions))


def test_solutions_do_not_depend_on_when_the_filter_catches_up(rocking_run):
    """A node publishes each solution, then calls catch_up; an offline run never calls it; a
    caller may read the state, which catches up too. All get the same solutions."""
    _, events, _, solutions = rocking_run
    for catch_up in (FusionEngine.catch_up, lambda engine: engine.nav_state):
        engine = FusionEngine(engine_config())
        caught_up = []
        for event in events:
            caught_up += deliver(engine, event)
            catch_up(engine)
        caught_up += engine.flush()
        np.testing.assert_array_equal(solution_matrix(caught_up), solution_matrix(solutions))


def test_measurements_later_than_the_delay_are_rejected_as_too_late(rocking_run):
    _, events, _, _ = rocking_run
    late = [e for e in events if e[2] != "heading"]
    engine = FusionEngine(engine_config())
    for event in late:
        deliver(engine, event)
    engine.add_measurement(20.0, GnssHeading(0.5, HEADING_VAR))  # 40 s after its stamp
    assert engine.health().counters["gnss_heading"].rejected == {"too_late": 1}


def test_malformed_input_is_rejected_counted_and_never_reaches_the_state(rocking_run):
    _, events, _, solutions = rocking_run
    bad_inputs = [
        ("imu", (30.005, (math.nan, 0, 0), (0, 0, 9.8)), "non_finite"),
        ("imu", (30.006, (0, 0, 0), (0, math.inf, 9.8)), "non_finite"),
        ("imu", (30.007, (40.0, 0, 0), (0, 0, 9.8)), "out_of_range"),
        ("imu", (30.008, (0, 0, 0), (0, 0, 170.0)), "out_of_range"),
        ("imu", (30.009, (0, 0), (0, 0, 9.8)), "malformed"),
        ("imu", (29.5, (0, 0, 0), (0, 0, 9.8)), "stamp_not_increasing"),
        ("imu", (30.0, (0, 0, 0), (0, 0, 9.8)), "duplicate_stamp"),
        ("fix", (30.05, math.nan, 117.7, 0.0, POSITION_COV), "non_finite"),
        ("fix", (30.05, 38.9, 117.7, 0.0, np.diag((0.0, 4e-4, 4e-4))), "non_positive_variance"),
        ("fix", (30.05, 95.0, 117.7, 0.0, POSITION_COV), "out_of_range"),
        ("fix", (30.05, 38.9, 117.7, 0.0, np.eye(2)), "malformed"),
        ("vel", (30.05, (0, math.nan, 0), VELOCITY_COV), "non_finite"),
        ("vel", (30.05, (0, 0, 0), -VELOCITY_COV), "non_positive_variance"),
        ("vel", (30.05, (500.0, 0, 0), VELOCITY_COV), "out_of_range"),
        ("heading", (30.05, math.inf, HEADING_VAR), "non_finite"),
        ("heading", (30.05, 0.3, 0.0), "non_positive_variance"),
        ("heading", (30.05, "north", HEADING_VAR), "malformed"),
    ]
    engine = FusionEngine(engine_config())
    polluted = []
    injected = False
    for event in events:
        polluted += deliver(engine, event)
        if event[2] == "imu" and event[0] >= 30.0 and not injected:
            injected = True
            for kind, args, _ in bad_inputs:
                polluted += deliver(engine, (args[0], 0, kind, args[1:]))
    polluted += engine.flush()
    np.testing.assert_array_equal(solution_matrix(polluted), solution_matrix(solutions))
    counters = engine.health().counters
    expected: dict[str, dict[str, int]] = {}
    for kind, _, reason in bad_inputs:
        name = {"imu": "imu", "fix": "gnss_fix", "vel": "gnss_velocity"}.get(kind, "gnss_heading")
        expected.setdefault(name, {}).setdefault(reason, 0)
        expected[name][reason] += 1
    for name, reasons in expected.items():
        assert counters[name].rejected == reasons


def test_duplicate_measurement_stamp_is_rejected():
    buoy = RockingBuoy()
    events = make_events(buoy, 12.0)
    engine = FusionEngine(engine_config())
    for event in events:
        deliver(engine, event)
        if event[2] == "heading" and event[0] == pytest.approx(11.9):
            deliver(engine, event)
    assert engine.health().counters["gnss_heading"].rejected == {"duplicate_stamp": 1}


def test_gate_rejects_an_outlier_exactly_as_if_it_were_absent(rocking_run):
    _, events, _, _ = rocking_run
    outlier_time = 40.0
    without = [e for e in events if not (e[2] == "fix" and abs(e[0] - outlier_time) < 1e-9)]
    _, clean = run(without)
    polluted_events = []
    for e in events:
        if e[2] == "fix" and abs(e[0] - outlier_time) < 1e-9:
            lat, lon, alt, cov = e[3]
            e = (e[0], e[1], "fix", (lat + 3e-4, lon, alt, cov))  # 33 m north
        polluted_events.append(e)
    engine, polluted = run(polluted_events)
    counters = engine.health().counters["gnss_fix"]
    assert counters.rejected == {"gate": 1}
    np.testing.assert_array_equal(solution_matrix(polluted), solution_matrix(clean))


def test_gnss_outage_coasts_and_recovers():
    buoy = RockingBuoy()
    events = [e for e in make_events(buoy, 60.0) if not (e[2] != "imu" and 30.0 <= e[0] < 40.0)]
    engine, solutions = run(events)
    by_time = {round(s.t_s, 2): s for s in solutions}
    assert not by_time[29.0].coasting_fix and not by_time[29.0].coasting_heading
    assert by_time[35.0].coasting_fix and by_time[35.0].coasting_heading
    assert by_time[35.0].coasting_velocity
    assert not by_time[45.0].coasting_fix and not by_time[45.0].coasting_heading
    errors = attitude_errors_rad(buoy, solutions)
    assert errors.max() < math.radians(0.02)
    assert engine.health().counters["gnss_fix"].rejected == {}


def test_diagnostics_say_the_set_the_counters_and_what_is_coasting(rocking_run):
    _, _, engine, _ = rocking_run
    health = engine.health()
    values = diagnostic_values(health)
    assert values["sensor_set"] == "a: dual-antenna GNSS"
    assert values["gnss_heading.accepted"] == health.counters["gnss_heading"].accepted
    assert values["gnss_fix.used_for_alignment"] > 0 and "imu.used_for_alignment" not in values
    assert values["processed_up_to_s"] == "59.990000"
    assert health_status(health, "imu/data_raw", 0, 5) == ("warn", "no imu/data_raw samples")
    assert health_status(health, "imu/data_raw", 100, 5) == (
        "ok",
        "aligned on a: dual-antenna GNSS, 5 solutions published",
    )
    coasting = dataclasses.replace(health, coasting_fix=True, coasting_heading=True)
    assert health_status(coasting, "imu/data_raw", 100, 5)[1].endswith(
        "coasting without GNSS fix, heading"
    )


def test_output_rate_decimates_solutions():
    buoy = RockingBuoy()
    _, solutions = run(make_events(buoy, 30.0), engine_config(output_rate_hz=10.0))
    stamps = np.array([s.t_s for s in solutions])
    np.testing.assert_allclose(np.diff(stamps), 0.1, atol=1e-9)
    assert len(stamps) == pytest.approx((30.0 - stamps[0]) * 10, abs=1)


def test_persistent_heading_offset_resets_the_yaw():
    """After gate_reset_count consecutive rejections the yaw is re-initialised from the
    measurement, and the (now consistent) headings are accepted again."""
    buoy = RockingBuoy()
    offset = math.radians(20.0)
    events = []
    for e in make_events(buoy, 40.0):
        if e[2] == "heading" and e[0] >= 20.0:
            e = (e[0], e[1], "heading", (e[3][0] + offset, e[3][1]))
        events.append(e)
    config = engine_config(gate_reset_count=10)
    engine, solutions = run(events, config)
    counters = engine.health().counters["gnss_heading"]
    assert counters.resets == 1
    assert counters.rejected["gate"] >= 10
    assert counters.accepted > 250
    last = solutions[-1]
    yaw_error = last.euler_rad[2] - buoy.euler(last.t_s)[0][0, 2]
    assert math.degrees(abs(yaw_error - offset)) < 0.5


def test_imu_gap_restarts_the_alignment():
    buoy = RockingBuoy()
    events = [e for e in make_events(buoy, 50.0) if not (e[2] == "imu" and 20.0 < e[0] < 21.0)]
    engine, solutions = run(events)
    health = engine.health()
    assert health.imu_gaps == 1
    assert health.alignments == 2
    stamps = np.array([s.t_s for s in solutions])
    assert not np.any((stamps > 20.0) & (stamps < 30.9))  # re-levelling after the gap
    assert attitude_errors_rad(buoy, solutions).max() < math.radians(0.02)


def test_an_imu_outage_keeps_only_the_last_seconds_of_measurements_and_realigns():
    buoy = RockingBuoy()
    events = [e for e in make_events(buoy, 90.0) if not (e[2] == "imu" and 20.0 < e[0] < 70.0)]
    engine, solutions = run(events)
    health = engine.health()
    assert health.imu_gaps == 1 and health.alignments == 2
    # Of the 10 Hz measurements stamped during the 50 s outage, those more than
    # MAX_MEASUREMENT_LEAD_S older than the newest were given up; the rest fed the realignment.
    outage_epochs = 499  # 20.1 s to 69.9 s
    lead_epochs = round(MAX_MEASUREMENT_LEAD_S * 10)
    for kind in ("gnss_fix", "gnss_velocity", "gnss_heading"):
        given_up = health.counters[kind].rejected.get("beyond_imu_data", 0)
        assert outage_epochs - lead_epochs - 1 <= given_up <= outage_epochs - lead_epochs + 1
    stamps = np.array([s.t_s for s in solutions])
    assert stamps.max() > 85.0
    assert attitude_errors_rad(buoy, solutions).max() < math.radians(0.02)


def test_flush_rejects_measurements_after_the_last_imu_sample():
    buoy = RockingBuoy()
    engine = FusionEngine(engine_config())
    for event in make_events(buoy, 15.0):
        deliver(engine, event)
    engine.add_measurement(16.0, GnssHeading(0.1, HEADING_VAR))
    engine.flush()
    assert engine.health().counters["gnss_heading"].rejected == {"beyond_imu_data": 1}


def test_configured_map_origin_is_used():
    buoy = RockingBuoy()
    config = engine_config(
        origin_latitude_deg=LATITUDE_DEG + 1e-4,
        origin_longitude_deg=LONGITUDE_DEG,
        origin_altitude_m=-2.0,
    )
    _, solutions = run(make_events(buoy, 15.0), config)
    meridian, _ = earth.radii_of_curvature_m(LATITUDE)
    north = -math.radians(1e-4) * meridian
    np.testing.assert_allclose(solutions[-1].position_map_m, (0.0, north, 2.0), atol=0.01)


def test_config_validation_names_the_field():
    with pytest.raises(ConfigError, match="gyro_noise_deg_sqrt_h"):
        FusionConfig(gyro_noise_deg_sqrt_h=-1.0)
    with pytest.raises(ConfigError, match="gate_probability"):
        FusionConfig(gate_probability=1.0)
    with pytest.raises(ConfigError, match=r"gnss\.secondary_antenna"):
        FusionConfig(primary_antenna_body_m=(0, 0, 1), secondary_antenna_body_m=(0.01, 0, 1))
    with pytest.raises(ConfigError, match=r"origin\."):
        FusionConfig(origin_latitude_deg=10.0)
    with pytest.raises(ConfigError, match="primary_antenna_body_m"):
        FusionConfig(primary_antenna_body_m=(0, 1))
    with pytest.raises(ConfigError, match="record_innovations"):
        FusionConfig(record_innovations="yes")
    with pytest.raises(ConfigError, match="gate_reset_count"):
        FusionConfig(gate_reset_count=2.5)
    with pytest.raises(ConfigError, match="max_imu_gap_s"):
        FusionConfig(max_imu_gap_s=math.nan)
    config = FusionConfig(
        primary_antenna_body_m=[0, -0.5, 1], output_rate_hz=5, gate_reset_count=20.0
    )
    assert config.primary_antenna_body_m == (0.0, -0.5, 1.0)
    assert config.output_rate_hz == 5.0 and isinstance(config.output_rate_hz, float)
    assert config.gate_reset_count == 20 and isinstance(config.gate_reset_count, int)
    assert config.baseline_body_m == (0.75, 0.5, 0.0)
    assert not config.has_origin


def test_innovation_log_records_every_gated_measurement():
    buoy = RockingBuoy()
    engine, _ = run(make_events(buoy, 20.0), engine_config(record_innovations=True))
    log = engine.innovation_log
    counters = engine.health().counters
    assert len(log) == sum(
        counters[k].accepted for k in ("gnss_fix", "gnss_velocity", "gnss_heading")
    )
    assert {record.kind for record in log} == {"gnss_fix", "gnss_velocity", "gnss_heading"}
    assert FusionEngine(engine_config()).innovation_log is None


# -- a source the engine does not know -------------------------------------------------------
