from pathlib import Path

from setuptools import find_packages, setup

PACKAGE = "sensor_sim"
HERE = Path(__file__).parent


# What ros2 launch and the nodes look for under share/<package>: parameter files, the Foxglove
# layout and the launch files.
SHARED_FOLDERS = ("config", "launch")
SHARED_SUFFIXES = (".yaml", ".json", ".py")


def shared_files():
    return [
        str(path.relative_to(HERE))
        for folder in SHARED_FOLDERS
        for path in sorted((HERE / folder).rglob("*"))
        if path.suffix in SHARED_SUFFIXES
    ]


def shared_data_files():
    """Install config/ and launch/ (and their sub-folders) under share/<package>/."""
    grouped = {}
    for relative in shared_files():
        folder = str(Path("share", PACKAGE, Path(relative).parent))
        grouped.setdefault(folder, []).append(relative)
    return sorted(grouped.items())


setup(
    name=PACKAGE,
    version="0.1.0",
    packages=find_packages(exclude=["test"]),
    package_data={PACKAGE: ["scenarios/*.yaml"]},
    data_files=[
        ("share/ament_index/resource_index/packages", ["resource/" + PACKAGE]),
        ("share/" + PACKAGE, ["package.xml"]),
        *shared_data_files(),
    ],
    install_requires=["setuptools"],
    extras_require={"test": ["pytest"]},
    zip_safe=False,
    maintainer="Buoy wind maintainers",
    maintainer_email="maintainers@buoy-wind.invalid",
    description="Simulated buoy sensors, truth, simulation clock, bag recorder and player.",
    license="Apache-2.0",
    entry_points={
        # Its parameters' declarations, for buoy_common.parameter_docs.
        "buoy_common.parameter_sets": ["sensor_sim = sensor_sim.parameters:parameter_sets"],
        "console_scripts": [
            "sim_clock_node = sensor_sim.sim_clock_node:main",
            "imu_sim_node = sensor_sim.imu_sim_node:main",
            "gnss_sim_node = sensor_sim.gnss_sim_node:main",
            "anemometer_sim_node = sensor_sim.anemometer_sim_node:main",
            "dvl_sim_node = sensor_sim.dvl_sim_node:main",
            "truth_node = sensor_sim.truth_node:main",
            "bag_recorder = sensor_sim.bag_recorder_node:main",
            "bag_player = sensor_sim.bag_player_node:main",
            "run_scenario = sensor_sim.run_scenario:main",
            "simulate_bag = sensor_sim.simulate_bag:main",
        ],
    },
)
