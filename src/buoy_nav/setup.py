from pathlib import Path

from setuptools import find_packages, setup

PACKAGE = "buoy_nav"
HERE = Path(__file__).parent


def config_files():
    return [str(p.relative_to(HERE)) for p in sorted((HERE / "config").rglob("*.yaml"))]


def config_data_files():
    """Install config/ (and its sub-folders) under share/<package>/config."""
    grouped = {}
    for relative in config_files():
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
        *config_data_files(),
    ],
    install_requires=["setuptools"],
    extras_require={"test": ["pytest"]},
    zip_safe=False,
    maintainer="Buoy wind maintainers",
    maintainer_email="maintainers@buoy-wind.invalid",
    description="Dual-antenna GNSS/SINS error-state Kalman filter for a buoy, live and from bags.",
    license="Apache-2.0",
    entry_points={
        "console_scripts": [
            "fusion_node = buoy_nav.fusion_node:main",
            "fuse_bag = buoy_nav.fuse_bag:main",
            "calibrate_imu = buoy_nav.calibrate_imu:main",
            "calibrate_magnetometer = buoy_nav.calibrate_magnetometer:main",
        ],
    },
)
