"""Flow compensator on an anemometer: streaming equals batch, one output per input, decisions
from stamps only."""

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from wind_comp.compensator import (
    CompensatorInputError,
    CorrectedBatch,
    FlowCompensator,
    SampleStatus,
)
from wind_comp.config import CompensatorConfig, ConfigError
from wind_comp.flow_uncertainty import FlowCovariance

LEVER_ARM_M = (0.3, -0.1, 3.2)
MOUNTING_RPY_DEG = (2.0, -1.5, 90.0)
RATE_BODY_RAD_S = np.array([0.3, -0.2, 0.15])
ATTITUDE_0 = Rotation.from_euler("ZYX", [40.0, 3.0, -6.0], degrees=True)
TRUE_WIND_ENU = np.array([6.0, -3.0, 0.4])


def config(**overrides) -> CompensatorConfig:
    return CompensatorConfig(
        anemometer_position_body_m=LEVER_ARM_M, anemometer_rpy_deg=MOUNTING_RPY_DEG, **overrides
    )


def compensator_of(cfg: CompensatorConfig) -> FlowCompensator:
    return FlowCompensator(cfg.flow_sensor(), cfg.max_nav_gap_s, cfg.nav_history_s)


def nav_truth(t_s):
    """Constant body rate, linearly changing velocity: interpolation of these is exact."""
    attitude = ATTITUDE_0 * Rotation.from_rotvec(np.outer(t_s, RATE_BODY_RAD_S))
    rates = np.tile(RATE_BODY_RAD_S, (len(t_s), 1))
    velocities = np.array([0.5, 1.0, 0.0]) + np.outer(t_s, [0.2, -0.1, 0.05])
    return attitude, rates, velocities


def nav_covariances(t_s):
    """(N, 3, 3, 3) attitude, velocity and rate covariances that change from sample to sample
    (rad², m²/s², rad²/s²), as a filter's do."""
    scale = 1.0 + 0.5 * np.sin(np.asarray(t_s))[:, None, None]
    attitude = np.diag(np.radians([0.3, 0.3, 1.0]) ** 2) * scale
    velocity = np.diag([0.02, 0.02, 0.01]) ** 2 * scale
    rate = np.diag(np.radians([0.05, 0.05, 0.05]) ** 2) * scale
    return np.stack((attitude, velocity, rate), axis=1)


def anemometer_readings(t_s):
    """First-principles reading of the steady true wind from the moving sensor."""
    attitude, rates, velocities = nav_truth(t_s)
    sensor_velocity = velocities + attitude.apply(np.cross(rates, LEVER_ARM_M))
    mounting = Rotation.from_euler("ZYX", MOUNTING_RPY_DEG[::-1], degrees=True)
    return mounting.inv().apply(attitude.inv().apply(TRUE_WIND_ENU - sensor_velocity))


def scenario():
    """Navigation at 100 Hz with a gap, wind at 10 Hz starting before and ending after it,
    with malformed wind samples and stamps."""
    nav_t = np.arange(0.5, 12.0, 0.01)
    nav_t = nav_t[(nav_t < 5.0) | (nav_t > 5.3)]
    attitude, rates, velocities = nav_truth(nav_t)
    wind_t = np.arange(0.0, 12.5, 0.1) + 0.004
    wind = anemometer_readings(wind_t)
    wind[20] = np.nan
    wind[30] = [150.0, 0.0, 0.0]
    wind_t[40] = wind_t[39]  # duplicate stamp
    wind_t[80] = wind_t[70]  # backwards stamp
    return nav_t, attitude.as_quat(), rates, velocities, wind_t, wind


def no_navigation():
    """No navigation samples, as :meth:`FlowCompensator.add_arrivals` takes them."""
    return np.empty(0), np.empty((0, 4)), np.empty((0, 3)), np.empty((0, 3))


def joined(batches) -> CorrectedBatch:
    """Outputs collected in several goes, as one batch."""
    columns = [
        np.concatenate([getattr(batch, name) for batch in batches])
        for name in (
            "t_s",
            "status",
            "flow_enu_mps",
            "tilt_term_enu_mps",
            "rotation_term_enu_mps",
            "translation_term_enu_mps",
            "flow_sensor_mps",
        )
    ]
    covariance = FlowCovariance(
        *(np.concatenate([batch.covariance[part] for batch in batches]) for part in (0, 1))
    )
    return CorrectedBatch(*columns, covariance)


