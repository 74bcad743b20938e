"""Fusion engine: ordering, interpolation at stamps, input validation, gating, outages."""

import math
from dataclasses import dataclass
from types import SimpleNamespace

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from buoy_common.contract import Reason
from buoy_nav import earth
from buoy_nav.aiding import AIDING_SOURCES, GnssFix, GnssHeading, GnssVelocity
from buoy_nav.aiding.base import FIX, AidingSource, MeasurementModel, as_floats
from buoy_nav.alignment import AlignmentState
from buoy_nav.config import ConfigError, FusionConfig
from buoy_nav.engine import MAX_MEASUREMENT_LEAD_S, FusionEngine
from buoy_nav.fusion_messages import feed_message
from buoy_nav.smoothed_solutions import FixedIntervalSmoother
from buoy_nav.state_layout import UP

LATITUDE_DEG, LONGITUDE_DEG, ALTITUDE_M = 38.9, 117.7, 0.0
LATITUDE = math.radians(LATITUDE_DEG)
GRAVITY = earth.normal_gravity_mps2(LATITUDE, ALTITUDE_M)
EARTH_RATE = earth.earth_rate_enu_rad_s(LATITUDE)
PRIMARY = np.array((0.2, -0.5, 1.1))
SECONDARY = np.array((-1.1, 0.4, 0.8))
POSITION_COV = np.diag((4e-4, 4e-4, 16e-4))
VELOCITY_COV = np.diag((4e-4, 4e-4, 16e-4))
HEADING_VAR = (0.003 / 1.6) ** 2


class RockingBuoy:
    """A buoy rocking about its IMU at a fixed position, with exact sensor data.

    Euler angles (ZYX) are sums of sinusoids; the body rate comes from their analytic rates.
    """

    def __init__(self, roll_deg=8.0, pitch_deg=5.0, yaw_deg=30.0, yaw_swing_deg=3.0):
        self.amplitudes = np.radians((roll_deg, pitch_deg, yaw_swing_deg))
        self.yaw0 = math.radians(yaw_deg)
        self.omegas = 2 * math.pi / np.array((9.0, 6.0, 11.0))
        self.phases = np.array((0.0, 1.0, 2.0))

    def euler(self, t):
        t = np.atleast_1d(t)[:, None]
        angles = self.amplitudes * np.sin(self.omegas * t + self.phases)
        angles[:, 2] += self.yaw0
        rates = self.amplitudes * self.omegas * np.cos(self.omegas * t + self.phases)
        return angles, rates

    def rotation(self, t):
        angles, _ = self.euler(t)
        return Rotation.from_euler("ZYX", angles[:, ::-1])

    def body_rate(self, t):
        angles, rates = self.euler(t)
        roll, pitch = angles[:, 0], angles[:, 1]
        droll, dpitch, dyaw = rates.T
        return np.column_stack(
            (
                droll - dyaw * np.sin(pitch),
                dpitch * np.cos(roll) + dyaw * np.sin(roll) * np.cos(pitch),
                -dpitch * np.sin(roll) + dyaw * np.cos(roll) * np.cos(pitch),
            )
        )

    def imu(self, t):
        rotation = self.rotation(t)
        gyro = self.body_rate(t) + rotation.inv().apply(EARTH_RATE)
        force = rotation.inv().apply(np.array((0.0, 0.0, GRAVITY)))
        return gyro, force

    def gnss(self, t):
        """Per stamp: antenna fix (deg, deg, m), antenna velocity ENU, baseline azimuth."""
        rotation = self.rotation(t)
        lever = rotation.apply(PRIMARY)
        plane = earth.LocalTangentPlane(LATITUDE, math.radians(LONGITUDE_DEG), ALTITUDE_M)
        lat, lon, alt = plane.geodetic_from_enu(lever)
        velocity = rotation.apply(np.cross(self.body_rate(t), PRIMARY))
        baseline = rotation.apply(SECONDARY - PRIMARY)
        heading = np.arctan2(baseline[:, 1], baseline[:, 0])
        return np.degrees(lat), np.degrees(lon), alt, velocity, heading


