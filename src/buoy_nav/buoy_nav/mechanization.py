"""Strapdown mechanization in the local-level East-North-Up frame.

The integrator carries the nominal navigation state (attitude ``R_nb``, ENU velocity of the
``base_link`` origin, geodetic position, IMU bias estimates) from one IMU sample to the next.

Inputs are instantaneous samples (gyro rate ω_ib in rad/s and specific force in m/s², body
frame), not increments. Each step forms the angle and velocity increments of the interval by
integrating the parabola through the last three samples (the trapezoid rule plus a curvature
term; for equal steps the Adams-Moulton weights (−1, 8, 5)/12), then corrects them for coning
and sculling with the two-sample previous-increment algorithms. The plain trapezoid would
overstate an oscillating rate by (ΩT)²/12, and for coning motion that alone drifts as much as
the uncorrected coning term, which would leave the coning correction only half effective.
The coning and sculling corrections are exact when the rate and specific force vary linearly
across the two intervals. For intervals of unequal length (a step split at a measurement stamp)
both the curvature term and the corrections use the factor ``k = T² / (6 T_prev (T_prev + T))``,
which is 1/12 for equal lengths. The first step after (re)initialisation uses the trapezoid
without corrections.

Attitude update: ``R_nb(k) = Exp(−ω_in T) · R_nb(k−1) · Exp(φ_k)`` with φ_k the coning-corrected
rotation vector of the body and ω_in = ω_ie + ω_en the rotation of ENU with respect to inertial
space. Velocity update: the specific-force increment, rotation-compensated to third order and
sculling-corrected, turned into ENU with the start attitude (plus half the navigation-frame
rotation), then gravity and Coriolis. Position update: trapezoid on velocity, converted to
latitude/longitude with the WGS-84 radii of curvature.

Over the steps since the last covariance propagation it also sums what the discrete error model
needs (:class:`PropagationSums`). The step is compiled (numba, cached on disk) and updates in
place the one array that holds the integrator's state: at twice the IMU rate the interpreter's
cost per operation would otherwise dominate the offline run.
"""

import contextlib
import copy
import math
import signal
import threading
from dataclasses import dataclass

import numba
import numpy as np

from buoy_nav import earth
from buoy_nav.config import FusionConfig
from buoy_nav.error_state_filter import ImuErrorModel, NavState, discrete_error_model
from buoy_nav.rotations import (
    Quaternion,
    normalize_quaternion,
    quaternion_from_rotation_vector,
    rotation_matrix_elements,
)

_OMEGA = earth.EARTH_RATE_RAD_S


@dataclass(frozen=True)
class PropagationSums:
    """Integrals over the IMU steps since the last covariance propagation.

    duration_s: total time T (s).
    rotation_integral_s: ∫ R_nb dt (3×3, s); maps body-frame sensor errors into ENU.
    specific_force_increment_enu_mps: ∫ f^n dt (ENU, m/s); couples attitude error into velocity.
    gyro_rate_sq_integral_rad2_s: ∫ ω_ib² dt per body axis (rad²/s), for the scale-factor noise.
    force_deviation_sq_integral_m2_s3: ∫ (f − (0, 0, g))² dt per body axis (m²/s³): the specific
      force a floating, upright ``base_link`` sees beyond gravity, for the scale-factor noise
      (the gravity part of a scale-factor error is constant and taken up by the bias state).
    """

    duration_s: float
    rotation_integral_s: np.ndarray
    specific_force_increment_enu_mps: np.ndarray
    gyro_rate_sq_integral_rad2_s: np.ndarray
    force_deviation_sq_integral_m2_s3: np.ndarray


