"""The wave-band figures of a motion correction, on series whose answer is known."""

import numpy as np
import pytest

from wind_comp.motion_residual import (
    SEGMENT_S,
    motion_residual,
    platform_velocity_left,
    vertical_acceleration_mps2,
    wave_band_hz,
)

RATE_HZ = 10.0
DURATION_S = 1200.0


@pytest.fixture
def sea():
    """Twenty minutes of a buoy heaving in a narrow band of waves around 0.15 Hz, and turbulence
    (white, 0.3 m/s) that knows nothing of it."""
    rng = np.random.default_rng(7)
    t = np.arange(0.0, DURATION_S, 1.0 / RATE_HZ)
    frequencies = rng.uniform(0.12, 0.18, 12)
    phases = rng.uniform(0.0, 2.0 * np.pi, 12)

    def heave_velocity(delay_s=0.0):
        return sum(
            0.15 * np.sin(2.0 * np.pi * f * (t - delay_s) + p)
            for f, p in zip(frequencies, phases, strict=True)
        )

    heave_acceleration = sum(
        0.15 * 2.0 * np.pi * f * np.cos(2.0 * np.pi * f * t + p)
        for f, p in zip(frequencies, phases, strict=True)
    )
    turbulence = 0.3 * rng.standard_normal(t.size)
    return t, heave_velocity, heave_acceleration, turbulence


def test_the_wave_band_surrounds_the_heave(sea):
    _, _, heave_acceleration, _ = sea
    low, high = wave_band_hz(heave_acceleration, RATE_HZ)
    assert 0.10 <= low <= 0.12 and 0.18 <= high <= 0.20


def test_the_vertical_acceleration_needs_no_attitude():
    """|f| − mean|f| of a buoy tilted by 20° that heaves: the heave, whatever the tilt."""
    heave = 0.5 * np.sin(np.linspace(0.0, 20.0 * np.pi, 2000))
    tilt = np.radians(20.0)
    force = (
        np.column_stack([np.full(2000, np.sin(tilt)), np.zeros(2000), np.full(2000, np.cos(tilt))])
        * (9.81 + heave)[:, None]
    )
    np.testing.assert_allclose(vertical_acceleration_mps2(force), heave - heave.mean(), atol=1e-9)


def test_a_perfect_correction_leaves_the_turbulence_and_no_coherence(sea):
    _, heave_velocity, heave_acceleration, turbulence = sea
    measured = turbulence - heave_velocity()
    band = wave_band_hz(heave_acceleration, RATE_HZ)
    result = motion_residual(measured, turbulence, heave_acceleration, RATE_HZ)
    # White turbulence of 0.3 m/s puts 2 σ² Δf / rate of its variance in a band Δf wide; the band
    # takes whole spectral bins, edges included (one bin, 1/SEGMENT_S, more than high − low).
    width_hz = band[1] - band[0] + 1.0 / SEGMENT_S
    turbulence_in_band = 0.3**2 * width_hz * 2.0 / RATE_HZ
    heave_variance = np.var(heave_velocity())
    assert result.variance_share == pytest.approx(
        turbulence_in_band / (turbulence_in_band + heave_variance), rel=0.15
    )
    assert result.coherence_before > 0.9
    assert result.coherence_after < 0.1


@pytest.mark.parametrize("gain", [0.8, 1.0, 1.1])
def test_a_correction_with_the_wrong_gain_leaves_its_error_in_phase(sea, gain):
    _, heave_velocity, heave_acceleration, turbulence = sea
    band = wave_band_hz(heave_acceleration, RATE_HZ)
    corrected = turbulence + (1.0 - gain) * heave_velocity()
    left = platform_velocity_left(corrected, heave_velocity(), RATE_HZ, band)
    assert left.real == pytest.approx(1.0 - gain, abs=0.02)
    assert abs(left.imag) < 0.02


def test_a_late_correction_leaves_its_error_a_quarter_period_out_of_phase(sea):
    """The correction applied 0.2 s late: v(t) − v(t − δ) ≈ ω δ in quadrature, and the real
    part 1 − cos(ω δ) ≈ 0.02 at 0.15 Hz."""
    _, heave_velocity, heave_acceleration, turbulence = sea
    band = wave_band_hz(heave_acceleration, RATE_HZ)
    delay_s = 0.2
    corrected = turbulence + heave_velocity() - heave_velocity(delay_s)
    left = platform_velocity_left(corrected, heave_velocity(), RATE_HZ, band)
    omega_delay = 2.0 * np.pi * 0.15 * delay_s
    assert left.imag == pytest.approx(omega_delay, rel=0.15)
    assert left.real == pytest.approx(1.0 - np.cos(omega_delay), abs=0.02)
