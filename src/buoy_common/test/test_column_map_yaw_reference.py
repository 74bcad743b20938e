"""A column map's ahrs.yaw_reference is the nodes' parameter of that name: the same choices, the
same default, so a map and the nodes that are given none agree."""

import copy

import pytest
import yaml

from buoy_common.extrinsics import SHARED_PARAMETERS
from buoy_common.records.column_map import MapError, load_column_map

MAP = {
    "format": "delimited",
    "delimiter": ",",
    "columns": 4,
    "time": {"column": 1, "unit": "ms", "epoch": "2024-05-01T00:00:00Z"},
    "anemometer": {
        "axes": "FLU",
        "u": {"column": 2, "unit": "m/s"},
        "v": {"column": 3, "unit": "m/s"},
        "w": {"column": 4, "unit": "m/s"},
    },
}


def _loaded(tmp_path, ahrs):
    column_map = copy.deepcopy(MAP)
    column_map["ahrs"] = ahrs
    path = tmp_path / "map.yaml"
    path.write_text(yaml.safe_dump(column_map))
    return load_column_map(path)


def test_a_map_without_yaw_reference_takes_the_parameters_default(tmp_path):
    parameter = SHARED_PARAMETERS["ahrs.yaw_reference"]
    assert _loaded(tmp_path, {}).ahrs_yaw_reference == parameter.default == "true_north"


def test_a_map_takes_the_parameters_choices(tmp_path):
    assert _loaded(tmp_path, {"yaw_reference": "magnetic_north"}).ahrs_yaw_reference == (
        "magnetic_north"
    )
    with pytest.raises(MapError, match=r"ahrs\.yaw_reference: one of true_north, magnetic_north"):
        _loaded(tmp_path, {"yaw_reference": "grid_north"})
