"""NetCDF-CF output of ``process_bag``: the corrected series, the products, the navigation and
their quality control in one self-describing file (CF-1.10, ACDD-1.3).

The file holds, each on a time dimension of its own (a flat dataset, no groups, so that every
CF reader sees every variable):

- ``time``: the corrected wind, one value per ``anemometer/wind`` sample with its header stamp
  (``eastward_wind``, ``northward_wind``, ``upward_air_velocity``, ``wind_speed``,
  ``wind_from_direction``) and ``wind_status``, the outcome of each sample's correction (0
  valid, else the reason it is NaN);
- ``current_time``: the current, one value per ``dvl/velocity`` sample, and ``current_status``;
- ``nav_time``: the navigation solution the corrections used (``nav/*``): position, roll,
  pitch, heading, velocity over ground;
- ``wind_time_<window>``, ``current_time_<window>``: the averaged products of each window
  length, with the window's bounds, coverage and QARTOD ``quality_flag``
  (:mod:`wind_comp.products`); the coordinate is the window's middle, its bounds the window;
- ``flux_time_<window>``: the eddy-covariance fluxes of the wind and their quality control
  (:mod:`wind_comp.flux_products`), likewise.

Every time coordinate is float64 seconds since midnight UTC of the day the data start
(:class:`TimeAxis`), which gives the stamps back to within a nanosecond. Values are the ones
``process_bag`` writes to its bag and CSVs, to their float64 bits (a test holds them equal).
Direction conventions as on the topics: wind FROM, current TOWARD, clockwise from the north the
run's heading was referenced to; vectors ENU. What the file says about the run (that north, the
sensors used, the site, the span of the data) comes from its :class:`OutputFacts`
(:mod:`buoy_processing.output_facts`).

The series are kept in memory until the file is written: 33 bytes per wind or DVL sample and
88 per navigation solution (0.76 GB for a day of 100 Hz navigation).
"""

from __future__ import annotations

import datetime
import os
from dataclasses import dataclass, field
from importlib import metadata
from pathlib import Path

import numpy as np
import xarray as xr

from buoy_common.safe_output import OutputError, staging_path
from buoy_processing.netcdf_variables import (
    CLOCKWISE_FROM_NORTH,
    GEOGRAPHIC_STANDARD_NAMES,
    TimeAxis,
    flow_variables,
    navigation_variables,
    product_variables,
)
from buoy_processing.output_facts import MAGNETIC_NORTH, OutputFacts
from buoy_processing.output_series import FlowSeries, NavigationSeries
from wind_comp.compensator import SampleStatus
from wind_comp.flux_products import FluxProduct
from wind_comp.products import CurrentProduct, WindProduct

CONVENTIONS = "CF-1.10, ACDD-1.3"
STANDARD_NAME_VOCABULARY = "CF Standard Name Table v93"
_NANOSECONDS = 1_000_000_000
_GIVEN_SITE_COMMENT = (
    "the site the run was given (site.* or origin.*, from the parameters or the imported "
    "record), not measured: the run had no GNSS fix"
)

_LATITUDE_ONLY_COMMENT = (
    "position unknown: the run was given a latitude (site.latitude_deg) for gravity and the "
    "Earth's rate, and no longitude; the navigation carries that latitude and a nominal "
    "longitude of 0, which are not the buoy's position"
)


@dataclass
class NetcdfContent:
    """What a processed bag puts in its NetCDF file."""

    source: str
    """The input bag, as the user named it (``source`` and ``history`` attributes)."""
    navigation: NavigationSeries
    facts: OutputFacts
    """North reference, sensors, site and span of the run: what the file says about it."""
    wind: FlowSeries | None = None
    current: FlowSeries | None = None
    wind_products: list[WindProduct] = field(default_factory=list)
    current_products: list[CurrentProduct] = field(default_factory=list)
    fluxes: list[FluxProduct] = field(default_factory=list)
    fluxes_despiked: bool = False
    """Whether the spikes the fluxes count were taken out of them (``flux_despike``)."""
    history: str = ""
    """The command that made the file."""
    attributes: dict[str, str] = field(default_factory=dict)
    """Global attributes given by the user (``creator_name``, ``institution``, ``license``,
    ``project``, ...), over the ones this module sets."""


# -- the file ---------------------------------------------------------------------------------


def _iso(t_s: float) -> str:
    moment = datetime.datetime.fromtimestamp(t_s, tz=datetime.UTC)
    return moment.isoformat(timespec="milliseconds").replace("+00:00", "Z")


