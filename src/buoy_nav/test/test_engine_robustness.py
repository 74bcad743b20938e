"""Fusion engine: a source registered from outside, steps of the IMU clock, IMU spikes and outages,
the integrity monitor and what the smoother is told of it."""

import math
from dataclasses import dataclass
from types import SimpleNamespace

import numpy as np
import pytest
from engine_scenario import (
    RockingBuoy,
    attitude_errors_rad,
    deliver,
    engine_config,
    make_events,
    run,
)
from scipy.spatial.transform import Rotation

from buoy_common.contract import Reason
from buoy_nav.aiding import AIDING_SOURCES
from buoy_nav.aiding.base import FIX, AidingSource, MeasurementModel, as_floats
from buoy_nav.engine import FusionEngine
from buoy_nav.fusion_messages import feed_message
from buoy_nav.smoothed_solutions import FixedIntervalSmoother
from buoy_nav.state_layout import UP


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
    the integration steps are split there): the samples after the step are held until they have
    spanned a while with none of the old sequence in between (they are not a second IMU's stream),
    then released, none lost."""
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
    assert stamp_s == pytest.approx(30.0, abs=1e-9)
    assert measured_step_s == pytest.approx(step_s, abs=1e-9)
    assert health.counters["imu"].rejected == {}
    assert health.imu_gaps == 0 and health.alignments == 1
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


@pytest.mark.parametrize("offset_s", [-5.0, 0.3, 40.0])
def test_a_second_imu_stream_never_moves_the_filter(offset_s):
    """Another buoy's IMU samples (rocking otherwise, on its own clock ``offset_s`` off) each
    delivered just after one of the buoy's own, from 20 s to 30 s: every one is rejected, no
    step of the clock is taken, and the run is the one without them."""
    buoy, other = RockingBuoy(), RockingBuoy(roll_deg=3.0, yaw_deg=120.0)
    events = make_events(buoy, 40.0)
    other_events = {e[0]: e for e in make_events(other, 40.0) if e[2] == "imu"}
    interleaved = []
    for event in events:
        interleaved.append(event)
        if event[2] == "imu" and 20.0 <= event[0] < 30.0:
            _, order, kind, args = other_events[event[0]]
            interleaved.append((event[0] + offset_s, order, kind, args))
    engine, solutions = run(interleaved)
    _, reference = run(events)
    health = engine.health()
    reason = "stamp_not_increasing" if offset_s < 0 else "out_of_sequence"
    assert health.counters["imu"].rejected == {reason: 1000}
    assert health.imu_clock_steps == () and health.imu_gaps == 0 and health.alignments == 1
    samples, lead_s = engine.second_streams["imu"]
    assert samples == 1000
    assert lead_s == pytest.approx(offset_s, abs=0.011)
    assert [s.t_s for s in solutions] == [s.t_s for s in reference]
    assert [s.attitude_xyzw.tolist() for s in solutions] == [
        s.attitude_xyzw.tolist() for s in reference
    ]


def test_an_imu_outage_is_not_taken_for_a_clock_step():
    buoy = RockingBuoy()
    events = [e for e in make_events(buoy, 40.0) if not (e[2] == "imu" and 20.0 < e[0] < 21.0)]
    engine, _ = run(events)
    health = engine.health()
    assert health.imu_clock_steps == ()
    assert health.imu_gaps == 1


def test_a_stamp_off_the_imu_grid_before_an_outage_loses_no_sample_after_it():
    """A sample stamped 3 ms after the one before it (the IMU samples every 10 ms), then a 1 s
    outage: the IMU's interval stays 10 ms, the samples after the outage make its new sequence,
    and none is lost (taken for a 3 ms interval, they would not follow each other, and no new
    sequence would ever be confirmed)."""
    buoy = RockingBuoy()
    events = []
    for event in make_events(buoy, 40.0):
        t, order, kind, args = event
        if kind == "imu" and 20.0 - 1e-9 <= t < 21.0 - 1e-9:
            continue
        events.append(event)
        if kind == "imu" and abs(t - 19.99) < 1e-9:
            events.append((t + 0.003, order, kind, args))
    engine, solutions = run(events)
    health = engine.health()
    assert health.counters["imu"].accepted == sum(kind == "imu" for _, _, kind, _ in events)
    assert health.imu_gaps == 1 and health.imu_clock_steps == ()
    assert solutions[-1].t_s == pytest.approx(39.99)


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


@pytest.mark.parametrize("stamps_ahead", [3, 3.3])
def test_a_second_gnss_stream_ahead_never_reaches_the_filter(stamps_ahead):
    """Another buoy's GNSS (rocking otherwise: its heading 120° off) on its own clock
    ``stamps_ahead`` GNSS intervals ahead, each message delivered just after one of the buoy's
    own, from 20 s to 30 s: every one is rejected as out_of_sequence (on the buoy's grid when
    the buoy's own message of its stamp comes, off it at its turn), and the run is the one
    without them."""
    buoy, other = RockingBuoy(), RockingBuoy(roll_deg=3.0, yaw_deg=120.0)
    events = make_events(buoy, 40.0)
    gnss_stamps = sorted({e[0] for e in events if e[2] != "imu"})
    other_events = {(e[0], e[2]): e for e in make_events(other, 40.0) if e[2] != "imu"}
    interleaved = []
    for event in events:
        interleaved.append(event)
        if event[2] != "imu" and 20.0 <= event[0] < 30.0:
            _, order, kind, args = other_events[event[0], event[2]]
            index = gnss_stamps.index(event[0]) + int(stamps_ahead)
            # On the grid, its stamps are the buoy's own (integer nanoseconds in a message).
            stamp = gnss_stamps[index] + (stamps_ahead % 1) * 0.1
            interleaved.append((stamp, order, kind, args))
    engine, solutions = run(interleaved)
    _, reference = run(events)
    counters = engine.health().counters
    for kind in ("gnss_fix", "gnss_velocity", "gnss_heading"):
        assert counters[kind].rejected == {"out_of_sequence": 100}, kind
    assert len(engine.take_out_of_sequence()) == 300
    assert [s.t_s for s in solutions] == [s.t_s for s in reference]
    assert [s.attitude_xyzw.tolist() for s in solutions] == [
        s.attitude_xyzw.tolist() for s in reference
    ]
