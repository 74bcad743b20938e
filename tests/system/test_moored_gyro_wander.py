"""A moored buoy without GNSS whose gyro wanders more than the fusion is told, on the simulator.

OOI's FDCHP record (``test_real_record_uncertainty``) shows a horizontal velocity over ground
that wanders by about 1 m/s at periods of a minute while the fusion states 0.15 m/s. Its motion
pack's gyros wander at those periods by 0.03–0.06 °/s (the record's rates below 0.02 Hz, where
the pack's own roll and pitch change by 0.015–0.024 °/s), twenty to forty times the fusion's
default bias instability (5 °/h): integrated, a tilt error of a degree or two, and ``g δθ`` grows
into the velocity until the mooring's position constraint (σ 3 m) catches it, at about
``√(2 σ_p g δθ)``, 1 m/s. The simulator plays such a buoy: an FDCHP-like moored buoy (a motion
pack at 10 Hz whose slow attitude is off by 1.5° while it claims 1°, no magnetometer, no GNSS,
the record's short sea) whose gyro bias wanders by 150 °/h with a correlation time of 100 s.

- told the gyro's real wander, the fusion's horizontal velocity stays within its stated σ;
- with the default gyro model it does not: the record's failure, reproduced (expected failure).
"""

from __future__ import annotations

import numpy as np
import pytest
from test_nav_sensor_sets import fuse, scenario_messages

from buoy_nav.config import FusionConfig

pytestmark = pytest.mark.long

DURATION_S = 600.0
SETTLING_S = 120.0
GYRO_BIAS_INSTABILITY_DEG_H = 150.0
GYRO_BIAS_CORRELATION_TIME_S = 100.0
FDCHP_LIKE_MOORED_BUOY = (
    "sensors.gnss.receiver=none",
    "current=null",
    "sensors.magnetometer.fitted=false",
    "sensors.ahrs.fitted=true",
    "sensors.ahrs.yaw_reference=magnetic_north",
    "sensors.ahrs.sample_every=1",
    "sensors.ahrs.error_deg=1.5",
    "sensors.ahrs.claimed_sigma_deg=[1.0, 1.0, 2.0]",
    "sensors.rates.imu_hz=10.0",
    "waves.peak_period_s=2.0",
    "waves.significant_height_m=0.3",
    "waves.max_tilt_deg=10.0",
    f"sensors.imu.gyro_bias_instability_deg_h={GYRO_BIAS_INSTABILITY_DEG_H}",
    f"sensors.imu.gyro_bias_correlation_time_s={GYRO_BIAS_CORRELATION_TIME_S}",
)


@pytest.fixture(scope="module")
def wandering_gyro_run():
    return scenario_messages("open_ocean", DURATION_S, FDCHP_LIKE_MOORED_BUOY)


def horizontal_velocity_normalised_errors(config: FusionConfig, run) -> np.ndarray:
    """|error| / σ of the fused east and north velocity against the truth, after settling."""
    scenario, truth, messages = run
    _, solutions, times, _ = fuse(config, messages, scenario)
    settled = times >= SETTLING_S
    velocity = np.array([s.velocity_enu_mps for s in solutions])[settled, :2]
    sigma = np.sqrt([np.diag(s.velocity_covariance_m2s2)[:2] for s in solutions])[settled]
    true = truth.evaluate(times[settled]).velocity_enu_mps[:, :2]
    return np.abs(velocity - true) / sigma


def fdchp_like_config(**gyro_model) -> FusionConfig:
    scenario_site = {"site_latitude_deg": 20.0, "site_longitude_deg": 115.0}
    return FusionConfig(
        **scenario_site,
        ahrs_yaw_reference="magnetic_north",
        moored=True,
        ahrs_lag_s=0.2,
        **gyro_model,
    )


def test_told_the_gyros_wander_the_velocity_stays_within_its_sigma(wandering_gyro_run):
    normalised = horizontal_velocity_normalised_errors(
        fdchp_like_config(
            gyro_bias_instability_deg_h=GYRO_BIAS_INSTABILITY_DEG_H,
            gyro_bias_correlation_time_s=GYRO_BIAS_CORRELATION_TIME_S,
        ),
        wandering_gyro_run,
    )
    assert np.all((normalised > 3.0).mean(axis=0) <= 0.01)
    assert not np.any(normalised > 5.0)


@pytest.mark.xfail(
    strict=True,
    raises=AssertionError,
    reason="a gyro that wanders beyond the fusion's gyro model drives a slow tilt error, and "
    "the mooring's position constraint lets its velocity grow to about 1 m/s unstated: the "
    "FDCHP record's failure",
)
def test_with_the_default_gyro_model_the_velocity_leaves_its_sigma(wandering_gyro_run):
    normalised = horizontal_velocity_normalised_errors(fdchp_like_config(), wandering_gyro_run)
    assert np.all((normalised > 3.0).mean(axis=0) <= 0.01)
    assert not np.any(normalised > 5.0)