def make_events(buoy, duration, imu_rate=100.0, gnss_rate=10.0, gnss_offset_s=0.0):
    """Events (t, arrival order key, kind, args) of a run, in stamp order."""
    t_imu = np.arange(0.0, duration, 1.0 / imu_rate)
    t_gnss = np.arange(gnss_offset_s, duration, 1.0 / gnss_rate)
    gyro, force = buoy.imu(t_imu)
    lat, lon, alt, velocity, heading = buoy.gnss(t_gnss)
    events = [(t, 1, "imu", (gyro[k], force[k])) for k, t in enumerate(t_imu)]
    for k, t in enumerate(t_gnss):
        events.append((t, 0, "fix", (lat[k], lon[k], alt[k], POSITION_COV)))
        events.append((t, 0, "vel", (velocity[k], VELOCITY_COV)))
        events.append((t, 0, "heading", (heading[k], HEADING_VAR)))
    events.sort(key=lambda e: (e[0], e[1]))
    return events


MEASUREMENT_TYPES = {"fix": GnssFix, "vel": GnssVelocity, "heading": GnssHeading}


def deliver(engine, event):
    t, _, kind, args = event
    if kind == "imu":
        return engine.add_imu(t, *args)
    engine.add_measurement(t, MEASUREMENT_TYPES[kind](*args))
    return []


def run(events, config=None):
    engine = FusionEngine(config or engine_config())
    solutions = []
    for event in events:
        solutions += deliver(engine, event)
    solutions += engine.flush()
    return engine, solutions


def engine_config(**overrides):
    values = dict(primary_antenna_body_m=tuple(PRIMARY), secondary_antenna_body_m=tuple(SECONDARY))
    values.update(overrides)
    return FusionConfig(**values)


def attitude_errors_rad(buoy, solutions):
    t = np.array([s.t_s for s in solutions])
    estimate = Rotation.from_quat(np.array([s.attitude_xyzw for s in solutions]))
    return np.linalg.norm((buoy.rotation(t) * estimate.inv()).as_rotvec(), axis=1)


def solution_matrix(solutions):
    """Every number of every solution, for exact comparisons of whole runs."""
    rows = []
    for s in solutions:
        rows.append(
            np.concatenate(
                (
                    [s.t_s, s.latitude_deg, s.longitude_deg, s.altitude_m],
                    s.attitude_xyzw,
                    s.velocity_enu_mps,
                    s.position_map_m,
                    s.gyro_bias_rad_s,
                    s.accel_bias_mps2,
                    s.attitude_covariance_rad2.ravel(),
                    s.velocity_covariance_m2s2.ravel(),
                    s.position_covariance_m2.ravel(),
                    [s.coasting_fix, s.coasting_velocity, s.coasting_heading],
                )
            )
        )
    return np.array(rows)


@pytest.fixture(scope="module")
def rocking_run():
    buoy = RockingBuoy()
    events = make_events(buoy, 60.0)
    engine, solutions = run(events)
    return buoy, events, engine, solutions


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


@dataclass(frozen=True)
class Altitude:
    """A measurement the suite has no source for: the altitude of base_link (m) and its
    variance (m²), as a pressure sensor or a radar gauge could give."""

    altitude_m: float
    variance_m2: float


class AltitudeSource(AidingSource):
    """A whole aiding source defined outside the package: message, validation, model."""

    kind = "altitude"
    topic = "test/altitude"
    measurement_type = Altitude
    aids = FIX

    def measurement_from_message(self, message):
        return Altitude(message.altitude, message.variance)

    def validated(self, measurement):
        values = as_floats(measurement.altitude_m, measurement.variance_m2)
        if isinstance(values, Reason):
            return values
        return Altitude(*values) if values[1] > 0.0 else Reason.NON_POSITIVE_VARIANCE

    def model(self, measurement, point):
        jacobian = np.zeros((1, self.states.dim))
        jacobian[0, self.states.index("position", UP)] = 1.0
        predicted = np.array((point.state.altitude_m,))
        return MeasurementModel(
            predicted=predicted,
            innovation=np.array((measurement.altitude_m,)) - predicted,
            jacobian=jacobian,
            covariance=np.array(((measurement.variance_m2,),)),
        )

    def align(self, aligner, t_s, measurement, raw_gyro_rad_s):
        return None


