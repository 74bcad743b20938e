"""The compensation pipeline: live (one message at a time) and offline (stretches of messages)
decide identically by construction, and the navigation conversion is the physics it claims."""

import math
from dataclasses import astuple

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from buoy_nav.earth import EARTH_RATE_RAD_S
from buoy_nav.rotations import rotate_by_quaternion_components
from buoy_nav.stream_sequence import CONFIRMING_SPAN_S
from wind_comp.compensation_messages import FlowSample
from wind_comp.compensator import SampleStatus
from wind_comp.config import CompensatorConfig
from wind_comp.flux_products import FluxProduct
from wind_comp.pipeline import (
    NAV_SAMPLES_HELD_AT_MOST,
    NavigationColumns,
    level_rate_components,
    wind_pipeline,
)

RNG = np.random.default_rng(31)
LEVER_ARM_M = (0.2, -0.1, 3.0)
MOUNTING_RPY_DEG = (1.0, -2.0, 30.0)
LATITUDE_DEG = 35.0
RATE_NB_RAD_S = np.array([0.2, -0.15, 0.1])
ATTITUDE_0 = Rotation.from_euler("ZYX", [60.0, 4.0, -5.0], degrees=True)
TRUE_WIND_ENU = np.array([-4.0, 7.0, 0.3])
NAV_RATE_HZ = 100.0
WIND_RATE_HZ = 20.0
DURATION_S = 40.0
ANEMOMETER_GAP_S = (15.0, 25.0)  # no anemometer samples in between: 10 s, the nav history
NAV_LATENCY_S = 0.3  # the fusion's output delay, the log times of process_bag's nav/*
CONFIG = CompensatorConfig(
    anemometer_position_body_m=LEVER_ARM_M,
    anemometer_rpy_deg=MOUNTING_RPY_DEG,
    nav_history_s=10.0,
    product_windows_s=(10.0, 20.0),
    flux_window_s=10.0,
)


def navigation(t_s):
    """Attitude, rate ω_nb and ENU velocity of a buoy turning at a constant rate and
    accelerating uniformly: interpolating these is exact."""
    attitude = ATTITUDE_0 * Rotation.from_rotvec(np.outer(t_s, RATE_NB_RAD_S))
    velocity_enu = np.array([0.4, -0.2, 0.05]) + np.outer(t_s, [0.01, 0.02, -0.005])
    return attitude, np.tile(RATE_NB_RAD_S, (len(t_s), 1)), velocity_enu


def odometry_messages(t_s):
    """nav/odometry values as the fusion publishes them: ω_ib (what the gyros sense, the
    Earth's rotation included) and the velocity in body axes."""
    attitude, rate_nb, velocity_enu = navigation(t_s)
    latitude = math.radians(LATITUDE_DEG)
    earth_rate_enu = EARTH_RATE_RAD_S * np.array([0.0, math.cos(latitude), math.sin(latitude)])
    rate_ib = rate_nb + attitude.inv().apply(earth_rate_enu)
    velocity_body = attitude.inv().apply(velocity_enu)
    return [
        (float(t), tuple(q), tuple(w), tuple(v))
        for t, q, w, v in zip(
            t_s, attitude.as_quat().tolist(), rate_ib.tolist(), velocity_body.tolist(), strict=True
        )
    ]


def anemometer_samples(t_s):
    """What an anemometer on the moving buoy reads of the steady true wind."""
    attitude, rate_nb, velocity_enu = navigation(t_s)
    sensor_velocity = velocity_enu + attitude.apply(np.cross(rate_nb, LEVER_ARM_M))
    mounting = Rotation.from_euler("ZYX", MOUNTING_RPY_DEG[::-1], degrees=True)
    readings = mounting.inv().apply(attitude.inv().apply(TRUE_WIND_ENU - sensor_velocity))
    return [
        FlowSample(float(t), tuple(wind), None)
        for t, wind in zip(t_s, readings.tolist(), strict=True)
    ]


