"""Averaged wind and current products on analytic windows; the meteorological and oceanographic
direction conventions."""

import numpy as np
import pytest

from wind_comp.products import (
    CurrentAverager,
    ProductsError,
    QualityFlag,
    WindAverager,
    meteorological_direction_deg,
    oceanographic_direction_deg,
)

RATE_HZ = 10.0


def regular_stamps(start_s, stop_s):
    return np.arange(round(start_s * RATE_HZ), round(stop_s * RATE_HZ)) / RATE_HZ


@pytest.mark.parametrize(
    ("u_east", "v_north", "from_deg"),
    [
        (1.0, 0.0, 270.0),  # toward East, from West
        (0.0, 1.0, 180.0),  # toward North, from South
        (-1.0, 0.0, 90.0),  # toward West, from East
        (0.0, -1.0, 0.0),  # toward South, from North
        (1.0, 1.0, 225.0),  # toward North-East, from South-West
        (-2.0, -2.0, 45.0),
    ],
)
def test_meteorological_direction_conventions(u_east, v_north, from_deg):
    assert meteorological_direction_deg(u_east, v_north) == pytest.approx(from_deg, abs=1e-12)


def test_direction_stays_in_range_and_calm_is_undefined():
    # Wind toward South with a hair of eastward drift comes from just under 360°.
    tiny_east = np.geomspace(1e-20, 1e-12, 50)
    directions = meteorological_direction_deg(tiny_east, -np.ones_like(tiny_east))
    assert directions.min() >= 0.0 and directions.max() < 360.0
    angles = np.linspace(-np.pi, np.pi, 1001)
    directions = meteorological_direction_deg(np.cos(angles), np.sin(angles))
    assert directions.min() >= 0.0 and directions.max() < 360.0
    assert np.isnan(meteorological_direction_deg(0.0, 0.0))


def test_constant_wind_window():
    stamps = regular_stamps(0.0, 60.0)
    wind = np.tile([3.0, 4.0, 0.2], (len(stamps), 1))
    averager = WindAverager(window_s=60.0)
    assert averager.add_batch(stamps, wind) == []
    (product,) = averager.flush()
    assert (product.window_start_s, product.window_end_s) == (0.0, 60.0)
    assert (product.n_valid, product.n_invalid) == (600, 0)
    assert product.vector_mean_speed_mps == pytest.approx(5.0, abs=1e-12)
    assert product.scalar_mean_speed_mps == pytest.approx(5.0, abs=1e-12)
    assert product.gust_mps == pytest.approx(5.0, abs=1e-12)
    assert product.mean_w_enu_mps == pytest.approx(0.2, abs=1e-12)
    assert product.vector_mean_direction_deg == pytest.approx(
        np.degrees(np.arctan2(-3.0, -4.0)) % 360.0
    )
    for std in (product.std_u_mps, product.std_v_mps, product.std_w_mps):
        assert std == pytest.approx(0.0, abs=1e-12)


def test_rotating_wind_has_small_vector_mean_and_full_scalar_mean():
    stamps = regular_stamps(0.0, 60.0)
    angle = 2 * np.pi * stamps / 60.0  # one full turn per window
    wind = np.column_stack((8.0 * np.cos(angle), 8.0 * np.sin(angle), np.zeros_like(angle)))
    averager = WindAverager(window_s=60.0)
    averager.add_batch(stamps, wind)
    (product,) = averager.flush()
    assert product.scalar_mean_speed_mps == pytest.approx(8.0, abs=1e-12)
    assert product.vector_mean_speed_mps < 1e-9
    # Uniform phase: each component has standard deviation amplitude/√2.
    assert product.std_u_mps == pytest.approx(8.0 / np.sqrt(2), rel=1e-9)
    assert product.std_v_mps == pytest.approx(8.0 / np.sqrt(2), rel=1e-9)


def test_vector_mean_never_exceeds_scalar_mean():
    rng = np.random.default_rng(41)
    stamps = regular_stamps(0.0, 600.0)
    wind = rng.normal(loc=[2.0, -1.0, 0.0], scale=3.0, size=(len(stamps), 3))
    averager = WindAverager(window_s=60.0)
    products = averager.add_batch(stamps, wind) + averager.flush()
    assert len(products) == 10
    for product in products:
        assert product.vector_mean_speed_mps <= product.scalar_mean_speed_mps
        assert product.gust_mps >= product.scalar_mean_speed_mps


