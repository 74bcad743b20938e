"""``imu_sim_node``: simulated MEMS IMU on ``imu/data_raw`` (100 Hz by default)."""

from sensor_sim.sim_base_node import main_for_stream

main = main_for_stream("imu", __doc__)
