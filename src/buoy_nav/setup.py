from pathlib import Path

from setuptools import find_packages, setup

PACKAGE = "buoy_nav"
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
    description="Dual-antenna GNSS/SINS error-state Kalman filter for a buoy.",
    license="Apache-2.0",
    entry_points={
        # Its parameters' declarations, for buoy_common.parameter_docs.
        "buoy_common.parameter_sets": ["buoy_nav = buoy_nav.config:parameter_sets"],
        "console_scripts": [
            "fusion_node = buoy_nav.fusion_node:main",
            "calibrate_imu = buoy_nav.calibrate_imu:main",
            "calibrate_magnetometer = buoy_nav.calibrate_magnetometer:main",
            "assess_motion_pack = buoy_nav.assess_motion_pack:main",
        ],
    },
)