def test_windows_are_aligned_to_multiples_of_their_length():
    stamps = regular_stamps(30.0, 150.0)
    wind = np.tile([1.0, 0.0, 0.0], (len(stamps), 1))
    averager = WindAverager(window_s=60.0)
    products = averager.add_batch(stamps, wind)
    assert [(p.window_start_s, p.window_end_s) for p in products] == [(0.0, 60.0), (60.0, 120.0)]
    (last,) = averager.flush()
    assert (last.window_start_s, last.first_sample_s, last.last_sample_s) == (120.0, 120.0, 149.9)
    assert [p.n_valid for p in [*products, last]] == [300, 600, 300]
    # The first window holds only 30 s of data, so no 3 s mean starts before its data.
    assert products[0].first_sample_s == 30.0


def test_gust_is_the_largest_three_second_mean():
    stamps = regular_stamps(0.0, 60.0)
    speed = np.full(len(stamps), 5.0)
    speed[(stamps >= 20.0) & (stamps < 21.0)] = 11.0  # 1 s burst: 3 s mean 5 + 6/3
    speed[(stamps >= 40.0) & (stamps < 40.5)] = 14.0  # 0.5 s burst: 3 s mean 5 + 9/6
    wind = np.column_stack((np.zeros_like(speed), -speed, np.zeros_like(speed)))
    averager = WindAverager(window_s=60.0, gust_window_s=3.0)
    averager.add_batch(stamps, wind)
    (product,) = averager.flush()
    assert product.gust_mps == pytest.approx(7.0, abs=1e-12)
    assert product.vector_mean_direction_deg == pytest.approx(0.0, abs=1e-12)


def test_gust_running_mean_reaches_into_the_previous_window():
    stamps = regular_stamps(0.0, 120.0)
    speed = np.full(len(stamps), 4.0)
    speed[(stamps >= 58.5) & (stamps < 61.5)] = 10.0  # 3 s burst straddling the boundary
    wind = np.column_stack((speed, np.zeros_like(speed), np.zeros_like(speed)))
    averager = WindAverager(window_s=60.0)
    first, second = averager.add_batch(stamps, wind) + averager.flush()
    assert second.gust_mps == pytest.approx(10.0, abs=1e-12)
    assert first.gust_mps == pytest.approx(4.0 + 6.0 * 1.5 / 3.0, abs=1e-12)


def test_invalid_samples_are_counted_but_not_averaged():
    stamps = regular_stamps(0.0, 60.0)
    wind = np.tile([2.0, 0.0, 0.0], (len(stamps), 1))
    wind[::10] = [1e6, np.nan, 1e6]
    averager = WindAverager(window_s=60.0)
    averager.add_batch(stamps, wind)
    (product,) = averager.flush()
    assert (product.n_valid, product.n_invalid) == (540, 60)
    assert product.scalar_mean_speed_mps == pytest.approx(2.0, abs=1e-12)
    assert product.gust_mps == pytest.approx(2.0, abs=1e-12)


def test_window_with_only_invalid_samples_has_nan_statistics():
    averager = WindAverager(window_s=60.0)
    averager.add_batch(regular_stamps(0.0, 10.0), np.full((100, 3), np.nan))
    (product,) = averager.flush()
    assert (product.n_valid, product.n_invalid) == (0, 100)
    assert np.isnan([product.vector_mean_speed_mps, product.gust_mps, product.std_w_mps]).all()


def test_stamps_going_backwards_are_ignored_and_counted():
    averager = WindAverager(window_s=60.0)
    averager.add(1.0, [1.0, 0.0, 0.0])
    averager.add(1.0, [9.0, 0.0, 0.0])
    averager.add(0.5, [9.0, 0.0, 0.0])
    averager.add(np.nan, [9.0, 0.0, 0.0])
    averager.add(1.1, [1.0, 0.0, 0.0])
    (product,) = averager.flush()
    assert averager.n_rejected_stamps == 3
    assert product.n_valid == 2 and product.scalar_mean_speed_mps == 1.0


