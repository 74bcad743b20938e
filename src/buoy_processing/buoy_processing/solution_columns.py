"""The navigation of an offline run, handed to its outputs and corrections in bulk.

The live node makes every solution into its ``nav/*`` values
(:func:`buoy_nav.fusion_messages.nav_values`) and the compensation node takes its
``nav/odometry`` and ``nav/fix`` one by one. An offline run (but a smoothing one) does not: the
engine writes each solution as a row (:mod:`buoy_nav.solution_rows`), the run holds their exact
header stamps back and hands the rows held over as columns, to the output's ``nav/*``
(:mod:`buoy_processing.nav_rows_output`) and, before a correction decides samples, to the
corrections (:class:`wind_comp.pipeline.NavigationColumns`), every number as the messages'
values carry it, to the bit: the body velocity and its covariance from the compiled code that
makes them for the messages (:func:`buoy_nav.nav_numbers.body_numbers_of_solutions`), the rest
the rows' own.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from typing import NamedTuple

import numpy as np

from buoy_nav import solution_rows as row
from buoy_nav.nav_numbers import BODY_TWIST_COVARIANCE, VELOCITY_BODY, body_numbers_of_solutions
from buoy_nav.solution_rows import SolutionRows
from wind_comp.pipeline import NavigationColumns

HELD_AT_MOST = 512
"""Solutions held back at most: beyond, they are handed over, whether or not a correction is
about to decide samples. What a correction decides does not depend on when it takes them; the
output writes their ``nav/*`` as they are handed over, and a few thousand messages at a time
keep the bag's writing process in step (at 8,192 the hour at 100 Hz waited 0.6 s longer on
it)."""

Stamp = tuple[int, int]
"""A solution's header stamp (sec, nanosec): its IMU sample's, which its ``nav/*`` messages
would carry."""


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
    rows: np.ndarray
    """The solutions' rows themselves (:mod:`buoy_nav.solution_rows`)."""
    body_numbers: np.ndarray
    """(N, :data:`~buoy_nav.nav_numbers.BODY_NUMBERS`) each solution's body-frame numbers
    (:func:`~buoy_nav.nav_numbers.body_numbers`), which its ``nav/odometry`` carries too."""


def solution_columns(rows: np.ndarray, stamps: np.ndarray) -> SolutionColumns:
    """What the ``nav/odometry`` and ``nav/fix`` of the solutions written as ``rows``
    (:mod:`buoy_nav.solution_rows`) with their header ``stamps`` (N × (sec, nanosec)) carry, a
    row each."""
    secs, nanosecs = stamps[:, 0].copy(), stamps[:, 1].copy()
    attitude = np.ascontiguousarray(rows[:, row.ATTITUDE_XYZW])
    velocity = np.ascontiguousarray(rows[:, row.VELOCITY_ENU])
    body = body_numbers_of_solutions(
        attitude,
        velocity,
        _matrices(rows[:, row.VELOCITY_COVARIANCE]),
        _matrices(rows[:, row.GYRO_BIAS_COVARIANCE]),
    )
    twist = body[:, BODY_TWIST_COVARIANCE : BODY_TWIST_COVARIANCE + 36].reshape(-1, 6, 6)
    geodetic = np.ascontiguousarray(rows[:, row.GEODETIC])
    navigation = NavigationColumns(
        stamps_s=secs + nanosecs * 1e-9,
        attitude_xyzw=attitude,
        angular_rate_body_rad_s=np.ascontiguousarray(rows[:, row.ANGULAR_RATE]),
        velocity_body_mps=body[:, VELOCITY_BODY : VELOCITY_BODY + 3],
        attitude_covariance_rad2=_matrices(rows[:, row.ATTITUDE_COVARIANCE]),
        body_velocity_covariance_m2s2=twist[:, :3, :3],
        body_rate_covariance_rad2_s2=twist[:, 3:, 3:],
        fix_latitude_deg=geodetic[:, 0],
    )
    return SolutionColumns(navigation, secs, nanosecs, geodetic, velocity, rows, body)


def _matrices(columns: np.ndarray) -> np.ndarray:
    """N rows of nine row-major numbers as N 3×3 matrices, contiguous."""
    return np.ascontiguousarray(columns).reshape(-1, 3, 3)


class HeldBackSolutions:
    """The solutions of an offline run, from the fusion to the output's ``nav/*``, the
    corrections and the NetCDF file: written as rows by the engine, their stamps held back
    here, counted as the corrections' pipelines will count them, and handed over as columns,
    once for all, when a correction is about to decide samples (:meth:`hand_over`), at the end,
    and whenever :data:`HELD_AT_MOST` are held."""

    def __init__(self, rows: SolutionRows, takers: Sequence[Callable[[SolutionColumns], None]]):
        """rows: where the engine writes the solutions; takers: what each hand-over goes to,
        in order (the output's messages; each correction's pipeline and the NetCDF file's
        series add theirs, :meth:`add_taker`)."""
        self._rows = rows
        self._takers = list(takers)
        self._stamps: list[Stamp] = []
        self._latest_s = -math.inf
        self.in_order = 0
        """Of the solutions held, those whose stamp is later than every earlier one: the ones a
        pipeline keeps (:meth:`~wind_comp.pipeline.CompensationPipeline.add_odometry`)."""

    def take(self, stamps: Sequence[Stamp], latest_taken_s: float) -> None:
        """Hold the solutions of header ``stamps``, the latest rows written; ``latest_taken_s``:
        the latest stamp the pipelines took so far (s)."""
        latest_s = max(latest_taken_s, self._latest_s)
        for sec, nanosec in stamps:
            # The stamp a correction reads off a solution's nav/odometry.
            t_s = sec + nanosec * 1e-9
            if t_s > latest_s:
                latest_s = t_s
                self.in_order += 1
        self._latest_s = latest_s
        self._stamps.extend(stamps)
        if len(self._stamps) >= HELD_AT_MOST:
            self.hand_over()

    def add_taker(self, taker: Callable[[SolutionColumns], None]) -> None:
        """One more taker of every hand-over, after the others."""
        self._takers.append(taker)

    def hand_over(self) -> None:
        """Every solution held, as columns, to each taker."""
        if not self._stamps:
            return
        stamps = np.array(self._stamps, dtype=np.int64).reshape(-1, 2)
        columns = solution_columns(self._rows.take(len(stamps)), stamps)
        self._stamps = []
        self.in_order = 0
        for taker in self._takers:
            taker(columns)
