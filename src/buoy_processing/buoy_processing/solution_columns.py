"""The navigation of a run that writes no bag, handed to the corrections in bulk.

With a bag, every solution becomes its ``nav/*`` values
(:func:`buoy_nav.fusion_messages.nav_values`) and each correction takes its ``nav/odometry``
and ``nav/fix`` one by one, as the live node does. Without one, no message is made: the
corrections hold the solutions back with their exact header stamps and, before they decide
samples, take a stretch of them as columns (:class:`wind_comp.pipeline.NavigationColumns`),
every number as the messages' values carry it, to the bit: the body velocity and its covariance
from the compiled code that makes them for the messages
(:func:`buoy_nav.nav_numbers.body_numbers_of_solutions`), the rest copied from the solutions'
own arrays.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import NamedTuple

import numpy as np

from buoy_nav.nav_numbers import BODY_TWIST_COVARIANCE, VELOCITY_BODY, body_numbers_of_solutions
from buoy_nav.solution import NavSolution
from wind_comp.pipeline import NavigationColumns

NANOSECONDS = 1_000_000_000


class StampedSolution(NamedTuple):
    """A solution with the exact header stamp of its IMU sample (``sec``, ``nanosec``), which
    its ``nav/*`` messages would carry."""

    solution: NavSolution
    sec: int
    nanosec: int


def stamp_s(stamped: StampedSolution) -> float:
    """The header stamp (s) a correction reads off a solution's ``nav/odometry``."""
    return stamped.sec + stamped.nanosec * 1e-9


def navigation_columns(stamped: Sequence[StampedSolution]) -> NavigationColumns:
    """What the ``nav/odometry`` and ``nav/fix`` of the ``stamped`` solutions carry for a
    correction, a row each."""
    solutions = [item.solution for item in stamped]
    secs = np.array([item.sec for item in stamped], dtype=np.int64)
    nanosecs = np.array([item.nanosec for item in stamped], dtype=np.int64)
    attitude = np.array([solution.attitude_xyzw for solution in solutions], dtype=float)
    body = body_numbers_of_solutions(
        attitude,
        [solution.velocity_enu_mps for solution in solutions],
        [solution.velocity_covariance_m2s2 for solution in solutions],
        [solution.gyro_bias_covariance_rad2_s2 for solution in solutions],
    )
    twist = body[:, BODY_TWIST_COVARIANCE : BODY_TWIST_COVARIANCE + 36].reshape(-1, 6, 6)
    return NavigationColumns(
        stamps_s=secs + nanosecs * 1e-9,
        attitude_xyzw=attitude,
        angular_rate_body_rad_s=np.array(
            [solution.angular_rate_body_rad_s for solution in solutions], dtype=float
        ),
        velocity_body_mps=body[:, VELOCITY_BODY : VELOCITY_BODY + 3],
        attitude_covariance_rad2=np.array(
            [solution.attitude_covariance_rad2 for solution in solutions], dtype=float
        ),
        body_velocity_covariance_m2s2=twist[:, :3, :3],
        body_rate_covariance_rad2_s2=twist[:, 3:, 3:],
        fix_latitude_deg=np.array([solution.latitude_deg for solution in solutions], dtype=float),
    )


def navigation_values(stamped: Sequence[StampedSolution]) -> tuple[np.ndarray, np.ndarray]:
    """What the NetCDF file keeps of the ``stamped`` solutions
    (:class:`buoy_processing.output_series.NavigationSeries`): (N,) stamps ns and (N, 10)
    latitude, longitude (deg), altitude (m), quaternion x y z w, velocity E N U (m/s)."""
    stamps_ns = np.array([item.sec * NANOSECONDS + item.nanosec for item in stamped], np.int64)
    values = np.array(
        [
            (
                solution.latitude_deg,
                solution.longitude_deg,
                solution.altitude_m,
                *solution.attitude_xyzw,
                *solution.velocity_enu_mps,
            )
            for solution in (item.solution for item in stamped)
        ],
        dtype=float,
    ).reshape(-1, 10)
    return stamps_ns, values
