"""The variables of the NetCDF-CF file of ``process_bag`` (:mod:`buoy_processing.netcdf_output`):
its time coding, and the CF variables of the series kept while the bag is processed
(:mod:`buoy_processing.output_series`), the navigation and the products, with their standard names,
units, cell methods and flags.
"""

from __future__ import annotations

import datetime
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import xarray as xr

from buoy_common.contract import QualityFlag, window_label
from buoy_processing.output_series import NANOSECONDS, FlowSeries, NavigationSeries
from buoy_processing.report.attitude import rpy_rad_from_quaternions
from wind_comp.compensator import SampleStatus
from wind_comp.flux_quality import FLUX_FLAG_TESTS
from wind_comp.products import (
    GOOD_COVERAGE,
    MIN_COVERAGE,
    meteorological_direction_deg,
    oceanographic_direction_deg,
)

TIME_UNITS = "seconds"
"""Marks a product field that is a time: written in the file's time units."""

CLOCKWISE_FROM_NORTH = "{clockwise from north}"
"""Stands in the texts of the directions and headings for the north the run's heading was
referenced to, which :mod:`buoy_processing.netcdf_output` puts in its place."""

GEOGRAPHIC_STANDARD_NAMES = (
    "eastward_",
    "northward_",
    "wind_from_direction",
    "sea_water_velocity_to_direction",
    "platform_orientation",
    "platform_course",
)
"""Beginnings of the CF standard names whose axes are true east and true north: not the
names of quantities referenced to magnetic north."""


