"""The wave motion left in each flux window, against the simulator's truth.

The simulated anemometer on ``open_ocean``'s buoy (JONSWAP sea, Tp 9 s) reads the true wind less
the velocity of its measurement centre; the compensation pipeline (the one ``compensation_node``
and ``process_bag`` run) corrects it with the simulator's own navigation, published as
``nav/odometry`` would be. The two share no code. Then, per flux window:

- the window's wave band, from the platform velocity the correction applied, holds the sea's
  peak frequency 1/Tp;
- the correct correction leaves as little of the platform's vertical velocity in w as the true
  wind itself holds (the estimator's noise on turbulence that the heave does not move) and
  passes the "motion left" test;
- with half of the platform's vertical velocity put back into w the share is 0.5, and with the
  correction's velocity term left out 1: both fail;
- on ``sea_state``, whose buoy barely heaves, the share is noise: not evaluated;
- fed one message at a time, as the live node is, the pipeline publishes the same windows, to
  the bit, as fed in stretches, as ``process_bag`` does.
"""

from __future__ import annotations

from dataclasses import astuple

import numpy as np
import pytest

from buoy_common.contract import QualityFlag
from sensor_sim.scenario import load_scenario
from sensor_sim.sensor_errors import AnemometerErrorConfig
from sensor_sim.sensor_models import AnemometerSimulator
from sensor_sim.truth import TruthModel
from wind_comp.compensation_messages import FlowSample
from wind_comp.config import CompensatorConfig
from wind_comp.flux_products import FluxAverager, FluxProduct
from wind_comp.pipeline import wind_pipeline
from wind_comp.wave_motion_left import DEFAULT_THRESHOLDS, wave_motion_left

SCENARIO = "open_ocean"
PEAK_PERIOD_S = 9.0
POSITION_BODY_M = (0.2, -0.15, 2.7)
MOUNTING_RPY_DEG = (4.0, -3.0, 150.0)
WINDOW_S = 360.0
"""Long enough for the test's 20 spectral segments of 30 s."""
# The mean coherence of unrelated series over K = 23 segments of a window is about 1/K, and
# their share left about 1/√K of the ratio of the air's to the platform's band variance.
NOISE_SHARE = 0.06
HALF_TOLERANCE = 0.05


def simulated_buoy(duration_s: float, rate_hz: float, scenario: str = SCENARIO):
    """Stamps (s), the anemometer's readings (sensor axes, m/s), the navigation as
    ``nav/odometry`` carries it (attitude xyzw, body rate, body velocity) and the truth."""
    truth = TruthModel(load_scenario(scenario))
    sensor = AnemometerSimulator(
        truth, AnemometerErrorConfig(), POSITION_BODY_M, MOUNTING_RPY_DEG, seed=5
    )
    t_s = np.arange(0.0, duration_s, 1.0 / rate_hz)
    state = truth.evaluate(t_s)
    odometry = (
        state.attitude.as_quat(),
        state.angular_rate_body_rad_s,
        state.attitude.inv().apply(state.velocity_enu_mps),
    )
    return t_s, sensor.measure(t_s), odometry, state


def corrected(t_s, readings, odometry, wind_per_stretch: int | None):
    """The corrected samples and the flux windows of the pipeline fed each navigation sample
    before the anemometer sample of its stamp; results after every message
    (``wind_per_stretch`` None, as compensation_node) or every ``wind_per_stretch`` anemometer
    samples (as process_bag)."""
    config = CompensatorConfig(POSITION_BODY_M, MOUNTING_RPY_DEG, flux_window_s=WINDOW_S)
    pipeline = wind_pipeline(config)
    outputs = []
    for index, t in enumerate(t_s.tolist()):
        pipeline.add_odometry(t, *(values[index] for values in odometry))
        if wind_per_stretch is None:
            outputs.append(pipeline.ready())
        if index:
            pipeline.add_sample(FlowSample(t_s[index - 1], tuple(readings[index - 1]), None))
            if wind_per_stretch is None or index % wind_per_stretch == 0:
                outputs.append(pipeline.ready())
    outputs.append(pipeline.flush())
    samples = [output.samples for output in outputs if len(output.samples)]
    fluxes = [p for output in outputs for p in output.products if isinstance(p, FluxProduct)]
    return samples, sorted(fluxes, key=lambda product: product.window_start_s)


@pytest.fixture(scope="module")
def run():
    t_s, readings, odometry, state = simulated_buoy(2 * WINDOW_S + 5.0, 10.0)
    samples, fluxes = corrected(t_s, readings, odometry, wind_per_stretch=500)
    stamps = np.concatenate([batch.t_s for batch in samples])
    wind = np.concatenate([batch.flow_enu_mps for batch in samples])
    platform_up = np.concatenate([batch.translation_term_enu_mps[:, 2] for batch in samples])
    truth_at = np.searchsorted(t_s, stamps)
    return {
        "stamps": stamps,
        "wind": wind,
        "platform_up": platform_up,
        "true_wind": state.wind_enu_mps[truth_at],
        "true_platform_up": state.velocity_enu_mps[truth_at, 2],
        "fluxes": [f for f in fluxes if f.window_end_s <= t_s[-1]],
    }