def arrivals(
    nav_latency_s: float, wind_latency_s: float = 0.0, temperature_latency_s: float = 0.001
):
    """Every message in arrival order: a fix first, then each solution's odometry and fix as
    the fusion publishes them ``nav_latency_s`` after their stamp, and anemometer samples
    ``wind_latency_s`` after theirs, with a 10 s hole in the anemometer's record; the sonic
    temperature of each anemometer sample, with its stamp, ``temperature_latency_s`` after
    it."""
    nav_t = np.arange(0.0, DURATION_S, 1.0 / NAV_RATE_HZ)
    wind_t = np.arange(1.0, DURATION_S - 1.0, 1.0 / WIND_RATE_HZ) + 0.0031
    wind_t = wind_t[(wind_t < ANEMOMETER_GAP_S[0]) | (wind_t > ANEMOMETER_GAP_S[1])]
    timeline = [
        (t + nav_latency_s, 0, message)
        for t, message in zip(nav_t, odometry_messages(nav_t), strict=True)
    ]
    timeline += [
        (t + wind_latency_s, 1, sample)
        for t, sample in zip(wind_t, anemometer_samples(wind_t), strict=True)
    ]
    timeline += [
        (t + wind_latency_s + temperature_latency_s, 2, (t, 20.0 + 0.3 * math.sin(t)))
        for t in wind_t
    ]
    timeline.sort(key=lambda item: item[:2])
    kinds = ("odometry", "wind", "temperature")
    return [("fix", (0, LATITUDE_DEG))] + [(kinds[kind], message) for _, kind, message in timeline]


def feed(messages, wind_per_stretch: int | None):
    """Feed the pipeline as compensation_node does (``wind_per_stretch`` None: results after
    every message) or as process_bag does (results every ``wind_per_stretch`` anemometer
    samples). Returns the statuses, true winds and products, in order."""
    pipeline = wind_pipeline(CONFIG)
    outputs = []
    temperature_products = []
    waiting = 0
    for kind, values in messages:
        if kind == "fix":
            assert pipeline.add_fix(*values) is None
        elif kind == "odometry":
            assert pipeline.add_odometry(*values) is None
            pipeline.add_fix(0, LATITUDE_DEG)
            if wind_per_stretch is None:
                outputs.append(pipeline.ready())
        elif kind == "temperature":
            temperature_products.extend(pipeline.add_temperature(*values))
        else:
            # The samples resuming after the gap are held off the sequence, not rejected.
            assert pipeline.add_sample(values) is None
            waiting += 1
            if wind_per_stretch is None or waiting == wind_per_stretch:
                outputs.append(pipeline.ready())
                waiting = 0
    outputs.append(pipeline.flush())
    status = np.concatenate([output.samples.status for output in outputs])
    true_wind = np.concatenate([output.samples.flow_enu_mps for output in outputs])
    products = [product for output in outputs for product in output.products]
    return status, true_wind, products + temperature_products, pipeline


def in_order(products) -> list[tuple]:
    """Products as tuples, by kind, window length and start: flux windows waiting for the
    temperature may close after a later window of another kind."""
    rows = [(type(p).__name__, p.window_s, p.window_start_s, *astuple(p)) for p in products]
    return sorted(rows, key=lambda row: row[:3])


@pytest.mark.parametrize(("nav_latency_s", "wind_latency_s"), [(NAV_LATENCY_S, 0.0), (0.0, 0.2)])
def test_live_and_offline_decide_identically_across_an_anemometer_gap(
    nav_latency_s, wind_latency_s
):
    messages = arrivals(nav_latency_s, wind_latency_s)
    live_status, live_wind, live_products, live = feed(messages, wind_per_stretch=None)
    wind_t = np.array([values.t_s for kind, values in messages if kind == "wind"])
    # Every sample is corrected, those just before the gap included (navigation around them
    # arrived long before the anemometer resumed), and exactly; the samples after the gap,
    # held off the anemometer's sequence until they proved to be its own, too.
    before_gap = wind_t[wind_t < ANEMOMETER_GAP_S[0]][-3:]
    assert np.all(live_status == SampleStatus.VALID)
    assert before_gap.size == 3
    np.testing.assert_allclose(live_wind - TRUE_WIND_ENU, 0.0, atol=1e-9)
    assert live.n_pending == 0
    for wind_per_stretch in (1, 7, 256, 10_000):
        status, wind, products, offline = feed(messages, wind_per_stretch)
        np.testing.assert_array_equal(status, live_status)
        np.testing.assert_array_equal(wind, live_wind)
        np.testing.assert_equal(in_order(products), in_order(live_products))
        assert offline.counts == live.counts
    wind_products = [p for p in live_products if not isinstance(p, FluxProduct)]
    assert [p.window_s for p in wind_products[:3]] == [10.0, 10.0, 20.0]  # in closing order
    fluxes = sorted(
        (p for p in live_products if isinstance(p, FluxProduct)), key=lambda p: p.window_start_s
    )
    # wind from 1 to 39 s, a gap from 15 to 25 s: the windows on both sides of it are partial
    assert [p.window_start_s for p in fluxes] == [0.0, 10.0, 20.0, 30.0]
    assert [p.coverage for p in fluxes] == pytest.approx([0.9, 0.5, 0.5, 0.9])
    # every wind sample found its temperature; a steady wind carries no flux
    assert all(p.n_temperature == p.n_valid + p.n_invalid for p in fluxes)
    np.testing.assert_allclose([p.friction_velocity_mps for p in fluxes], 0.0, atol=1e-4)