def test_streaming_equals_batch():
    rng = np.random.default_rng(42)
    stamps = np.cumsum(rng.uniform(0.05, 0.15, 3000))
    wind = rng.normal(loc=[5.0, 2.0, 0.0], scale=2.0, size=(len(stamps), 3))
    wind[rng.integers(0, len(stamps), 100)] = np.nan
    stamps[[500, 1200]] = stamps[[499, 1000]]  # a repeated and a backwards stamp
    stamps[2000] = np.nan
    batch = WindAverager(window_s=60.0)
    batch_products = batch.add_batch(stamps, wind) + batch.flush()
    streaming = WindAverager(window_s=60.0)
    streamed_products = []
    for t, sample in zip(stamps, wind, strict=True):
        streamed_products += streaming.add(t, sample)
    streamed_products += streaming.flush()
    assert streamed_products == batch_products
    assert len(batch_products) >= 5
    in_parts = WindAverager(window_s=60.0)
    parts_products = []
    for part in np.array_split(np.arange(len(stamps)), 37):
        parts_products += in_parts.add_batch(stamps[part], wind[part])
    assert parts_products + in_parts.flush() == batch_products
    assert batch.n_rejected_stamps == streaming.n_rejected_stamps == in_parts.n_rejected_stamps == 3


def test_coverage_counts_the_valid_samples_of_a_full_window_and_flags_the_short_ones():
    stamps = np.concatenate(
        (
            regular_stamps(0.0, 60.0),  # full
            regular_stamps(60.0, 70.0),  # then a 15 s gap: three quarters
            regular_stamps(85.0, 120.0),
            regular_stamps(120.0, 180.0),  # invalid after its first 15 s: a quarter
            [180.0],  # a lone sample: the trailing window of a record cut short
            regular_stamps(240.0, 300.0),  # all invalid
        )
    )
    rng = np.random.default_rng(3)
    wind = rng.normal(loc=[6.0, -2.0, 0.0], scale=1.0, size=(len(stamps), 3))
    wind[(stamps >= 135.0) & (stamps < 180.0)] = np.nan
    wind[stamps >= 240.0] = np.nan
    averager = WindAverager(window_s=60.0)
    products = averager.add_batch(stamps, wind) + averager.flush()
    coverages = [product.coverage for product in products]
    assert coverages == pytest.approx([1.0, 0.75, 0.25, 1 / 600, 0.0], abs=0.5e-4)  # to 1e-4
    assert [product.quality_flag for product in products] == [
        QualityFlag.GOOD,
        QualityFlag.SUSPECT,
        QualityFlag.BAD,
        QualityFlag.BAD,
        QualityFlag.MISSING,
    ]
    lone = products[3]
    assert lone.n_valid == 1
    # One sample has no spread: not a standard deviation of 0, which reads as a steady wind.
    assert np.isnan([lone.std_u_mps, lone.std_v_mps, lone.std_w_mps]).all()


def test_coverage_is_not_evaluated_before_the_sampling_interval_is_known():
    averager = WindAverager(window_s=60.0)
    averager.add_batch(regular_stamps(0.0, 0.5), np.tile([3.0, 0.0, 0.0], (5, 1)))
    (product,) = averager.flush()
    assert np.isnan(product.coverage)
    assert product.quality_flag == QualityFlag.NOT_EVALUATED


def test_coverage_follows_a_change_of_sampling_rate():
    # 10 Hz for a minute, then 1 Hz: after the change the full 1 Hz windows are full.
    stamps = np.concatenate((regular_stamps(0.0, 60.0), np.arange(60.0, 3600.0, 1.0)))
    averager = WindAverager(window_s=600.0)
    products = averager.add_batch(stamps, np.tile([3.0, 0.0, 0.0], (len(stamps), 1)))
    assert products[-1].coverage == pytest.approx(1.0, abs=1e-12)
    assert products[-1].quality_flag == QualityFlag.GOOD


def test_bad_settings_raise():
    with pytest.raises(ProductsError, match="window_s"):
        WindAverager(window_s=0.0)
    with pytest.raises(ProductsError, match="gust_window_s"):
        WindAverager(window_s=60.0, gust_window_s=60.0)
    with pytest.raises(ProductsError, match="vector_enu_mps"):
        WindAverager().add(0.0, [1.0, 2.0])
    with pytest.raises(ProductsError, match="window_s"):
        CurrentAverager(window_s=-60.0)


