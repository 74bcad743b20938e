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

import math
from collections.abc import Callable, Sequence
from typing import NamedTuple

import numpy as np

from buoy_nav.nav_numbers import BODY_TWIST_COVARIANCE, VELOCITY_BODY, body_numbers_of_solutions
from buoy_nav.solution import NavSolution
from wind_comp.pipeline import NavigationColumns


class StampedSolution(NamedTuple):
    """A solution with the exact header stamp of its IMU sample (``sec``, ``nanosec``), which
    its ``nav/*`` messages would carry."""

    solution: NavSolution
    sec: int
    nanosec: int


def stamp_s(stamped: StampedSolution) -> float:
    """The header stamp (s) a correction reads off a solution's ``nav/odometry``."""
    return stamped.sec + stamped.nanosec * 1e-9


class SolutionColumns(NamedTuple):
    """Held-back solutions as columns: what the corrections take
    (:attr:`navigation`) and what the NetCDF file keeps of them."""

    navigation: NavigationColumns
    secs: np.ndarray
    """(N,) header stamps' seconds."""
    nanosecs: np.ndarray
    """(N,) header stamps' nanoseconds."""
    geodetic: np.ndarray
    """(N, 3) latitude, longitude (deg), altitude (m)."""
    velocity_enu_mps: np.ndarray
    """(N, 3) ENU velocity, m/s."""


def solution_columns(stamped: Sequence[StampedSolution]) -> SolutionColumns:
    """What the ``nav/odometry`` and ``nav/fix`` of the ``stamped`` solutions carry, a row
    each."""
    solutions = [item.solution for item in stamped]
    secs = np.array([item.sec for item in stamped], dtype=np.int64)
    nanosecs = np.array([item.nanosec for item in stamped], dtype=np.int64)
    attitude = np.array([solution.attitude_xyzw for solution in solutions], dtype=float)
    velocity = np.array([solution.velocity_enu_mps for solution in solutions], dtype=float)
    body = body_numbers_of_solutions(
        attitude,
        velocity,
        [solution.velocity_covariance_m2s2 for solution in solutions],
        [solution.gyro_bias_covariance_rad2_s2 for solution in solutions],
    )
    twist = body[:, BODY_TWIST_COVARIANCE : BODY_TWIST_COVARIANCE + 36].reshape(-1, 6, 6)
    geodetic = np.array(
        [
            (solution.latitude_deg, solution.longitude_deg, solution.altitude_m)
            for solution in solutions
        ],
        dtype=float,
    ).reshape(-1, 3)
    navigation = NavigationColumns(
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
        fix_latitude_deg=geodetic[:, 0],
    )
    return SolutionColumns(navigation, secs, nanosecs, geodetic, velocity)


class HeldBackSolutions:
    """The solutions of a run that writes no bag, from the fusion to the corrections and the
    NetCDF file: held back with their stamps, counted as the corrections' pipelines will count
    them, and handed over as columns, once for all, when a correction is about to decide
    samples (:meth:`hand_over`)."""

    def __init__(self, takers: Sequence[Callable[[SolutionColumns], None]]):
        """takers: what each hand-over goes to, in order (each correction's pipeline, the
        NetCDF file's series)."""
        self._takers = list(takers)
        self._held: list[StampedSolution] = []
        self._latest_s = -math.inf
        self.in_order = 0
        """Of the solutions held, those whose stamp is later than every earlier one: the ones a
        pipeline keeps (:meth:`~wind_comp.pipeline.CompensationPipeline.add_odometry`)."""

    def take(self, stamped: Sequence[StampedSolution], latest_taken_s: float) -> None:
        """Hold the ``stamped`` solutions; ``latest_taken_s``: the latest stamp the pipelines
        took so far (s)."""
        latest_s = max(latest_taken_s, self._latest_s)
        for item in stamped:
            t_s = stamp_s(item)
            if t_s > latest_s:
                latest_s = t_s
                self.in_order += 1
        self._latest_s = latest_s
        self._held.extend(stamped)

    def hand_over(self) -> None:
        """Every solution held, as columns, to each taker."""
        if not self._held:
            return
        columns = solution_columns(self._held)
        self._held = []
        self.in_order = 0
        for taker in self._takers:
            taker(columns)
