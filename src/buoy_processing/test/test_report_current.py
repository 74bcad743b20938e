"""The current's accuracy figures on synthetic series: window means compared as the products
are, and the two laws of averaging: white noise falls as 1/√T, the waves' orbital velocity as
1/T (its mean over a window is the water's displacement over the window divided by T)."""

import numpy as np
import pytest

from buoy_processing.report.current import CurrentData, error_by_window_length, window_errors

RATE_HZ = 1.0


def test_window_errors_compare_the_means_over_the_same_samples():
    t = np.arange(0.0, 1800.0, 1.0 / RATE_HZ)
    reference = np.tile([0.3, 0.0, 0.0], (t.size, 1))  # toward East
    estimate = reference + np.array([0.0, 0.01, 0.0])  # 1 cm/s northward: turned to the left
    estimate[700:720] = np.nan  # 20 of 600 samples of the second window: still counts
    estimate[1300:1400] = np.nan  # 100 of 600 of the third: does not
    errors = window_errors(t, estimate, reference, 600.0)
    np.testing.assert_array_equal(errors.window_start_s, [0.0, 600.0])
    np.testing.assert_allclose(errors.vector_error_mps, 0.01, rtol=1e-9)
    np.testing.assert_allclose(errors.reference_speed_mps, 0.3, rtol=1e-12)
    np.testing.assert_allclose(errors.speed_error_mps, np.hypot(0.3, 0.01) - 0.3, rtol=1e-9)
    # Toward East is 90°; turned toward North the direction decreases.
    expected_deg = np.degrees(np.arctan2(0.3, 0.01)) - 90.0
    np.testing.assert_allclose(errors.direction_error_deg, expected_deg, rtol=1e-9)
    assert expected_deg < 0.0


def test_a_window_not_covered_by_the_data_does_not_count():
    t = np.arange(300.0, 1500.0)  # starts half-way into the first 600 s window
    series = np.tile([0.2, 0.1, 0.0], (t.size, 1))
    errors = window_errors(t, series, series, 600.0)
    np.testing.assert_array_equal(errors.window_start_s, [600.0])


def test_averaging_removes_noise_as_one_over_root_t_and_waves_as_one_over_t():
    rng = np.random.default_rng(5)
    t = np.arange(0.0, 4 * 3600.0, 1.0 / RATE_HZ)
    current = np.tile([0.25, -0.1, 0.0], (t.size, 1))
    # A random sea of 40 components between 6 and 12 s at the DVL's depth.
    periods = rng.uniform(6.0, 12.0, 40)
    amplitudes = rng.uniform(0.02, 0.06, 40)
    phases = rng.uniform(0.0, 2 * np.pi, (40, 2))
    orbital = np.zeros((t.size, 3))
    for period, amplitude, (phase_x, phase_y) in zip(periods, amplitudes, phases, strict=True):
        omega = 2 * np.pi / period
        orbital[:, 0] += amplitude * np.sin(omega * t + phase_x)
        orbital[:, 1] += amplitude * np.sin(omega * t + phase_y)
    water = current + orbital
    noise_mps = 0.02
    estimate = water + rng.normal(0.0, noise_mps, (t.size, 3))
    rows = error_by_window_length(CurrentData(t, estimate, [], current, water), (60.0, 600.0))
    single, minute, ten_minutes = rows
    # Single samples: the orbital velocity's RMS and the noise's.
    assert single.water_vs_current_mps == pytest.approx(
        np.sqrt(np.mean(np.hypot(orbital[:, 0], orbital[:, 1]) ** 2)), rel=1e-9
    )
    assert single.estimate_vs_water_mps == pytest.approx(noise_mps * np.sqrt(2.0), rel=0.05)
    # White noise: the horizontal error of a T-sample mean is noise √(2/T).
    for row in (minute, ten_minutes):
        expected = noise_mps * np.sqrt(2.0 / (row.window_s * RATE_HZ))
        assert row.estimate_vs_water_mps == pytest.approx(expected, rel=0.25)
    # The waves: (ξ(t+T) − ξ(t)) / T, so ten times the window leaves a tenth, not a third.
    ratio = minute.water_vs_current_mps / ten_minutes.water_vs_current_mps
    assert 6.0 < ratio < 16.0
    assert ten_minutes.n_windows == 24 and minute.n_windows == 240


def test_the_error_by_window_length_needs_both_truths():
    t = np.arange(0.0, 100.0)
    data = CurrentData(t, np.zeros((t.size, 3)), [], None, np.zeros((t.size, 3)))
    with pytest.raises(ValueError, match="truth/current"):
        error_by_window_length(data)
