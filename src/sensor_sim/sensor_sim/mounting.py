"""Where the sensors sit on the buoy: the extrinsics of the interface contract's shared
parameters (``gnss.primary_antenna``, ``anemometer.position``, ...), positions in base_link
(FLU, m) and mounting rotations (roll, pitch, yaw, deg).

A scenario may place them (its ``sensors.extrinsics`` section, e.g. a single antenna on a mast
at (0.1, 0.2, 1.9) m); without one, and for every field it leaves out, the contract's defaults
hold. The nodes' parameters override both, as for every other sensor setting.
"""

from __future__ import annotations

from dataclasses import dataclass

from buoy_common.extrinsics import check_shared_fields, shared_field
from sensor_sim.sensor_errors import InvalidConfigValueError


@dataclass(frozen=True)
class Extrinsics:
    """Where the sensors sit on the buoy (shared parameters of the interface contract)."""

    primary_antenna_body_m: tuple[float, float, float] = shared_field("gnss.primary_antenna")
    secondary_antenna_body_m: tuple[float, float, float] = shared_field("gnss.secondary_antenna")
    tertiary_antenna_body_m: tuple[float, float, float] = shared_field("gnss.tertiary_antenna")
    anemometer_position_body_m: tuple[float, float, float] = shared_field("anemometer.position")
    anemometer_rpy_deg: tuple[float, float, float] = shared_field("anemometer.rpy_deg")
    dvl_position_body_m: tuple[float, float, float] = shared_field("dvl.position")
    dvl_rpy_deg: tuple[float, float, float] = shared_field("dvl.rpy_deg")

    def __post_init__(self):
        check_shared_fields(self)


@dataclass(frozen=True)
class ScenarioExtrinsics(Extrinsics):
    """Extrinsics as a scenario file's ``sensors.extrinsics`` section gives them: a value the
    contract refuses is reported as a scenario error naming the file and the section."""

    def __post_init__(self):
        try:
            super().__post_init__()
        except ValueError as error:
            raise InvalidConfigValueError("sensors.extrinsics", self, str(error)) from None