def test_a_source_registered_from_outside_runs_end_to_end():
    """The altitude source joins the fusion by registration alone: its messages are converted
    and validated by it, its model pulls the altitude off the (vertically vague) fixes."""
    offset_m = 0.3
    buoy = RockingBuoy()
    vague_vertical = np.diag((4e-4, 4e-4, 100.0))
    engine = FusionEngine(
        engine_config(record_innovations=True), sources=(*AIDING_SOURCES, AltitudeSource)
    )
    solutions = []
    for event in make_events(buoy, 40.0):
        t, _, kind, args = event
        if kind == "fix":
            event = (t, 0, kind, (*args[:3], vague_vertical))
        solutions += deliver(engine, event)
        if kind == "heading":
            message = SimpleNamespace(
                header=SimpleNamespace(
                    stamp=SimpleNamespace(sec=int(t), nanosec=round(t % 1 * 1e9))
                ),
                altitude=offset_m,
                variance=1e-4,
            )
            assert feed_message(engine, "test/altitude", message) == ([], None)
    bad = SimpleNamespace(header=message.header, altitude=0.0, variance=-1.0)
    assert feed_message(engine, "test/altitude", bad) == ([], Reason.NON_POSITIVE_VARIANCE)
    solutions += engine.flush()

    counters = engine.health().counters["altitude"]
    assert counters.used_for_alignment > 0
    assert counters.accepted + counters.used_for_alignment == 400
    assert counters.rejected == {"non_positive_variance": 1}
    assert "altitude" in {record.kind for record in engine.innovation_log}
    # Map origin: base_link at alignment, on the fix (truth altitude 0).
    assert solutions[-1].position_map_m[2] == pytest.approx(offset_m, abs=0.02)
    # The GNSS sources still do their work.
    assert attitude_errors_rad(buoy, solutions).max() < math.radians(0.02)

    # Unregistered, the same source's input is a programming error.
    plain = FusionEngine(engine_config())
    with pytest.raises(ValueError, match="input topic"):
        feed_message(plain, "test/altitude", message)
    with pytest.raises(TypeError, match="Altitude"):
        plain.add_measurement(1.0, Altitude(0.0, 1.0))


@pytest.mark.parametrize("step_s", [-5.0, 5.0])
def test_a_step_of_the_imu_clock_is_undone(step_s):
    """IMU stamps stepping back or ahead (the samples arriving as before, with the GNSS's in
    between) are put back on the GNSS clock: the run is the one without the step, but for the
    rounding of the re-stamped stamps (measurements then fall a few ulps off an IMU stamp, and
    the integration steps are split there) and, for a step back, the first sample after it:
    one stale sample is not a step, so it is rejected, and its successor confirms the step."""
    buoy = RockingBuoy()
    events = make_events(buoy, 50.0)
    stepped = [
        (e[0] + step_s, *e[1:]) if e[2] == "imu" and e[0] >= 30.0 - 1e-9 else e for e in events
    ]
    engine, solutions = run(stepped)
    _, reference = run(events)
    health = engine.health()
    assert len(health.imu_clock_steps) == 1
    stamp_s, measured_step_s = health.imu_clock_steps[0]
    lost = 1 if step_s < 0 else 0
    assert stamp_s == pytest.approx(30.0 + 0.01 * lost, abs=1e-9)
    assert measured_step_s == pytest.approx(step_s, abs=1e-9)
    assert health.counters["imu"].rejected == ({"stamp_not_increasing": 1} if lost else {})
    assert health.imu_gaps == 0 and health.alignments == 1
    if lost:
        reference = [s for s in reference if abs(s.t_s - 30.0) > 1e-6]
    assert len(solutions) == len(reference)
    stamps, reference_stamps = (np.array([s.t_s for s in run]) for run in (solutions, reference))
    np.testing.assert_allclose(stamps, reference_stamps, rtol=0.0, atol=1e-9)
    attitudes, reference_attitudes = (
        Rotation.from_quat(np.array([s.attitude_xyzw for s in run]))
        for run in (solutions, reference)
    )
    assert (attitudes * reference_attitudes.inv()).magnitude().max() < 1e-4  # rad
    velocity_difference = np.array(
        [s.velocity_enu_mps - r.velocity_enu_mps for s, r in zip(solutions, reference, strict=True)]
    )
    assert np.abs(velocity_difference).max() < 1e-4
    assert attitude_errors_rad(buoy, solutions).max() < math.radians(0.02)


def test_an_imu_outage_is_not_taken_for_a_clock_step():
    buoy = RockingBuoy()
    events = [e for e in make_events(buoy, 40.0) if not (e[2] == "imu" and 20.0 < e[0] < 21.0)]
    engine, _ = run(events)
    health = engine.health()
    assert health.imu_clock_steps == ()
    assert health.imu_gaps == 1


