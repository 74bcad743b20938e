"""The processing nodes of one buoy: ``fusion_node`` and ``compensation_node`` (and
``current_node`` for a buoy with a DVL).

    ros2 launch wind_comp processing.launch.py [namespace:=/buoy1] [use_sim_time:=true]
        [buoy_params:=/path/to/buoy.yaml] [current:=true]

Each node takes the shared buoy file (lever arms, antennas, anemometer mounting) and its own
parameter file, as the commands that start them by hand do (README, "Running the nodes").

Arguments:
- ``namespace``: namespace of both nodes and so of every topic (default: none).
- ``buoy_params``: the shared buoy parameter file (default: buoy_common's ``config/buoy.yaml``).
- ``use_sim_time``: take time from ``/clock`` (a replay or the simulator; default false).
- ``current``: also start ``current_node`` with ``config/current.yaml`` (default false).
"""

from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument
from launch.conditions import IfCondition
from launch.substitutions import LaunchConfiguration, PathJoinSubstitution
from launch_ros.actions import Node
from launch_ros.substitutions import FindPackageShare


def generate_launch_description():
    namespace = LaunchConfiguration("namespace")
    buoy_params = LaunchConfiguration("buoy_params")
    use_sim_time = LaunchConfiguration("use_sim_time")
    current = LaunchConfiguration("current")
    return LaunchDescription(
        [
            DeclareLaunchArgument(
                "namespace", default_value="", description="namespace of the nodes and topics"
            ),
            DeclareLaunchArgument(
                "buoy_params",
                default_value=PathJoinSubstitution(
                    [FindPackageShare("buoy_common"), "config", "buoy.yaml"]
                ),
                description="the shared buoy parameter file",
            ),
            DeclareLaunchArgument(
                "use_sim_time", default_value="false", description="take time from /clock"
            ),
            DeclareLaunchArgument(
                "current",
                default_value="false",
                description="also start current_node (a buoy with a DVL)",
            ),
            Node(
                package="buoy_nav",
                executable="fusion_node",
                namespace=namespace,
                output="screen",
                parameters=[
                    buoy_params,
                    PathJoinSubstitution([FindPackageShare("buoy_nav"), "config", "fusion.yaml"]),
                    {"use_sim_time": use_sim_time},
                ],
            ),
            Node(
                package="wind_comp",
                executable="compensation_node",
                namespace=namespace,
                output="screen",
                parameters=[
                    buoy_params,
                    PathJoinSubstitution(
                        [FindPackageShare("wind_comp"), "config", "compensation.yaml"]
                    ),
                    {"use_sim_time": use_sim_time},
                ],
            ),
            Node(
                package="wind_comp",
                executable="current_node",
                namespace=namespace,
                output="screen",
                condition=IfCondition(current),
                parameters=[
                    buoy_params,
                    PathJoinSubstitution([FindPackageShare("wind_comp"), "config", "current.yaml"]),
                    {"use_sim_time": use_sim_time},
                ],
            ),
        ]
    )
