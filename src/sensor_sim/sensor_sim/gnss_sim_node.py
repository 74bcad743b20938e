"""``gnss_sim_node``: simulated dual-antenna RTK receiver on ``gnss/fix``, ``gnss/vel``,
``gnss/heading`` and ``gnss/baseline`` (10 Hz by default)."""

from sensor_sim.sim_base_node import main_for_stream

main = main_for_stream("gnss", __doc__)
