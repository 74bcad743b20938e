"""The NetCDF-CF file: read back with xarray it holds what was given, to the bit; the IOOS
compliance checker finds it CF-1.10 compliant and ACDD-1.3 complete; it never replaces a file
it was not allowed to."""

from __future__ import annotations

import copy
import dataclasses
import functools
import math
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest
import xarray as xr
from compliance_checker.cf import util as checker_queries
from compliance_checker.runner import CheckSuite
from scipy.spatial.transform import Rotation

from buoy_common.contract import QualityFlag
from buoy_common.record_facts import ImportedRecord
from buoy_common.records.screening import FieldCounts
from buoy_common.safe_output import OutputError
from buoy_nav.config import FusionConfig
from buoy_processing.netcdf_output import NetcdfContent, write_netcdf
from buoy_processing.netcdf_variables import product_time_name, product_variable_name
from buoy_processing.output_facts import SourceUse, output_facts
from buoy_processing.output_series import FlowSeries, NavigationSeries
from wind_comp.compensator import CorrectedBatch, SampleStatus
from wind_comp.config import CompensatorConfig
from wind_comp.flow_uncertainty import FlowCovariance
from wind_comp.flux_products import FluxAverager
from wind_comp.flux_quality import FLUX_FLAG_TESTS
from wind_comp.products import WindAverager

START_S = 1_767_225_600  # 2026-01-01T00:00:00Z
WIND_RATE_HZ = 20
NAV_RATE_HZ = 50
DURATION_S = 150
ROLL_DEG, PITCH_DEG, YAW_ENU_DEG = 5.0, -3.0, 30.0  # yaw from East: heading 60°
VELOCITY_ENU_MPS = (1.0, 1.0, 0.1)  # toward North-East: course 45°, √2 m/s
LATITUDE_DEG, LONGITUDE_DEG, ALTITUDE_M = 41.5, -70.7, 3.0
RNG = np.random.default_rng(5)


