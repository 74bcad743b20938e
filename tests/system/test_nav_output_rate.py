"""``--nav-rate-hz``: the navigation written at a lower rate is a subset of the full-rate one,
message for message, while the corrected wind, which still uses every solution, is
byte-identical; the processed bag's facts and the NetCDF file say and hold the same."""

from __future__ import annotations

import numpy as np
import pytest
import xarray as xr

from buoy_common.bag_io import BagReader
from buoy_nav.config import fusion_config_from_files
from buoy_processing.bag_fusion import fuse_bag
from buoy_processing.bag_processing import process_bag
from buoy_processing.output_facts import read_output_facts
from processed_bags import BAGS_DIR, BUOY_PARAMETERS, processed_bag, processed_netcdf
from ros_messages import raw_stamp_ns
from wind_comp.config import compensator_config_from_files

BAG = "wind_tunnel_10"
NAV_RATE_HZ = 10.0
IMU_STEP_S = 0.01
NAV_TOPICS = ("/nav/odometry", "/nav/imu", "/nav/velocity", "/nav/fix", "/tf")
CORRECTED_TOPICS = (
    "/wind/true",
    "/wind/true_with_covariance",
    "/wind/mean_1min",
    "/wind/stats_1min",
    "/wind/mean_10min",
    "/wind/stats_10min",
    "/wind/fluxes_30min",
)


def messages(bag, topic: str) -> list[tuple[int, bytes]]:
    with BagReader(bag) as reader:
        return [(m.log_time_ns, m.raw) for m in reader.messages([topic])]


def process_decimated(out, write_bag: bool = True):
    """``process_bag --nav-rate-hz 10`` of the bag into ``out``/bag, with its NetCDF file
    ``out``/bag.nc (``write_bag`` False: ``--no-bag``); the output bag's path."""
    process_bag(
        BAGS_DIR / BAG,
        out / "bag",
        fusion_config_from_files([BUOY_PARAMETERS]),
        compensator_config_from_files([BUOY_PARAMETERS]),
        netcdf_path=out / "bag.nc",
        nav_rate_hz=NAV_RATE_HZ,
        write_bag=write_bag,
    )
    return out / "bag"


@pytest.fixture(scope="module")
def decimated(tmp_path_factory):
    """``process_bag --nav-rate-hz 10`` of the bag, with its NetCDF file."""
    return process_decimated(tmp_path_factory.mktemp("nav_rate"))


def test_corrected_wind_and_products_are_byte_identical(decimated, tmp_path_factory):
    full = processed_bag(tmp_path_factory, BAG)
    for topic in CORRECTED_TOPICS:
        ours = messages(decimated, topic)
        assert ours, topic
        assert ours == messages(full, topic), topic


def test_nav_and_tf_are_a_subset_of_the_full_rate_ones_at_the_rate(decimated, tmp_path_factory):
    full = processed_bag(tmp_path_factory, BAG)
    log_times = [log_time_ns for log_time_ns, _ in messages(decimated, "/nav/odometry")]
    for topic in NAV_TOPICS:
        ours = messages(decimated, topic)
        everything = messages(full, topic)
        assert set(ours) <= set(everything), topic
        # Each solution's messages and transform together, logged with its IMU sample.
        assert [log_time_ns for log_time_ns, _ in ours] == log_times, topic
    stamps = [raw_stamp_ns(raw) for _, raw in messages(decimated, "/nav/odometry")]
    intervals_s = np.diff(stamps) / 1e9
    # One solution per period: never closer than a period less half an IMU step, and no
    # solution left out of a period but the rest of the last one.
    assert intervals_s.min() >= 1 / NAV_RATE_HZ - IMU_STEP_S / 2
    assert intervals_s.max() <= 1 / NAV_RATE_HZ + IMU_STEP_S / 2
    full_stamps = [raw_stamp_ns(raw) for _, raw in messages(full, "/nav/odometry")]
    assert stamps[0] == full_stamps[0]
    assert (full_stamps[-1] - stamps[-1]) / 1e9 < 1 / NAV_RATE_HZ


def test_facts_state_the_rate_and_the_netcdf_navigation_is_the_bags(decimated, tmp_path_factory):
    assert read_output_facts(decimated).nav_rate_hz == NAV_RATE_HZ
    assert read_output_facts(processed_bag(tmp_path_factory, BAG)).nav_rate_hz == 0.0
    stamps = [raw_stamp_ns(raw) for _, raw in messages(decimated, "/nav/odometry")]
    with BagReader(decimated) as reader:
        latitudes = [reader.decode(m).latitude for m in reader.messages(["nav/fix"])]
    with (
        xr.open_dataset(decimated.with_name("bag.nc")) as ours,
        xr.open_dataset(processed_netcdf(tmp_path_factory, BAG)) as theirs,
    ):
        nav_ns = ours["nav_time"].values.astype("datetime64[ns]").astype(np.int64)
        assert np.abs(nav_ns - stamps).max() <= 1
        np.testing.assert_array_equal(ours["latitude"].values, latitudes)
        np.testing.assert_array_equal(ours["eastward_wind"].values, theirs["eastward_wind"])


def test_without_a_bag_the_netcdf_navigation_is_the_same_subset(decimated, tmp_path):
    """Without a bag the solutions reach the NetCDF file in bulk, the rate's choice made of
    their stamps alone: the same solutions, to the bit."""
    process_decimated(tmp_path, write_bag=False)
    with (
        xr.open_dataset(tmp_path / "bag.nc", decode_times=False) as ours,
        xr.open_dataset(decimated.with_name("bag.nc"), decode_times=False) as theirs,
    ):
        assert 0 < ours.sizes["nav_time"] < ours.sizes["time"]
        assert sorted(ours.variables) == sorted(theirs.variables)
        for variable in theirs.variables:
            np.testing.assert_array_equal(ours[variable], theirs[variable], err_msg=variable)


@pytest.mark.long
def test_smoothed_navigation_at_a_lower_rate_is_a_subset(tmp_path):
    config = fusion_config_from_files([BUOY_PARAMETERS])
    fuse_bag(BAGS_DIR / BAG, tmp_path / "full", config, smooth=True)
    fuse_bag(BAGS_DIR / BAG, tmp_path / "decimated", config, smooth=True, nav_rate_hz=NAV_RATE_HZ)
    for topic in (*NAV_TOPICS, "/nav/forward/odometry"):
        ours = messages(tmp_path / "decimated", topic)
        everything = messages(tmp_path / "full", topic)
        assert set(ours) <= set(everything), topic
        assert 0 < len(ours) < len(everything) / 5, topic
