"""``dvl_sim_node``: simulated Doppler velocity log (water track) on ``dvl/velocity`` (1 Hz by
default), for scenarios whose platform carries one (``sensors.dvl``)."""

from sensor_sim.sim_base_node import main_for_stream

main = main_for_stream("dvl", __doc__)