@dataclass(frozen=True)
class TimeAxis:
    """The file's time coding: float64 seconds since midnight UTC of the day its data start.

    A reference near the data keeps the float64 seconds exact to far below a nanosecond (at
    the epoch 1970 they would resolve only 0.24 µs), so a reader decoding them gets the
    sensors' stamps back to within a nanosecond."""

    reference_ns: int

    @classmethod
    def starting_on_the_day_of(cls, first_stamp_ns: int) -> TimeAxis:
        day_ns = 86_400 * NANOSECONDS
        return cls(first_stamp_ns // day_ns * day_ns)

    @property
    def units(self) -> str:
        day = datetime.datetime.fromtimestamp(self.reference_ns // NANOSECONDS, tz=datetime.UTC)
        return f"seconds since {day:%Y-%m-%dT%H:%M:%S}Z"

    def from_ns(self, stamps_ns: np.ndarray) -> np.ndarray:
        """Integer nanoseconds since the epoch as the file's seconds."""
        return (np.asarray(stamps_ns, dtype=np.int64) - self.reference_ns) / NANOSECONDS

    def from_s(self, t_s) -> np.ndarray:
        """Float seconds since the epoch as the file's seconds."""
        return np.asarray(t_s, dtype=float) - self.reference_ns // NANOSECONDS


def _time_attributes(axis: TimeAxis, long_name: str, bounds: str | None = None) -> dict:
    attributes = {
        "standard_name": "time",
        "long_name": long_name,
        "units": axis.units,
        "calendar": "standard",
        "axis": "T",
    }
    if bounds is not None:
        attributes["bounds"] = bounds
    return attributes


def _status_attributes(what: str, reason: Callable[[SampleStatus], str]) -> dict:
    meanings = " ".join(
        "valid" if status == SampleStatus.VALID else str(reason(status)) for status in SampleStatus
    )
    return {
        "standard_name": "status_flag",
        "long_name": f"outcome of the motion correction of each {what} sample",
        "flag_values": np.array([status.value for status in SampleStatus], dtype=np.int8),
        "flag_meanings": meanings,
        "comment": "0: corrected; any other value: the sample is NaN, for the reason named",
    }


def _flag_attributes(long_name: str, comment: str) -> dict:
    """CF flag attributes of an IOOS QARTOD flag variable."""
    return {
        "standard_name": "quality_flag",
        "long_name": long_name,
        "flag_values": np.array([flag.value for flag in QualityFlag], dtype=np.int8),
        "flag_meanings": " ".join(flag.name.lower() for flag in QualityFlag),
        "comment": comment,
        "coverage_content_type": "qualityInformation",
    }


COVERAGE_FLAG_COMMENT = (
    f"good: coverage >= {GOOD_COVERAGE}; suspect: coverage >= {MIN_COVERAGE}; bad: "
    "lower coverage; missing: no valid sample; not_evaluated: the sampling interval "
    "was not yet known (IOOS QARTOD flags)"
)


def _quality_flag_attributes(what: str) -> dict:
    long_name = f"QARTOD quality flag of each {what} window"
    if what == "flux":
        tests = " ".join(f"{test.name}_flag" for test in FLUX_FLAG_TESTS)
        comment = (
            "the worst of the named flux tests (fail over suspect over good over "
            f"not_evaluated): {tests}"
        )
        return _flag_attributes(long_name, comment)
    return _flag_attributes(long_name, COVERAGE_FLAG_COMMENT)


def _flux_test_flag_variables(what: str, window_s: float, windows, dimension: str) -> dict:
    """One QARTOD flag variable per named flux test (``flux_30min_drag_coefficient_flag``,
    ...); none for other products."""
    if what != "flux":
        return {}
    flag_name = product_variable_name(what, window_s, "quality_flag")
    return {
        f"{what}_{window_label(window_s)}_{test.field}": xr.DataArray(
            np.array([getattr(window, test.field) for window in windows], dtype=np.int8),
            dims=dimension,
            attrs={
                **_flag_attributes(
                    f"QARTOD flag of the {test.name} test of each flux window: {test.meaning}",
                    f"one of the tests whose worst is {flag_name} (wind_comp.flux_quality)",
                ),
            },
        )
        for test in FLUX_FLAG_TESTS
    }


def flow_variables(series: FlowSeries, wind: bool, axis: TimeAxis) -> dict[str, xr.DataArray]:
    """The per-sample variables of the wind (``wind``) or the current."""
    stamps_ns, flows, status = series.columns()
    dimension = "time" if wind else "current_time"
    speeds = np.hypot(flows[:, 0], flows[:, 1])
    if wind:
        names = ("eastward_wind", "northward_wind", "upward_air_velocity")
        what, direction = "wind", meteorological_direction_deg(flows[:, 0], flows[:, 1])
        speed_name, direction_name, status_name = (
            "wind_speed",
            "wind_from_direction",
            "wind_status",
        )
        standard_names = (*names, "wind_speed", "wind_from_direction")
        direction_comment = "meteorological: where the wind blows FROM, " + CLOCKWISE_FROM_NORTH
    else:
        names = ("eastward_current", "northward_current", "upward_current")
        what, direction = "current", oceanographic_direction_deg(flows[:, 0], flows[:, 1])
        speed_name, direction_name, status_name = (
            "current_speed",
            "current_to_direction",
            "current_status",
        )
        standard_names = (
            "eastward_sea_water_velocity",
            "northward_sea_water_velocity",
            "upward_sea_water_velocity",
            "sea_water_speed",
            "sea_water_velocity_to_direction",
        )
        direction_comment = "oceanographic: where the water flows TOWARD, " + CLOCKWISE_FROM_NORTH
    prefix = "" if wind else "current_"
    error_names = tuple(f"{prefix}{axis}_standard_error" for axis in "uvw")
    common = {"ancillary_variables": status_name, "coverage_content_type": "physicalMeasurement"}
    variables = {
        dimension: xr.DataArray(
            axis.from_ns(stamps_ns),
            dims=dimension,
            attrs=_time_attributes(axis, f"header stamp of each {what} sample"),
        )
    }
    standard_errors = series.standard_errors()
    for column, (name, standard_name) in enumerate(zip(names, standard_names, strict=False)):
        axis_name = ("east", "north", "up")[column]
        variables[name] = xr.DataArray(
            flows[:, column],
            dims=dimension,
            attrs={
                "standard_name": standard_name,
                "long_name": f"motion-corrected {what}, {axis_name}",
                "units": "m s-1",
                **common,
                "ancillary_variables": f"{status_name} {error_names[column]}",
            },
        )
        variables[error_names[column]] = xr.DataArray(
            standard_errors[:, column],
            dims=dimension,
            attrs={
                "standard_name": f"{standard_name} standard_error",
                "long_name": f"1 sigma of the motion-corrected {what}, {axis_name}",
                "units": "m s-1",
                "comment": "from the navigation's covariances and the sensor's noise; NaN "
                "where the sample is",
                "coverage_content_type": "qualityInformation",
            },
        )
    variables[speed_name] = xr.DataArray(
        speeds,
        dims=dimension,
        attrs={
            "standard_name": standard_names[3],
            "long_name": f"horizontal speed of the motion-corrected {what}",
            "units": "m s-1",
            **common,
        },
    )
    variables[direction_name] = xr.DataArray(
        np.asarray(direction, dtype=float),
        dims=dimension,
        attrs={
            "standard_name": standard_names[4],
            "long_name": f"direction of the motion-corrected {what}",
            "units": "degree",
            "comment": direction_comment,
            **common,
        },
    )
    variables[status_name] = xr.DataArray(
        status.copy(), dims=dimension, attrs=_status_attributes(what, series.reason)
    )
    return variables


_POSITION_STANDARD_NAMES = ("latitude", "longitude", "height_above_reference_ellipsoid")


def navigation_variables(navigation: NavigationSeries, axis: TimeAxis) -> dict[str, xr.DataArray]:
    stamps_ns, columns = navigation.columns()
    dimension = "nav_time"
    rpy_deg = (
        np.degrees(rpy_rad_from_quaternions(columns[:, 3:7])) if len(columns) else np.empty((0, 3))
    )
    heading_deg = (90.0 - rpy_deg[:, 2]) % 360.0
    common = {"coverage_content_type": "referenceInformation"}

    def variable(values, standard_name, long_name, units, **extra):
        # Where each solution was: the position variables are its auxiliary coordinates.
        if standard_name not in _POSITION_STANDARD_NAMES:
            extra = {"coordinates": "latitude longitude altitude", **extra}
        attributes = {"long_name": long_name, "units": units, **common, **extra}
        if standard_name:
            attributes["standard_name"] = standard_name
        return xr.DataArray(values, dims=dimension, attrs=attributes)

    return {
        dimension: xr.DataArray(
            axis.from_ns(stamps_ns),
            dims=dimension,
            attrs=_time_attributes(axis, "stamp of each navigation solution (nav/odometry)"),
        ),
        "latitude": variable(
            columns[:, 0], "latitude", "latitude of the IMU (base_link origin)", "degrees_north"
        ),
        "longitude": variable(
            columns[:, 1], "longitude", "longitude of the IMU (base_link origin)", "degrees_east"
        ),
        "altitude": variable(
            columns[:, 2],
            "height_above_reference_ellipsoid",
            "ellipsoidal height of the IMU (WGS-84)",
            "m",
            positive="up",
            axis="Z",
        ),
        "roll": variable(
            rpy_deg[:, 0],
            "platform_roll_starboard_down",
            "roll of the buoy, R = Rz(yaw) Ry(pitch) Rx(roll) about forward-left-up body axes",
            "degree",
        ),
        "pitch": variable(
            rpy_deg[:, 1],
            "platform_pitch_fore_down",
            "pitch of the buoy, R = Rz(yaw) Ry(pitch) Rx(roll) about forward-left-up body axes",
            "degree",
        ),
        "heading": variable(
            heading_deg,
            "platform_orientation",
            "heading of the buoy's forward (x) axis, " + CLOCKWISE_FROM_NORTH,
            "degree",
        ),
        "speed_over_ground": variable(
            np.hypot(columns[:, 7], columns[:, 8]),
            "platform_speed_wrt_ground",
            "horizontal speed of the IMU over ground",
            "m s-1",
        ),
        "course_over_ground": variable(
            oceanographic_direction_deg(columns[:, 7], columns[:, 8]),
            "platform_course",
            "direction the IMU moves over ground, " + CLOCKWISE_FROM_NORTH,
            "degree",
        ),
        "heave_rate": variable(
            columns[:, 9], "platform_heave_rate_up", "upward velocity of the IMU", "m s-1"
        ),
    }


@dataclass(frozen=True)
class _ProductVariable:
    field: str
    name: str
    standard_name: str | None
    units: str | None
    cell_method: str | None
    long_name: str


_SHARED_PRODUCT_VARIABLES = (
    _ProductVariable("n_valid", "n_valid", "number_of_observations", "1", None,
                     "valid samples in the window"),
    _ProductVariable("n_invalid", "n_invalid", None, "1", None,
                     "invalid samples in the window (counted, not averaged)"),
    _ProductVariable("coverage", "coverage", None, "1", None,
                     "share of a full window's samples the window holds valid"),
    _ProductVariable("first_sample_s", "first_sample_time", "time", TIME_UNITS, None,
                     "stamp of the window's first sample"),
    _ProductVariable("last_sample_s", "last_sample_time", "time", TIME_UNITS, None,
                     "stamp of the window's last sample"),
)  # fmt: skip

_WIND_PRODUCT_VARIABLES = (
    _ProductVariable("mean_u_enu_mps", "mean_eastward_wind", "eastward_wind", "m s-1", "mean",
                     "vector-mean wind, east"),
    _ProductVariable("mean_v_enu_mps", "mean_northward_wind", "northward_wind", "m s-1", "mean",
                     "vector-mean wind, north"),
    _ProductVariable("mean_w_enu_mps", "mean_upward_air_velocity", "upward_air_velocity",
                     "m s-1", "mean", "vector-mean wind, up"),
    _ProductVariable("vector_mean_speed_mps", "vector_mean_wind_speed", "wind_speed", "m s-1",
                     "mean", "horizontal speed of the vector-mean wind"),
    _ProductVariable("vector_mean_direction_deg", "vector_mean_wind_from_direction",
                     "wind_from_direction", "degree", "mean",
                     "direction of the vector-mean wind (FROM, " + CLOCKWISE_FROM_NORTH + ")"),
    _ProductVariable("scalar_mean_speed_mps", "scalar_mean_wind_speed", "wind_speed", "m s-1",
                     "mean", "mean of the horizontal speeds"),
    _ProductVariable("gust_mps", "gust", "wind_speed_of_gust", "m s-1", "maximum",
                     "largest running mean of the horizontal speed over gust_window_s"),
    _ProductVariable("std_u_mps", "std_eastward_wind", "eastward_wind", "m s-1",
                     "standard_deviation", "standard deviation of the east wind"),
    _ProductVariable("std_v_mps", "std_northward_wind", "northward_wind", "m s-1",
                     "standard_deviation", "standard deviation of the north wind"),
    _ProductVariable("std_w_mps", "std_upward_air_velocity", "upward_air_velocity", "m s-1",
                     "standard_deviation", "standard deviation of the vertical wind"),
    _ProductVariable("mean_u_standard_error_mps", "mean_eastward_wind_standard_error",
                     "eastward_wind standard_error", "m s-1", None,
                     "1 sigma of the vector-mean wind, east"),
    _ProductVariable("mean_v_standard_error_mps", "mean_northward_wind_standard_error",
                     "northward_wind standard_error", "m s-1", None,
                     "1 sigma of the vector-mean wind, north"),
    _ProductVariable("mean_w_standard_error_mps", "mean_upward_air_velocity_standard_error",
                     "upward_air_velocity standard_error", "m s-1", None,
                     "1 sigma of the vector-mean wind, up"),
    *_SHARED_PRODUCT_VARIABLES,
)  # fmt: skip

_CURRENT_PRODUCT_VARIABLES = (
    _ProductVariable("mean_u_enu_mps", "mean_eastward_current", "eastward_sea_water_velocity",
                     "m s-1", "mean", "vector-mean current, east"),
    _ProductVariable("mean_v_enu_mps", "mean_northward_current", "northward_sea_water_velocity",
                     "m s-1", "mean", "vector-mean current, north"),
    _ProductVariable("mean_w_enu_mps", "mean_upward_current", "upward_sea_water_velocity",
                     "m s-1", "mean", "vector-mean current, up"),
    _ProductVariable("speed_mps", "current_speed", "sea_water_speed", "m s-1", "mean",
                     "horizontal speed of the vector-mean current"),
    _ProductVariable("direction_deg", "current_to_direction", "sea_water_velocity_to_direction",
                     "degree", "mean",
                     "direction of the vector-mean current (TOWARD, " + CLOCKWISE_FROM_NORTH + ")"),
    _ProductVariable("std_u_mps", "std_eastward_current", "eastward_sea_water_velocity",
                     "m s-1", "standard_deviation", "standard deviation of the east current"),
    _ProductVariable("std_v_mps", "std_northward_current", "northward_sea_water_velocity",
                     "m s-1", "standard_deviation", "standard deviation of the north current"),
    _ProductVariable("std_w_mps", "std_upward_current", "upward_sea_water_velocity", "m s-1",
                     "standard_deviation", "standard deviation of the vertical current"),
    _ProductVariable("mean_u_standard_error_mps", "mean_eastward_current_standard_error",
                     "eastward_sea_water_velocity standard_error", "m s-1", None,
                     "1 sigma of the vector-mean current, east"),
    _ProductVariable("mean_v_standard_error_mps", "mean_northward_current_standard_error",
                     "northward_sea_water_velocity standard_error", "m s-1", None,
                     "1 sigma of the vector-mean current, north"),
    _ProductVariable("mean_w_standard_error_mps", "mean_upward_current_standard_error",
                     "upward_sea_water_velocity standard_error", "m s-1", None,
                     "1 sigma of the vector-mean current, up"),
    *_SHARED_PRODUCT_VARIABLES,
)  # fmt: skip


_FLUX_VARIABLES = (
    _ProductVariable("mean_speed_mps", "mean_wind_speed", "wind_speed", "m s-1", "mean",
                     "mean wind along the rotated x axis (the mean wind)"),
    _ProductVariable("tilt_deg", "tilt", None, "degree", None,
                     "tilt of the rotation: of the mean wind (double rotation) or of the plane "
                     "(planar fit)"),
    _ProductVariable("u_w_m2_s2", "u_w", None, "m2 s-2", None,
                     "kinematic momentum flux u'w', along the mean wind, linearly detrended"),
    _ProductVariable("v_w_m2_s2", "v_w", None, "m2 s-2", None,
                     "kinematic momentum flux v'w', across the mean wind, linearly detrended"),
    _ProductVariable("friction_velocity_mps", "friction_velocity",
                     "magnitude_of_surface_friction_velocity_in_air", "m s-1", None,
                     "friction velocity u* = (u'w'^2 + v'w'^2)^(1/4)"),
    _ProductVariable("stress_n_m2", "stress", "magnitude_of_surface_downward_stress", "N m-2",
                     None, "wind stress rho u*^2"),
    _ProductVariable("air_density_kg_m3", "air_density", "air_density", "kg m-3", "mean",
                     "air density of the stress, from the sonic temperature as virtual "
                     "temperature and air_pressure_pa"),
    _ProductVariable("w_ts_k_mps", "w_ts", None, "K m s-1", None,
                     "buoyancy flux w'Ts' of the sonic temperature; NaN without one"),
    _ProductVariable("spikes_u", "spikes_u", None, "1", None,
                     "Vickers-Mahrt spikes in u"),
    _ProductVariable("spikes_v", "spikes_v", None, "1", None, "Vickers-Mahrt spikes in v"),
    _ProductVariable("spikes_w", "spikes_w", None, "1", None, "Vickers-Mahrt spikes in w"),
    _ProductVariable("spikes_ts", "spikes_ts", None, "1", None,
                     "Vickers-Mahrt spikes in the sonic temperature"),
    _ProductVariable("invalid_share", "invalid_share", None, "1", None,
                     "share of the window's samples that are invalid"),
    _ProductVariable("stationarity_u_w_percent", "stationarity_u_w", None, "percent", None,
                     "Foken-Wichura non-stationarity of u'w' (six sub-windows; < 30 % "
                     "stationary)"),
    _ProductVariable("stationarity_w_ts_percent", "stationarity_w_ts", None, "percent", None,
                     "Foken-Wichura non-stationarity of w'Ts'"),
    _ProductVariable("n_temperature", "n_temperature", None, "1", None,
                     "wind samples paired with a sonic temperature"),
    _ProductVariable("stress_along_n_m2", "stress_along_wind", None, "N m-2", None,
                     "stress along the mean wind, -rho u'w' (positive: momentum carried down)"),
    _ProductVariable("stress_cross_n_m2", "stress_across_wind", None, "N m-2", None,
                     "stress across the mean wind (toward its left), -rho v'w'"),
    _ProductVariable("sigma_w_mps", "std_upward_air_velocity", "upward_air_velocity", "m s-1",
                     "standard_deviation",
                     "standard deviation of the detrended vertical wind (frame of the mean "
                     "wind)"),
    _ProductVariable("sigma_ts_k", "std_sonic_temperature", None, "K", "standard_deviation",
                     "standard deviation of the detrended sonic temperature; NaN without one"),
    _ProductVariable("obukhov_stability", "obukhov_stability", None, "1", None,
                     "stability z/L from the measurement height, u* and w'Ts'; NaN when "
                     "either is unknown"),
    _ProductVariable("itc_w_deviation_percent", "itc_w_deviation", None, "percent", None,
                     "deviation of sigma_w/u* from 1.3(1+2|z/L|)^(1/3), 1.25 without z/L "
                     "(integral turbulence characteristics, Foken et al. 2004)"),
    _ProductVariable("drag_coefficient", "drag_coefficient",
                     "surface_drag_coefficient_for_momentum_in_air", "1", None,
                     "u*^2/U^2 at the sonic's height"),
    _ProductVariable("drag_coefficient_neutral_10m", "drag_coefficient_neutral_10m", None, "1",
                     None, "COARE 3.5 neutral 10-m drag coefficient at the mean speed "
                     "(Edson et al. 2013), the drag coefficient test's reference"),
    _ProductVariable("cross_wind_stress_ratio", "cross_wind_stress_ratio", None, "1", None,
                     "|v'w'| / |u'w'| in the frame of the mean wind"),
    _ProductVariable("w_ts_correlation", "w_ts_correlation", None, "1", None,
                     "correlation w'Ts' / (sigma_w sigma_T); NaN without a sonic temperature"),
    _ProductVariable("temperature_scale_k", "temperature_scale", None, "K", None,
                     "temperature scale T* = -w'Ts'/u*; NaN without a sonic temperature"),
    *_SHARED_PRODUCT_VARIABLES,
    _ProductVariable("wave_band_low_hz", "wave_band_low_frequency", None, "Hz", None,
                     "lower edge of the wave band, where the spectrum of the platform's "
                     "vertical acceleration exceeds a tenth of its peak"),
    _ProductVariable("wave_band_high_hz", "wave_band_high_frequency", None, "Hz", None,
                     "upper edge of the wave band"),
    _ProductVariable("motion_left_coherence", "motion_left_coherence", None, "1", None,
                     "mean coherence of the corrected upward air velocity with the platform's "
                     "vertical velocity over the wave band"),
    _ProductVariable("motion_left_coherence_threshold", "motion_left_coherence_threshold", None,
                     "1", None,
                     "coherence over the wave band that unrelated series would not exceed "
                     "(compensation.motion_left_coherence_sigmas above their mean)"),
    _ProductVariable("motion_left_share", "motion_left_share", None, "1", None,
                     "share of the platform's vertical velocity left in the corrected upward "
                     "air velocity over the wave band"),
)  # fmt: skip
AUXILIARY_FIELD_PREFIXES = (
    "n_", "first", "last", "spikes_", "stationarity_", "itc_", "cross_wind_",
    "drag_coefficient_neutral", "wave_band_",
)  # fmt: skip
"""Product fields that describe a window's sampling or its tests rather than the air."""
_TABLES = {
    "wind": _WIND_PRODUCT_VARIABLES,
    "current": _CURRENT_PRODUCT_VARIABLES,
    "flux": _FLUX_VARIABLES,
}


def product_variable_name(what: str, window_s: float, field_name: str) -> str:
    """The NetCDF variable of product field ``field_name`` (a :class:`WindProduct`,
    :class:`CurrentProduct` or :class:`FluxProduct` field) of ``what`` (``wind``, ``current``,
    ``flux``) windows of ``window_s`` seconds: ``wind_10min_gust``,
    ``current_1min_quality_flag``, ``flux_30min_friction_velocity``, ..."""
    table = _TABLES[what]
    if field_name == "quality_flag":
        return f"{what}_{window_label(window_s)}_quality_flag"
    spec = next(spec for spec in table if spec.field == field_name)
    return f"{what}_{window_label(window_s)}_{spec.name}"


def _ancillary_variables(what: str, window_s: float, spec: _ProductVariable) -> str:
    """The ``ancillary_variables`` of a product variable: the window's quality flag, and for a
    mean component its standard error."""
    flag_name = product_variable_name(what, window_s, "quality_flag")
    error_field = spec.field.replace("_enu_mps", "_standard_error_mps")
    if spec.field.endswith("_enu_mps") and any(s.field == error_field for s in _TABLES[what]):
        return f"{flag_name} {product_variable_name(what, window_s, error_field)}"
    return flag_name


def product_time_name(what: str, window_s: float) -> str:
    """The time dimension (and coordinate) of the ``what`` products of ``window_s`` s."""
    return f"{what}_time_{window_label(window_s)}"


def product_variables(
    what: str, products: list, axis: TimeAxis, despiked: bool = False
) -> dict[str, xr.DataArray]:
    """The variables of the ``what`` products, per window length; ``despiked``: the spikes the
    fluxes count were taken out of them (said on the spike counts)."""
    table = _TABLES[what]
    variables = {}
    for window_s in sorted({product.window_s for product in products}):
        windows = [product for product in products if product.window_s == window_s]
        dimension = product_time_name(what, window_s)
        bounds_name = f"{dimension}_bounds"
        starts = np.array([product.window_start_s for product in windows])
        ends = np.array([product.window_end_s for product in windows])
        label = window_label(window_s)
        flag_name = product_variable_name(what, window_s, "quality_flag")
        variables[dimension] = xr.DataArray(
            axis.from_s((starts + ends) / 2.0),
            dims=dimension,
            attrs=_time_attributes(axis, f"middle of each {label} {what} window", bounds_name),
        )
        variables[bounds_name] = xr.DataArray(
            axis.from_s(np.column_stack((starts, ends))), dims=(dimension, "bounds")
        )
        for spec in table:
            values = np.array([getattr(product, spec.field) for product in windows])
            attributes = {"long_name": f"{spec.long_name} ({label} windows)"}
            if spec.standard_name:
                attributes["standard_name"] = spec.standard_name
            if spec.units == TIME_UNITS:
                values = axis.from_s(values)
                attributes.update(units=axis.units, calendar="standard")
            elif spec.units:
                attributes["units"] = spec.units
            if spec.cell_method:
                attributes["cell_methods"] = f"{dimension}: {spec.cell_method}"
            if spec.field == "gust_mps":
                attributes["gust_window_s"] = windows[0].gust_window_s
            if spec.field.startswith(AUXILIARY_FIELD_PREFIXES):
                attributes["coverage_content_type"] = "auxiliaryInformation"
            elif spec.field.endswith("_standard_error_mps"):
                attributes["coverage_content_type"] = "qualityInformation"
            elif spec.field.startswith("motion_left_"):
                attributes["coverage_content_type"] = "qualityInformation"
                attributes["ancillary_variables"] = f"{what}_{label}_motion_left_flag"
            else:
                attributes["coverage_content_type"] = "physicalMeasurement"
                attributes["ancillary_variables"] = _ancillary_variables(what, window_s, spec)
            if spec.field.startswith(("n_", "spikes_")):
                values = values.astype(np.int32)
            if despiked and spec.field.startswith("spikes_"):
                attributes["comment"] = (
                    "these samples were taken out of the fluxes (NaN) before the rotation, "
                    "the detrending and the covariances (compensation.flux_despike)"
                )
            variables[f"{what}_{label}_{spec.name}"] = xr.DataArray(
                values, dims=dimension, attrs=attributes
            )
        variables[flag_name] = xr.DataArray(
            np.array([product.quality_flag for product in windows], dtype=np.int8),
            dims=dimension,
            attrs=_quality_flag_attributes(what),
        )
        variables.update(_flux_test_flag_variables(what, window_s, windows, dimension))
    return variables
