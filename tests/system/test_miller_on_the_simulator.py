"""The compensation's Miller correction undoes the simulator's anemometer exactly.

The simulated anemometer reads the true wind minus the velocity of its measurement centre
(platform velocity plus rotation × lever arm), turned into its own axes; the two packages share
no code. Given the simulator's true attitude, body rate and velocity, ``wind_comp``'s
compensator (the one ``compensation_node`` and ``process_bag`` run) must return the true wind to
rounding, for a mount off the mast axis and turned about all three axes, on a buoy rolling in
irregular waves.
"""

from __future__ import annotations

import numpy as np

from sensor_sim.scenario import load_scenario
from sensor_sim.sensor_errors import AnemometerErrorConfig
from sensor_sim.sensor_models import AnemometerSimulator
from sensor_sim.truth import TruthModel
from wind_comp.compensator import FlowCompensator
from wind_comp.config import CompensatorConfig

POSITION_BODY_M = (0.2, -0.15, 2.7)
MOUNTING_RPY_DEG = (4.0, -3.0, 150.0)
# The same arithmetic on exact inputs: rounding of a few operations on 10 m/s.
EXACT_MPS = 1e-9
# Each term of the correction moves the wind by more than this on this buoy, so leaving any
# one out would fail the test by far.
TERM_SIZE_MPS = 0.1


def test_wind_comp_recovers_the_simulated_true_wind():
    truth = TruthModel(load_scenario("open_ocean"))
    sensor = AnemometerSimulator(
        truth, AnemometerErrorConfig(noise_mps=0.0), POSITION_BODY_M, MOUNTING_RPY_DEG, seed=1
    )
    t_s = np.arange(0.0, 60.0, 0.05)
    reading = sensor.measure(t_s)
    state = truth.evaluate(t_s)
    config = CompensatorConfig(POSITION_BODY_M, MOUNTING_RPY_DEG)
    compensator = FlowCompensator(config.flow_sensor(), config.max_nav_gap_s, config.nav_history_s)
    navigation = (
        t_s,
        state.attitude.as_quat(),
        state.angular_rate_body_rad_s,
        state.velocity_enu_mps,
    )
    # As they would arrive live: each wind sample after the navigation sample that follows it.
    nav_before_wind = np.minimum(np.arange(t_s.size) + 2, t_s.size)
    compensator.add_arrivals(navigation, t_s, reading, nav_before_wind)
    corrected = compensator.flush()
    valid = corrected.valid
    assert np.count_nonzero(valid) >= t_s.size - 1  # the last stamp has no navigation after it
    error = corrected.flow_enu_mps[valid] - state.wind_enu_mps[valid]
    assert np.max(np.abs(error)) < EXACT_MPS, np.max(np.abs(error), axis=0)

    def largest_mps(term):
        return float(np.max(np.linalg.norm(term[valid], axis=1)))

    assert largest_mps(corrected.rotation_term_enu_mps) > TERM_SIZE_MPS
    assert largest_mps(corrected.translation_term_enu_mps) > TERM_SIZE_MPS
    # The tilt term alone, i.e. the reading levelled and turned North-up, is still off.
    assert largest_mps(corrected.tilt_term_enu_mps - state.wind_enu_mps) > TERM_SIZE_MPS