def _global_attributes(content: NetcdfContent, dataset: xr.Dataset) -> dict:
    now = _iso(datetime.datetime.now(tz=datetime.UTC).timestamp())
    facts = content.facts
    sensors = facts.sensor_text()
    current = (
        " The surface current from the DVL's water track, corrected the same way."
        if content.current is not None
        else ""
    )
    attributes = {
        "Conventions": CONVENTIONS,
        "title": "Motion-corrected wind and current from a moving ocean buoy",
        "summary": (
            "Wind measured by an anemometer on a moving buoy, corrected for the buoy's motion "
            "(Miller et al. 2008) with the attitude and velocity of an error-state Kalman "
            f"filter; sensors used: {sensors}.{current} Per-sample series with their correction "
            "status, window-averaged products (vector and scalar means, gust, standard "
            "deviations) with coverage and QARTOD quality flags, and the navigation solution."
            f"{_emptiness_sentence(content)}"
        ),
        "keywords": (
            "EARTH SCIENCE > ATMOSPHERE > ATMOSPHERIC WINDS > SURFACE WINDS, "
            "EARTH SCIENCE > OCEANS > OCEAN CIRCULATION > OCEAN CURRENTS, buoy, motion "
            "correction, eddy covariance"
        ),
        "keywords_vocabulary": "GCMD Science Keywords",
        "standard_name_vocabulary": STANDARD_NAME_VOCABULARY,
        "id": Path(content.source).name,
        "naming_authority": "buoy_wind",
        "source": f"process_bag of the rosbag2 recording {content.source}"
        + (f". {facts.record_text()}" if facts.record is not None else ""),
        "history": f"{now} {content.history}".strip(),
        "processing_level": "motion-corrected, quality-controlled (QARTOD flags from coverage)",
        "product_version": metadata.version("wind_comp"),
        "date_created": now,
        "date_modified": now,
        "platform": "moored or drifting surface buoy",
        "instrument": sensors,
        "cdm_data_type": "Trajectory",
        "comment": (
            "Vectors are ENU (east, north, up). Wind direction is where the wind blows FROM, "
            f"current direction where the water flows TOWARD. {facts.north_sentence()}"
            " Invalid samples are NaN and keep their stamp; the *_status variables say why."
            f"{_position_sentence(facts)}{_with_space(facts.screening_text())}"
        ),
        "north_reference": facts.north,
    }
    attributes.update(_time_coverage(facts, dataset))
    if facts.position_known and np.isfinite(dataset["latitude"].values).any():
        attributes.update(_geospatial_attributes(dataset))
    attributes.update(content.attributes)
    return attributes


def _emptiness_sentence(content: NetcdfContent) -> str:
    """What the file lacks although its summary names it, with a leading space: a series
    without one valid sample, a run without a navigation solution; ``""`` when nothing."""
    lacking = [
        f"none of the {len(series)} {name} samples is valid"
        for name, series in (("wind", content.wind), ("current", content.current))
        if series is not None and not np.any(series.columns()[2] == SampleStatus.VALID)
    ]
    if not len(content.navigation):
        lacking.append("the navigation holds no solution")
    if not lacking:
        return ""
    text = "; ".join(lacking)
    return f" In this file {text}."


def _position_sentence(facts: OutputFacts) -> str:
    """Where the data were taken when no GNSS fix says it (the variables do then), with a
    leading space; ``""`` with fixes."""
    if facts.position_from_gnss:
        return ""
    text = facts.site_text()
    return f" {text[0].upper()}{text[1:]}."


def _with_space(sentence: str) -> str:
    return f" {sentence}" if sentence else ""


def _time_coverage(facts: OutputFacts, dataset: xr.Dataset) -> dict:
    """The span of the data: from its first to its last sample (never a window's bounds)."""
    if facts.first_sample_s is None:
        return {}
    start, end = facts.first_sample_s, facts.last_sample_s
    attributes = {
        "time_coverage_start": _iso(start),
        "time_coverage_end": _iso(end),
        "time_coverage_duration": f"PT{end - start:.3f}S",
    }
    if "time" in dataset.coords and dataset["time"].size > 1:
        interval_s = float(np.median(np.diff(dataset["time"].values)))
        attributes["time_coverage_resolution"] = f"PT{interval_s:.6g}S"
    return attributes


def _geospatial_attributes(dataset: xr.Dataset) -> dict:
    latitudes = dataset["latitude"].values
    longitudes = dataset["longitude"].values
    heights = dataset["altitude"].values
    return {
        "geospatial_lat_min": float(np.nanmin(latitudes)),
        "geospatial_lat_max": float(np.nanmax(latitudes)),
        "geospatial_lat_units": "degrees_north",
        "geospatial_lon_min": float(np.nanmin(longitudes)),
        "geospatial_lon_max": float(np.nanmax(longitudes)),
        "geospatial_lon_units": "degrees_east",
        "geospatial_vertical_min": float(np.nanmin(heights)),
        "geospatial_vertical_max": float(np.nanmax(heights)),
        "geospatial_vertical_units": "m",
        "geospatial_vertical_positive": "up",
    }


