"""The shared parameters: one rule each, the same for every configuration that holds them."""

import dataclasses
import math

import pytest

from buoy_common.extrinsics import (
    MIN_ANTENNA_SEPARATION_M,
    SHARED_PARAMETERS,
    check_shared_fields,
    field_parameter,
    shared_field,
)
from buoy_common.parameters import ParameterError, build_config, config_parameters


@dataclasses.dataclass(frozen=True)
class _Antennas:
    primary: tuple[float, float, float] = shared_field("gnss.primary_antenna")
    secondary: tuple[float, float, float] = shared_field("gnss.secondary_antenna")
    own_setting_s: float = 1.0

    def __post_init__(self):
        check_shared_fields(self)


@dataclasses.dataclass(frozen=True)
class _Origin:
    latitude: float = shared_field("origin.latitude_deg")
    longitude: float = shared_field("origin.longitude_deg")
    altitude: float = shared_field("origin.altitude_m")

    def __post_init__(self):
        check_shared_fields(self)


def test_shared_fields_are_declared_under_the_contract_names_with_their_defaults():
    rows = config_parameters(_Antennas, prefix="test.")
    assert rows == [
        ("primary", "gnss.primary_antenna", SHARED_PARAMETERS["gnss.primary_antenna"].default),
        (
            "secondary",
            "gnss.secondary_antenna",
            SHARED_PARAMETERS["gnss.secondary_antenna"].default,
        ),
        ("own_setting_s", "test.own_setting_s", 1.0),
    ]
    assert field_parameter(dataclasses.fields(_Antennas)[2]) is None


def test_every_default_obeys_its_own_rule():
    for parameter in SHARED_PARAMETERS.values():
        assert parameter.check(parameter.default) is None, parameter.name


@pytest.mark.parametrize(
    ("parameter", "bad_value"),
    [
        ("gnss.primary_antenna", (0.0, math.nan, 1.0)),
        ("gnss.primary_antenna", (0.0, 0.0, 250.0)),
        ("gnss.primary_antenna", (0.0, 1.0)),
        ("anemometer.position", (math.inf, 0.0, 3.0)),
        ("anemometer.rpy_deg", (0.0, 95.0, 0.0)),
        ("anemometer.rpy_deg", (181.0, 0.0, 0.0)),
        ("origin.latitude_deg", 90.0),
        ("origin.longitude_deg", -180.5),
        ("origin.altitude_m", 2.0e5),
    ],
)
def test_each_rule_refuses_what_no_buoy_can_have(parameter, bad_value):
    assert SHARED_PARAMETERS[parameter].check(bad_value) is not None


def test_antennas_closer_than_the_minimum_are_refused_naming_the_parameter():
    # A 0.07 m baseline: refused by every configuration holding both antennas, not just one.
    with pytest.raises(ValueError, match=r"gnss\.secondary_antenna"):
        _Antennas(primary=(0.0, 0.0, 1.0), secondary=(0.07, 0.0, 1.0))
    _Antennas(primary=(0.0, 0.0, 1.0), secondary=(MIN_ANTENNA_SEPARATION_M, 0.0, 1.0))


def test_origin_is_given_whole_or_not_at_all():
    _Origin()
    _Origin(latitude=35.0, longitude=120.0, altitude=0.0)
    with pytest.raises(ValueError, match="all set or all NaN"):
        _Origin(latitude=35.0)


def test_build_config_reports_the_parameter_name():
    with pytest.raises(ParameterError, match=r"gnss\.primary_antenna"):
        build_config(_Antennas, {"gnss.primary_antenna": [0.0, 0.0, 500.0]})
    config = build_config(_Antennas, {"gnss.secondary_antenna": [1.0, 0.0, 1.0]}, prefix="test.")
    assert config.secondary == (1.0, 0.0, 1.0)
