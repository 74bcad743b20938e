"""Stretches of IMU samples in one compiled call against one input at a time, on the simulator.

An offline run hands the engine the IMU messages between two other sensor messages together,
with the motion pack's attitudes and the GNSS measurements among them
(:meth:`FusionEngine.add_inputs`): they are screened one by one, then each stretch with nothing
else to do goes through :mod:`buoy_nav.imu_stretch`, its epochs made there, and the engine
takes the inputs that need it. Fed the same messages
one at a time (:meth:`FusionEngine.add_imu`, :func:`feed_message`, as a live node feeds them),
the engine must give the same rows, stamps, counters, source health, innovations, state and
covariance to the bit: on a clean sea state, its GNSS messages in another order than the
engine stacks them in and for a while stamped between two IMU samples, and through a GNSS
outage (the covariance then propagated in batches between the IMU samples); on IMU samples
with a spike, non-finite values, a repeated stamp, a second stream, a gap that restarts the
alignment and a step of the IMU's clock; on a GNSS velocity biased enough that the filter is
distrusted, realigned and the velocity suspended; with the solutions decimated to 10 Hz and the
IMU's calibration applied; and on a moored motion pack whose attitudes come with faults (refused
quaternions, a stamp out of order, a non-finite covariance, attitudes the gate rejects, an
outage), alone and with a magnetometer.
"""

from __future__ import annotations

import copy
import dataclasses
import math
from collections import Counter

import numpy as np
import pytest
from gnss_faults import biased_velocity
from scipy.spatial.transform import Rotation
from test_nav_sensor_sets import (
    MAGNETOMETER,
    calibrated_magnetometer,
    moored_config,
    scenario_messages,
)

from buoy_common.contract import (
    AHRS_TOPIC,
    GNSS_BASELINE_TOPIC,
    GNSS_FIX_TOPIC,
    GNSS_VELOCITY_TOPIC,
    IMU_RAW_TOPIC,
    MAGNETOMETER_TOPIC,
    Reason,
    header_seconds,
)
from buoy_nav import imu_stretch as stretch_module
from buoy_nav import imu_stretches
from buoy_nav.aiding.ahrs_attitude import attitude_stretch_model
from buoy_nav.aiding.base import vector_of
from buoy_nav.aiding.magnetometer import magnetometer_stretch_model
from buoy_nav.aiding_epoch import (
    APPLIED,
    BOOK_ROW,
    BOOK_STATUS,
    MODELS,
    ROW_SLOT,
    TERM_MODEL,
    WATCHED,
)
from buoy_nav.config import FusionConfig
from buoy_nav.engine import FusionEngine
from buoy_nav.fusion_messages import FUSION_INPUT_MSGTYPES, feed_message
from buoy_nav.imu_stretches import MeasurementInput
from buoy_nav.innovation_watch import SCALE
from buoy_nav.mean_velocity_watch import BLOCK_START
from buoy_nav.prediction import RealtimePrediction
from buoy_nav.solution_rows import SolutionRows

IMU = "imu"
APPLIED_GNSS_TOPICS = (GNSS_FIX_TOPIC, GNSS_VELOCITY_TOPIC, GNSS_BASELINE_TOPIC)


def fusion_inputs(messages) -> list[tuple]:
    """The fusion's inputs of ``messages`` in order: ``(IMU, (stamp s, gyro, force))`` for an
    IMU sample, ``(topic, message)`` for the others."""
    inputs = []
    for topic, _, message in messages:
        if topic == IMU_RAW_TOPIC:
            sample = (
                header_seconds(message.header),
                vector_of(message.angular_velocity),
                vector_of(message.linear_acceleration),
            )
            inputs.append((IMU, sample))
        elif topic in FUSION_INPUT_MSGTYPES:
            inputs.append((topic, message))
    return inputs


