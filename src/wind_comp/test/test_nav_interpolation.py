"""Navigation interpolation against analytic trajectories, gaps and the bounded history."""

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from buoy_nav.rotations import quaternion_multiply, rotation_matrix_elements
from wind_comp.nav_interpolation import (
    InterpolationStatus,
    NavTrack,
    NavTrackError,
    slerp,
    slerp_components,
)

RATE_BODY_RAD_S = np.array([0.4, -0.25, 0.6])
ATTITUDE_0 = Rotation.from_euler("ZYX", [30.0, 5.0, -8.0], degrees=True)


def constant_rate_attitude(t_s):
    """R(t) = R0·exp([ω×]t): rotation at a constant body rate."""
    return ATTITUDE_0 * Rotation.from_rotvec(np.outer(t_s, RATE_BODY_RAD_S))


def linear_velocity(t_s):
    return np.array([1.0, -2.0, 0.5]) + np.outer(t_s, [0.3, 0.1, -0.2])


def linear_rate(t_s):
    return RATE_BODY_RAD_S + np.outer(t_s, [0.01, 0.02, -0.03])


def analytic_track(stamps_s, max_gap_s=0.1, history_s=np.inf) -> NavTrack:
    track = NavTrack(max_gap_s=max_gap_s, history_s=history_s)
    quats = constant_rate_attitude(stamps_s).as_quat()
    for t, quat, rate, velocity in zip(
        stamps_s, quats, linear_rate(stamps_s), linear_velocity(stamps_s), strict=True
    ):
        assert track.append(t, quat, rate, velocity)
    return track


def test_constant_rate_rotation_and_linear_signals_are_interpolated_exactly():
    stamps = np.arange(0.0, 2.0, 0.05)
    track = analytic_track(stamps)
    rng = np.random.default_rng(21)
    queries = np.sort(np.concatenate((stamps[:-1] + 0.025, rng.uniform(0.0, stamps[-1], 200))))
    nav = track.interpolate(queries)
    assert nav.valid.all()
    assert (nav.status == InterpolationStatus.OK).all()
    angle_error = (nav.attitude_nb.inv() * constant_rate_attitude(queries)).magnitude()
    assert angle_error.max() < 1e-12
    np.testing.assert_allclose(nav.velocity_enu_mps, linear_velocity(queries), atol=1e-13)
    np.testing.assert_allclose(nav.angular_rate_body_rad_s, linear_rate(queries), atol=1e-13)


def test_query_on_a_sample_returns_that_sample_even_beside_a_gap():
    stamps = np.array([0.0, 0.05, 0.1, 0.5])
    track = analytic_track(stamps)
    nav = track.interpolate(stamps)
    assert nav.valid.all()
    np.testing.assert_allclose(nav.velocity_enu_mps, linear_velocity(stamps), atol=0)
    assert (nav.attitude_nb.inv() * constant_rate_attitude(stamps)).magnitude().max() < 1e-15


def test_gap_before_start_and_after_end_are_never_extrapolated():
    track = analytic_track(np.array([1.0, 1.05, 1.1, 1.3, 1.35]))
    queries = np.array([0.9, 1.02, 1.2, 1.32, 1.4, np.nan])
    nav = track.interpolate(queries)
    expected = [
        InterpolationStatus.BEFORE_START,
        InterpolationStatus.OK,
        InterpolationStatus.GAP,
        InterpolationStatus.OK,
        InterpolationStatus.AFTER_END,
        InterpolationStatus.INVALID_STAMP,
    ]
    np.testing.assert_array_equal(nav.status, expected)
    np.testing.assert_array_equal(nav.valid, [False, True, False, True, False, False])
    assert np.isnan(nav.velocity_enu_mps[~nav.valid]).all()
    assert np.isnan(nav.angular_rate_body_rad_s[~nav.valid]).all()


def test_gap_limit_is_inclusive():
    track = NavTrack(max_gap_s=0.25)
    for t in (0.0, 0.25, 0.75):
        track.append(t, [0, 0, 0, 1], np.zeros(3), np.zeros(3))
    nav = track.interpolate([0.1, 0.5])
    np.testing.assert_array_equal(nav.status, [InterpolationStatus.OK, InterpolationStatus.GAP])