def rows(batch: CorrectedBatch) -> list[tuple[float, SampleStatus]]:
    """(stamp, status) of each output."""
    return [(t, SampleStatus(code)) for t, code in zip(batch.t_s, batch.status, strict=True)]


def correct_at_once(cfg, nav_t, quats, rates, velocities, wind_t, wind) -> CorrectedBatch:
    """All samples handed over as one stretch of columns, each wind sample arriving with the
    navigation up to its stamp, and flushed: the offline path."""
    compensator = compensator_of(cfg)
    nav_before_wind = np.searchsorted(nav_t, np.maximum.accumulate(wind_t), side="right")
    compensator.add_arrivals(
        (nav_t, quats, rates, velocities, True, nav_covariances(nav_t)),
        wind_t,
        wind,
        nav_before_wind,
    )
    return compensator.flush()


def stream(nav_t, quats, rates, velocities, wind_t, wind, nav_latency_s, cfg=None):
    """Feed the samples in arrival order, navigation arriving ``nav_latency_s`` after its stamp
    and wind in array order, collecting the output after every message."""
    compensator = compensator_of(cfg or config())
    wind_arrival = np.maximum.accumulate(wind_t)  # a bad stamp arrives in its array place
    arrivals = [(t + nav_latency_s, 0, i) for i, t in enumerate(nav_t)]
    arrivals += [(t, 1, i) for i, t in enumerate(wind_arrival)]
    arrivals.sort()
    outputs = []
    covariances = nav_covariances(nav_t)
    for _, kind, i in arrivals:
        if kind == 0:
            compensator.add_nav(nav_t[i], quats[i], rates[i], velocities[i], True, covariances[i])
        else:
            compensator.add_sample(wind_t[i], wind[i])
        outputs.append(compensator.ready())
    outputs.append(compensator.flush())
    return joined(outputs), compensator


def test_streaming_equals_batch_whatever_the_arrival_order():
    # One sample at a time (the live node) and one stretch of columns (offline) give the same
    # bits, edge cases included: wind before the first and after the last navigation sample,
    # across a navigation gap, NaN, too fast, and with stamps repeated or going backwards.
    data = scenario()
    batch = correct_at_once(config(), *data)
    assert {
        SampleStatus.VALID,
        SampleStatus.NO_NAVIGATION,
        SampleStatus.NAV_GAP,
        SampleStatus.INVALID_MEASUREMENT,
        SampleStatus.SPEED_OUT_OF_RANGE,
        SampleStatus.INVALID_STAMP,
    } <= set(batch.status.tolist())
    for nav_latency_s in (-0.5, 0.0, 0.037, 0.5):
        outputs, compensator = stream(*data, nav_latency_s=nav_latency_s)
        np.testing.assert_array_equal(outputs.t_s, batch.t_s)
        np.testing.assert_array_equal(outputs.status, batch.status)
        for name in (
            "flow_enu_mps",
            "tilt_term_enu_mps",
            "rotation_term_enu_mps",
            "translation_term_enu_mps",
        ):
            np.testing.assert_array_equal(getattr(outputs, name), getattr(batch, name))
        np.testing.assert_array_equal(outputs.covariance.total, batch.covariance.total)
        np.testing.assert_array_equal(outputs.covariance.sensor, batch.covariance.sensor)
        assert compensator.counts == batch.counts()
        assert compensator.n_pending == 0
    # Every valid sample states its covariance, every invalid one none.
    valid = batch.valid
    assert np.all(np.isfinite(batch.covariance.total[valid]))
    assert np.all(np.isnan(batch.covariance.total[~valid]))
    assert np.all(np.trace(batch.covariance.navigation[valid], axis1=1, axis2=2) > 0)


def test_wind_added_in_batches_equals_wind_added_one_by_one():
    nav_t, quats, rates, velocities, wind_t, wind = scenario()
    one_by_one = compensator_of(config())
    in_batches = compensator_of(config())
    for compensator in (one_by_one, in_batches):
        for i in range(len(nav_t)):
            compensator.add_nav(nav_t[i], quats[i], rates[i], velocities[i])
    for i in range(len(wind_t)):
        one_by_one.add_sample(wind_t[i], wind[i])
    for part in np.array_split(np.arange(len(wind_t)), 7):
        in_batches.add_arrivals(no_navigation(), wind_t[part], wind[part], np.zeros(len(part)))
    expected, got = one_by_one.flush(), in_batches.flush()
    assert rows(got) == rows(expected)
    np.testing.assert_array_equal(got.flow_enu_mps, expected.flow_enu_mps)
    with pytest.raises(CompensatorInputError):
        in_batches.add_arrivals(no_navigation(), wind_t[:3], wind[:2], np.zeros(3))


