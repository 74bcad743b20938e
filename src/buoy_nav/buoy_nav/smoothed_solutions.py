"""The forward filter's solutions kept on disk, and the smoothed solutions made from them.

A solution is stored as the forward filter emitted it (nominal state, bias-corrected rates and
force, covariance blocks) with the exact header stamp and the bag log time it is written with:
475 bytes per solution, 0.17 GB per hour at 100 Hz (on disk, see :mod:`buoy_nav.spill`). After
the backward pass the smoothed error of each solution's stamp
(:class:`buoy_nav.smoother.SmoothedEpochs`) is injected into its nominal state with the filter's
own convention (:func:`buoy_nav.error_state_filter.inject_error_state`, here for whole blocks of
solutions at once): ``R = Exp([φ×]) R``, ``v + δv``, the position moved by δp ENU metres, the
biases plus δb, hence the bias-corrected rate ``ω − δb_g`` and specific force ``f − δb_a``.
Where the integrity monitor distrusted the forward filter, the smoothed covariance keeps the
inflation the forward solution was published with (:func:`buoy_nav.integrity.distrust_variances`):
the smoother inherits the forward filter's error there, and the wind refuses it alike.
"""

from __future__ import annotations

from collections.abc import Iterator
from typing import NamedTuple

import numpy as np
from scipy.spatial.transform import Rotation

from buoy_nav import earth
from buoy_nav.integrity import IntegrityEvent, distrust_variances, distrusted_at
from buoy_nav.smoother import SmoothedEpochs, SmootherRecorder
from buoy_nav.solution import NavSolution
from buoy_nav.spill import SpillDirectory
from buoy_nav.state_layout import EAST, NORTH, UP, StateLayout

SOLUTION_DTYPE = np.dtype(
    [
        ("t_s", "f8"),
        ("sec", "i8"),
        ("nanosec", "i8"),
        ("log_time_ns", "i8"),
        ("attitude_xyzw", "f8", (4,)),
        ("angular_rate_body_rad_s", "f8", (3,)),
        ("angular_rate_nb_body_rad_s", "f8", (3,)),
        ("specific_force_body_mps2", "f8", (3,)),
        ("velocity_enu_mps", "f8", (3,)),
        ("latitude_deg", "f8"),
        ("longitude_deg", "f8"),
        ("altitude_m", "f8"),
        ("position_map_m", "f8", (3,)),
        ("attitude_covariance_rad2", "f8", (3, 3)),
        ("velocity_covariance_m2s2", "f8", (3, 3)),
        ("position_covariance_m2", "f8", (3, 3)),
        ("gyro_bias_covariance_rad2_s2", "f8", (3, 3)),
        ("gyro_bias_rad_s", "f8", (3,)),
        ("accel_bias_mps2", "f8", (3,)),
        ("coasting", "?", (3,)),
    ]
)
_ARRAY_FIELDS = (
    "attitude_xyzw",
    "angular_rate_body_rad_s",
    "angular_rate_nb_body_rad_s",
    "specific_force_body_mps2",
    "velocity_enu_mps",
    "position_map_m",
    "attitude_covariance_rad2",
    "velocity_covariance_m2s2",
    "position_covariance_m2",
    "gyro_bias_covariance_rad2_s2",
    "gyro_bias_rad_s",
    "accel_bias_mps2",
)
SOLUTIONS_PER_BLOCK = 20_000
"""Solutions smoothed at a time (about 7 MB of records)."""


class StampedSolution(NamedTuple):
    """A forward and a smoothed solution of one stamp, with the stamp's header (sec, nanosec)
    and the log time the forward one was written with."""

    forward: NavSolution
    smoothed: NavSolution
    sec: int
    nanosec: int
    log_time_ns: int