def wind_series(valid: bool = True) -> tuple:
    """A wind series of 150 s at 20 Hz: random wind, every 20th sample invalid (or all)."""
    n = DURATION_S * WIND_RATE_HZ
    nanosecs = (np.arange(n) % WIND_RATE_HZ) * (1_000_000_000 // WIND_RATE_HZ)
    secs = START_S + np.arange(n) // WIND_RATE_HZ
    flows = RNG.normal([6.0, -3.0, 0.0], 1.5, size=(n, 3))
    status = np.zeros(n, dtype=np.int8)
    status[::20] = SampleStatus.NAV_GAP
    if not valid:
        status[:] = SampleStatus.INVALID_MEASUREMENT
    flows[status != 0] = np.nan
    zeros = np.zeros((n, 3))
    navigation_part = np.diag([0.04, 0.05, 0.01]) ** 2 * RNG.uniform(0.5, 2.0, size=(n, 1, 1))
    sensor_part = np.broadcast_to(np.diag([0.05, 0.05, 0.03]) ** 2, (n, 3, 3)).copy()
    navigation_part[status != 0] = sensor_part[status != 0] = np.nan
    covariance = FlowCovariance(navigation_part, sensor_part)
    batch = CorrectedBatch(
        secs + nanosecs * 1e-9,
        status,
        flows,
        zeros,
        zeros,
        zeros,
        np.full((n, 3), 5.0),
        covariance,
    )
    series = FlowSeries(CompensatorConfig().flow_sensor().reason)
    # in two pieces, as process_bag hands them over
    for part in (slice(0, 1000), slice(1000, n)):
        series.add(
            secs[part],
            nanosecs[part],
            CorrectedBatch(
                batch.t_s[part],
                status[part],
                flows[part],
                zeros[part],
                zeros[part],
                zeros[part],
                zeros[part],
                FlowCovariance(navigation_part[part], sensor_part[part]),
            ),
        )
    return series, secs * 1_000_000_000 + nanosecs, flows, status, covariance


def navigation() -> NavigationSeries:
    quaternion = Rotation.from_euler("ZYX", [YAW_ENU_DEG, PITCH_DEG, ROLL_DEG], degrees=True)
    series = NavigationSeries()
    n = DURATION_S * NAV_RATE_HZ
    series.add(
        SimpleNamespace(
            sec=START_S + i // NAV_RATE_HZ,
            nanosec=(i % NAV_RATE_HZ) * (1_000_000_000 // NAV_RATE_HZ),
            latitude_deg=LATITUDE_DEG,
            longitude_deg=LONGITUDE_DEG,
            altitude_m=ALTITUDE_M,
            attitude_xyzw=tuple(quaternion.as_quat()),
            velocity_enu_mps=VELOCITY_ENU_MPS,
        )
        for i in range(n)
    )
    return series


GNSS_RUN = (
    {"anemometer/wind": 3000},
    {"gnss_fix": SourceUse(150), "gnss_velocity": SourceUse(150), "gnss_heading": SourceUse(150)},
)
MAGNETIC_MOTION_PACK_RUN = (
    {"anemometer/wind": 3000},
    {"ahrs": SourceUse(3000), "moored": SourceUse(150)},
)


def facts_of(run, stamps_ns: np.ndarray, **parameters):
    """The facts of a run with the valid flow samples and source use of ``run``, over
    ``stamps_ns``."""
    valid_flow_samples, uses = run
    config = dataclasses.replace(FusionConfig(), **parameters)
    return output_facts(
        config, valid_flow_samples, uses, [(stamps_ns[0] * 1e-9, stamps_ns[-1] * 1e-9)]
    )


def content(valid: bool = True) -> tuple[NetcdfContent, np.ndarray, np.ndarray, np.ndarray]:
    series, stamps_ns, flows, status, covariance = wind_series(valid)
    products = []
    for window_s in (60.0, 600.0):
        averager = WindAverager(window_s)
        products += averager.add_batch(stamps_ns * 1e-9, flows, covariance) + averager.flush()
    fluxes = FluxAverager(60.0)
    for stamp_ns in stamps_ns:
        fluxes.add_temperature(stamp_ns * 1e-9, 20.0 + RNG.normal(0.0, 0.2))
    flux_products = fluxes.add_batch(stamps_ns * 1e-9, flows) + fluxes.flush()
    return (
        NetcdfContent(
            source="bags/example",
            navigation=navigation(),
            wind=series,
            wind_products=products,
            fluxes=flux_products,
            history="process_bag bags/example out --netcdf out.nc",
            attributes={"license": "CC-BY-4.0"},
            facts=facts_of(GNSS_RUN, stamps_ns),
        ),
        stamps_ns,
        flows,
        status,
    )


@pytest.fixture(scope="module")
def written(tmp_path_factory):
    path = tmp_path_factory.mktemp("netcdf") / "example.nc"
    made, stamps_ns, flows, status = content()
    write_netcdf(path, made, overwrite=False)
    return path, made, stamps_ns, flows, status


def test_the_file_holds_the_series_the_products_and_the_navigation(written):
    path, made, stamps_ns, flows, status = written
    with xr.open_dataset(path, decode_times=False) as dataset:
        np.testing.assert_array_equal(dataset["time"].values, (stamps_ns - START_S * 10**9) / 1e9)
        assert dataset["time"].attrs["units"] == "seconds since 2026-01-01T00:00:00Z"
        for axis, name in enumerate(("eastward_wind", "northward_wind", "upward_air_velocity")):
            np.testing.assert_array_equal(dataset[name].values, flows[:, axis])
        np.testing.assert_array_equal(dataset["wind_status"].values, status)
        # Each component links its standard error, the square root of the sample's variance.
        total = made.wind.standard_errors()
        for axis, name in enumerate(("eastward_wind", "northward_wind", "upward_air_velocity")):
            error_name = f"{'uvw'[axis]}_standard_error"
            assert dataset[name].attrs["ancillary_variables"] == f"wind_status {error_name}"
            assert dataset[error_name].attrs["standard_name"] == f"{name} standard_error"
            np.testing.assert_array_equal(dataset[error_name].values, total[:, axis])
        assert np.isnan(total[status != 0]).all() and np.isfinite(total[status == 0]).all()
        meanings = dataset["wind_status"].attrs["flag_meanings"].split()
        assert meanings[SampleStatus.NAV_GAP] == "nav_gap"
        assert meanings[SampleStatus.INVALID_MEASUREMENT] == "invalid_wind"
        # a wind toward ESE, (6, -3): blowing from WNW, 296.6°
        valid = status == 0
        np.testing.assert_allclose(
            dataset["wind_from_direction"].values[valid],
            np.degrees(np.arctan2(-flows[valid, 0], -flows[valid, 1])) % 360,
            atol=1e-12,
        )
        assert np.isnan(dataset["wind_speed"].values[~valid]).all()
        np.testing.assert_allclose(dataset["roll"].values, ROLL_DEG, atol=1e-9)
        np.testing.assert_allclose(dataset["pitch"].values, PITCH_DEG, atol=1e-9)
        np.testing.assert_allclose(dataset["heading"].values, 90.0 - YAW_ENU_DEG, atol=1e-9)
        np.testing.assert_allclose(dataset["speed_over_ground"].values, math.sqrt(2), atol=1e-12)
        np.testing.assert_allclose(dataset["course_over_ground"].values, 45.0, atol=1e-9)
        np.testing.assert_array_equal(dataset["latitude"].values, LATITUDE_DEG)
        assert dataset.attrs["time_coverage_start"] == "2026-01-01T00:00:00.000Z"
        assert dataset.attrs["time_coverage_resolution"] == "PT0.05S"
        assert dataset.attrs["license"] == "CC-BY-4.0"
        assert dataset.attrs["geospatial_lat_min"] == LATITUDE_DEG
        for window_s in (60.0, 600.0):
            products = [p for p in made.wind_products if p.window_s == window_s]
            bounds = dataset[f"{product_time_name('wind', window_s)}_bounds"].values
            np.testing.assert_array_equal(
                bounds, [[p.window_start_s - START_S, p.window_end_s - START_S] for p in products]
            )
            for field in ("vector_mean_speed_mps", "gust_mps", "std_w_mps", "coverage"):
                np.testing.assert_array_equal(
                    dataset[product_variable_name("wind", window_s, field)].values,
                    [getattr(p, field) for p in products],
                )
            flags = dataset[product_variable_name("wind", window_s, "quality_flag")].values
            assert flags.tolist() == [p.quality_flag for p in products]
            mean_name = product_variable_name("wind", window_s, "mean_u_enu_mps")
            error_name = product_variable_name("wind", window_s, "mean_u_standard_error_mps")
            assert error_name in dataset[mean_name].attrs["ancillary_variables"].split()
            np.testing.assert_array_equal(
                dataset[error_name].values, [p.mean_u_standard_error_mps for p in products]
            )
            assert dataset[error_name].attrs["standard_name"] == "eastward_wind standard_error"
            speed_name = product_variable_name("wind", window_s, "vector_mean_speed_mps")
            flag_name = product_variable_name("wind", window_s, "quality_flag")
            assert dataset[speed_name].attrs["ancillary_variables"] == flag_name
        for field in ("friction_velocity_mps", "w_ts_k_mps", "stationarity_u_w_percent"):
            np.testing.assert_array_equal(
                dataset[product_variable_name("flux", 60.0, field)].values,
                [getattr(p, field) for p in made.fluxes],
            )
        assert dataset["flux_1min_n_temperature"].values.tolist() == [1200, 1200, 600]
        assert dataset["flux_1min_mean_wind_speed"].attrs["ancillary_variables"] == (
            "flux_1min_quality_flag"
        )
        # each named flux test in a CF flag variable of its own
        for test in FLUX_FLAG_TESTS:
            variable = dataset[f"flux_1min_{test.field}"]
            assert variable.values.tolist() == [getattr(p, test.field) for p in made.fluxes]
            assert variable.attrs["flag_values"].tolist() == [1, 2, 3, 4, 9]
            assert variable.attrs["flag_meanings"].split()[3] == "bad"
        overall = dataset["flux_1min_quality_flag"]
        assert all(test.field in overall.attrs["comment"] for test in FLUX_FLAG_TESTS)
    # Full 1-min windows hold 95 % of their samples valid; the trailing 30 s of the 150 s are
    # a partial one, and the 10-min window a quarter full: flagged, not passed off as full.
    one_minute = [p for p in made.wind_products if p.window_s == 60.0]
    assert [p.quality_flag for p in one_minute] == [1, 1, 4]
    assert [p.quality_flag for p in made.wind_products if p.window_s == 600.0] == [4]
    with xr.open_dataset(path) as decoded:  # CF time decoding, as any reader does
        assert decoded["time"].values[1] == np.datetime64("2026-01-01T00:00:00.050")


# Which variables of the dataset are latitudes, axes, auxiliary coordinates, geophysical...: the
# checker asks these anew for every variable it checks, thousands of times a run over a file of a
# hundred variables, and the asking was nine tenths of the check's time (some 20 s of CPU). The
# answers depend on the file alone, which the checker opens read-only, so the first answer of a
# run serves the rest, as the checker itself caches get_coordinate_variables. The same checks
# run and give the same verdicts: only the repeated asking goes.
DATASET_QUERIES = (
    "coordinate_dimension_matrix",
    "get_auxiliary_coordinate_variables",
    "get_axis_variables",
    "get_bounds_variables",
    "get_cell_boundary_variables",
    "get_forecast_metadata_variables",
    "get_geophysical_variables",
    "get_instrument_variables",
    "get_latitude_variables",
    "get_longitude_variables",
    "get_platform_variables",
    "get_time_variables",
    "get_z_variables",
)


def answered_once(query):
    """``query(dataset)``, asked of the dataset once: later calls get a copy of that answer,
    which they may extend as they would a fresh one."""
    answers = {}

    @functools.wraps(query)
    def remembered(dataset):
        if dataset not in answers:
            answers[dataset] = query(dataset)
        return copy.copy(answers[dataset])

    return remembered


def compliance_results(path: Path, checkers: list[str]) -> dict:
    """The IOOS compliance checker's results for ``path`` by each of ``checkers``, in one run
    over one opened dataset."""
    with pytest.MonkeyPatch.context() as patch:
        # raising: a query the checker no longer has fails here, not silently slow
        for name in DATASET_QUERIES:
            patch.setattr(checker_queries, name, answered_once(getattr(checker_queries, name)))
        suite = CheckSuite()
        suite.load_all_available_checkers()
        return suite.run_all(suite.load_dataset(str(path)), checkers, [])


@pytest.mark.filterwarnings("ignore::DeprecationWarning")  # the checker's own, of its plugins
def test_the_file_is_cf_compliant_and_acdd_complete(written):
    path = written[0]
    results = compliance_results(path, ["cf:1.10", "acdd:1.3"])

    def failed(result) -> bool:
        value = result.value
        return value[0] < value[1] if isinstance(value, tuple) else not value

    cf_results, cf_errors = results["cf:1.10"]
    assert not cf_errors
    assert [(r.name, r.msgs) for r in cf_results if failed(r)] == []
    acdd_results, acdd_errors = results["acdd:1.3"]
    assert not acdd_errors
    high_failures = [r for r in acdd_results if r.weight == 3 and failed(r)]
    # Every highly recommended global attribute is there, and every variable has a CF
    # standard name but the bounds and the quantities that have none.
    with xr.open_dataset(path) as dataset:
        without = {
            name
            for name, variable in dataset.variables.items()
            if "standard_name" not in variable.attrs
        }
    no_cf_name = ("_bounds", "_coverage", "_n_invalid", "_n_temperature", "_invalid_share")
    no_cf_name += ("_tilt", "_u_w", "_v_w", "_w_ts", "_spikes_u", "_spikes_v", "_spikes_w")
    no_cf_name += ("_spikes_ts", "_stationarity_u_w", "_stationarity_w_ts")
    no_cf_name += ("_wave_band_low_frequency", "_wave_band_high_frequency")
    no_cf_name += ("_motion_left_coherence", "_motion_left_coherence_threshold")
    no_cf_name += ("_motion_left_share",)
    no_cf_name += ("_stress_along_wind", "_stress_across_wind", "_std_sonic_temperature")
    no_cf_name += ("_obukhov_stability", "_itc_w_deviation", "_drag_coefficient_neutral_10m")
    no_cf_name += ("_cross_wind_stress_ratio", "_w_ts_correlation", "_temperature_scale")
    assert all(name.endswith(no_cf_name) for name in without), without
    assert any(name.startswith("flux_1min_") for name in without)
    assert all(r.msgs == ["standard_name"] for r in high_failures), high_failures
    assert {r.name.split('"')[1] for r in high_failures} <= without


def test_all_invalid_wind_still_gives_the_navigation_and_missing_windows(tmp_path):
    made, _, _, _ = content(valid=False)
    path = write_netcdf(tmp_path / "invalid.nc", made, overwrite=False)
    with xr.open_dataset(path, decode_times=False) as dataset:
        assert np.isnan(dataset["eastward_wind"].values).all()
        assert (dataset["wind_status"].values == SampleStatus.INVALID_MEASUREMENT).all()
        assert dataset["latitude"].size == DURATION_S * NAV_RATE_HZ
        flags = dataset[product_variable_name("wind", 60.0, "quality_flag")].values
        assert (flags == QualityFlag.MISSING).all()


def test_an_existing_file_is_replaced_only_when_asked(tmp_path):
    made, _, _, _ = content()
    path = tmp_path / "out.nc"
    path.write_text("someone's file")
    with pytest.raises(OutputError, match="--overwrite"):
        write_netcdf(path, made, overwrite=False)
    assert path.read_text() == "someone's file"
    write_netcdf(path, made, overwrite=True)
    with xr.open_dataset(path) as dataset:
        assert "eastward_wind" in dataset
    directory = tmp_path / "a_directory.nc"
    directory.mkdir()
    with pytest.raises(OutputError, match="not a file"):
        write_netcdf(directory, made, overwrite=True)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a_directory.nc", "out.nc"]


def test_despiked_fluxes_say_so_on_their_spike_counts(written, tmp_path):
    path, made, _, _, _ = written
    despiked = write_netcdf(
        tmp_path / "despiked.nc", dataclasses.replace(made, fluxes_despiked=True), False
    )
    for file, expected in ((path, False), (despiked, True)):
        with xr.open_dataset(file, decode_times=False) as dataset:
            for component in ("u", "v", "w", "ts"):
                variable = dataset[product_variable_name("flux", 60.0, f"spikes_{component}")]
                assert ("compensation.flux_despike" in variable.attrs.get("comment", "")) is (
                    expected
                )


def test_the_wave_motion_left_of_each_flux_window_is_there_with_its_flag(written, tmp_path):
    _, made, _, _, _ = written
    # The example's 1-min windows are too short for the test: give them figures of their own.
    nan = math.nan
    figures = [
        (0.1, 0.3, 0.05, 0.07, 0.02, 1),
        (0.1, 0.4, 0.6, 0.07, 0.5, 4),
        (nan, nan, nan, nan, nan, 2),
    ]
    fluxes = [
        dataclasses.replace(
            window,
            wave_band_low_hz=low,
            wave_band_high_hz=high,
            motion_left_coherence=coherence,
            motion_left_coherence_threshold=threshold,
            motion_left_share=share,
            motion_left_flag=flag,
        )
        for window, (low, high, coherence, threshold, share, flag) in zip(
            made.fluxes, figures, strict=True
        )
    ]
    path = write_netcdf(tmp_path / "motion.nc", dataclasses.replace(made, fluxes=fluxes), False)
    with xr.open_dataset(path, decode_times=False) as dataset:
        for field, column in (
            ("wave_band_low_hz", 0),
            ("wave_band_high_hz", 1),
            ("motion_left_coherence", 2),
            ("motion_left_coherence_threshold", 3),
            ("motion_left_share", 4),
        ):
            variable = dataset[product_variable_name("flux", 60.0, field)]
            np.testing.assert_array_equal(variable.values, [row[column] for row in figures])
            assert variable.attrs["units"] == ("Hz" if field.startswith("wave") else "1")
            assert "wave band" in variable.attrs["long_name"]
        share = dataset["flux_1min_motion_left_share"]
        assert share.attrs["ancillary_variables"] == "flux_1min_motion_left_flag"
        flag = dataset["flux_1min_motion_left_flag"]
        assert flag.dtype == np.int8
        assert flag.values.tolist() == [1, 4, 2]
        assert flag.attrs["flag_values"].tolist() == [f.value for f in QualityFlag]
        assert "motion_left test" in flag.attrs["long_name"]


def test_the_file_states_the_north_the_sensors_and_the_span_of_the_samples(written):
    path, _, stamps_ns, _, _ = written
    with xr.open_dataset(path, decode_times=False) as dataset:
        assert dataset.attrs["north_reference"] == "true north"
        assert "clockwise from true north" in dataset.attrs["comment"]
        assert "dual-antenna GNSS" in dataset.attrs["instrument"]
        assert "DVL" not in dataset.attrs["instrument"]
        assert "clockwise from true north" in dataset["heading"].attrs["long_name"]
        assert dataset["wind_from_direction"].attrs["standard_name"] == "wind_from_direction"
        # The data end with their last sample, not with the middle of the 10-min window that
        # the 150 s of samples only begin.
        assert dataset.attrs["time_coverage_end"] == "2026-01-01T00:02:29.950Z"
        assert stamps_ns[-1] - START_S * 10**9 == 149_950_000_000
        assert dataset.attrs["time_coverage_duration"] == "PT149.950S"


def magnetic_heading_file(directory: Path) -> Path:
    """The file of a motion pack whose heading is magnetic, with no declination known."""
    made, stamps_ns, _, _ = content()
    facts = facts_of(
        MAGNETIC_MOTION_PACK_RUN,
        stamps_ns,
        ahrs_yaw_reference="magnetic_north",
        magnetic_declination_deg=0.0,
        site_latitude_deg=LATITUDE_DEG,
        site_longitude_deg=LONGITUDE_DEG,
    )
    return write_netcdf(directory / "magnetic.nc", dataclasses.replace(made, facts=facts), False)


def test_a_magnetic_heading_without_declination_is_said(tmp_path):
    path = magnetic_heading_file(tmp_path)
    with xr.open_dataset(path, decode_times=False) as dataset:
        assert dataset.attrs["north_reference"] == "magnetic north"
        assert "magnetic north (no declination applied)" in dataset.attrs["comment"]
        assert "GNSS" not in dataset.attrs["instrument"] + dataset.attrs["summary"]
        assert "motion pack" in dataset.attrs["instrument"]
        for name in ("heading", "wind_from_direction", "eastward_wind", "u_standard_error"):
            assert "standard_name" not in dataset[name].attrs, name
            assert "magnetic" in dataset[name].attrs["comment"], name
        assert dataset["upward_air_velocity"].attrs["standard_name"] == "upward_air_velocity"
        assert "not measured" in dataset["latitude"].attrs["comment"]
        assert dataset.attrs["geospatial_lat_min"] == LATITUDE_DEG


@pytest.mark.filterwarnings("ignore::DeprecationWarning")  # the checker's own, of its plugins
def test_a_magnetic_heading_file_stays_cf_compliant(tmp_path):
    path = magnetic_heading_file(tmp_path)
    results, errors = compliance_results(path, ["cf:1.10"])["cf:1.10"]
    assert not errors
    assert [r.name for r in results if _failed(r)] == []


def _failed(result) -> bool:
    value = result.value
    return value[0] < value[1] if isinstance(value, tuple) else not value


def test_a_latitude_alone_is_no_position_and_the_record_is_stated(tmp_path):
    made, stamps_ns, _, _ = content()
    record = ImportedRecord(
        record="day.dat",
        column_map="map.yaml",
        description="a sonic and a motion pack",
        start_ns=stamps_ns[0],
        start_source="time column",
        sensors=("sonic", "imu", "ahrs"),
        field_counts={"anemometer.w": FieldCounts(read=20, filled=2, invalid=1, out_of_range=0)},
    )
    facts = facts_of(
        MAGNETIC_MOTION_PACK_RUN,
        stamps_ns,
        ahrs_yaw_reference="magnetic_north",
        magnetic_declination_deg=0.0,
        site_latitude_deg=LATITUDE_DEG,
    )
    facts = dataclasses.replace(facts, record=record)
    path = write_netcdf(tmp_path / "latitude.nc", dataclasses.replace(made, facts=facts), False)
    with xr.open_dataset(path, decode_times=False) as dataset:
        assert not any(key.startswith("geospatial_lat") for key in dataset.attrs)
        assert not any(key.startswith("geospatial_lon") for key in dataset.attrs)
        assert "given for gravity; position unknown" in dataset.attrs["comment"]
        assert "anemometer.w 20/2/1/0" in dataset.attrs["comment"]
        assert "day.dat" in dataset.attrs["source"]
        assert "(start from the time column)" in dataset.attrs["source"]
        assert "position unknown" in dataset["longitude"].attrs["comment"]