def feed_live_with_latency(messages):
    """Feed the pipeline one message at a time as compensation_node does. Returns the statuses
    of the outputs, in order, and how long each waited: the newest anemometer stamp added
    when it came out less its own stamp, s."""
    pipeline = wind_pipeline(CONFIG)
    status, waited_s = [], []
    newest_wind_s = -math.inf
    for kind, values in messages:
        if kind == "fix":
            pipeline.add_fix(*values)
        elif kind == "odometry":
            pipeline.add_odometry(*values)
        elif kind == "wind":
            assert pipeline.add_sample(values) is None
            newest_wind_s = values.t_s
        else:
            continue
        samples = pipeline.ready().samples
        status.extend(samples.status.tolist())
        waited_s.extend((newest_wind_s - samples.t_s).tolist())
    status.extend(pipeline.flush().samples.status.tolist())
    return np.array(status), np.array(waited_s), pipeline


def jittered_copies(messages: list, late_s: float) -> list:
    """The latest wind sample of ``messages`` and its temperature stamped ``late_s`` (s)
    later."""
    wind = next(values for kind, values in reversed(messages) if kind == "wind")
    temperature = next(values for kind, values in reversed(messages) if kind == "temperature")
    t_s = wind.t_s + late_s
    return [("wind", wind._replace(t_s=t_s)), ("temperature", (t_s, *temperature[1:]))]


@pytest.mark.parametrize("off_grid", [False, True], ids=["on grid", "off grid"])
@pytest.mark.parametrize("missed_samples", [3, 10, 100])
def test_wind_resumes_valid_after_an_anemometer_outage(missed_samples, off_grid):
    """The anemometer misses ``missed_samples`` samples from 30 s on (``off_grid``: the last
    before them followed by one stamped 0.3 intervals later, a driver's jitter): the samples
    after the outage are held off its sequence (they could be a second stream's) until they
    span CONFIRMING_SPAN_S with none of the old sequence in between, then corrected: every
    sample gets its output, valid, the resumed ones at most a confirming span late, live and
    offline alike."""
    messages, wind_t, missed = [], [], 0
    for kind, values in arrivals(NAV_LATENCY_S):
        if kind in ("wind", "temperature"):
            t_s = values.t_s if kind == "wind" else values[0]
            if t_s > 30.0 and missed < 2 * missed_samples:
                missed += 1  # the sample and its temperature
                if off_grid and missed == 1:
                    messages += jittered_copies(messages, 0.3 / WIND_RATE_HZ)
                    wind_t.append(messages[-2][1].t_s)
                continue
            if kind == "wind":
                wind_t.append(t_s)
        messages.append((kind, values))
    wind_t = np.array(wind_t)
    status, waited_s, live = feed_live_with_latency(messages)
    assert len(status) == len(wind_t)
    np.testing.assert_array_equal(status, SampleStatus.VALID)
    assert live.take_given_up() == 0
    resumed = wind_t > 30.0
    interval_s = 1.0 / WIND_RATE_HZ
    steady = wind_t < ANEMOMETER_GAP_S[0] - 1.0
    assert np.all(waited_s[steady] <= NAV_LATENCY_S + interval_s)
    assert waited_s[resumed].max() == pytest.approx(CONFIRMING_SPAN_S, abs=1.01 * interval_s)
    for wind_per_stretch in (1, 7, 10_000):
        offline_status, _, _, offline = feed(messages, wind_per_stretch)
        np.testing.assert_array_equal(offline_status, status)
        assert offline.counts == live.counts


def test_both_arrival_orders_decide_alike():
    first, second = (
        feed(arrivals(*latencies), None) for latencies in ((NAV_LATENCY_S, 0), (0, 0.2))
    )
    np.testing.assert_array_equal(first[0], second[0])
    np.testing.assert_array_equal(first[1], second[1])