def with_imu_faults(inputs: list[tuple]) -> list[tuple]:
    """``inputs`` with, among the IMU samples after the first minute: a 5 rad/s spike, a
    non-finite force, a rate of two numbers and one of None, a repeated sample, three samples
    of a second stream 0.25 s ahead, a sample 4 ms after another (the screening learns a
    shorter interval), a force beyond the sensor's range, a sample 3 ms after another and
    then 0.8 s of samples lost (a gap beyond ``max_imu_gap_s``), and from 100 s on the IMU's
    clock 3 s behind."""
    faulty, imu_count, first_s = [], 0, None
    for kind, item in inputs:
        if kind != IMU:
            faulty.append((kind, item))
            continue
        t, gyro, force = item
        first_s = t if first_s is None else first_s
        elapsed = t - first_s
        imu_count += 1
        if 80.0 <= elapsed < 80.8:
            continue
        if elapsed >= 100.0:
            t -= 3.0
        if imu_count == 7200:
            force = (1000.0, force[1], force[2])
        faulty.append((IMU, (t, gyro, force)))
        if imu_count == 6000:
            faulty.append((IMU, (t + 0.01, (gyro[0] + 5.0, gyro[1], gyro[2]), force)))
        elif imu_count == 6500:
            faulty.append((IMU, (t + 0.01, gyro, (math.nan, force[1], force[2]))))
        elif imu_count == 6800:
            faulty.append((IMU, (t + 0.005, gyro[:2], force)))
        elif imu_count == 6900:
            faulty.append((IMU, (t + 0.005, (None, gyro[1], gyro[2]), force)))
        elif imu_count == 7000:
            faulty.append((IMU, (t, gyro, force)))
        elif imu_count in (7500, 7501, 7502):
            faulty.append((IMU, (t + 0.25, gyro, force)))
        elif imu_count == 7700:
            faulty.append((IMU, (t + 0.004, gyro, force)))
        elif imu_count == 8000:  # the last before the samples lost
            faulty.append((IMU, (t + 0.003, gyro, force)))
    return faulty


def without_gnss_between(inputs: list[tuple], from_s: float, to_s: float) -> list[tuple]:
    """``inputs`` without the aiding measurements of [``from_s``, ``to_s``) after the first IMU
    sample (an outage: the covariance is then propagated in batches between IMU samples)."""
    first_s = next(item[0] for kind, item in inputs if kind == IMU)
    kept, now_s = [], first_s
    for kind, item in inputs:
        if kind == IMU:
            now_s = item[0]
        elif from_s <= now_s - first_s < to_s:
            continue
        kept.append((kind, item))
    return kept


def with_gnss_reordered(inputs: list[tuple], from_s: float, to_s: float) -> list[tuple]:
    """``inputs`` with the measurements between two IMU samples in the reverse order (the
    baseline first, the fix last: not the order the engine stacks them in), and those of
    [``from_s``, ``to_s``) after the first IMU sample stamped 3 ms later (between two IMU
    samples: the engine applies them there)."""
    first_s = next(item[0] for kind, item in inputs if kind == IMU)
    reordered, between = [], []
    for kind, item in [*inputs, (IMU, None)]:
        if kind != IMU:
            message = item
            if from_s <= header_seconds(item.header) - first_s < to_s:
                message = copy.deepcopy(item)
                stamp = message.header.stamp
                stamp_ns = stamp.sec * 10**9 + stamp.nanosec + 3 * 10**6
                stamp.sec, stamp.nanosec = divmod(stamp_ns, 10**9)
            between.append((kind, message))
            continue
        reordered += between[::-1]
        between = []
        if item is not None:
            reordered.append((kind, item))
    return reordered


def one_at_a_time(config: FusionConfig, inputs: list[tuple]):
    """The engine fed each input alone: (engine, its rows, each IMU sample's stamps)."""
    rows = SolutionRows()
    engine = FusionEngine(config, solution_rows=rows)
    stamps = []
    for kind, item in inputs:
        if kind == IMU:
            stamps.append((engine.add_imu(*item), engine.last_input_rejection))
            engine.catch_up()
        else:
            feed_message(engine, kind, item)
    engine.flush()
    return engine, rows.take(rows.count), stamps