# Layout of the integrator's state vector (one float64 array, so that the compiled step reads and
# writes it in place), by where each block starts and, after the colon, how long it is: the
# nominal state, the previous step for the curvature, coning and sculling terms, and the
# propagation sums.
_ATTITUDE = 0  # 4: quaternion x, y, z, w of R_nb
_ROTATION = 4  # 9: R_nb, row-major
_VELOCITY = 13  # 3: ENU, m/s
_LATITUDE, _LONGITUDE, _ALTITUDE = 16, 17, 18  # rad, rad, m
_GYRO_BIAS = 19  # 3: rad/s, body
_ACCEL_BIAS = 22  # 3: m/s², body
_NAV_FRAME_RATE = 25  # 3: ω_in, ENU, rad/s
_PREVIOUS_DT = 28  # s; 0 when there is no previous step
_PREVIOUS_DTHETA = 29  # 3: body angle increment of the previous step (rad)
_PREVIOUS_DVEL = 32  # 3: body velocity increment of the previous step (m/s)
_OLDER_GYRO = 35  # 3: raw sample at the previous step's start (rad/s)
_OLDER_FORCE = 38  # 3: (m/s²)
_DURATION = 41  # s integrated since the last take_propagation_sums; the sums follow it
_ROTATION_SUM = 42  # 9: ∫ R_nb dt, row-major
_FORCE_SUM = 51  # 3: ∫ f^n dt
_RATE_SQ_SUM = 54  # 3
_FORCE_DEVIATION_SQ_SUM = 57  # 3
_STATE_SIZE = 60