def test_empty_track_waits_for_samples():
    nav = NavTrack().interpolate([0.0, 5.0])
    np.testing.assert_array_equal(nav.status, [InterpolationStatus.AFTER_END] * 2)
    assert len(NavTrack().interpolate([]).valid) == 0


def test_slerp_takes_the_short_arc_whatever_the_quaternion_sign():
    stamps = np.arange(0.0, 1.0, 0.05)
    quats = constant_rate_attitude(stamps).as_quat()
    flipped = quats * np.where(np.arange(len(stamps)) % 2 == 0, 1.0, -1.0)[:, None]
    rates, velocities = linear_rate(stamps), linear_velocity(stamps)
    plain = NavTrack.from_arrays(stamps, quats, rates, velocities)
    signed = NavTrack.from_arrays(stamps, flipped, rates, velocities)
    queries = stamps[:-1] + 0.02
    plain_attitude = plain.interpolate(queries).attitude_nb
    difference = plain_attitude.inv() * signed.interpolate(queries).attitude_nb
    assert difference.magnitude().max() < 1e-12


def test_rejected_samples_are_counted_and_do_not_enter_the_track():
    track = NavTrack()
    good = ([0, 0, 0, 1], np.zeros(3), np.zeros(3))
    assert track.append(1.0, *good)
    assert not track.append(1.0, *good)  # duplicate stamp
    assert not track.append(0.5, *good)  # backwards
    assert not track.append(1.1, [0, 0, 0, 0], np.zeros(3), np.zeros(3))
    assert not track.append(1.2, [0, 0, 0, 1], [np.nan, 0, 0], np.zeros(3))
    assert not track.append(np.inf, *good)
    assert track.append(1.05, *good)
    assert (track.n_accepted, track.n_rejected_out_of_order, track.n_rejected_invalid) == (2, 2, 3)
    assert len(track) == 2


def test_from_arrays_matches_appending_one_by_one():
    rng = np.random.default_rng(22)
    stamps = np.cumsum(rng.uniform(0.005, 0.04, 400))
    stamps[[50, 51, 200]] = stamps[[49, 30, 150]]  # duplicate and backwards stamps
    quats = rng.normal(size=(400, 4))
    quats[77] = 0.0
    rates = rng.normal(size=(400, 3))
    rates[90, 1] = np.nan
    velocities = rng.normal(size=(400, 3))
    batch = NavTrack.from_arrays(stamps, quats, rates, velocities)
    streamed = NavTrack()
    for row in zip(stamps, quats, rates, velocities, strict=True):
        streamed.append(*row)
    assert (batch.n_accepted, batch.n_rejected_out_of_order, batch.n_rejected_invalid) == (
        streamed.n_accepted,
        streamed.n_rejected_out_of_order,
        streamed.n_rejected_invalid,
    )
    queries = np.sort(rng.uniform(stamps[0] - 0.5, stamps.max() + 0.5, 1000))
    a, b = batch.interpolate(queries), streamed.interpolate(queries)
    np.testing.assert_array_equal(a.status, b.status)
    np.testing.assert_array_equal(a.attitude_nb.as_quat(), b.attitude_nb.as_quat())
    np.testing.assert_array_equal(a.velocity_enu_mps, b.velocity_enu_mps)
    np.testing.assert_array_equal(a.angular_rate_body_rad_s, b.angular_rate_body_rad_s)


