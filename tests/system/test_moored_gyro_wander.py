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

- told the gyro's real wander, the fusion's horizontal velocity stays within its stated σ, but
  that σ (0.4 m/s) leaves no wind sample valid: the mooring's position σ of an open-ocean sea
  (3 m) lets the tilt error through;
- told also the sea's wave excursion (Hs/4 = 0.075 m) as the mooring's position σ, the error
  falls to centimetres per second, still within its σ;
- with the default gyro model it leaves its σ: the record's failure, reproduced (expected
  failure).
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
SIGNIFICANT_WAVE_HEIGHT_M = 0.3
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
    f"waves.significant_height_m={SIGNIFICANT_WAVE_HEIGHT_M}",
    "waves.max_tilt_deg=10.0",
    f"sensors.imu.gyro_bias_instability_deg_h={GYRO_BIAS_INSTABILITY_DEG_H}",
    f"sensors.imu.gyro_bias_correlation_time_s={GYRO_BIAS_CORRELATION_TIME_S}",
)


@pytest.fixture(scope="module")
def wandering_gyro_run():
    return scenario_messages("open_ocean", DURATION_S, FDCHP_LIKE_MOORED_BUOY)


def horizontal_velocity_errors(config: FusionConfig, run) -> tuple[np.ndarray, np.ndarray]:
    """Errors (m/s) of the fused east and north velocity against the truth, after settling,
    and their stated standard deviations (m/s)."""
    scenario, truth, messages = run
    _, solutions, times, _ = fuse(config, messages, scenario)
    settled = times >= SETTLING_S
    velocity = np.array([s.velocity_enu_mps for s in solutions])[settled, :2]
    sigma = np.sqrt([np.diag(s.velocity_covariance_m2s2)[:2] for s in solutions])[settled]
    true = truth.evaluate(times[settled]).velocity_enu_mps[:, :2]
    return velocity - true, sigma


def assert_within_sigma(errors_mps: np.ndarray, sigma_mps: np.ndarray) -> None:
    normalised = np.abs(errors_mps) / sigma_mps
    assert np.all((normalised > 3.0).mean(axis=0) <= 0.01)
    assert not np.any(normalised > 5.0)


def fdchp_like_config(**gyro_model) -> FusionConfig:
    scenario_site = {"site_latitude_deg": 20.0, "site_longitude_deg": 115.0}
    return FusionConfig(
        **scenario_site,
        ahrs_yaw_reference="magnetic_north",
        moored=True,
        ahrs_lag_s=0.2,
        **gyro_model,
    )


TOLD_THE_GYRO = {
    "gyro_bias_instability_deg_h": GYRO_BIAS_INSTABILITY_DEG_H,
    "gyro_bias_correlation_time_s": GYRO_BIAS_CORRELATION_TIME_S,
}


def test_told_the_gyros_wander_the_velocity_stays_within_its_sigma(wandering_gyro_run):
    errors, sigma = horizontal_velocity_errors(
        fdchp_like_config(**TOLD_THE_GYRO), wandering_gyro_run
    )
    assert_within_sigma(errors, sigma)
    assert np.all(np.median(sigma, axis=0) > 0.2)


def test_told_also_the_seas_excursion_the_velocity_error_is_centimetres(wandering_gyro_run):
    errors, sigma = horizontal_velocity_errors(
        fdchp_like_config(
            **TOLD_THE_GYRO, moored_position_sigma_horizontal_m=SIGNIFICANT_WAVE_HEIGHT_M / 4.0
        ),
        wandering_gyro_run,
    )
    assert_within_sigma(errors, sigma)
    assert np.all(np.sqrt(np.mean(errors**2, axis=0)) < 0.05)


@pytest.mark.xfail(
    strict=True,
    raises=AssertionError,
    reason="a gyro that wanders beyond the fusion's gyro model drives a slow tilt error, and "
    "the mooring's position constraint lets its velocity grow to about 1 m/s unstated: the "
    "FDCHP record's failure",
)
def test_with_the_default_gyro_model_the_velocity_leaves_its_sigma(wandering_gyro_run):
    assert_within_sigma(*horizontal_velocity_errors(fdchp_like_config(), wandering_gyro_run))
