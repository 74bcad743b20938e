"""``anemometer_sim_node``: simulated 3-D sonic anemometer on ``anemometer/wind`` (20 Hz)."""

from sensor_sim.sim_base_node import main_for_stream

main = main_for_stream("anemometer", __doc__)