def test_extending_in_chunks_matches_appending_one_by_one_with_bounded_history():
    rng = np.random.default_rng(23)
    stamps = np.cumsum(rng.uniform(0.005, 0.04, 600))
    stamps[[120, 121, 300]] = stamps[[119, 100, 250]]  # duplicate and backwards stamps
    quats = rng.normal(size=(600, 4))
    quats[333] = 0.0
    rates = rng.normal(size=(600, 3))
    rates[90, 1] = np.inf
    velocities = rng.normal(size=(600, 3))
    chunked, streamed = NavTrack(history_s=2.0), NavTrack(history_s=2.0)
    boundaries = np.sort(rng.choice(np.arange(1, 600), 40, replace=False))
    queries_per_chunk = []
    for chunk in np.split(np.arange(600), boundaries):
        chunked.extend(stamps[chunk], quats[chunk], rates[chunk], velocities[chunk])
        chunked.forget_old_samples()
        for i in chunk:
            streamed.append(stamps[i], quats[i], rates[i], velocities[i])
            streamed.forget_old_samples()
        queries = rng.uniform(stamps[chunk[0]] - 3.0, stamps[chunk[-1]] + 0.1, 50)
        queries_per_chunk.append((chunked.interpolate(queries), streamed.interpolate(queries)))
        assert len(chunked) == len(streamed)
    assert (chunked.n_accepted, chunked.n_rejected_out_of_order, chunked.n_rejected_invalid) == (
        streamed.n_accepted,
        streamed.n_rejected_out_of_order,
        streamed.n_rejected_invalid,
    )
    assert chunked.n_rejected_invalid == 2 and chunked.n_rejected_out_of_order == 3
    for a, b in queries_per_chunk:
        np.testing.assert_array_equal(a.status, b.status)
        np.testing.assert_array_equal(a.attitude_nb.as_quat(), b.attitude_nb.as_quat())
        np.testing.assert_array_equal(a.velocity_enu_mps, b.velocity_enu_mps)


def test_one_stamp_alone_is_interpolated_exactly_as_in_a_batch_for_every_outcome():
    rng = np.random.default_rng(24)
    stamps = np.cumsum(rng.uniform(0.005, 0.04, 300))
    stamps[270:] += 0.5  # a gap longer than max_gap_s, inside the kept history
    quats = rng.normal(size=(300, 4))
    rates = rng.normal(size=(300, 3))
    velocities = rng.normal(size=(300, 3))
    trusted = np.ones(300, dtype=bool)
    trusted[280] = False  # one sample the navigation does not vouch for
    track = NavTrack(history_s=3.0)
    track.extend(stamps, quats, rates, velocities, trusted)
    track.forget_old_samples()
    queries = np.concatenate(
        (
            rng.uniform(stamps[0] - 1.0, stamps[-1] + 1.0, 2000),
            stamps[-50:],  # exactly on samples
            [stamps[0] - 0.1, track.oldest_stamp_s - 0.1, stamps[-1] + 0.1, np.nan, np.inf],
        )
    )
    batch = track.interpolate(queries)
    assert set(batch.status.tolist()) == set(InterpolationStatus)
    for k, query in enumerate(queries.tolist()):
        one = track.interpolate([query])
        assert one.status[0] == batch.status[k]
        np.testing.assert_array_equal(one.attitude_xyzw[0], batch.attitude_xyzw[k])
        np.testing.assert_array_equal(
            one.angular_rate_body_rad_s[0], batch.angular_rate_body_rad_s[k]
        )
        np.testing.assert_array_equal(one.velocity_enu_mps[0], batch.velocity_enu_mps[k])
    assert NavTrack().interpolate([1.0]).status[0] == InterpolationStatus.AFTER_END


def test_history_is_bounded_and_old_stamps_are_reported_evicted():
    stamps = np.arange(0.0, 60.0, 0.01)
    track = analytic_track(stamps, history_s=1.0)
    track.forget_old_samples()
    assert len(track) <= 102
    assert track.oldest_stamp_s <= track.newest_stamp_s - 1.0
    nav = track.interpolate([-1.0, 30.0, track.newest_stamp_s - 1.0 + 1e-3])
    np.testing.assert_array_equal(
        nav.status,
        [InterpolationStatus.BEFORE_START, InterpolationStatus.EVICTED, InterpolationStatus.OK],
    )