def test_every_sample_gets_one_output_with_its_stamp_and_reason():
    nav_t, quats, rates, velocities, wind_t, wind = scenario()
    batch = correct_at_once(config(), nav_t, quats, rates, velocities, wind_t, wind)
    assert len(batch) == len(wind_t)
    status = batch.status
    assert status[20] == SampleStatus.INVALID_MEASUREMENT
    assert status[30] == SampleStatus.SPEED_OUT_OF_RANGE
    assert status[40] == SampleStatus.INVALID_STAMP
    assert status[80] == SampleStatus.INVALID_STAMP
    before_nav = wind_t < nav_t[0]
    after_nav = wind_t > nav_t[-1]
    in_gap = (wind_t > 5.0) & (wind_t < 5.3)
    assert (status[before_nav] == SampleStatus.NO_NAVIGATION).all()
    assert (status[after_nav] == SampleStatus.NO_NAVIGATION).all()
    assert (status[in_gap] == SampleStatus.NAV_GAP).all()
    assert np.isnan(batch.flow_enu_mps[~batch.valid]).all()
    counts = batch.counts()
    assert counts[SampleStatus.INVALID_STAMP] == 2
    assert sum(counts.values()) == len(wind_t)
    # Everything else is bracketed by exact navigation and recovers the true wind.
    expected_valid = ~(before_nav | after_nav | in_gap)
    expected_valid[[20, 30, 40, 80]] = False
    np.testing.assert_array_equal(batch.valid, expected_valid)
    recovered = batch.flow_enu_mps[batch.valid]
    np.testing.assert_allclose(recovered - TRUE_WIND_ENU, 0.0, atol=1e-9)


def test_sample_waits_until_navigation_brackets_it():
    compensator = compensator_of(config())
    attitude, rates, velocities = nav_truth(np.array([0.0, 0.05, 0.1]))
    quats = attitude.as_quat()
    compensator.add_nav(0.0, quats[0], rates[0], velocities[0])
    compensator.add_sample(0.07, anemometer_readings(np.array([0.07]))[0])
    assert len(compensator.ready()) == 0
    compensator.add_nav(0.05, quats[1], rates[1], velocities[1])
    assert len(compensator.ready()) == 0
    compensator.add_nav(0.1, quats[2], rates[2], velocities[2])
    result = compensator.ready()
    assert rows(result) == [(0.07, SampleStatus.VALID)]
    np.testing.assert_allclose(result.flow_enu_mps[0], TRUE_WIND_ENU, atol=1e-9)


def test_expire_gives_up_only_on_old_samples_and_flush_on_the_rest():
    compensator = compensator_of(config())
    for t in (1.0, 1.1, 1.2):
        compensator.add_sample(t, [1.0, 0.0, 0.0])
    expired = compensator.expire(before_t_s=1.15)
    assert rows(expired) == [
        (1.0, SampleStatus.NAVIGATION_TIMEOUT),
        (1.1, SampleStatus.NAVIGATION_TIMEOUT),
    ]
    assert compensator.n_pending == 1
    assert rows(compensator.flush()) == [(1.2, SampleStatus.NO_NAVIGATION)]
    assert compensator.counts[SampleStatus.NAVIGATION_TIMEOUT] == 2


def test_outputs_keep_input_order_behind_a_pending_sample():
    compensator = compensator_of(config())
    compensator.add_nav(0.0, [0, 0, 0, 1], np.zeros(3), np.zeros(3))
    compensator.add_sample(0.05, [1.0, 0.0, 0.0])  # waits for navigation
    compensator.add_sample(0.04, [1.0, 0.0, 0.0])  # rejected at once, but returned second
    assert len(compensator.ready()) == 0
    compensator.add_nav(0.1, [0, 0, 0, 1], np.zeros(3), np.zeros(3))
    assert rows(compensator.ready()) == [
        (0.05, SampleStatus.VALID),
        (0.04, SampleStatus.INVALID_STAMP),
    ]