def _state_the_north(dataset: xr.Dataset, facts: OutputFacts) -> None:
    """Put the run's north into the texts of the directions and headings; with magnetic north,
    take away the CF standard names that mean true north and say what the axes are."""
    clockwise = facts.clockwise_from()
    magnetic = facts.north == MAGNETIC_NORTH
    for variable in dataset.variables.values():
        attributes = variable.attrs
        for key, value in attributes.items():
            if isinstance(value, str) and CLOCKWISE_FROM_NORTH in value:
                attributes[key] = value.replace(CLOCKWISE_FROM_NORTH, clockwise)
        if magnetic and attributes.get("standard_name", "").startswith(GEOGRAPHIC_STANDARD_NAMES):
            del attributes["standard_name"]
            comment = attributes.get("comment", "").rstrip(".")
            attributes["comment"] = f"{comment}. {_MAGNETIC_AXES_COMMENT}".lstrip(". ")


_MAGNETIC_AXES_COMMENT = (
    "East and north here are magnetic east and north (no declination applied), so this is not "
    "the CF quantity of true east or north and carries no standard_name."
)


def time_axis(content: NetcdfContent) -> TimeAxis:
    """The time coding of ``content``'s file: from the day of its first stamp (the epoch for
    a file without any)."""
    firsts = [int(series.columns()[0][0]) for series in (content.navigation, content.wind,
              content.current) if series is not None and len(series)]  # fmt: skip
    firsts += [
        int(product.window_start_s) * _NANOSECONDS
        for product in (*content.wind_products, *content.current_products, *content.fluxes)
    ]
    return TimeAxis.starting_on_the_day_of(min(firsts, default=0))


def netcdf_dataset(content: NetcdfContent) -> xr.Dataset:
    """The CF dataset of ``content`` (see the module docstring)."""
    axis = time_axis(content)
    variables: dict[str, xr.DataArray] = {}
    variables.update(navigation_variables(content.navigation, axis))
    if content.wind is not None:
        variables.update(flow_variables(content.wind, True, axis))
        variables.update(product_variables("wind", content.wind_products, axis))
        variables.update(product_variables("flux", content.fluxes, axis, content.fluxes_despiked))
    if content.current is not None:
        variables.update(flow_variables(content.current, False, axis))
        variables.update(product_variables("current", content.current_products, axis))
    coordinates = {name: array for name, array in variables.items() if name == array.dims[0]}
    data = {name: array for name, array in variables.items() if name not in coordinates}
    dataset = xr.Dataset(data, coords=coordinates)
    _state_the_north(dataset, content.facts)
    facts = content.facts
    if facts.site_deg is not None and not facts.position_from_gnss:
        for name in ("latitude", "longitude", "altitude"):
            dataset[name].attrs["comment"] = _GIVEN_SITE_COMMENT
    elif facts.latitude_only_deg is not None and not facts.position_from_gnss:
        for name in ("latitude", "longitude", "altitude"):
            dataset[name].attrs["comment"] = _LATITUDE_ONLY_COMMENT
    dataset.attrs = _global_attributes(content, dataset)
    return dataset


def check_netcdf_output(path, overwrite: bool) -> None:
    """Raise OutputError, before anything is read, if ``path`` cannot be written: it exists
    (without ``overwrite``), or it is not a regular file (never replaced)."""
    path = Path(path)
    if not (path.exists() or path.is_symlink()):
        return
    if not path.is_file():
        raise OutputError(f"output {path} exists and is not a file; refusing to replace it")
    if not overwrite:
        raise OutputError(f"output {path} exists; use --overwrite to replace it")


def write_netcdf(path, content: NetcdfContent, overwrite: bool) -> Path:
    """Write ``content`` as NetCDF-4 at ``path``; it appears only once complete, replacing an
    existing file only with ``overwrite`` (OutputError otherwise)."""
    path = Path(path)
    check_netcdf_output(path, overwrite)
    dataset = netcdf_dataset(content)
    encoding = {
        name: {"_FillValue": None}
        for name, array in dataset.variables.items()
        if not np.issubdtype(array.dtype, np.floating)
        or name in dataset.coords
        or name.endswith("_bounds")
    }
    staged = staging_path(path)
    try:
        dataset.to_netcdf(staged, format="NETCDF4", engine="netcdf4", encoding=encoding)
        if path.exists() and not overwrite:
            raise OutputError(f"output {path} appeared while it was being written")
        os.replace(staged, path)
    finally:
        staged.unlink(missing_ok=True)
    return path