class StrapdownIntegrator:
    """Nominal navigation state integrated from consecutive IMU samples.

    Attributes (read them, and change the state only through :meth:`set_state`):
      attitude_xyzw: quaternion of R_nb (body FLU → ENU).
      rotation_elements: R_nb as a row-major 9-tuple.
      nav_frame_rate_enu_rad_s: ω_in = ω_ie + ω_en used by the last step (ENU, rad/s).
      accumulated_duration_s: time integrated since the last :meth:`take_propagation_sums`.
      velocity_enu_mps: velocity of the ``base_link`` origin over ground, ENU.
      latitude_rad, longitude_rad, altitude_m: WGS-84 position of the ``base_link`` origin.
      gyro_bias_rad_s, accel_bias_mps2: bias estimates subtracted from the raw samples (body).
    """

    def __init__(
        self,
        attitude_xyzw,
        velocity_enu_mps,
        latitude_rad: float,
        longitude_rad: float,
        altitude_m: float,
        gyro_bias_rad_s=(0.0, 0.0, 0.0),
        accel_bias_mps2=(0.0, 0.0, 0.0),
        coning_correction: bool = True,
        sculling_correction: bool = True,
    ):
        self.coning_correction = coning_correction
        self.sculling_correction = sculling_correction
        # No previous step yet, and empty sums.
        self._state = np.zeros(_STATE_SIZE)
        self.set_state(
            attitude_xyzw,
            velocity_enu_mps,
            latitude_rad,
            longitude_rad,
            altitude_m,
            gyro_bias_rad_s,
            accel_bias_mps2,
        )

    def set_state(
        self,
        attitude_xyzw,
        velocity_enu_mps,
        latitude_rad: float,
        longitude_rad: float,
        altitude_m: float,
        gyro_bias_rad_s,
        accel_bias_mps2,
    ):
        """Replace the nominal state (after a filter correction); increments history is kept."""
        state = self._state
        attitude = normalize_quaternion(_floats(attitude_xyzw))
        ve, vn, _ = velocity_enu_mps = _floats(velocity_enu_mps)
        lat = float(latitude_rad)
        alt = float(altitude_m)
        state[_ATTITUDE : _ATTITUDE + 4] = attitude
        state[_ROTATION : _ROTATION + 9] = rotation_matrix_elements(*attitude)
        state[_VELOCITY : _VELOCITY + 3] = velocity_enu_mps
        state[_LATITUDE] = lat
        state[_LONGITUDE] = float(longitude_rad)
        state[_ALTITUDE] = alt
        state[_GYRO_BIAS : _GYRO_BIAS + 3] = _floats(gyro_bias_rad_s)
        state[_ACCEL_BIAS : _ACCEL_BIAS + 3] = _floats(accel_bias_mps2)
        # earth.navigation_frame_rate_enu_rad_s (ω_ie + ω_en) in floats, the same arithmetic.
        meridian, prime_vertical = earth.radii_of_curvature_m(lat)
        east_radius = prime_vertical + alt
        state[_NAV_FRAME_RATE : _NAV_FRAME_RATE + 3] = (
            0.0 + -vn / (meridian + alt),
            _OMEGA * math.cos(lat) + ve / east_radius,
            _OMEGA * math.sin(lat) + ve * math.tan(lat) / east_radius,
        )

    @property
    def attitude_xyzw(self) -> Quaternion:
        return tuple(self._state[_ATTITUDE : _ATTITUDE + 4].tolist())

    @property
    def rotation_elements(self) -> tuple[float, ...]:
        return tuple(self._state[_ROTATION : _ROTATION + 9].tolist())

    @property
    def velocity_enu_mps(self) -> tuple[float, float, float]:
        return tuple(self._state[_VELOCITY : _VELOCITY + 3].tolist())

    @property
    def latitude_rad(self) -> float:
        return float(self._state[_LATITUDE])

    @property
    def longitude_rad(self) -> float:
        return float(self._state[_LONGITUDE])

    @property
    def altitude_m(self) -> float:
        return float(self._state[_ALTITUDE])

    @property
    def gyro_bias_rad_s(self) -> tuple[float, float, float]:
        return tuple(self._state[_GYRO_BIAS : _GYRO_BIAS + 3].tolist())

    @property
    def accel_bias_mps2(self) -> tuple[float, float, float]:
        return tuple(self._state[_ACCEL_BIAS : _ACCEL_BIAS + 3].tolist())

    @property
    def nav_frame_rate_enu_rad_s(self) -> tuple[float, float, float]:
        return tuple(self._state[_NAV_FRAME_RATE : _NAV_FRAME_RATE + 3].tolist())

    @property
    def accumulated_duration_s(self) -> float:
        return float(self._state[_DURATION])

    def fork(self) -> "StrapdownIntegrator":
        """An independent copy that integrates ahead without touching this one's propagation
        sums (its own sums start empty)."""
        twin = copy.copy(self)
        twin._state = self._state.copy()
        twin._state[_DURATION:] = 0.0
        return twin

    def nav_state(self) -> NavState:
        """The nominal state as a :class:`NavState` (arrays are copies)."""
        state = self._state
        return NavState(
            attitude_xyzw=self.attitude_xyzw,
            velocity_enu_mps=state[_VELOCITY : _VELOCITY + 3].copy(),
            latitude_rad=float(state[_LATITUDE]),
            longitude_rad=float(state[_LONGITUDE]),
            altitude_m=float(state[_ALTITUDE]),
            gyro_bias_rad_s=state[_GYRO_BIAS : _GYRO_BIAS + 3].copy(),
            accel_bias_mps2=state[_ACCEL_BIAS : _ACCEL_BIAS + 3].copy(),
        )

    def set_nav_state(self, state: NavState):
        """:meth:`set_state` from a :class:`NavState`."""
        self.set_state(
            state.attitude_xyzw,
            state.velocity_enu_mps,
            state.latitude_rad,
            state.longitude_rad,
            state.altitude_m,
            state.gyro_bias_rad_s,
            state.accel_bias_mps2,
        )

    @property
    def rotation_nb(self) -> np.ndarray:
        """R_nb as a 3×3 array."""
        return self._state[_ROTATION : _ROTATION + 9].reshape(3, 3).copy()

    def step(self, dt_s: float, gyro_start, gyro_end, force_start, force_end):
        """Advance the state by ``dt_s`` (s) between two raw IMU samples.

        gyro_start, gyro_end: raw angular rate ω_ib at the start and end of the step (body, rad/s).
        force_start, force_end: raw specific force at the start and end (body, m/s²).
        The bias estimates are removed here.
        """
        # Handed over as scalars, so that tuples, lists and arrays alike run the one compiled
        # specialisation (a sequence type of its own would compile again in the data path).
        g0x, g0y, g0z = gyro_start
        g1x, g1y, g1z = gyro_end
        f0x, f0y, f0z = force_start
        f1x, f1y, f1z = force_end
        _strapdown_step(
            self._state,
            dt_s,
            g0x,
            g0y,
            g0z,
            g1x,
            g1y,
            g1z,
            f0x,
            f0y,
            f0z,
            f1x,
            f1y,
            f1z,
            self.coning_correction,
            self.sculling_correction,
        )

    def take_propagation_sums(self) -> PropagationSums:
        """Return the integrals accumulated since the last call and restart them."""
        state = self._state
        sums = PropagationSums(
            duration_s=float(state[_DURATION]),
            rotation_integral_s=state[_ROTATION_SUM : _ROTATION_SUM + 9].reshape(3, 3).copy(),
            specific_force_increment_enu_mps=state[_FORCE_SUM : _FORCE_SUM + 3].copy(),
            gyro_rate_sq_integral_rad2_s=state[_RATE_SQ_SUM : _RATE_SQ_SUM + 3].copy(),
            force_deviation_sq_integral_m2_s3=state[
                _FORCE_DEVIATION_SQ_SUM : _FORCE_DEVIATION_SQ_SUM + 3
            ].copy(),
        )
        state[_DURATION:] = 0.0
        return sums


