"""The navigation solution the engine emits, how it is built, and at what rate."""

import math
from dataclasses import dataclass

import numpy as np

from buoy_nav import earth
from buoy_nav import solution_vector as vec
from buoy_nav.error_state_filter import ErrorStateFilter
from buoy_nav.mechanization import StrapdownIntegrator
from buoy_nav.rotations import euler_from_rotation_matrix, rotation_matrix_from_quaternion
from buoy_nav.solution_rows import SolutionRows
from buoy_nav.solution_vector import solution_vector
from buoy_nav.state_layout import StateLayout
from buoy_nav.strapdown_kernel import (
    ACCEL_BIAS,
    ALTITUDE,
    GYRO_BIAS,
    LATITUDE,
)


@dataclass(frozen=True, slots=True)
class NavSolution:
    """Navigation solution at one IMU sample (all arrays float64).

    t_s: stamp (s). attitude_xyzw: quaternion of R_nb (body FLU → ENU).
    angular_rate_body_rad_s: bias-corrected gyro rate ω_ib (body).
    angular_rate_nb_body_rad_s: ω_nb, rate relative to ENU (Earth and transport rate removed).
    specific_force_body_mps2: bias-corrected specific force (body).
    velocity_enu_mps: velocity over ground of the ``base_link`` origin (ENU).
    latitude_deg, longitude_deg, altitude_m: WGS-84 position of the ``base_link`` origin.
    position_map_m: the same position in the ``map`` ENU frame (m).
    attitude_covariance_rad2: covariance of the attitude error φ (ENU, 3×3, rad²), where
      R_true = Exp([φ×]) R_estimated.
    velocity_covariance_m2s2, position_covariance_m2: ENU 3×3 covariances.
    gyro_bias_covariance_rad2_s2: covariance of the gyro bias estimate (body, 3×3, rad²/s²):
      the uncertainty of the bias-corrected angular rates.
    gyro_bias_rad_s, accel_bias_mps2: bias estimates (body).
    The covariance and bias arrays are read-only: consecutive solutions share them until the
    filter changes them.
    aligned: the filter is aligned (always True in emitted solutions).
    coasting_fix, coasting_velocity, coasting_heading: no measurement of a source aiding that
      quantity (:data:`buoy_nav.aiding.base.AIDED_QUANTITIES`) was accepted for longer than
      ``coasting_timeout_s`` (for the heading: neither a heading nor a baseline).
    """

    t_s: float
    attitude_xyzw: np.ndarray
    angular_rate_body_rad_s: np.ndarray
    angular_rate_nb_body_rad_s: np.ndarray
    specific_force_body_mps2: np.ndarray
    velocity_enu_mps: np.ndarray
    latitude_deg: float
    longitude_deg: float
    altitude_m: float
    position_map_m: np.ndarray
    attitude_covariance_rad2: np.ndarray
    velocity_covariance_m2s2: np.ndarray
    position_covariance_m2: np.ndarray
    gyro_bias_covariance_rad2_s2: np.ndarray
    gyro_bias_rad_s: np.ndarray
    accel_bias_mps2: np.ndarray
    aligned: bool
    coasting_fix: bool
    coasting_velocity: bool
    coasting_heading: bool

    @property
    def euler_rad(self) -> tuple[float, float, float]:
        """(roll, pitch, yaw) in rad of R_nb = Rz(yaw) Ry(pitch) Rx(roll)."""
        return euler_from_rotation_matrix(rotation_matrix_from_quaternion(self.attitude_xyzw))


Emitted = NavSolution | float
"""What the engine emits of a solution: the solution, or its stamp (s) when it is written as a
row (:class:`SolutionBuilder`'s ``rows``)."""


