"""The IMU screening: real motion passes, changes no platform can make do not."""

import math
from pathlib import Path

import numpy as np
import pytest

from buoy_common.bag_io import BagReader
from buoy_nav.config import FusionConfig
from buoy_nav.imu_screening import ImuPlausibility

BAGS = Path(__file__).resolve().parents[3] / "bags"
RATE_HZ = 100.0


def default_screening() -> ImuPlausibility:
    config = FusionConfig()
    return ImuPlausibility(
        config.max_angular_acceleration_rad_s2,
        config.max_jerk_mps3,
        math.radians(config.gyro_noise_deg_sqrt_h) / 60.0,
        config.accel_noise_mps_sqrt_h / 60.0,
    )


def screen(screening, stamps_s, gyros, forces) -> np.ndarray:
    return np.array(
        [
            screening.plausible(float(t), tuple(g), tuple(f))
            for t, g, f in zip(stamps_s, gyros, forces, strict=True)
        ]
    )


@pytest.mark.parametrize("bag", ["open_ocean", "tilt_table", "wind_tunnel_10", "sea_state"])
def test_the_recorded_scenarios_lose_no_sample(bag):
    """Waves, the tilt table and the tunnel's 10°/s turns, with the simulated sensor noise."""
    with BagReader(BAGS / bag) as reader:
        messages = [reader.decode(m) for m in reader.messages(["imu/data_raw"])]
    stamps = [m.header.stamp.sec + m.header.stamp.nanosec * 1e-9 for m in messages]
    gyros = [(m.angular_velocity.x, m.angular_velocity.y, m.angular_velocity.z) for m in messages]
    forces = [
        (m.linear_acceleration.x, m.linear_acceleration.y, m.linear_acceleration.z)
        for m in messages
    ]
    assert screen(default_screening(), stamps, gyros, forces).all()


def test_motion_at_the_angular_acceleration_limit_passes_and_a_spike_does_not():
    config = FusionConfig()
    limit = config.max_angular_acceleration_rad_s2
    t = np.arange(0.0, 10.0, 1.0 / RATE_HZ)
    # ω = A sin(Ωt) has angular acceleration up to A·Ω: here 0.95 of the limit.
    frequency = 2.0 * math.pi * 2.0
    rate = 0.95 * limit / frequency * np.sin(frequency * t)
    gyros = np.stack([rate, np.zeros_like(t), np.zeros_like(t)], axis=1)
    forces = np.tile([0.0, 0.0, 9.81], (t.size, 1))
    assert screen(default_screening(), t, gyros, forces).all()

    spiked = gyros.copy()
    spiked[500:505, 1] = 30.0  # five samples of 30 rad/s
    forces_spiked = forces.copy()
    forces_spiked[700, 2] = 100.0
    accepted = screen(default_screening(), t, spiked, forces_spiked)
    assert np.flatnonzero(~accepted).tolist() == [500, 501, 502, 503, 504, 700]


def test_a_lasting_change_is_accepted_once_the_platform_could_have_made_it():
    """The screening cannot lock itself out: the bound grows with the time since the last
    accepted sample, so a new level (a real manoeuvre the limit underrates) is taken up."""
    config = FusionConfig()
    t = np.arange(0.0, 2.0, 1.0 / RATE_HZ)
    step_rad_s = 10.0
    gyros = np.zeros((t.size, 3))
    gyros[100:, 2] = step_rad_s
    forces = np.tile([0.0, 0.0, 9.81], (t.size, 1))
    accepted = screen(default_screening(), t, gyros, forces)
    first_after = 100 + int(np.argmax(accepted[100:]))
    waited_s = t[first_after] - t[99]
    assert waited_s == pytest.approx(step_rad_s / config.max_angular_acceleration_rad_s2, abs=0.011)
    assert accepted[first_after:].all()