# The Earth-model and rotation functions the step calls, compiled from their one source.
_normal_gravity_mps2 = numba.njit(cache=True)(earth.normal_gravity_mps2)
_quaternion_from_rotation_vector = numba.njit(cache=True)(quaternion_from_rotation_vector)


@numba.njit(cache=True)
def _strapdown_step(
    state,
    dt_s,
    g0x,
    g0y,
    g0z,
    g1x,
    g1y,
    g1z,
    f0x,
    f0y,
    f0z,
    f1x,
    f1y,
    f1z,
    coning_correction,
    sculling_correction,
):
    """One step of :meth:`StrapdownIntegrator.step` on its state vector, in place (see the module
    docstring for the algorithm; the layout is that of the ``_ATTITUDE`` … constants)."""
    bgx, bgy, bgz = state[_GYRO_BIAS], state[_GYRO_BIAS + 1], state[_GYRO_BIAS + 2]
    bax, bay, baz = (
        state[_ACCEL_BIAS],
        state[_ACCEL_BIAS + 1],
        state[_ACCEL_BIAS + 2],
    )
    half_dt = 0.5 * dt_s
    dthx = (g0x + g1x - 2.0 * bgx) * half_dt
    dthy = (g0y + g1y - 2.0 * bgy) * half_dt
    dthz = (g0z + g1z - 2.0 * bgz) * half_dt
    dvx = (f0x + f1x - 2.0 * bax) * half_dt
    dvy = (f0y + f1y - 2.0 * bay) * half_dt
    dvz = (f0z + f1z - 2.0 * baz) * half_dt
    previous_dt = state[_PREVIOUS_DT]
    k = 0.0
    if previous_dt > 0.0:
        k = dt_s * dt_s / (6.0 * previous_dt * (previous_dt + dt_s))
        # Curvature of the parabola through the older, start and end samples.
        ogx, ogy, ogz = (
            state[_OLDER_GYRO],
            state[_OLDER_GYRO + 1],
            state[_OLDER_GYRO + 2],
        )
        ofx, ofy, ofz = (
            state[_OLDER_FORCE],
            state[_OLDER_FORCE + 1],
            state[_OLDER_FORCE + 2],
        )
        dthx -= k * ((g1x - g0x) * previous_dt + (ogx - g0x) * dt_s)
        dthy -= k * ((g1y - g0y) * previous_dt + (ogy - g0y) * dt_s)
        dthz -= k * ((g1z - g0z) * previous_dt + (ogz - g0z) * dt_s)
        dvx -= k * ((f1x - f0x) * previous_dt + (ofx - f0x) * dt_s)
        dvy -= k * ((f1y - f0y) * previous_dt + (ofy - f0y) * dt_s)
        dvz -= k * ((f1z - f0z) * previous_dt + (ofz - f0z) * dt_s)

    # Body rotation vector and velocity increment in the start-of-step body frame.
    rvx, rvy, rvz = dthx, dthy, dthz
    # Rotation of the body during the step: ½ Δθ × Δv + ⅙ Δθ × (Δθ × Δv), the series of
    # ∫ Exp([ωt×]) f dt to third order (the third term matters for fast rolls).
    cx = dthy * dvz - dthz * dvy
    cy = dthz * dvx - dthx * dvz
    cz = dthx * dvy - dthy * dvx
    bvx = dvx + 0.5 * cx + (dthy * cz - dthz * cy) / 6.0
    bvy = dvy + 0.5 * cy + (dthz * cx - dthx * cz) / 6.0
    bvz = dvz + 0.5 * cz + (dthx * cy - dthy * cx) / 6.0
    if previous_dt > 0.0:
        px, py, pz = (
            state[_PREVIOUS_DTHETA],
            state[_PREVIOUS_DTHETA + 1],
            state[_PREVIOUS_DTHETA + 2],
        )
        if coning_correction:
            rvx += k * (py * dthz - pz * dthy)
            rvy += k * (pz * dthx - px * dthz)
            rvz += k * (px * dthy - py * dthx)
        if sculling_correction:
            ux, uy, uz = (
                state[_PREVIOUS_DVEL],
                state[_PREVIOUS_DVEL + 1],
                state[_PREVIOUS_DVEL + 2],
            )
            bvx += k * (py * dvz - pz * dvy + uy * dthz - uz * dthy)
            bvy += k * (pz * dvx - px * dvz + uz * dthx - ux * dthz)
            bvz += k * (px * dvy - py * dvx + ux * dthy - uy * dthx)
    state[_PREVIOUS_DT] = dt_s
    (
        state[_PREVIOUS_DTHETA],
        state[_PREVIOUS_DTHETA + 1],
        state[_PREVIOUS_DTHETA + 2],
    ) = dthx, dthy, dthz
    (
        state[_PREVIOUS_DVEL],
        state[_PREVIOUS_DVEL + 1],
        state[_PREVIOUS_DVEL + 2],
    ) = dvx, dvy, dvz
    state[_OLDER_GYRO], state[_OLDER_GYRO + 1], state[_OLDER_GYRO + 2] = (
        g0x,
        g0y,
        g0z,
    )
    state[_OLDER_FORCE], state[_OLDER_FORCE + 1], state[_OLDER_FORCE + 2] = (
        f0x,
        f0y,
        f0z,
    )

    # Earth model at the start-of-step position.
    lat = state[_LATITUDE]
    alt = state[_ALTITUDE]
    ve, vn, vu = state[_VELOCITY], state[_VELOCITY + 1], state[_VELOCITY + 2]
    sin_lat = math.sin(lat)
    cos_lat = math.cos(lat)
    w_sq = 1.0 - earth.ECCENTRICITY_SQ * sin_lat * sin_lat
    prime_vertical = earth.SEMI_MAJOR_AXIS_M / math.sqrt(w_sq)
    north_radius = prime_vertical * (1.0 - earth.ECCENTRICITY_SQ) / w_sq + alt
    east_radius = prime_vertical + alt
    gravity = _normal_gravity_mps2(lat, alt)
    wie_n = _OMEGA * cos_lat
    wie_u = _OMEGA * sin_lat
    wen_e = -vn / north_radius
    wen_n = ve / east_radius
    wen_u = wen_n * sin_lat / cos_lat
    win_e = wen_e
    win_n = wie_n + wen_n
    win_u = wie_u + wen_u
    (
        state[_NAV_FRAME_RATE],
        state[_NAV_FRAME_RATE + 1],
        state[_NAV_FRAME_RATE + 2],
    ) = win_e, win_n, win_u

    # Specific-force velocity increment in ENU (start attitude, half the frame rotation).
    r00, r01, r02 = state[_ROTATION], state[_ROTATION + 1], state[_ROTATION + 2]
    r10, r11, r12 = state[_ROTATION + 3], state[_ROTATION + 4], state[_ROTATION + 5]
    r20, r21, r22 = state[_ROTATION + 6], state[_ROTATION + 7], state[_ROTATION + 8]
    fne = r00 * bvx + r01 * bvy + r02 * bvz
    fnn = r10 * bvx + r11 * bvy + r12 * bvz
    fnu = r20 * bvx + r21 * bvy + r22 * bvz
    fne, fnn, fnu = (
        fne - half_dt * (win_n * fnu - win_u * fnn),
        fnn - half_dt * (win_u * fne - win_e * fnu),
        fnu - half_dt * (win_e * fnn - win_n * fne),
    )
    # Coriolis (2ω_ie + ω_en) × v and gravity (0, 0, −g).
    ce = win_e
    cn = wie_n + win_n
    cu = wie_u + win_u
    new_ve = ve + fne - (cn * vu - cu * vn) * dt_s
    new_vn = vn + fnn - (cu * ve - ce * vu) * dt_s
    new_vu = vu + fnu - (ce * vn - cn * ve + gravity) * dt_s

    state[_LATITUDE] = lat + (vn + new_vn) * half_dt / north_radius
    state[_LONGITUDE] += (ve + new_ve) * half_dt / (east_radius * cos_lat)
    state[_ALTITUDE] = alt + (vu + new_vu) * half_dt
    state[_VELOCITY], state[_VELOCITY + 1], state[_VELOCITY + 2] = (
        new_ve,
        new_vn,
        new_vu,
    )

    # R_nb(k) = Exp(−ω_in T) · R_nb(k−1) · Exp(φ_k), in quaternions.
    bx, by, bz, bw = _quaternion_from_rotation_vector(rvx, rvy, rvz)
    nx, ny, nz, nw = _quaternion_from_rotation_vector(-win_e * dt_s, -win_n * dt_s, -win_u * dt_s)
    ax, ay, az, aw = (
        state[_ATTITUDE],
        state[_ATTITUDE + 1],
        state[_ATTITUDE + 2],
        state[_ATTITUDE + 3],
    )
    ax, ay, az, aw = (
        aw * bx + ax * bw + ay * bz - az * by,
        aw * by - ax * bz + ay * bw + az * bx,
        aw * bz + ax * by - ay * bx + az * bw,
        aw * bw - ax * bx - ay * by - az * bz,
    )
    ax, ay, az, aw = (
        nw * ax + nx * aw + ny * az - nz * ay,
        nw * ay - nx * az + ny * aw + nz * ax,
        nw * az + nx * ay - ny * ax + nz * aw,
        nw * aw - nx * ax - ny * ay - nz * az,
    )
    norm = math.sqrt(ax * ax + ay * ay + az * az + aw * aw)
    if aw < 0.0:
        norm = -norm
    x, y, z, w = ax / norm, ay / norm, az / norm, aw / norm
    (
        state[_ATTITUDE],
        state[_ATTITUDE + 1],
        state[_ATTITUDE + 2],
        state[_ATTITUDE + 3],
    ) = x, y, z, w
    xx, yy, zz = x * x, y * y, z * z
    xy, xz, yz = x * y, x * z, y * z
    wx, wy, wz = w * x, w * y, w * z
    n00 = 1.0 - 2.0 * (yy + zz)
    n01 = 2.0 * (xy - wz)
    n02 = 2.0 * (xz + wy)
    n10 = 2.0 * (xy + wz)
    n11 = 1.0 - 2.0 * (xx + zz)
    n12 = 2.0 * (yz - wx)
    n20 = 2.0 * (xz - wy)
    n21 = 2.0 * (yz + wx)
    n22 = 1.0 - 2.0 * (xx + yy)
    state[_ROTATION], state[_ROTATION + 1], state[_ROTATION + 2] = n00, n01, n02
    state[_ROTATION + 3], state[_ROTATION + 4], state[_ROTATION + 5] = n10, n11, n12
    state[_ROTATION + 6], state[_ROTATION + 7], state[_ROTATION + 8] = n20, n21, n22

    # Integrals for the covariance propagation (trapezoid in the attitude).
    state[_ROTATION_SUM] += (r00 + n00) * half_dt
    state[_ROTATION_SUM + 1] += (r01 + n01) * half_dt
    state[_ROTATION_SUM + 2] += (r02 + n02) * half_dt
    state[_ROTATION_SUM + 3] += (r10 + n10) * half_dt
    state[_ROTATION_SUM + 4] += (r11 + n11) * half_dt
    state[_ROTATION_SUM + 5] += (r12 + n12) * half_dt
    state[_ROTATION_SUM + 6] += (r20 + n20) * half_dt
    state[_ROTATION_SUM + 7] += (r21 + n21) * half_dt
    state[_ROTATION_SUM + 8] += (r22 + n22) * half_dt
    state[_DURATION] += dt_s
    state[_FORCE_SUM] += fne
    state[_FORCE_SUM + 1] += fnn
    state[_FORCE_SUM + 2] += fnu
    inverse_dt = 1.0 / dt_s
    state[_RATE_SQ_SUM] += dthx * dthx * inverse_dt
    state[_RATE_SQ_SUM + 1] += dthy * dthy * inverse_dt
    state[_RATE_SQ_SUM + 2] += dthz * dthz * inverse_dt
    dvz_kinematic = dvz - gravity * dt_s
    state[_FORCE_DEVIATION_SQ_SUM] += dvx * dvx * inverse_dt
    state[_FORCE_DEVIATION_SQ_SUM + 1] += dvy * dvy * inverse_dt
    state[_FORCE_DEVIATION_SQ_SUM + 2] += dvz_kinematic * dvz_kinematic * inverse_dt