def test_held_samples_wait_through_expiry_until_settled_in_input_order():
    """Held samples (off the sensor's sequence) are neither looked up nor given up as late:
    settled as the sensor's they are corrected, settled as not, or never settled by the end,
    they are OUT_OF_SEQUENCE; everything after a held sample waits behind it."""
    compensator = compensator_of(config())
    stamps = np.array([0.0, 0.05, 0.1, 0.15, 0.2])
    attitude, rates, velocities = nav_truth(stamps)
    readings = anemometer_readings(stamps)
    held = np.array([False, True, True, False, True])
    compensator.add_arrivals(
        (stamps, attitude.as_quat(), rates, velocities),
        stamps[:4],
        readings[:4],
        [5, 5, 5, 5],
        held=held[:4],
    )
    assert rows(compensator.expire(before_t_s=1.0)) == [(0.0, SampleStatus.VALID)]
    assert compensator.n_pending == 3
    compensator.settle_held([2], [True])
    assert len(compensator.expire(before_t_s=1.0)) == 0  # behind the held sample 1
    compensator.settle_held([1], [False])
    result = compensator.ready()
    assert rows(result) == [
        (0.05, SampleStatus.OUT_OF_SEQUENCE),
        (0.1, SampleStatus.VALID),
        (0.15, SampleStatus.VALID),
    ]
    np.testing.assert_allclose(result.flow_enu_mps[1:], [TRUE_WIND_ENU] * 2, atol=1e-9)
    compensator.add_arrivals((np.empty(0),) * 4, stamps[4:], readings[4:], [0], held=held[4:])
    assert len(compensator.expire(before_t_s=1.0)) == 0
    assert rows(compensator.flush()) == [(0.2, SampleStatus.OUT_OF_SEQUENCE)]
    with pytest.raises(ValueError):
        compensator.settle_held([4], [True])


def test_wind_lagging_beyond_the_navigation_history_is_reported():
    compensator = compensator_of(config(nav_history_s=1.0))
    for t in np.arange(0.0, 5.0, 0.01):
        compensator.add_nav(t, [0, 0, 0, 1], np.zeros(3), np.zeros(3))
    compensator.add_sample(2.0, [1.0, 0.0, 0.0])
    compensator.add_sample(4.5, [1.0, 0.0, 0.0])
    assert rows(compensator.ready()) == [
        (2.0, SampleStatus.NAV_HISTORY_EXCEEDED),
        (4.5, SampleStatus.VALID),
    ]


def test_results_depend_on_the_arrival_order_only_not_on_how_often_they_are_collected():
    # Wind from 3 s on arriving 1.5 s after its navigation, with a 1 s history: it finds its
    # navigation forgotten. Collecting the results after every message, now and then, or once,
    # and handing stretches of arrivals over as columns, changes nothing.
    nav_t, quats, rates, velocities, wind_t, wind = scenario()
    wind_arrival = np.maximum.accumulate(wind_t)
    wind_arrival += np.where(wind_arrival >= 3.0, 1.5, 0.0)
    arrivals = [(t, 0, i) for i, t in enumerate(nav_t)]
    arrivals += [(t, 1, i) for i, t in enumerate(wind_arrival)]
    arrivals.sort()
    cfg = config(nav_history_s=1.0)

    def collected(every: int):
        compensator = compensator_of(cfg)
        outputs = []
        for n, (_, kind, i) in enumerate(arrivals, 1):
            if kind == 0:
                compensator.add_nav(nav_t[i], quats[i], rates[i], velocities[i])
            else:
                compensator.add_sample(wind_t[i], wind[i])
            if n % every == 0:
                outputs.append(compensator.ready())
        return joined([*outputs, compensator.flush()])

    def in_stretches(size: int):
        compensator = compensator_of(cfg)
        outputs = []
        for start in range(0, len(arrivals), size):
            stretch = arrivals[start : start + size]
            nav = [i for _, kind, i in stretch if kind == 0]
            winds = [i for _, kind, i in stretch if kind == 1]
            nav_before_wind = np.cumsum([kind == 0 for _, kind, _ in stretch])[
                [k for k, (_, kind, _) in enumerate(stretch) if kind == 1]
            ]
            compensator.add_arrivals(
                (nav_t[nav], quats[nav], rates[nav], velocities[nav]),
                wind_t[winds],
                wind[winds].reshape(-1, 3),
                nav_before_wind,
            )
            outputs.append(compensator.ready())
        return joined([*outputs, compensator.flush()])

    reference = collected(every=1)
    statuses = set(reference.status.tolist())
    assert {SampleStatus.NAV_HISTORY_EXCEEDED, SampleStatus.VALID} <= statuses
    for outputs in (collected(13), collected(len(arrivals)), in_stretches(50), in_stretches(5000)):
        assert rows(outputs) == rows(reference)
        np.testing.assert_array_equal(outputs.flow_enu_mps, reference.flow_enu_mps)