def test_wind_arriving_after_the_navigation_history_is_reported_alike_live_and_offline():
    # From 5 s on the anemometer's samples are held up and arrive, in order, once the
    # navigation has reached 18 s: those lagging it by more than the 10 s history find their
    # navigation forgotten, live and offline alike.
    messages = arrivals(0.0)
    held = [m for m in messages if m[0] == "wind" and m[1].t_s >= 5.0]
    others = [m for m in messages if not (m[0] == "wind" and m[1].t_s >= 5.0)]
    release = next(i for i, m in enumerate(others) if m[0] == "odometry" and m[1][0] >= 18.0)
    messages = others[: release + 1] + held + others[release + 1 :]
    live_status, live_wind, _, _ = feed(messages, None)
    wind_t = np.array([values.t_s for kind, values in messages if kind == "wind"])
    assert np.all(
        live_status[(wind_t >= 5.0) & (wind_t < 7.9)] == SampleStatus.NAV_HISTORY_EXCEEDED
    )
    decided_by_navigation = (wind_t < 5.0) | (wind_t > 8.1)
    assert np.all(live_status[decided_by_navigation] == SampleStatus.VALID)
    for wind_per_stretch in (5, 10_000):
        status, wind, _, _ = feed(messages, wind_per_stretch)
        np.testing.assert_array_equal(status, live_status)
        np.testing.assert_array_equal(wind, live_wind)


def test_rejections_are_reported_and_every_sample_gets_its_output():
    pipeline = wind_pipeline(CONFIG)
    odometry = odometry_messages(np.array([0.0, 0.01, 0.02]))
    assert pipeline.add_odometry(*odometry[1]) is None
    assert pipeline.add_odometry(*odometry[0]) == "stamp_not_increasing"
    samples = anemometer_samples(np.array([0.005, 0.015]))
    assert pipeline.add_sample(samples[1]) is None
    assert pipeline.add_sample(samples[0]) == "stamp_not_increasing"
    assert pipeline.add_sample(FlowSample(0.02, (math.nan,) * 3, "wrong_frame")) == "wrong_frame"
    with pytest.raises(ValueError, match="quaternion of 4"):
        pipeline.add_odometry(0.015, (0.0, 0.0, 1.0), (0.0, 0.0, 0.0), (0.0, 0.0, 0.0))
    assert pipeline.add_odometry(*odometry[2]) is None
    output = pipeline.flush()
    assert output.samples.status.tolist() == [
        SampleStatus.VALID,
        SampleStatus.INVALID_STAMP,
        SampleStatus.INVALID_MEASUREMENT,
    ]
    assert pipeline.n_nav_accepted == 2


def test_earth_rate_removal_inverts_what_a_gyro_senses():
    attitudes = Rotation.random(50, random_state=5)
    latitudes_deg = RNG.uniform(-89, 89, 50)
    rates_nb = RNG.normal(0, 0.2, (50, 3))
    phi = np.radians(latitudes_deg)
    earth_enu = EARTH_RATE_RAD_S * np.column_stack([np.zeros(50), np.cos(phi), np.sin(phi)])
    sensed = rates_nb + attitudes.inv().apply(earth_enu)
    recovered = np.stack(
        level_rate_components(sensed.T, attitudes.as_quat().T, latitudes_deg), axis=-1
    )
    np.testing.assert_allclose(recovered, rates_nb, atol=1e-15)
    # The Earth's rate has the same length in any attitude.
    np.testing.assert_allclose(
        np.linalg.norm(sensed - recovered, axis=1), EARTH_RATE_RAD_S, rtol=1e-12
    )


def test_earth_rate_is_kept_without_a_latitude():
    rates = RNG.normal(0, 0.1, (4, 3))
    quats = Rotation.random(4, random_state=1).as_quat()
    kept = np.stack(np.broadcast_arrays(*level_rate_components(rates.T, quats.T, math.nan)), -1)
    np.testing.assert_array_equal(kept, rates)
    single = np.array(level_rate_components(tuple(rates[0]), tuple(quats[0]), 0.0), dtype=float)
    # At the equator the Earth's rate is horizontal, pointing North.
    np.testing.assert_allclose(
        Rotation.from_quat(quats[0]).apply(rates[0] - single), [0, EARTH_RATE_RAD_S, 0], atol=1e-15
    )