def in_stretches(config: FusionConfig, inputs: list[tuple]):
    """The engine fed the IMU samples between two other inputs together, with the motion
    pack's attitudes among them, but for the first IMU sample of each run, fed alone and its
    filtering left for the run's call to catch up."""
    rows = SolutionRows()
    engine = FusionEngine(config, solution_rows=rows)
    run_topics = {source.topic for source in engine.stretched_sources}
    stamps, waiting = [], []
    for kind, item in [*inputs, (None, None)]:
        if kind == IMU:
            waiting.append(item)
            continue
        if kind in run_topics:
            source = engine.source_of_topic(kind)
            measurement = source.measurement_from_message(item)
            waiting.append(MeasurementInput(source, header_seconds(item.header), measurement))
            continue
        if waiting:
            first, rest = waiting[0], waiting[1:]
            if type(first) is MeasurementInput:
                first, rest = None, waiting
            else:
                stamps.append((engine.add_imu(*first), engine.last_input_rejection))
            outcomes = engine.add_inputs(rest)
            stamps += [out for out, i in zip(outcomes, rest, strict=True) if type(i) is tuple]
            waiting = []
        if kind is not None:
            feed_message(engine, kind, item)
    engine.flush()
    return engine, rows.take(rows.count), stamps


@pytest.fixture
def stretch_counts(monkeypatch) -> Counter:
    """Inputs offered to the compiled stretch and taken by it, the aiding measurements it
    applied (the pack's attitudes and the magnetometer's fields among them) and the mooring's
    epochs, the stretches that forked the prediction afresh, and the forks the engine made
    itself among the inputs it was given together, counted."""
    counts = Counter()
    compiled = stretch_module.imu_stretch

    def counted(raw, order, *arguments):
        state = arguments[4]
        forked_at = state[stretch_module.FORKED_AT]
        aiding, mooring, went = arguments[-3:]
        widened = mooring.watch.status[SCALE] > 1.0
        block_starts = mooring.velocity_watches.block[:, BLOCK_START].copy()
        taken, stepped, stop = compiled(raw, order, *arguments)
        moved = mooring.velocity_watches.block[:, BLOCK_START] != block_starts
        counts["velocity blocks closed"] += int(np.sum(moved & ~np.isnan(block_starts)))
        counts["forked"] += state[stretch_module.FORKED_AT] != forked_at
        counts["offered"] += order.shape[0]
        counts["taken"] += taken
        mooring_epochs = int(went[stretch_module.MOORING_EPOCHS])
        counts["mooring epochs"] += mooring_epochs
        counts["mooring epochs at a widened σ"] += mooring_epochs if widened else 0
        books = aiding.books[: went[stretch_module.AIDING_BOOKS]]
        watched = books[books[:, BOOK_STATUS] >= WATCHED, BOOK_ROW].astype(int)
        counts["watched"] += watched.size
        applied = books[books[:, BOOK_STATUS] == APPLIED, BOOK_ROW].astype(int)
        counts["aiding applied"] += applied.size
        models = aiding.terms[aiding.rows[applied, ROW_SLOT].astype(int), TERM_MODEL]
        counts["fields applied"] += int(np.sum(models == MODELS.index(magnetometer_stretch_model)))
        counts["attitudes applied"] += int(np.sum(models == MODELS.index(attitude_stretch_model)))
        return taken, stepped, stop

    monkeypatch.setattr(imu_stretches, "imu_stretch", counted)
    add_inputs, predict = FusionEngine.add_inputs, RealtimePrediction.predict
    adding = []

    def counted_add_inputs(engine, inputs):
        adding.append(engine)
        try:
            return add_inputs(engine, inputs)
        finally:
            adding.pop()

    def counted_predict(prediction, *arguments):
        counts["forked by the engine"] += bool(adding) and prediction.ahead is None
        return predict(prediction, *arguments)

    monkeypatch.setattr(FusionEngine, "add_inputs", counted_add_inputs)
    monkeypatch.setattr(RealtimePrediction, "predict", counted_predict)
    return counts


