"""A simulated buoy live: the simulated sensors, truth and clock, with the processing nodes.

    ros2 launch sensor_sim demo.launch.py [scenario:=sea_state] [rate_factor:=1.0]
        [namespace:=/buoy1]

What ``run_scenario SCENARIO --compensation`` starts, under ``ros2 launch``: the simulation
clock, the truth, IMU, GNSS and anemometer nodes with the shared buoy file, and
``wind_comp``'s ``processing.launch.py``. The sensors publish on the simulation clock's ticks;
the processing nodes, as on a buoy, run on header stamps. Record it with
``ros2 bag record -a`` or ``bag_recorder``.

Arguments:
- ``scenario``: a shipped scenario name or a scenario YAML file (default ``sea_state``).
- ``rate_factor``: simulated seconds per wall-clock second (default 1.0).
- ``namespace``: namespace of every node and topic (default: none).
"""

from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument, IncludeLaunchDescription
from launch.substitutions import LaunchConfiguration, PathJoinSubstitution
from launch_ros.actions import Node
from launch_ros.substitutions import FindPackageShare

SENSOR_EXECUTABLES = ("truth_node", "imu_sim_node", "gnss_sim_node", "anemometer_sim_node")


def generate_launch_description():
    scenario = LaunchConfiguration("scenario")
    namespace = LaunchConfiguration("namespace")
    buoy_params = PathJoinSubstitution([FindPackageShare("buoy_common"), "config", "buoy.yaml"])
    sensors = [
        Node(
            package="sensor_sim",
            executable=executable,
            namespace=namespace,
            output="screen",
            parameters=[buoy_params, {"scenario": scenario}],
        )
        for executable in SENSOR_EXECUTABLES
    ]
    return LaunchDescription(
        [
            DeclareLaunchArgument(
                "scenario", default_value="sea_state", description="scenario name or YAML file"
            ),
            DeclareLaunchArgument(
                "rate_factor",
                default_value="1.0",
                description="simulated seconds per wall-clock second",
            ),
            DeclareLaunchArgument(
                "namespace", default_value="", description="namespace of the nodes and topics"
            ),
            IncludeLaunchDescription(
                PathJoinSubstitution(
                    [FindPackageShare("wind_comp"), "launch", "processing.launch.py"]
                ),
                launch_arguments={"namespace": namespace}.items(),
            ),
            *sensors,
            Node(
                package="sensor_sim",
                executable="sim_clock_node",
                namespace=namespace,
                output="screen",
                parameters=[
                    {"scenario": scenario, "rate_factor": LaunchConfiguration("rate_factor")}
                ],
            ),
        ]
    )