def test_one_message_converts_exactly_as_a_batch_of_messages():
    # The node converts each nav/odometry as a column of one, process_bag whole columns.
    attitudes = Rotation.random(40, random_state=13).as_quat() * RNG.uniform(0.5, 2.0, (40, 1))
    rates = RNG.normal(0, 0.3, (40, 3))
    velocities_body = RNG.normal(0, 2.0, (40, 3))
    latitudes_deg = RNG.uniform(-89, 89, 40)
    latitudes_deg[[3, 17]] = math.nan
    batch_rates = np.stack(level_rate_components(rates.T, attitudes.T, latitudes_deg), axis=-1)
    batch_velocities = np.stack(
        rotate_by_quaternion_components(attitudes.T, velocities_body.T), axis=-1
    )
    for k in range(40):
        one = slice(k, k + 1)
        one_rate = level_rate_components(rates[one].T, attitudes[one].T, latitudes_deg[one])
        one_velocity = rotate_by_quaternion_components(attitudes[one].T, velocities_body[one].T)
        np.testing.assert_array_equal(np.stack(one_rate, axis=-1)[0], batch_rates[k])
        np.testing.assert_array_equal(np.stack(one_velocity, axis=-1)[0], batch_velocities[k])
    np.testing.assert_array_equal(batch_rates[[3, 17]], rates[[3, 17]])


def test_navigation_too_uncertain_corrects_no_wind_alike_live_and_offline():
    """Solutions whose attitude 1σ exceeds max_attitude_sigma_deg (from 10 s to 12 s) leave
    the wind samples they bracket invalid as navigation_not_trusted, and only those."""
    limit_rad = math.radians(CONFIG.max_attitude_sigma_deg)
    untrusted_s = (10.0, 12.0)
    messages = []
    for kind, values in arrivals(NAV_LATENCY_S):
        if kind == "odometry":
            inside = untrusted_s[0] <= values[0] <= untrusted_s[1]
            values = (*values, (2.0 * limit_rad) ** 2 if inside else (0.5 * limit_rad) ** 2)
        messages.append((kind, values))
    live_status, live_wind, _, _ = feed(messages, None)
    wind_t = np.array([values.t_s for kind, values in messages if kind == "wind"])
    # The samples bracketed by a navigation sample inside the span (one nav interval, 10 ms,
    # on either side of it).
    affected = (wind_t > untrusted_s[0] - 0.01) & (wind_t < untrusted_s[1] + 0.01)
    assert np.all(live_status[affected] == SampleStatus.NAVIGATION_NOT_TRUSTED)
    assert np.all(np.isnan(live_wind[affected]))
    assert np.all(live_status[~affected] == SampleStatus.VALID)
    assert CONFIG.flow_sensor().reason(SampleStatus.NAVIGATION_NOT_TRUSTED) == (
        "navigation_not_trusted"
    )
    for wind_per_stretch in (1, 7, 10_000):
        status, wind, _, _ = feed(messages, wind_per_stretch)
        np.testing.assert_array_equal(status, live_status)
        np.testing.assert_array_equal(wind, live_wind)


def test_navigation_waits_for_a_sample_it_can_decide_and_never_without_bound():
    """Live, navigation stamped before every waiting sample is held back, not handed over at
    each message; a sensor that stops leaves at most a stretch of it held."""
    pipeline = wind_pipeline(CONFIG)
    held_at_most = NAV_SAMPLES_HELD_AT_MOST
    stamps_s = np.arange(3 * held_at_most) / NAV_RATE_HZ
    handed_over = []
    for odometry in odometry_messages(stamps_s):
        pipeline.add_odometry(*odometry)
        pipeline.ready()
        handed_over.append(pipeline.compensator.nav_track.n_accepted)
    assert max(np.diff([0, *handed_over])) == held_at_most
    assert len(stamps_s) - handed_over[-1] < held_at_most
    assert pipeline.n_nav_accepted == len(stamps_s)
    # A sample stamped after the navigation so far is decided by the first navigation after it.
    t_s = stamps_s[-1] + 0.005
    pipeline.add_sample(anemometer_samples(np.array([t_s]))[0])
    assert len(pipeline.ready().samples) == 0
    pipeline.add_odometry(*odometry_messages(np.array([t_s - 0.002]))[0])
    assert len(pipeline.ready().samples) == 0
    pipeline.add_odometry(*odometry_messages(np.array([t_s + 0.005]))[0])
    assert pipeline.ready().samples.status.tolist() == [SampleStatus.VALID]