@pytest.mark.parametrize(
    ("u_east", "v_north", "toward_deg"),
    [
        (1.0, 0.0, 90.0),
        (0.0, 1.0, 0.0),
        (-1.0, 0.0, 270.0),
        (0.0, -1.0, 180.0),
        (np.sqrt(3.0), 1.0, 60.0),  # paper 003's current
        (-2.0, -2.0, 225.0),
    ],
)
def test_oceanographic_direction_is_where_the_water_goes(u_east, v_north, toward_deg):
    assert oceanographic_direction_deg(u_east, v_north) == pytest.approx(toward_deg, abs=1e-12)
    # The same vector as a wind comes from the opposite side.
    from_deg = meteorological_direction_deg(u_east, v_north)
    assert (toward_deg - from_deg) % 360.0 == pytest.approx(180.0, abs=1e-12)


def test_slack_water_has_no_direction():
    assert np.isnan(oceanographic_direction_deg(0.0, 0.0))
    directions = oceanographic_direction_deg(-np.geomspace(1e-20, 1e-12, 50), np.ones(50))
    assert directions.min() >= 0.0 and directions.max() < 360.0


def test_current_window_keeps_of_the_wave_orbital_motion_its_sampled_mean():
    """A steady current plus a wave orbital velocity A sin(w t + phase) along x, sampled at
    1 Hz: the window mean is the current plus the sampled sinusoid's mean, in closed form
    (A/N) sin(phase + w (N-1)/2) sin(N w/2) / sin(w/2), and its standard deviation is the
    sinusoid's."""
    amplitude, period, phase = 0.5, 9.0, 0.7
    omega = 2.0 * np.pi / period
    current = np.array([0.3 * np.sin(np.deg2rad(120.0)), 0.3 * np.cos(np.deg2rad(120.0)), 0.0])
    stamps = np.arange(600.0, 1200.0)
    orbital = amplitude * np.sin(omega * stamps + phase)
    samples = current + np.outer(orbital, [1.0, 0.0, 0.0])
    averager = CurrentAverager(window_s=600.0)
    assert averager.add_batch(stamps, samples) == []
    (product,) = averager.flush()
    n = stamps.size
    sampled_mean = (
        amplitude
        / n
        * np.sin(omega * stamps[0] + phase + omega * (n - 1) / 2)
        * np.sin(n * omega / 2)
        / np.sin(omega / 2)
    )
    assert product.mean_u_enu_mps == pytest.approx(current[0] + sampled_mean, abs=1e-12)
    assert product.mean_v_enu_mps == pytest.approx(current[1], abs=1e-12)
    mean = np.array([product.mean_u_enu_mps, product.mean_v_enu_mps])
    assert product.speed_mps == pytest.approx(np.hypot(*mean), abs=1e-15)
    assert product.direction_deg == pytest.approx(
        np.degrees(np.arctan2(mean[0], mean[1])) % 360.0, abs=1e-12
    )
    assert abs(product.direction_deg - 120.0) < 0.2
    assert product.std_u_mps == pytest.approx(orbital.std(), abs=1e-12)
    assert product.std_v_mps == pytest.approx(0.0, abs=1e-12)
    assert (product.window_start_s, product.window_end_s) == (600.0, 1200.0)
    assert (product.n_valid, product.n_invalid) == (600, 0)


def test_current_streaming_equals_batch_and_invalid_samples_are_counted():
    rng = np.random.default_rng(3)
    stamps = np.arange(0.0, 1900.0)
    currents = rng.normal([0.2, -0.1, 0.0], 0.3, (stamps.size, 3))
    currents[rng.uniform(size=stamps.size) < 0.05] = np.nan
    streaming = CurrentAverager(600.0)
    one_by_one = [p for t, c in zip(stamps, currents, strict=True) for p in streaming.add(t, c)]
    one_by_one += streaming.flush()
    batched = CurrentAverager(600.0)
    in_batches = batched.add_batch(stamps[:700], currents[:700])
    in_batches += batched.add_batch(stamps[700:], currents[700:]) + batched.flush()
    assert one_by_one == in_batches
    assert [p.window_start_s for p in in_batches] == [0.0, 600.0, 1200.0, 1800.0]
    for product in in_batches:
        inside = (stamps >= product.window_start_s) & (stamps < product.window_end_s)
        valid = inside & np.all(np.isfinite(currents), axis=1)
        assert product.n_valid == np.count_nonzero(valid)
        assert product.n_invalid == np.count_nonzero(inside & ~valid)
        np.testing.assert_allclose(
            [product.mean_u_enu_mps, product.mean_v_enu_mps, product.mean_w_enu_mps],
            currents[valid].mean(axis=0),
            atol=1e-15,
        )
