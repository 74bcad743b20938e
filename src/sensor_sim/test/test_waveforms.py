"""Smooth waveforms: ramps cover their travel at the set rate with continuous derivatives."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.integrate import cumulative_trapezoid

from sensor_sim.waveforms import RampProfile, Sinusoids


def test_ramp_travel_rate_and_timing():
    profile = RampProfile.from_waypoints(
        start_s=2.0,
        initial_value=0.0,
        targets=[3.0, -1.0, -1.2],
        holds_s=[1.0, 0.5, 0.0],
        rate=1.5,
        corner_s=0.4,
    )
    t = np.linspace(0.0, 12.0, 120001)
    value, rate, accel = profile.evaluate(t)
    assert np.all(value[t <= 2.0] == 0.0)
    # Ramp 1: 3 / 1.5 = 2 s at full rate plus 0.4 s of corners, then a 1 s hold at 3.
    assert value[np.searchsorted(t, 4.4)] == pytest.approx(3.0, abs=1e-12)
    assert np.all(np.abs(value[(t >= 4.4) & (t <= 5.4)] - 3.0) < 1e-12)
    assert np.max(np.abs(rate)) == pytest.approx(1.5, abs=1e-12)
    # The short last ramp (0.2 in 0.133 s < corner) still peaks at the rate and lands exactly.
    assert value[-1] == pytest.approx(-1.2, abs=1e-12)
    arrival_s = 2.0 + 2.4 + 1.0 + (4.0 / 1.5 + 0.4) + 0.5 + 2 * 0.2 / 1.5
    np.testing.assert_allclose(value[t >= arrival_s], -1.2, atol=1e-12)
    assert np.all(value[t < arrival_s - 1e-3] > -1.2 + 1e-9)
    # Derivatives integrate back and are continuous (no jumps between neighbouring samples).
    np.testing.assert_allclose(cumulative_trapezoid(rate, t), value[1:] - value[0], atol=1e-8)
    np.testing.assert_allclose(cumulative_trapezoid(accel, t), rate[1:] - rate[0], atol=2e-6)
    step = t[1] - t[0]
    # The shortest corner (the 0.2 ramp's 0.2/1.5 s) sets the largest rate change r pi / (2 tau).
    peak_accel = 1.5 * np.pi / (2 * 0.2 / 1.5)
    assert np.max(np.abs(accel)) == pytest.approx(peak_accel, rel=1e-6)
    assert np.max(np.abs(np.diff(rate))) <= peak_accel * step * 1.0001
    peak_jerk = 1.5 * np.pi**2 / (2 * (0.2 / 1.5) ** 2)
    assert np.max(np.abs(np.diff(accel))) <= peak_jerk * step * 1.0001


def test_zero_travel_ramps_only_hold():
    profile = RampProfile.from_waypoints(0.0, 1.0, [1.0, 1.0], [2.0, 2.0], rate=1.0, corner_s=0.5)
    value, rate, accel = profile.evaluate(np.linspace(-1.0, 10.0, 111))
    assert np.all(value == 1.0)
    assert np.all(rate == 0.0)
    assert np.all(accel == 0.0)


def test_ramp_arguments_are_checked():
    with pytest.raises(ValueError, match="positive"):
        RampProfile.from_waypoints(0.0, 0.0, [1.0], [0.0], rate=0.0, corner_s=0.5)


def test_sinusoid_derivatives():
    wave = Sinusoids.single(2.0, 4.0, 0.3)
    t = np.linspace(0.0, 10.0, 5)
    value, rate, accel = wave.evaluate(t)
    omega = 2 * np.pi / 4.0
    np.testing.assert_allclose(value, 2.0 * np.sin(omega * t + 0.3))
    np.testing.assert_allclose(rate, 2.0 * omega * np.cos(omega * t + 0.3))
    np.testing.assert_allclose(accel, -(omega**2) * value)