class SolutionStore:
    """The forward solutions, in the order emitted, in a spill table of ``spill``."""

    def __init__(self, spill: SpillDirectory):
        self._table = spill.table("solutions", SOLUTION_DTYPE)

    def __len__(self) -> int:
        return len(self._table)

    def add(self, solution: NavSolution, sec: int, nanosec: int, log_time_ns: int) -> None:
        record = self._table.next_record()
        record["t_s"] = solution.t_s
        record["sec"] = sec
        record["nanosec"] = nanosec
        record["log_time_ns"] = log_time_ns
        for name in _ARRAY_FIELDS:
            record[name] = getattr(solution, name)
        record["latitude_deg"] = solution.latitude_deg
        record["longitude_deg"] = solution.longitude_deg
        record["altitude_m"] = solution.altitude_m
        record["coasting"] = (
            solution.coasting_fix,
            solution.coasting_velocity,
            solution.coasting_heading,
        )

    def smoothed(
        self,
        epochs: SmoothedEpochs,
        states: StateLayout,
        map_plane: earth.LocalTangentPlane,
        distrust: tuple[list[IntegrityEvent], tuple[float, float]],
    ) -> Iterator[StampedSolution]:
        """Every stored solution with its smoothed twin, in the stored order; ``distrust``:
        the periods the forward filter was not trusted and the (attitude, velocity) variances
        its solutions had added then."""
        events, (attitude_variance, velocity_variance) = distrust
        diagonal = np.diag_indices(3)
        total = len(self._table)
        for start in range(0, total, SOLUTIONS_PER_BLOCK):
            rows = self._table.rows(start, min(total, start + SOLUTIONS_PER_BLOCK))
            error, covariance = epochs.at(rows["t_s"])
            smoothed = smoothed_rows(rows, error, covariance, states, map_plane)
            distrusted = distrusted_at(rows["t_s"], events)
            if distrusted.any():
                for name, variance in (
                    ("attitude_covariance_rad2", attitude_variance),
                    ("velocity_covariance_m2s2", velocity_variance),
                ):
                    blocks = smoothed[name][distrusted]
                    blocks[:, diagonal[0], diagonal[1]] += variance
                    smoothed[name][distrusted] = blocks
            for forward_row, smoothed_row in zip(rows, smoothed, strict=True):
                yield StampedSolution(
                    _solution(forward_row),
                    _solution(smoothed_row),
                    int(forward_row["sec"]),
                    int(forward_row["nanosec"]),
                    int(forward_row["log_time_ns"]),
                )

    def close(self) -> None:
        self._table.close()