def innovations(engine: FusionEngine) -> list | None:
    """The engine's innovation log (recorded when ``record_innovations``), in bytes."""
    if engine.innovation_log is None:
        return None
    return [
        (
            record.t_s,
            record.kind,
            np.asarray(record.innovation).tobytes(),
            np.asarray(record.innovation_covariance).tobytes(),
            record.nis,
            record.accepted,
        )
        for record in engine.innovation_log
    ]


def kept_motion(engine: FusionEngine) -> list:
    """What the engine's contradictions keep of the receiver's motion (every fix and velocity of
    their window, each as stamp and bytes)."""
    motion = engine._contradictions.motion
    return [
        (sample[0], *(np.asarray(part).tobytes() for part in sample[1:]))
        for sample in (*motion._fixes, *motion._velocities)
    ]


def judged_outcomes(engine: FusionEngine) -> dict:
    """What the engine's books judge the sources by: each source's recent gate outcomes with
    their stamps (in bytes), and the stamps each source and aided quantity was last accepted."""
    windows = {
        kind: (list(health._failed), np.asarray(health._stamps_s, dtype=float).tobytes())
        for kind, health in engine._gates._health.items()
    }
    recency = engine._recency
    return {
        "windows": windows,
        "accepted": dict(recency._last_accepted),
        "aided": list(recency._last_aided),
    }


def assert_same_engines(first: FusionEngine, second: FusionEngine) -> None:
    health, other = first.health(), second.health()
    assert health.counters == other.counters
    assert health.source_health == other.source_health
    assert (health.realignments, health.imu_gaps, health.alignments) == (
        other.realignments,
        other.imu_gaps,
        other.alignments,
    )
    assert health.imu_clock_steps == other.imu_clock_steps
    # What the IMU's screening learnt (the sample interval, its noise allowance) is the same.
    screening, other_screening = (
        engine._imu_input.steady_screening() for engine in (first, second)
    )
    assert (screening is None) == (other_screening is None)
    if screening is not None:
        for array, other_array in zip(screening, other_screening, strict=True):
            assert np.array_equal(array, other_array)
    assert innovations(first) == innovations(second)
    assert judged_outcomes(first) == judged_outcomes(second)
    assert kept_motion(first) == kept_motion(second)
    assert np.array_equal(first.covariance, second.covariance)
    state, other_state = first.nav_state, second.nav_state
    for field in dataclasses.fields(state):
        name = field.name
        assert np.array_equal(getattr(state, name), getattr(other_state, name)), name


def stretched_as_alone(config: FusionConfig, inputs: list[tuple], min_rows: int) -> FusionEngine:
    """The engine fed ``inputs`` in stretches, asserted the same as fed one at a time (more
    than ``min_rows`` rows, so that the equality cannot hold on nothing)."""
    stretched, rows, stamps = in_stretches(config, inputs)
    alone, expected_rows, expected_stamps = one_at_a_time(config, inputs)
    assert stamps == expected_stamps
    assert rows.shape == expected_rows.shape and rows.shape[0] > min_rows
    assert np.array_equal(rows, expected_rows)
    assert_same_engines(stretched, alone)
    return stretched


CASES = {
    "clean, GNSS out of order and off the IMU's grid, then an outage": (
        "sea_state",
        120.0,
        FusionConfig(record_innovations=True),
        False,
        False,
    ),
    "imu faults": ("sea_state", 160.0, FusionConfig(), True, False),
    "biased velocity": (
        "sea_state",
        240.0,
        FusionConfig(),
        False,
        True,
    ),
    "decimated, calibrated": (
        "open_ocean",
        90.0,
        FusionConfig(
            output_rate_hz=10.0,
            imu_gyro_bias_rad_s=(1e-4, -2e-4, 5e-5),
            imu_accel_bias_mps2=(0.02, -0.01, 0.03),
            imu_accel_scale=(1.001, 0.999, 1.002),
        ),
        False,
        False,
    ),
}


