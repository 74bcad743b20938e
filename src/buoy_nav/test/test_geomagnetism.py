"""The fusion's geomagnetic model (WMM) against the simulator's (IGRF, an independent model and
package): the two agree on the field to well within what a magnetometer check tolerates."""

import datetime
import math

import numpy as np
import ppigrf
import pytest

from buoy_nav.geomagnetism import (
    SECONDS_PER_JULIAN_YEAR,
    declination_rad,
    declinations_rad,
    wmm_declination_deg,
    wmm_field_enu_t,
)

PLACES_DEG = [(35.0, 120.0), (38.5, -70.0), (-45.0, 170.0), (60.0, -150.0), (0.0, 0.0)]
DATE = datetime.datetime(2024, 6, 1)
T_S = DATE.replace(tzinfo=datetime.UTC).timestamp()


@pytest.mark.parametrize("latitude_deg, longitude_deg", PLACES_DEG)
def test_the_field_vector_agrees_with_the_igrf(latitude_deg, longitude_deg):
    wmm = np.array(wmm_field_enu_t(math.radians(latitude_deg), math.radians(longitude_deg), T_S))
    east, north, up = ppigrf.igrf(longitude_deg, latitude_deg, 0.0, DATE)
    igrf = np.array([float(np.squeeze(c)) for c in (east, north, up)]) * 1e-9
    assert np.linalg.norm(wmm - igrf) < 0.01 * np.linalg.norm(igrf)


@pytest.mark.parametrize("latitude_deg, longitude_deg", PLACES_DEG)
def test_the_field_vector_points_along_the_declination(latitude_deg, longitude_deg):
    latitude, longitude = math.radians(latitude_deg), math.radians(longitude_deg)
    east, north, _ = wmm_field_enu_t(latitude, longitude, T_S)
    azimuth_from_north_deg = math.degrees(math.atan2(east, north))
    assert azimuth_from_north_deg == pytest.approx(
        wmm_declination_deg(latitude, longitude, T_S), abs=1e-9
    )


@pytest.mark.parametrize("configured_deg", [math.nan, -3.25])
@pytest.mark.parametrize("latitude_deg, longitude_deg", PLACES_DEG)
def test_declinations_at_many_stamps_are_each_ones(configured_deg, latitude_deg, longitude_deg):
    """The declinations of many stamps at once are those of each alone, to the bit: the model's
    over a decade, within a tenth of a year and across its steps, or the configured one."""
    rng = np.random.default_rng(5)
    stamps_s = np.concatenate(
        (
            T_S + rng.uniform(-5.0, 5.0, 300) * SECONDS_PER_JULIAN_YEAR,
            T_S + rng.uniform(-1e5, 1e5, 100),
        )
    )
    latitude, longitude = math.radians(latitude_deg), math.radians(longitude_deg)
    alone = [declination_rad(configured_deg, latitude, longitude, t_s) for t_s in stamps_s]
    at_once = declinations_rad(configured_deg, latitude, longitude, stamps_s)
    assert at_once.tobytes() == np.array(alone).tobytes()
    assert math.isnan(configured_deg) == (len(set(alone)) > 10)