def smoothed_rows(
    rows: np.ndarray,
    error: np.ndarray,
    covariance: np.ndarray,
    states: StateLayout,
    map_plane: earth.LocalTangentPlane,
) -> np.ndarray:
    """Solution records (:data:`SOLUTION_DTYPE`) with the error states ``error`` (N × n,
    relative to each record's nominal state) injected, and the blocks of ``covariance``."""
    out = rows.copy()
    phi = error[:, states.attitude]
    forward_rotation = Rotation.from_quat(rows["attitude_xyzw"])
    rotation = Rotation.from_rotvec(phi) * forward_rotation
    out["attitude_xyzw"] = rotation.as_quat()
    out["velocity_enu_mps"] = rows["velocity_enu_mps"] + error[:, states.velocity]
    latitude = np.radians(rows["latitude_deg"])
    altitude = rows["altitude_m"]
    sin_lat = np.sin(latitude)
    w_sq = 1.0 - earth.ECCENTRICITY_SQ * sin_lat**2
    prime_vertical = earth.SEMI_MAJOR_AXIS_M / np.sqrt(w_sq)
    meridian = prime_vertical * (1.0 - earth.ECCENTRICITY_SQ) / w_sq
    position = error[:, states.position]
    new_latitude = latitude + position[:, NORTH] / (meridian + altitude)
    new_longitude = np.radians(rows["longitude_deg"]) + position[:, EAST] / (
        (prime_vertical + altitude) * np.cos(latitude)
    )
    new_altitude = altitude + position[:, UP]
    out["latitude_deg"] = np.degrees(new_latitude)
    out["longitude_deg"] = np.degrees(new_longitude)
    out["altitude_m"] = new_altitude
    out["position_map_m"] = map_plane.enu_from_geodetic(new_latitude, new_longitude, new_altitude)
    gyro_bias_error = error[:, states.gyro_bias]
    accel_bias_error = error[:, states.accel_bias]
    out["gyro_bias_rad_s"] = rows["gyro_bias_rad_s"] + gyro_bias_error
    out["accel_bias_mps2"] = rows["accel_bias_mps2"] + accel_bias_error
    rate = rows["angular_rate_body_rad_s"] - gyro_bias_error
    out["angular_rate_body_rad_s"] = rate
    out["specific_force_body_mps2"] = rows["specific_force_body_mps2"] - accel_bias_error
    # ω_nb = ω_ib − R_nbᵀ ω_in: the navigation-frame rate ω_in (ENU) is the forward one.
    frame_rate_body = rows["angular_rate_body_rad_s"] - rows["angular_rate_nb_body_rad_s"]
    frame_rate_enu = forward_rotation.apply(frame_rate_body)
    out["angular_rate_nb_body_rad_s"] = rate - rotation.apply(frame_rate_enu, inverse=True)
    out["attitude_covariance_rad2"] = covariance[:, states.attitude, states.attitude]
    out["velocity_covariance_m2s2"] = covariance[:, states.velocity, states.velocity]
    out["position_covariance_m2"] = covariance[:, states.position, states.position]
    out["gyro_bias_covariance_rad2_s2"] = covariance[:, states.gyro_bias, states.gyro_bias]
    return out


def _solution(row: np.void) -> NavSolution:
    coasting = row["coasting"]
    return NavSolution(
        t_s=float(row["t_s"]),
        **{name: np.array(row[name]) for name in _ARRAY_FIELDS},
        latitude_deg=float(row["latitude_deg"]),
        longitude_deg=float(row["longitude_deg"]),
        altitude_m=float(row["altitude_m"]),
        aligned=True,
        coasting_fix=bool(coasting[0]),
        coasting_velocity=bool(coasting[1]),
        coasting_heading=bool(coasting[2]),
    )


class FixedIntervalSmoother:
    """The smoother of one engine's run: records its epochs and the solutions handed to
    :meth:`add`, and after the end of the data yields them smoothed (:meth:`smoothed`).

    The engine must emit the solutions of its own filter (``realtime_output`` false): a
    prediction ahead of the filter has no epoch to be smoothed at. ``spill_parent`` is where the
    temporary directory of the records is made (None: the system's temporary directory); it is
    removed by :meth:`close` or on leaving the ``with`` block.
    """

    def __init__(self, engine, spill_parent=None):
        if engine.config.realtime_output:
            raise ValueError("smoothing needs the filter's own solutions: realtime_output false")
        self.engine = engine
        self.spill = SpillDirectory(spill_parent)
        self.recorder = SmootherRecorder(engine.states, self.spill)
        engine.recorder = self.recorder
        self.store = SolutionStore(self.spill)

    def add(self, solution: NavSolution, sec: int, nanosec: int, log_time_ns: int) -> None:
        """A forward solution, with the header stamp and log time its messages carry."""
        self.store.add(solution, sec, nanosec, log_time_ns)

    def smoothed(self) -> Iterator[StampedSolution]:
        """After the engine's ``flush``: each added solution with its smoothed twin."""
        if len(self.store) == 0:
            return
        epochs = self.recorder.smooth()
        engine = self.engine
        distrust = (list(engine.health().integrity_events), distrust_variances(engine.config))
        yield from self.store.smoothed(epochs, engine.states, engine.map_plane, distrust)

    def close(self) -> None:
        self.store.close()
        self.recorder.epochs.close()
        self.spill.cleanup()

    def __enter__(self) -> FixedIntervalSmoother:
        return self

    def __exit__(self, *exc) -> None:
        self.close()