def load_compiled_kernels() -> None:
    """Compile the fusion's compiled functions, or load them from the cache, now: a node calls
    this at start-up so that no sensor message ever waits for the compiler (up to 2 s on the
    first run after an install or a change of their source)."""
    with _stop_signals_held():
        _run_compiled_kernels()


@contextlib.contextmanager
def _stop_signals_held():
    """Hold SIGINT and SIGTERM until the block ends, then deliver them to the handlers they had.

    An exception raised inside numba's compiler or cache loader (a tool's signal handler raises
    KeyboardInterrupt) leaves its code library half-built: the process then fails on a later
    call or crashes at exit instead of stopping cleanly. Python runs signal handlers in the main
    thread only, so elsewhere there is nothing to hold."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    held, previous = [], {}
    for number in (signal.SIGINT, signal.SIGTERM):
        handler = signal.getsignal(number)
        if handler is not None:  # None: installed outside Python, cannot be put back
            previous[number] = signal.signal(number, lambda caught, _frame: held.append(caught))
    try:
        yield
    finally:
        for number, handler in previous.items():
            signal.signal(number, handler)
        for number in held:
            signal.raise_signal(number)


def _run_compiled_kernels() -> None:
    integrator = StrapdownIntegrator((0.0, 0.0, 0.0, 1.0), (0.0, 0.0, 0.0), 0.0, 0.0, 0.0)
    integrator.step(0.01, (0.0, 0.0, 0.0), (0.0, 0.0, 0.0), (0.0, 0.0, 9.8), (0.0, 0.0, 9.8))
    discrete_error_model(
        integrator.take_propagation_sums(),
        0.0,
        0.0,
        (0.0, 0.0, 0.0),
        ImuErrorModel.from_config(FusionConfig()),
    )


def interpolate_sample(
    t_s: float, t_start: float, start, t_end: float, end, t_older=None, older=None
):
    """IMU sample (3 floats) at ``t_s`` within [t_start, t_end], for splitting a step there.

    With the sample before ``start`` (``t_older``, ``older``) it is read off the parabola through
    the three samples, the same parabola the integrator integrates over the step, so the two
    sub-steps add up to the unsplit step; without it, linear interpolation.
    """
    if older is None:
        fraction = (t_s - t_start) / (t_end - t_start)
        return tuple(a + (b - a) * fraction for a, b in zip(start, end, strict=True))
    w_older = (t_s - t_start) * (t_s - t_end) / ((t_older - t_start) * (t_older - t_end))
    w_start = (t_s - t_older) * (t_s - t_end) / ((t_start - t_older) * (t_start - t_end))
    w_end = (t_s - t_older) * (t_s - t_start) / ((t_end - t_older) * (t_end - t_start))
    return tuple(
        w_older * a + w_start * b + w_end * c for a, b, c in zip(older, start, end, strict=True)
    )


def _floats(values) -> tuple[float, ...]:
    return tuple(map(float, values))  # a sequence or array of numbers as Python floats