class SolutionBuilder:
    """Builds :class:`NavSolution` from an integrator's state.

    At the IMU rate most consecutive solutions share the filter's covariance and bias estimates:
    their read-only arrays are made once and kept until :meth:`covariance_changed` or
    :meth:`biases_changed`. ``map_plane`` is the ``map`` frame the positions are expressed in
    (set before the first solution). With ``rows`` (an offline run's) the
    solutions are written there instead (:meth:`row`); the engine makes each through
    :attr:`emit`.
    """

    def __init__(self, map_plane: earth.LocalTangentPlane | None, rows: SolutionRows | None = None):
        self.map_plane = map_plane
        self.rows = rows
        """Where the solutions are written as rows instead (None: made as :class:`NavSolution`)."""
        self._distrust_variances: tuple[float, float] | None = None
        self._covariance_blocks: tuple[np.ndarray, ...] | None = None
        self._block_layout: StateLayout | None = None
        self._block_indices: np.ndarray | None = None
        self._bias_arrays: tuple[np.ndarray, np.ndarray] | None = None

    @property
    def emit(self):
        """:meth:`solution`, or :meth:`row` when the solutions are written as rows. Looked up
        each time: a bound method kept on the builder would hold it in a reference cycle, and
        with it the rows, until the collector's next full pass."""
        return self.solution if self.rows is None else self.row

    def covariance_changed(self) -> None:
        self._covariance_blocks = None

    def distrust(self, variances: tuple[float, float] | None) -> None:
        """While the filter is found inconsistent with its aiding, its own covariance is not
        to be believed: ``variances`` (attitude rad², velocity m²/s²) are added to each axis of
        the published blocks; None: the filter's covariance as it is."""
        if variances != self._distrust_variances:
            self._distrust_variances = variances
            self._covariance_blocks = None

    def biases_changed(self) -> None:
        self._bias_arrays = None

    def solution(
        self,
        integrator: StrapdownIntegrator,
        kalman: ErrorStateFilter,
        t: float,
        gyro,
        force,
        coasting: tuple[bool, bool, bool],
    ) -> NavSolution:
        """The solution of ``integrator``'s state at stamp ``t`` (raw gyro and force there),
        with the covariance of ``kalman`` and the (fix, velocity, heading) coasting flags."""
        if self._covariance_blocks is None:
            self._covariance_blocks = self._published_covariance_blocks(kalman)
        state = integrator.state_vector
        if self._bias_arrays is None:
            self._bias_arrays = (
                _read_only(state[GYRO_BIAS : GYRO_BIAS + 3].copy()),
                _read_only(state[ACCEL_BIAS : ACCEL_BIAS + 3].copy()),
            )
        gx, gy, gz = gyro
        fx, fy, fz = force
        vector = solution_vector(state, gx, gy, gz, fx, fy, fz, self.map_plane.scalar_terms)
        latitude, longitude, altitude = state[LATITUDE : ALTITUDE + 1].tolist()
        attitude_cov, velocity_cov, position_cov, gyro_bias_cov = self._covariance_blocks
        gyro_bias, accel_bias = self._bias_arrays
        return NavSolution(
            t_s=t,
            attitude_xyzw=vector[vec.ATTITUDE_XYZW],
            angular_rate_body_rad_s=vector[vec.ANGULAR_RATE],
            angular_rate_nb_body_rad_s=vector[vec.ANGULAR_RATE_NB],
            specific_force_body_mps2=vector[vec.SPECIFIC_FORCE],
            velocity_enu_mps=vector[vec.VELOCITY_ENU],
            latitude_deg=math.degrees(latitude),
            longitude_deg=math.degrees(longitude),
            altitude_m=altitude,
            position_map_m=vector[vec.POSITION_MAP],
            attitude_covariance_rad2=attitude_cov,
            velocity_covariance_m2s2=velocity_cov,
            position_covariance_m2=position_cov,
            gyro_bias_covariance_rad2_s2=gyro_bias_cov,
            gyro_bias_rad_s=gyro_bias,
            accel_bias_mps2=accel_bias,
            aligned=True,
            coasting_fix=coasting[0],
            coasting_velocity=coasting[1],
            coasting_heading=coasting[2],
        )

    def row(
        self,
        integrator: StrapdownIntegrator,
        kalman: ErrorStateFilter,
        t: float,
        gyro,
        force,
        coasting: tuple[bool, bool, bool],
    ) -> float:
        """:meth:`solution`'s numbers that :class:`~buoy_nav.solution_rows.SolutionRows` keeps,
        written as a row of :attr:`rows`; returns the stamp ``t`` (the ``coasting`` flags are
        not kept)."""
        self.rows.append(
            t,
            integrator.state_vector,
            gyro,
            force,
            self.map_plane.scalar_terms,
            kalman.covariance,
            self._block_indices_of(kalman.states),
            self._distrust_variances,
        )
        return t

    def row_arguments(self, kalman: ErrorStateFilter) -> tuple:
        """What :meth:`row` hands the row writer besides the sample: the plane's terms,
        ``kalman``'s covariance, its published blocks' indices, whether the filter is
        distrusted and the variances then added (:mod:`buoy_nav.imu_stretch`)."""
        distrust = self._distrust_variances
        return (
            self.map_plane.scalar_terms,
            kalman.covariance,
            self._block_indices_of(kalman.states),
            distrust is not None,
            (0.0, 0.0) if distrust is None else distrust,
        )

    def _block_indices_of(self, states: StateLayout) -> np.ndarray:
        """:func:`_published_block_indices` of ``states``, made once per layout."""
        if self._block_layout is not states:
            self._block_layout = states
            self._block_indices = _published_block_indices(states)
        return self._block_indices

    def _published_covariance_blocks(self, kalman: ErrorStateFilter) -> tuple[np.ndarray, ...]:
        """The attitude (rad²), velocity (m²/s²), position (m²) and gyro bias (rad²/s²)
        blocks of ``kalman``'s covariance, read-only, the first two widened while the filter is
        distrusted."""
        # One gather copies all four blocks (each a contiguous 3×3 of the result): half the
        # time of four slices copied one by one, at a new covariance per IMU sample.
        blocks = kalman.covariance.take(self._block_indices_of(kalman.states))
        if self._distrust_variances is not None:
            for block, variance in zip(blocks, self._distrust_variances, strict=False):
                block[np.diag_indices(3)] += variance
        blocks.setflags(write=False)
        return tuple(blocks)


