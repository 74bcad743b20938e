from setuptools import find_packages, setup

PACKAGE = "buoy_processing"

setup(
    name=PACKAGE,
    version="0.1.0",
    packages=find_packages(exclude=["test"]),
    data_files=[
        ("share/ament_index/resource_index/packages", ["resource/" + PACKAGE]),
        ("share/" + PACKAGE, ["package.xml"]),
    ],
    install_requires=["setuptools"],
    extras_require={"test": ["pytest"]},
    zip_safe=False,
    maintainer="Buoy wind maintainers",
    maintainer_email="maintainers@buoy-wind.invalid",
    description="The offline application: bags fused and corrected, archives, NetCDF, reports.",
    license="Apache-2.0",
    entry_points={
        "console_scripts": [
            "calibrate_mounting = buoy_processing.calibrate_mounting:main",
            "fuse_bag = buoy_processing.fuse_bag:main",
            "process_archive = buoy_processing.process_archive:main",
            "process_bag = buoy_processing.process_bag:main",
            "wind_report = buoy_processing.wind_report:main",
        ],
    },
)
