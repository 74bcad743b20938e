"""The Earth's magnetic field: the declination (the ``magnetic.declination_deg`` parameter, or
the World Magnetic Model at the position) and the model's field vector, which a calibrated
magnetometer must reproduce in strength and dip (package ``pygeomag``, the NOAA/BGS model that
compasses and charts use).

The field changes by about 0.1° of declination per 10 km and per year at mid latitudes, so it is
evaluated once per 0.05° cell of latitude and longitude and per tenth of a year, and kept.
"""

from __future__ import annotations

import math
from functools import lru_cache
from typing import NamedTuple

import numpy as np
from pygeomag import GeoMag

SECONDS_PER_JULIAN_YEAR = 365.25 * 86400.0
UNIX_EPOCH_DECIMAL_YEAR = 1970.0
_CELL_DEG = 0.05
_YEAR_STEP = 0.1


@lru_cache(maxsize=1)
def _model() -> GeoMag:
    return GeoMag()


NANOTESLA = 1e-9
PARALLEL_STEP_DEG = 1.0
"""Spacing (deg) of the longitudes at which the field along a parallel is evaluated."""


@lru_cache(maxsize=256)
def _wmm_cell(latitude_cell: int, longitude_cell: int, year_step: int):
    model = _model()
    year = min(max(year_step * _YEAR_STEP, model.life_span[0]), model.life_span[1] - 1e-3)
    return model.calculate(
        glat=latitude_cell * _CELL_DEG,
        glon=longitude_cell * _CELL_DEG,
        alt=0.0,
        time=year,
        allow_date_outside_lifespan=True,
    )


def _cell(angle_rad: float) -> int:
    """The index of the cell a latitude or longitude (rad) falls in."""
    return round(math.degrees(angle_rad) / _CELL_DEG)


def _wmm_at(latitude_rad: float, longitude_rad: float, t_s: float):
    return _wmm_cell(_cell(latitude_rad), _cell(longitude_rad), _year_step(t_s))


def _decimal_year(t_s):
    """The decimal year of a stamp, or of each of an array of them (s since the Unix epoch)."""
    return UNIX_EPOCH_DECIMAL_YEAR + t_s / SECONDS_PER_JULIAN_YEAR


def _year_step(t_s: float) -> int:
    """The tenth of a year (the model's step) a stamp (s since the Unix epoch) falls in."""
    return round(_decimal_year(t_s) / _YEAR_STEP)


def _year_steps(stamps_s: np.ndarray) -> np.ndarray:
    """:func:`_year_step` of each of ``stamps_s`` (rounded half to even, as ``round``)."""
    return np.rint(_decimal_year(stamps_s) / _YEAR_STEP)


CELL_MARGIN_RAD = 1e-9
"""How far inside its cell's edges (rad) a position is held to be in the cell: far beyond the
rounding of the cell's index."""


@lru_cache(maxsize=16)
def wmm_cell_bounds_rad(latitude_rad: float, longitude_rad: float) -> tuple[float, ...]:
    """(lowest, highest latitude, lowest, highest longitude), rad: the open bounds, less
    :data:`CELL_MARGIN_RAD`, of the cell the model is evaluated for at a position (rad); the
    field is the same anywhere within them at one time. Kept for the last positions asked: an
    offline run asks it for every attitude and field at the one position the filter had when
    their rows were made."""
    bounds = []
    for angle_rad in (latitude_rad, longitude_rad):
        cell = _cell(angle_rad)
        bounds += [
            math.radians((cell - 0.5) * _CELL_DEG) + CELL_MARGIN_RAD,
            math.radians((cell + 0.5) * _CELL_DEG) - CELL_MARGIN_RAD,
        ]
    return tuple(bounds)


def wmm_declination_deg(latitude_rad: float, longitude_rad: float, t_s: float) -> float:
    """Declination (deg, east positive) of the WMM at a position (rad) and a time (s since the
    Unix epoch), at sea level."""
    return float(_wmm_at(latitude_rad, longitude_rad, t_s).d)


def wmm_field_enu_t(latitude_rad: float, longitude_rad: float, t_s: float) -> tuple:
    """The WMM's field vector (east, north, up; tesla) at a position (rad) and a time (s since
    the Unix epoch), at sea level."""
    result = _wmm_at(latitude_rad, longitude_rad, t_s)
    return (
        float(result.y) * NANOTESLA,
        float(result.x) * NANOTESLA,
        -float(result.z) * NANOTESLA,
    )


def declination_rad(
    configured_deg: float, latitude_rad: float, longitude_rad: float, t_s: float
) -> float:
    """The declination to use (rad, east positive): ``configured_deg`` unless NaN, else the WMM
    at the position and time."""
    if not math.isnan(configured_deg):
        return math.radians(configured_deg)
    return math.radians(wmm_declination_deg(latitude_rad, longitude_rad, t_s))


def declinations_rad(
    configured_deg: float, latitude_rad: float, longitude_rad: float, stamps_s
) -> np.ndarray:
    """:func:`declination_rad` at each of ``stamps_s`` (s since the Unix epoch) at one position
    (rad), the model evaluated once per tenth of a year they span: the same numbers."""
    stamps = np.asarray(stamps_s, dtype=float)
    if not math.isnan(configured_deg):
        return np.full(stamps.shape, math.radians(configured_deg))
    steps = _year_steps(stamps)
    latitude_cell, longitude_cell = _cell(latitude_rad), _cell(longitude_rad)
    declinations = np.empty(stamps.shape)
    for step in np.unique(steps).tolist():
        result = _wmm_cell(latitude_cell, longitude_cell, int(step))
        declinations[steps == step] = math.radians(float(result.d))
    return declinations


class FieldRange(NamedTuple):
    """The strengths (T) and dips (rad, positive pointing down) the Earth's field takes."""

    strength_t: tuple[float, float]
    """Smallest and largest strength."""
    dip_rad: tuple[float, float]
    """Smallest and largest dip."""


def _range_of(results) -> FieldRange:
    strengths = [float(result.f) * NANOTESLA for result in results]
    dips = [math.radians(float(result.i)) for result in results]
    return FieldRange((min(strengths), max(strengths)), (min(dips), max(dips)))


def wmm_field_range_at(latitude_rad: float, longitude_rad: float, t_s: float) -> FieldRange:
    """The WMM's field at a position (rad) and a time (s since the Unix epoch), at sea level,
    as a range of one strength and one dip."""
    return _range_of([_wmm_at(latitude_rad, longitude_rad, t_s)])


def wmm_field_range_along_parallel(latitude_rad: float, t_s: float) -> FieldRange:
    """The range of the WMM's field strength and dip along the parallel of ``latitude_rad``
    (rad), over every longitude (every :data:`PARALLEL_STEP_DEG`), at a time (s since the Unix
    epoch), at sea level: what a buoy at that latitude may see when its longitude is not
    known."""
    return _parallel_range(_cell(latitude_rad), _year_step(t_s))


@lru_cache(maxsize=16)
def _parallel_range(latitude_cell: int, year_step: int) -> FieldRange:
    cells_per_step = round(PARALLEL_STEP_DEG / _CELL_DEG)
    return _range_of(
        [
            _wmm_cell(latitude_cell, longitude_cell, year_step)
            for longitude_cell in range(
                round(-180.0 / _CELL_DEG), round(180.0 / _CELL_DEG), cells_per_step
            )
        ]
    )