class OutputDecimation:
    """Decimation of the solutions to ``output_rate_hz`` (0: every sample) on a grid anchored at
    the first output after each :meth:`restart`."""

    def __init__(self, output_rate_hz: float):
        self._period = 1.0 / output_rate_hz if output_rate_hz > 0 else 0.0
        self._next_output_time = -math.inf

    def restart(self) -> None:
        self._next_output_time = -math.inf

    @property
    def period_s(self) -> float:
        """The output period (s; 0: every sample)."""
        return self._period

    @property
    def next_output_s(self) -> float:
        """The stamp (s) from which the next sample is output, half a step of tolerance
        before it (:mod:`buoy_nav.imu_stretch` takes and gives it back)."""
        return self._next_output_time

    @next_output_s.setter
    def next_output_s(self, t_s: float) -> None:
        self._next_output_time = t_s

    def due(self, t: float, span: float) -> bool:
        """Whether the sample at stamp ``t`` (``span`` s after the previous one) is output."""
        period = self._period
        if period == 0.0:
            return True
        # Half an IMU step of tolerance absorbs stamp jitter and float rounding of the grid.
        if t + 0.5 * span < self._next_output_time:
            return False
        following = self._next_output_time + period
        self._next_output_time = following if following > t else t + period
        return True


def _published_block_indices(states: StateLayout) -> np.ndarray:
    """Flat (row-major) indices into a covariance of ``states`` of its attitude, velocity,
    position and gyro bias blocks, shaped (4, 3, 3)."""
    return np.array(
        [
            [
                [row * states.dim + column for column in states.indices(name)]
                for row in states.indices(name)
            ]
            for name in ("attitude", "velocity", "position", "gyro_bias")
        ]
    )


def _read_only(array: np.ndarray) -> np.ndarray:
    array.setflags(write=False)
    return array