def test_queries_as_of_an_earlier_newest_stamp_are_answered_with_the_history_then():
    rng = np.random.default_rng(25)
    stamps = np.cumsum(rng.uniform(0.005, 0.04, 800))
    quats, rates, velocities = (rng.normal(size=(800, n)) for n in (4, 3, 3))
    whole = NavTrack(history_s=2.0)
    whole.extend(stamps, quats, rates, velocities)
    unbounded = NavTrack.from_arrays(stamps, quats, rates, velocities)
    queries = rng.uniform(stamps[0] - 0.5, stamps[-1] + 0.5, 3000)
    as_of_index = rng.integers(0, 800, 3000)
    later = whole.interpolate(queries, as_of_newest_s=stamps[as_of_index])
    for k in range(0, 3000, 37):
        as_of_s = float(stamps[as_of_index[k]])
        if queries[k] <= as_of_s:
            # Asked when the newest sample was as_of_s: the track as it stood then answers.
            reference = NavTrack(history_s=2.0)
            n = as_of_index[k] + 1
            reference.extend(stamps[:n], quats[:n], rates[:n], velocities[:n])
            reference.forget_old_samples()
        else:
            # Asked before the samples around it arrived: none of them was forgotten by then.
            reference = unbounded
        expected = reference.interpolate(queries[k : k + 1])
        assert later.status[k] == expected.status[0]
        np.testing.assert_array_equal(later.velocity_enu_mps[k], expected.velocity_enu_mps[0])
        one = whole.interpolate(queries[k : k + 1], as_of_s)
        assert one.status[0] == later.status[k]
        np.testing.assert_array_equal(one.velocity_enu_mps[0], later.velocity_enu_mps[k])
    assert {InterpolationStatus.EVICTED, InterpolationStatus.OK} <= set(later.status.tolist())
    # Asked before any sample arrived: nothing was forgotten.
    early = whole.interpolate(stamps[5:6] + 0.001, as_of_newest_s=-np.inf)
    assert early.status[0] == InterpolationStatus.OK


def test_malformed_arguments_raise():
    with pytest.raises(NavTrackError, match="max_gap_s"):
        NavTrack(max_gap_s=0.0)
    with pytest.raises(NavTrackError, match="quat_xyzw"):
        NavTrack().append(0.0, [0, 0, 1], np.zeros(3), np.zeros(3))
    with pytest.raises(NavTrackError, match="t_query_s"):
        NavTrack().interpolate(np.zeros((2, 2)))


def test_quaternion_arithmetic_agrees_with_scipy_and_is_the_same_alone_or_in_a_batch():
    rng = np.random.default_rng(5)
    start = Rotation.random(200, random_state=rng)
    # Steps from 1e-9 rad (a 100 Hz track at rest) to nearly half a turn.
    angles = np.geomspace(1e-9, 3.0, 200)
    axes = rng.normal(size=(200, 3))
    axes /= np.linalg.norm(axes, axis=1, keepdims=True)
    end = start * Rotation.from_rotvec(axes * angles[:, None])
    fraction = rng.uniform(0.0, 1.0, 200)
    # The sign of a quaternion must not matter: flip half of the ends.
    end_xyzw = end.as_quat() * np.where(rng.uniform(size=200) < 0.5, -1.0, 1.0)[:, None]

    blended = slerp(start.as_quat(), end_xyzw, fraction)
    expected = start * Rotation.from_rotvec(axes * (angles * fraction)[:, None])
    assert (Rotation.from_quat(blended).inv() * expected).magnitude().max() < 1e-14
    np.testing.assert_allclose(np.linalg.norm(blended, axis=1), 1.0, atol=1e-15)

    # One quaternion in plain floats (the live path) gives the batch's bits.
    one_by_one = np.array(
        [
            slerp_components(
                tuple(start.as_quat()[k].tolist()),
                tuple(end_xyzw[k].tolist()),
                float(fraction[k]),
            )
            for k in range(200)
        ],
        dtype=float,
    )
    np.testing.assert_array_equal(one_by_one, blended)

    np.testing.assert_allclose(
        np.stack(rotation_matrix_elements(*blended.T), axis=1).reshape(-1, 3, 3),
        Rotation.from_quat(blended).as_matrix(),
        atol=1e-15,
    )
    product = np.stack(
        quaternion_multiply(tuple(start.as_quat().T), tuple(end.as_quat().T)), axis=1
    )
    np.testing.assert_allclose(
        Rotation.from_quat(product).as_matrix(), (start * end).as_matrix(), atol=1e-15
    )