@pytest.mark.parametrize("case", CASES)
def test_stretches_give_the_engine_one_sample_at_a_time_gives(case, stretch_counts):
    name, duration_s, config, imu_faults, velocity_bias = CASES[case]
    overrides = (
        (
            "sensors.gnss.position_noise_horizontal_m=2.0",
            "sensors.gnss.position_noise_vertical_m=4.0",
        )
        if velocity_bias
        else ()
    )
    scenario, _, messages = scenario_messages(name, duration_s, overrides)
    if velocity_bias:
        messages = biased_velocity(messages, 60.0, scenario.start_time_ns, 1.0)
    inputs = fusion_inputs(messages)
    if imu_faults:
        inputs = with_imu_faults(inputs)
    if case.startswith("clean"):
        inputs = without_gnss_between(with_gnss_reordered(inputs, 40.0, 60.0), 80.0, 100.0)
    stretched = stretched_as_alone(config, inputs, 500)
    imu_samples = sum(kind == IMU for kind, _ in inputs)
    # The first sample of each run (one in ten between the GNSS epochs) is fed alone.
    assert stretch_counts["taken"] >= 0.7 * imu_samples, "the stretch took too few samples"
    # The GNSS epochs too (the heading is superseded by the baseline): all but those of the
    # outage's end, the faults' and the distrust's.
    applicable = sum(kind in APPLIED_GNSS_TOPICS for kind, _ in inputs)
    share = 0.15 if velocity_bias else 0.5
    assert stretch_counts["aiding applied"] >= share * applicable, "too few GNSS epochs"
    # The prediction is forked afresh once a second of stamps: within a stretch for some (the
    # distrust of the biased velocity leaves most to the engine).
    assert stretch_counts["forked"] >= 0.05 * duration_s, "the stretches never forked"
    health = stretched.health()
    if imu_faults:
        rejected = health.counters[IMU].rejected
        for reason in (
            Reason.IMPLAUSIBLE_CHANGE,
            Reason.NON_FINITE,
            Reason.DUPLICATE_STAMP,
            Reason.OUT_OF_RANGE,
            Reason.MALFORMED,
        ):
            assert rejected[reason] >= 1, reason
        assert rejected[Reason.OUT_OF_SEQUENCE] == 3, "the second stream's alone"
        assert health.imu_clock_steps, "the clock's step was undone"
    if velocity_bias:
        assert health.realignments >= 1
        assert health.source_health["gnss_velocity"].suspended


def with_pack_faults(inputs: list[tuple]) -> list[tuple]:
    """``inputs`` with, among the motion pack's attitudes after the first minute: a zero
    quaternion, a non-unit one and one stamped before the last (each an extra message), one
    with a non-finite covariance, twelve in a row turned 120° in yaw (the gate rejects them),
    two seconds of them lost and the pack's clock half a sample interval later from then on
    (off its sequence's grid); and twelve seconds without IMU samples from 110 s (the
    attitudes run ahead of the IMU beyond what the engine keeps)."""
    faulty, count = [], 0
    first_s = next(item[0] for kind, item in inputs if kind == IMU)
    turn = Rotation.from_euler("z", 120.0, degrees=True)
    for kind, item in inputs:
        if kind == IMU and 110.0 <= item[0] - first_s < 122.0:
            continue
        if kind != AHRS_TOPIC:
            faulty.append((kind, item))
            continue
        count += 1
        if 900 <= count < 920:
            continue
        message = copy.deepcopy(item)
        if count >= 920:
            stamp_ns = message.header.stamp.sec * 10**9 + message.header.stamp.nanosec + 5 * 10**7
            message.header.stamp.sec, message.header.stamp.nanosec = divmod(stamp_ns, 10**9)
        if count == 760:
            message.orientation_covariance[4] = math.nan
        elif 800 <= count < 812:
            q = message.orientation
            x, y, z, w = (turn * Rotation.from_quat((q.x, q.y, q.z, q.w))).as_quat()
            q.x, q.y, q.z, q.w = float(x), float(y), float(z), float(w)
        faulty.append((kind, message))
        if count in (700, 720, 740):
            extra = copy.deepcopy(item)
            if count == 700:
                extra.orientation.x = extra.orientation.y = 0.0
                extra.orientation.z = extra.orientation.w = 0.0
            elif count == 720:
                extra.orientation.w *= 1.1
            else:
                extra.header.stamp.sec -= 1
            faulty.append((kind, extra))
    return faulty