def test_a_second_anemometer_stream_gets_invalid_outputs_alike_live_and_offline():
    """Another sonic's samples, its clock 0.3 s ahead, each just after one of the buoy's own
    from 5 s to 10 s: each gets its output, invalid as out_of_sequence, and the buoy's own
    samples are corrected as without them."""
    clean = arrivals(NAV_LATENCY_S)
    messages, second = [], []
    for kind, values in clean:
        messages.append((kind, values))
        if kind == "wind":
            second.append(False)
            if 5.0 <= values.t_s < 10.0:
                messages.append(("wind", values._replace(t_s=values.t_s + 0.3)))
                second.append(True)
    second = np.array(second)
    live_status, live_wind, _, live = feed(messages, None)
    clean_status, clean_wind, _, _ = feed(clean, None)
    assert np.count_nonzero(second) == 100
    assert np.all(live_status[second] == SampleStatus.OUT_OF_SEQUENCE)
    assert np.all(np.isnan(live_wind[second]))
    np.testing.assert_array_equal(live_status[~second], clean_status)
    np.testing.assert_array_equal(live_wind[~second], clean_wind)
    assert live.second_stream[0] == 100
    assert live.take_given_up() == 100
    assert live.second_stream[1] == pytest.approx(0.3, abs=0.06)
    for wind_per_stretch in (1, 7, 10_000):
        status, wind, _, _ = feed(messages, wind_per_stretch)
        np.testing.assert_array_equal(status, live_status)
        np.testing.assert_array_equal(wind, live_wind)


def _odometry_batch(count: int) -> tuple:
    """``count`` solutions' odometry and fix values with what a run can hand over: a stamp
    repeated and one going back (left out), a fix without a finite latitude and one beyond
    ±90° (not taken), a NaN variance first on the diagonal and one later (the builtin max
    keeps the first NaN and skips a later one), and one attitude beyond the trusted σ."""
    t_s = 100.0 + 0.01 * np.arange(count)
    t_s[5] = t_s[4]
    t_s[9] = t_s[7]
    attitude, _, _ = navigation(t_s)
    quaternions = attitude.as_quat()
    rates = RNG.normal(scale=0.2, size=(count, 3))
    velocities = RNG.normal(scale=1.0, size=(count, 3))
    factors = RNG.normal(scale=1e-3, size=(count, 3, 3))
    attitude_covariance = factors @ factors.transpose(0, 2, 1)
    attitude_covariance[11, 0, 0] = math.nan
    attitude_covariance[12, 2, 2] = math.nan
    attitude_covariance[13] *= 1e6
    factors = RNG.normal(scale=1e-2, size=(count, 6, 6))
    twist_covariance = factors @ factors.transpose(0, 2, 1)
    latitudes = np.full(count, LATITUDE_DEG) + 1e-4 * np.arange(count)
    latitudes[2] = math.nan
    latitudes[3] = 91.0
    return t_s, quaternions, rates, velocities, attitude_covariance, twist_covariance, latitudes


def test_navigation_in_bulk_is_the_messages_one_by_one():
    """What a run without a bag hands over at once gives the pipeline the rows, the latitude
    and the latest stamp that the same solutions' ``nav/odometry`` and ``nav/fix``, one by
    one, give it, to the bit."""
    t_s, quaternions, rates, velocities, attitude_cov, twist_cov, latitudes = _odometry_batch(20)
    one_by_one = wind_pipeline(CONFIG)
    for index in range(len(t_s)):
        one_by_one.add_odometry(
            float(t_s[index]),
            tuple(quaternions[index].tolist()),
            tuple(rates[index].tolist()),
            tuple(velocities[index].tolist()),
            max(*np.diagonal(attitude_cov[index]).tolist()),
            tuple(attitude_cov[index].ravel().tolist()),
            tuple(twist_cov[index].ravel().tolist()),
        )
        one_by_one.add_fix(0, float(latitudes[index]))
    in_bulk = wind_pipeline(CONFIG)
    in_bulk.add_navigation_columns(
        NavigationColumns(
            stamps_s=t_s,
            attitude_xyzw=quaternions,
            angular_rate_body_rad_s=rates,
            velocity_body_mps=velocities,
            attitude_covariance_rad2=attitude_cov,
            body_velocity_covariance_m2s2=twist_cov[:, :3, :3],
            body_rate_covariance_rad2_s2=twist_cov[:, 3:, 3:],
            fix_latitude_deg=latitudes,
        )
    )
    assert in_bulk.n_navigation_held == one_by_one.n_navigation_held == len(t_s) - 2
    assert bytes(in_bulk._nav) == bytes(one_by_one._nav)
    assert in_bulk.latitude_deg == one_by_one.latitude_deg
    assert in_bulk.latest_navigation_stamp_s == one_by_one.latest_navigation_stamp_s