def test_an_imu_spike_inside_the_magnitude_limits_is_rejected_and_leaves_no_trace(rocking_run):
    """Five gyro samples of 30 rad/s and one accelerometer sample of 100 m/s² (inside the
    magnitude limits) change no solution beyond what losing those samples does."""
    buoy, events, _, reference = rocking_run
    spiked = []
    for event in events:
        t, order, kind, args = event
        if kind == "imu" and 30.0 - 1e-9 <= t < 30.05 - 1e-9:
            args = (np.array([30.0, 0.0, 0.0]), args[1])
        elif kind == "imu" and 40.0 - 1e-9 <= t < 40.01 - 1e-9:
            args = (args[0], np.array([0.0, 0.0, 100.0]))
        spiked.append((t, order, kind, args))
    engine, solutions = run(spiked)
    assert engine.health().counters["imu"].rejected == {"implausible_change": 6}
    assert len(solutions) == len(reference) - 6
    assert attitude_errors_rad(buoy, solutions).max() < math.radians(0.02)
    assert engine.health().trusted


def gyro_fault_events(buoy):
    """70 s of the rocking buoy with a gyro offset of 0.3 rad/s from 30 to 31 s."""
    events = []
    for t, order, kind, args in make_events(buoy, 70.0):
        if kind == "imu" and 30.0 - 1e-9 <= t < 31.0 - 1e-9:
            args = (args[0] + np.array([0.3, 0.0, 0.0]), args[1])
        events.append((t, order, kind, args))
    return events


def test_a_filter_at_odds_with_its_aiding_says_so_and_realigns():
    """A gyro offset of 0.3 rad/s for 1 s (each sample within the platform's limits) turns the
    attitude 17° away: the gates reject the GNSS, the navigation is declared not trusted, its
    attitude covariance grows past 1° at once, and a realignment brings the attitude back."""
    buoy = RockingBuoy()
    engine, solutions = run(gyro_fault_events(buoy))
    health = engine.health()
    assert health.counters["imu"].rejected == {}
    assert len(health.integrity_events) >= 1
    event = health.integrity_events[0]
    assert 30.0 < event.start_s < 31.5
    assert event.reason.startswith("gate_rejections:")
    stamps = np.array([s.t_s for s in solutions])
    errors = attitude_errors_rad(buoy, solutions)
    sigma = np.sqrt([s.attitude_covariance_rad2.diagonal().max() for s in solutions])
    # Every solution whose attitude is off by more than 1° says so by its covariance, except
    # those emitted before the gates could see the error (processing lags by the measurement
    # delay, and the trust ends at the third rejection).
    detected_by_s = event.start_s + engine.config.max_measurement_delay_s + 0.01
    wrong = (errors > math.radians(1.0)) & (stamps > detected_by_s)
    assert np.all(sigma[wrong] > math.radians(1.0))
    assert health.trusted
    assert errors[stamps > 65.0].max() < math.radians(0.1)


def test_the_smoother_is_told_of_the_integrity_monitors_inflation_and_realignment():
    """The gyro fault smoothed: the inflation is process noise to the smoother, so the
    corrections that pull the state back after it do not reach back to the sound stretch
    before the fault; the smoothed solutions of the period of distrust keep the inflated
    covariance (the wind refuses them alike); after the realignment the smoothed attitude is
    on its truth."""
    buoy = RockingBuoy()
    engine = FusionEngine(engine_config(realtime_output=False))
    with FixedIntervalSmoother(engine) as smoother:
        for event in gyro_fault_events(buoy):
            for solution in deliver(engine, event):
                smoother.add(solution, 0, 0, 0)
        for solution in engine.flush():
            smoother.add(solution, 0, 0, 0)
        pairs = list(smoother.smoothed())
    event = engine.health().integrity_events[0]
    forward = [pair.forward for pair in pairs]
    smoothed = [pair.smoothed for pair in pairs]
    stamps = np.array([s.t_s for s in smoothed])
    errors = attitude_errors_rad(buoy, smoothed)
    assert errors[(stamps > 10.0) & (stamps < 30.0)].max() < math.radians(0.1)
    assert errors[stamps > 65.0].max() < math.radians(0.1)
    distrusted = (stamps >= event.start_s) & (stamps < event.end_s)
    assert distrusted.any()
    for forward_solution, smoothed_solution in zip(
        np.array(forward)[distrusted], np.array(smoothed)[distrusted], strict=True
    ):
        forward_sigma = np.sqrt(forward_solution.attitude_covariance_rad2.diagonal())
        smoothed_sigma = np.sqrt(smoothed_solution.attitude_covariance_rad2.diagonal())
        assert np.all(smoothed_sigma > math.radians(engine.config.integrity_attitude_sigma_deg))
        assert np.all(forward_sigma > math.radians(engine.config.integrity_attitude_sigma_deg))