PACK_CASES = {
    # (the configuration, the least share of the seconds whose mooring constraint the stretches
    # apply, and the least share of those they apply at a widened σ)
    "moored pack": (moored_config(use_magnetometer=False, ahrs_lag_s=0.2), 0.5, 0.0),
    # Each attitude shares its stamp with a field: the two stacked in one epoch.
    "moored pack, magnetometer": (moored_config(ahrs_lag_s=0.2), 0.5, 0.0),
    # The mooring's innovations widen its σ once first judged, between two closes of the
    # mean velocity's blocks (its window's fifth, 61 s, no multiple of 10 s), and follow the
    # window from then on: the stretches widen and narrow it as the engine does.
    "moored pack, mooring's sigma claimed too small": (
        moored_config(
            use_magnetometer=False,
            ahrs_lag_s=0.2,
            moored_position_sigma_horizontal_m=0.15,
            moored_check_window_s=305.0,
        ),
        0.5,
        0.4,
    ),
    # On the corner of the cells the geomagnetic model is evaluated for: the filter's position
    # wanders across their edges, and the pack's true north with it.
    "free pack": (
        FusionConfig(
            site_latitude_deg=35.025,
            site_longitude_deg=120.025,
            ahrs_yaw_reference="magnetic_north",
            use_magnetometer=False,
            ahrs_lag_s=0.2,
        ),
        0.0,
        0.0,
    ),
}


@pytest.mark.parametrize("case", PACK_CASES)
def test_stretches_take_the_motion_pack_as_one_input_at_a_time_does(case, stretch_counts):
    """A motion pack (its attitude with every tenth IMU sample; moored, the constraint once a
    second) with faulty attitudes: the same to the bit, most IMU samples in the stretch, most
    of the pack's epochs too (with a magnetometer, each attitude stacked with the field of its
    stamp, most of the fields), and of the mooring's constraints as many as its case
    expects."""
    duration_s = 150.0
    _, _, messages = scenario_messages("moored_motion_pack", duration_s)
    config, least_mooring_share, least_widened_share = PACK_CASES[case]
    magnetometer = config.use_magnetometer
    inputs = with_pack_faults(fusion_inputs(messages))
    if config.moored and not magnetometer:
        # The fields of a magnetometer not used end each run all the same: without them the
        # stretches span many constraints.
        inputs = [(kind, item) for kind, item in inputs if kind != MAGNETOMETER_TOPIC]
    stretched = stretched_as_alone(config, inputs, 10_000)
    counters = stretched.health().counters["ahrs"]
    for reason in (
        Reason.ZERO_QUATERNION,
        Reason.NON_UNIT_QUATERNION,
        Reason.STAMP_NOT_INCREASING,
        Reason.NON_FINITE,
        Reason.GATE,
    ):
        assert counters.rejected.get(reason, 0) >= 1, reason
    imu_samples = sum(kind == IMU for kind, _ in inputs)
    assert stretch_counts["taken"] >= 0.7 * imu_samples, "the stretch took too few inputs"
    assert stretch_counts["attitudes applied"] >= 0.5 * counters.accepted, "too few taken"
    if magnetometer:
        fields = stretched.health().counters["magnetometer"].accepted
        assert stretch_counts["fields applied"] >= 0.5 * fields, "too few fields taken"
    # The prediction is forked afresh once a second of stamps: in a stretch for most.
    assert stretch_counts["forked by the engine"] <= 0.5 * duration_s, "the stretches seldom forked"
    constraints = stretch_counts["mooring epochs"]
    assert constraints >= least_mooring_share * duration_s, "too few constraints taken"
    widened = stretch_counts["mooring epochs at a widened σ"]
    assert widened >= least_widened_share * constraints, "too few taken at a widened σ"
    if config.moored:
        # Of the mean velocity's blocks, 10 s and 30 s long, most closed in the stretches.
        assert stretch_counts["velocity blocks closed"] >= 0.5 * (duration_s / 10.0)


