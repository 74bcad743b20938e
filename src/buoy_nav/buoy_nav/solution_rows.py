"""Solutions as rows of one block, for an offline run.

An offline run needs of each solution only the numbers its ``nav/*`` messages, its corrections
and its NetCDF file take. Built as a :class:`NavSolution` each, with its arrays, made into the
values of its messages and gathered into columns later, they cost more than the filter's step
that made them; written here, one compiled call a solution, they are columns already. Every
number is the one :meth:`SolutionBuilder.solution` gives, to the bit.
"""

import math

import numba
import numpy as np

from buoy_nav.solution_vector import solution_vector
from buoy_nav.strapdown_kernel import (
    ALTITUDE,
    ATTITUDE,
    LATITUDE,
    LONGITUDE,
    STATE_SIZE,
)

# The columns of a row: what the messages, the corrections and the NetCDF file take of a
# solution.
STAMP = 0
"""t_s: the solution's stamp (s)."""
ATTITUDE_XYZW = slice(1, 5)
"""Quaternion of R_nb (body FLU → ENU)."""
ANGULAR_RATE = slice(5, 8)
"""Bias-corrected gyro rate ω_ib (body, rad/s)."""
VELOCITY_ENU = slice(8, 11)
"""Velocity over ground (ENU, m/s)."""
GEODETIC = slice(11, 14)
"""Latitude, longitude (deg), altitude (m)."""
ATTITUDE_COVARIANCE = slice(14, 23)
"""Attitude error's covariance (ENU, rad², 3×3 row-major)."""
VELOCITY_COVARIANCE = slice(23, 32)
"""Velocity's covariance (ENU, m²/s², 3×3 row-major)."""
POSITION_COVARIANCE = slice(32, 41)
"""Position's covariance (ENU, m², 3×3 row-major)."""
GYRO_BIAS_COVARIANCE = slice(41, 50)
"""Gyro bias's covariance (body, rad²/s², 3×3 row-major)."""
POSITION_MAP = slice(50, 53)
"""Position in the ``map`` frame (ENU, m)."""
SPECIFIC_FORCE = slice(53, 56)
"""Bias-corrected specific force (body, m/s²)."""
ROW_WIDTH = 56

_FIRST_CAPACITY = 4096

_RADIANS_TO_DEGREES = 180.0 / math.pi


class SolutionRows:
    """The solutions written since the last :meth:`take`, a row each (the columns above)."""

    def __init__(self):
        self._block = np.empty((_FIRST_CAPACITY, ROW_WIDTH))
        self.count = 0
        """Rows written and not yet taken."""

    def append(
        self,
        t_s: float,
        state: np.ndarray,
        gyro_rad_s: tuple[float, float, float],
        force_mps2: tuple[float, float, float],
        plane_terms: np.ndarray,
        covariance: np.ndarray,
        block_indices: np.ndarray,
        distrust_variances: tuple[float, float] | None,
    ) -> None:
        """Write the solution of the nominal ``state`` (strapdown_kernel's layout) at stamp
        ``t_s`` (s) with the raw gyro and specific force samples there (body rad/s, m/s²), its
        ``map`` position in the plane of ``plane_terms``
        (:attr:`~buoy_nav.earth.LocalTangentPlane.scalar_terms`) and the filter's
        ``covariance``, whose published blocks are at ``block_indices``
        (:class:`~buoy_nav.solution.SolutionBuilder`'s), the attitude and velocity variances
        ``distrust_variances`` (rad², m²/s²) added to their diagonals when not None."""
        if self.count == self._block.shape[0]:
            self._block = np.concatenate((self._block, np.empty_like(self._block)))
        gx, gy, gz = gyro_rad_s
        fx, fy, fz = force_mps2
        distrusted = distrust_variances is not None
        attitude_variance, velocity_variance = distrust_variances if distrusted else (0.0, 0.0)
        write_row(
            self._block,
            self.count,
            t_s,
            state,
            gx,
            gy,
            gz,
            fx,
            fy,
            fz,
            plane_terms,
            covariance,
            block_indices,
            distrusted,
            attitude_variance,
            velocity_variance,
        )
        self.count += 1

    @property
    def block(self) -> np.ndarray:
        """The rows' block: :attr:`count` rows written, room for the rest (writers that add
        several at a time set :attr:`count` after)."""
        return self._block

    def extend(self, rows: np.ndarray) -> None:
        """Hold ``rows`` (n × :data:`ROW_WIDTH`) after those held: rows another process wrote
        and handed over."""
        needed = self.count + rows.shape[0]
        if needed > self._block.shape[0]:
            capacity = max(needed, 2 * self._block.shape[0])
            grown = np.empty((capacity, ROW_WIDTH))
            grown[: self.count] = self._block[: self.count]
            self._block = grown
        self._block[self.count : needed] = rows
        self.count = needed

    def take(self, count: int) -> np.ndarray:
        """The oldest ``count`` rows (count × :data:`ROW_WIDTH`), no longer held."""
        if count > self.count:
            raise ValueError(f"{count} rows asked for, {self.count} written")
        taken = self._block[:count].copy()
        left = self.count - count
        self._block[:left] = self._block[count : self.count]
        self.count = left
        return taken


@numba.njit(cache=True)
def write_row(
    block,
    row,
    t_s,
    state,
    gx,
    gy,
    gz,
    fx,
    fy,
    fz,
    plane_terms,
    covariance,
    block_indices,
    distrusted,
    attitude_variance,
    velocity_variance,
):
    """Row ``row`` of ``block``: :meth:`SolutionRows.append`'s arguments as the columns of the
    module; each number computed as :meth:`~buoy_nav.solution.SolutionBuilder.solution`
    computes it (its vectors by :func:`~buoy_nav.solution_vector.solution_vector`, its degrees
    as ``math.degrees``)."""
    values = block[row]
    vector = solution_vector(state, gx, gy, gz, fx, fy, fz, plane_terms)
    values[STAMP] = t_s
    values[1:5] = vector[0:4]  # attitude
    values[5:8] = vector[4:7]  # bias-corrected rate
    values[8:11] = vector[13:16]  # velocity
    values[11] = state[LATITUDE] * _RADIANS_TO_DEGREES
    values[12] = state[LONGITUDE] * _RADIANS_TO_DEGREES
    values[13] = state[ALTITUDE]
    dimension = covariance.shape[1]
    for block_index in range(4):  # attitude, velocity, position, gyro bias
        for i in range(3):
            for j in range(3):
                index = block_indices[block_index, i, j]
                value = covariance[index // dimension, index % dimension]
                if distrusted and i == j and block_index < 2:
                    value += attitude_variance if block_index == 0 else velocity_variance
                values[14 + 9 * block_index + 3 * i + j] = value
    values[50:53] = vector[16:19]  # map position
    values[53:56] = vector[10:13]  # bias-corrected force


def load_compiled_solution_rows() -> None:
    """Compile the row writer, or load it from the cache, now (see
    :func:`buoy_nav.mechanization.load_compiled_kernels`)."""
    state = np.zeros(STATE_SIZE)
    state[ATTITUDE + 3] = 1.0
    indices = np.arange(36, dtype=np.int64).reshape(4, 3, 3)
    SolutionRows().append(
        0.0, state, (0.0, 0.0, 0.0), (0.0, 0.0, 9.8), np.zeros(12), np.eye(6), indices, (1e-6, 1e-4)
    )
