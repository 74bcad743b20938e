"""``truth_node``: the simulation's answer on ``truth/odometry``, ``truth/wind`` and, when the
scenario has a current, ``truth/current`` (50 Hz by default)."""

from sensor_sim.sim_base_node import main_for_stream

main = main_for_stream("truth", __doc__)