def test_stretches_take_the_mooring_among_imu_samples_alone(stretch_counts):
    """A moored buoy's IMU samples alone once its magnetometer has given the alignment its
    heading and stopped: the same to the bit, the mooring's constraints applied in the
    stretches for most of the seconds after."""
    duration_s, heading_s = 75.0, 40.0
    _, _, messages = scenario_messages("moored_motion_pack", duration_s)
    inputs = fusion_inputs(messages)
    start_s = inputs[0][1][0]
    inputs = [
        (kind, item)
        for kind, item in inputs
        if kind == IMU
        or (kind == MAGNETOMETER_TOPIC and header_seconds(item.header) < start_s + heading_s)
    ]
    stretched_as_alone(moored_config(use_ahrs=False), inputs, 5_000)
    assert stretch_counts["mooring epochs"] >= 0.5 * (duration_s - heading_s)


def test_stretches_take_the_magnetometer_as_one_input_at_a_time_does(stretch_counts):
    """A single GNSS antenna at 1 Hz and a magnetometer at 10 Hz, a steel hull passing for ten
    seconds (the gate rejects its fields, and a run of rejections suspends the magnetometer
    until it agrees again), and a field not finite: the same to the bit, most of the fields'
    epochs in the stretches, and most of those of the suspended magnetometer, watched there
    (nine in ten alone at their stamp: an epoch that fuses nothing)."""
    duration_s = 120.0
    _, _, messages = scenario_messages(
        "sea_state",
        duration_s,
        (
            "sensors.gnss.receiver=single_antenna",
            *MAGNETOMETER,
            "sensors.magnetometer.disturbances_s=[[60, 70]]",
        ),
    )
    inputs = [
        (kind, item)
        for kind, item in fusion_inputs(messages)
        if kind not in (GNSS_FIX_TOPIC, GNSS_VELOCITY_TOPIC)
        or round(header_seconds(item.header) * 10.0) % 10 == 0
    ]
    fields = [index for index, (kind, _) in enumerate(inputs) if kind == MAGNETOMETER_TOPIC]
    broken = copy.deepcopy(inputs[fields[500]][1])
    broken.magnetic_field.y = math.nan
    inputs[fields[500]] = (MAGNETOMETER_TOPIC, broken)
    config = FusionConfig(
        site_latitude_deg=35.0,
        site_longitude_deg=120.0,
        record_innovations=True,
        **calibrated_magnetometer(),
    )
    stretched = stretched_as_alone(config, inputs, 5_000)
    counters = stretched.health().counters["magnetometer"]
    assert counters.rejected.get(Reason.NON_FINITE, 0) == 1
    assert counters.rejected.get(Reason.GATE, 0) + counters.rejected.get(Reason.SUSPENDED, 0) > 50
    assert stretch_counts["fields applied"] >= 0.5 * counters.accepted, "too few fields taken"
    assert stretch_counts["fields applied"] <= counters.accepted
    # Suspended, the magnetometer is watched in the stretches until it may resume.
    suspended = counters.rejected.get(Reason.SUSPENDED, 0)
    assert 0.5 * suspended <= stretch_counts["watched"] <= suspended