def test_wrong_wind_shape_raises():
    with pytest.raises(CompensatorInputError, match="flow_sensor_mps"):
        compensator_of(config()).add_sample(0.0, [1.0, 2.0])


@pytest.mark.parametrize(
    ("overrides", "field"),
    [
        ({"max_nav_gap_s": -0.1}, "max_nav_gap_s"),
        ({"max_wind_speed_mps": np.nan}, "max_wind_speed_mps"),
        ({"anemometer_position_body_m": (0.0, 3.0)}, "anemometer_position_body_m"),
        ({"anemometer_rpy_deg": (0.0, np.inf, 0.0)}, "anemometer_rpy_deg"),
        ({"anemometer_rpy_deg": "abc"}, "anemometer_rpy_deg"),
        ({"nav_history_s": 0.05}, "nav_history_s"),
        ({"product_windows_s": (60.0, -1.0)}, "product_windows_s"),
        ({"gust_window_s": 90.0}, "gust_window_s"),
        ({"gust_window_s": True}, "gust_window_s"),
    ],
)
def test_config_errors_name_the_field(overrides, field):
    values = {
        "anemometer_position_body_m": LEVER_ARM_M,
        "anemometer_rpy_deg": MOUNTING_RPY_DEG,
    } | overrides
    with pytest.raises(ConfigError, match=field):
        CompensatorConfig(**values)


def test_config_takes_lists_and_keeps_the_wmo_windows_by_default():
    cfg = CompensatorConfig(anemometer_position_body_m=[0, 0, 3], anemometer_rpy_deg=[0, 0, 0])
    assert cfg.anemometer_position_body_m == (0.0, 0.0, 3.0)
    assert cfg.product_windows_s == (60.0, 600.0)


@pytest.mark.parametrize(
    ("attitude_sigma_deg", "vertical_sigma_mps", "refused"),
    [(0.5, 0.01, False), (6.0, 0.01, True), (0.5, 0.3, True)],
    ids=["within", "heading_too_uncertain", "vertical_too_uncertain"],
)
def test_the_sigma_gate_refuses_a_sample_beyond_its_limits(
    attitude_sigma_deg, vertical_sigma_mps, refused
):
    """A 5.9 m/s relative wind turned by a yaw error of σ rad moves by about 5.9σ m/s: 6° is
    0.6 m/s, beyond the 0.5 m/s horizontal limit; 0.5° is 0.05 m/s, within. A vertical velocity
    σ of 0.3 m/s is beyond the 0.25 m/s vertical limit."""
    cfg = config(max_attitude_sigma_deg=10.0)
    compensator = compensator_of(cfg)
    nav_t, quats, rates, velocities, wind_t, wind = scenario()
    covariances = np.zeros((nav_t.size, 3, 3, 3))
    covariances[:, 0] = np.diag(np.radians([0.2, 0.2, attitude_sigma_deg]) ** 2)
    covariances[:, 1] = np.diag([0.01, 0.01, vertical_sigma_mps]) ** 2
    compensator.add_arrivals(
        (nav_t, quats, rates, velocities, True, covariances),
        wind_t[60:70],
        wind[60:70],
        np.full(10, nav_t.size),
    )
    batch = compensator.flush()
    expected = SampleStatus.UNCERTAINTY_TOO_LARGE if refused else SampleStatus.VALID
    assert set(batch.status.tolist()) == {expected}
    assert np.isnan(batch.flow_enu_mps).all() == refused
    assert np.isnan(batch.covariance.total).all() == refused
    assert cfg.flow_sensor().reason(SampleStatus.UNCERTAINTY_TOO_LARGE) == "uncertainty_too_large"