def windows_of(stamps, wind, platform_up) -> list[FluxProduct]:
    averager = FluxAverager(WINDOW_S)
    return averager.add_batch(stamps, wind, platform_up) + averager.flush()


def test_each_window_finds_the_seas_wave_band(run):
    assert len(run["fluxes"]) == 2
    for window in run["fluxes"]:
        assert window.wave_band_low_hz <= 1.0 / PEAK_PERIOD_S <= window.wave_band_high_hz
        assert window.wave_band_high_hz < 0.5


def test_the_correct_correction_leaves_what_the_true_wind_holds_and_passes(run):
    for window in run["fluxes"]:
        in_window = (run["stamps"] >= window.window_start_s) & (run["stamps"] < window.window_end_s)
        floor = wave_motion_left(
            run["stamps"][in_window],
            run["true_wind"][in_window, 2],
            run["true_platform_up"][in_window],
            0.1,
            DEFAULT_THRESHOLDS,
        )
        assert floor.share < NOISE_SHARE, floor
        # the buoy heaves enough (0.6 m/s) for the share to be known: evaluated
        assert floor.share_standard_error < DEFAULT_THRESHOLDS.max_share_standard_error, floor
        assert window.motion_left_share < floor.share + NOISE_SHARE, (window, floor)
        assert window.motion_left_coherence < window.motion_left_coherence_threshold, window
        assert window.motion_left_flag == QualityFlag.GOOD


def test_half_the_platform_velocity_put_back_leaves_half_and_fails(run):
    wind = run["wind"].copy()
    wind[:, 2] += 0.5 * run["platform_up"]
    for window in windows_of(run["stamps"], wind, run["platform_up"])[:2]:
        assert window.motion_left_share == pytest.approx(0.5, abs=HALF_TOLERANCE), window
        assert window.motion_left_flag == QualityFlag.BAD
        assert window.quality_flag == QualityFlag.BAD


def test_leaving_out_the_velocity_term_leaves_all_of_it_and_fails(run):
    wind = run["wind"].copy()
    wind[:, 2] -= run["platform_up"]
    for window in windows_of(run["stamps"], wind, run["platform_up"])[:2]:
        assert window.motion_left_share == pytest.approx(1.0, abs=2 * HALF_TOLERANCE), window
        assert window.motion_left_flag == QualityFlag.BAD


def test_live_and_offline_publish_the_same_wave_motion_left():
    """One window, at 5 Hz so that a message at a time stays quick."""
    t_s, readings, odometry, _ = simulated_buoy(WINDOW_S + 10.0, 5.0)
    _, live = corrected(t_s, readings, odometry, wind_per_stretch=None)
    for stretch in (7, 10_000):
        _, offline = corrected(t_s, readings, odometry, wind_per_stretch=stretch)
        np.testing.assert_equal([astuple(w) for w in offline], [astuple(w) for w in live])
    assert live[0].motion_left_flag == QualityFlag.GOOD
    assert np.isfinite(live[0].motion_left_share)


def test_a_buoy_that_barely_heaves_is_not_evaluated():
    """sea_state's buoy heaves at 0.014 m/s in its wave band, under 0.09 m/s of the air's
    turbulence in the same band: the share, of the corrected wind as of the true one, is noise
    (above 1), so the test is not evaluated; its figures are still published."""
    t_s, readings, odometry, state = simulated_buoy(WINDOW_S + 5.0, 10.0, "sea_state")
    samples, fluxes = corrected(t_s, readings, odometry, wind_per_stretch=500)
    (window,) = [f for f in fluxes if f.window_end_s <= t_s[-1]]
    assert window.motion_left_flag == QualityFlag.NOT_EVALUATED, window
    assert window.motion_left_share > 0.5, window
    assert np.isfinite(window.motion_left_coherence)
    stamps = np.concatenate([batch.t_s for batch in samples])
    inside = (stamps >= window.window_start_s) & (stamps < window.window_end_s)
    truth_at = np.searchsorted(t_s, stamps[inside])
    platform_up = state.velocity_enu_mps[truth_at, 2]
    true_left = wave_motion_left(
        stamps[inside], state.wind_enu_mps[truth_at, 2], platform_up, 0.1, DEFAULT_THRESHOLDS
    )
    assert np.std(platform_up) < 0.03
    assert true_left.share_standard_error > DEFAULT_THRESHOLDS.max_share_standard_error
    assert true_left.flag == QualityFlag.NOT_EVALUATED
