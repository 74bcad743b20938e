"""The compiled strapdown step: the layout of the integrator's state vector, and one step on it
in place (the algorithm is in the docstring of :mod:`buoy_nav.mechanization`).

The step is compiled (numba, cached on disk): at twice the IMU rate the interpreter's cost per
operation would otherwise dominate the offline run. Each stage of the step is a function of its
own, on scalars, inlined into the one compiled step (compiled apart, they would double the time
of the first compilation).
"""

import math

import numba

from buoy_nav import earth
from buoy_nav.rotations import (
    normalize_quaternion,
    quaternion_from_rotation_vector,
    quaternion_multiply,
    rotation_matrix_elements,
)

_OMEGA = earth.EARTH_RATE_RAD_S

# Layout of the integrator's state vector (one float64 array, so that the compiled step reads and
# writes it in place), by where each block starts and, after the colon, how long it is: the
# nominal state, the previous step for the curvature, coning and sculling terms, and the
# propagation sums.
ATTITUDE = 0  # 4: quaternion x, y, z, w of R_nb
ROTATION = 4  # 9: R_nb, row-major
VELOCITY = 13  # 3: ENU, m/s
LATITUDE, LONGITUDE, ALTITUDE = 16, 17, 18  # rad, rad, m
GYRO_BIAS = 19  # 3: rad/s, body
ACCEL_BIAS = 22  # 3: m/s², body
NAV_FRAME_RATE = 25  # 3: ω_in, ENU, rad/s
PREVIOUS_DT = 28  # s; 0 when there is no previous step
PREVIOUS_DTHETA = 29  # 3: body angle increment of the previous step (rad)
PREVIOUS_DVEL = 32  # 3: body velocity increment of the previous step (m/s)
OLDER_GYRO = 35  # 3: raw sample at the previous step's start (rad/s)
OLDER_FORCE = 38  # 3: (m/s²)
DURATION = 41  # s integrated since the last take_propagation_sums; the sums follow it
ROTATION_SUM = 42  # 9: ∫ R_nb dt, row-major
FORCE_SUM = 51  # 3: ∫ f^n dt
RATE_SQ_SUM = 54  # 3
FORCE_DEVIATION_SQ_SUM = 57  # 3
STATE_SIZE = 60


# The Earth-model and rotation functions the step calls, compiled from their one source.
_normal_gravity_mps2 = numba.njit(cache=True)(earth.normal_gravity_mps2)
_quaternion_from_rotation_vector = numba.njit(cache=True)(quaternion_from_rotation_vector)
_quaternion_multiply = numba.njit(cache=True)(quaternion_multiply)
_normalize_quaternion = numba.njit(cache=True)(normalize_quaternion)
_rotation_matrix_elements = numba.njit(cache=True)(rotation_matrix_elements)
_radii_of_curvature_m = numba.njit(cache=True)(earth.radii_of_curvature_m)

# Blocks of the error state as :data:`buoy_nav.error_state_filter.ERROR_STATES` orders them
# (that module checks the two agree): attitude, velocity, position (ENU), gyro and
# accelerometer bias (body), three each.
ERROR_ATTITUDE, ERROR_VELOCITY, ERROR_POSITION, ERROR_GYRO_BIAS, ERROR_ACCEL_BIAS = 0, 3, 6, 9, 12


@numba.njit(cache=True)
def store_nominal(state, x, y, z, w):
    """Store the attitude quaternion (x, y, z, w) normalised, with its R_nb, and ω_in from the
    state's velocity and position (earth.navigation_frame_rate_enu_rad_s, the same arithmetic),
    after the nominal state was set other than by a step."""
    x, y, z, w = _normalize_quaternion((x, y, z, w))
    state[ATTITUDE], state[ATTITUDE + 1], state[ATTITUDE + 2], state[ATTITUDE + 3] = x, y, z, w
    elements = _rotation_matrix_elements(x, y, z, w)
    for i in range(9):
        state[ROTATION + i] = elements[i]
    ve, vn = state[VELOCITY], state[VELOCITY + 1]
    lat, alt = state[LATITUDE], state[ALTITUDE]
    meridian, prime_vertical = _radii_of_curvature_m(lat)
    east_radius = prime_vertical + alt
    state[NAV_FRAME_RATE] = 0.0 + -vn / (meridian + alt)
    state[NAV_FRAME_RATE + 1] = _OMEGA * math.cos(lat) + ve / east_radius
    state[NAV_FRAME_RATE + 2] = _OMEGA * math.sin(lat) + ve * math.tan(lat) / east_radius


@numba.njit(cache=True)
def inject_error_state(state, error):
    """Apply the error state ``error`` to the nominal state in ``state`` in place: THE
    error-injection convention (see :mod:`buoy_nav.error_state_filter`). R_true = Exp([φ×]) R,
    v += δv, the position moved by δp (ENU m: Δlat = δp_N / (R_M + h), Δlon = δp_E /
    ((R_N + h) cos lat), Δh = δp_U), both biases += δb."""
    rotation = _quaternion_from_rotation_vector(
        error[ERROR_ATTITUDE], error[ERROR_ATTITUDE + 1], error[ERROR_ATTITUDE + 2]
    )
    attitude = (
        state[ATTITUDE],
        state[ATTITUDE + 1],
        state[ATTITUDE + 2],
        state[ATTITUDE + 3],
    )
    x, y, z, w = _normalize_quaternion(_quaternion_multiply(rotation, attitude))
    lat, alt = state[LATITUDE], state[ALTITUDE]
    meridian, prime_vertical = _radii_of_curvature_m(lat)
    east, north, up = error[ERROR_POSITION], error[ERROR_POSITION + 1], error[ERROR_POSITION + 2]
    state[LATITUDE] = lat + north / (meridian + alt)
    state[LONGITUDE] += east / ((prime_vertical + alt) * math.cos(lat))
    state[ALTITUDE] = alt + up
    for i in range(3):
        state[VELOCITY + i] += error[ERROR_VELOCITY + i]
        state[GYRO_BIAS + i] += error[ERROR_GYRO_BIAS + i]
        state[ACCEL_BIAS + i] += error[ERROR_ACCEL_BIAS + i]
    store_nominal(state, x, y, z, w)


@numba.njit(cache=True)
def strapdown_step(
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
    """Advance ``state`` (the layout above) in place by ``dt_s`` (s) between the raw IMU samples
    (g0…, f0…) and (g1…, f1…) (body: rad/s, m/s²); the coning and sculling corrections when
    asked for."""
    dthx, dthy, dthz, dvx, dvy, dvz, k = _increments(
        state, dt_s, g0x, g0y, g0z, g1x, g1y, g1z, f0x, f0y, f0z, f1x, f1y, f1z
    )
    rvx, rvy, rvz, bvx, bvy, bvz = _compensated_increments(
        state, k, dthx, dthy, dthz, dvx, dvy, dvz, coning_correction, sculling_correction
    )
    _remember_step(state, dt_s, dthx, dthy, dthz, dvx, dvy, dvz, g0x, g0y, g0z, f0x, f0y, f0z)
    north_radius, east_radius, cos_lat, gravity, wie_n, wie_u, win_e, win_n, win_u = _earth_model(
        state
    )
    fne, fnn, fnu = _update_velocity_and_position(
        state,
        dt_s,
        bvx,
        bvy,
        bvz,
        north_radius,
        east_radius,
        cos_lat,
        gravity,
        wie_n,
        wie_u,
        win_e,
        win_n,
        win_u,
    )
    x, y, z, w = _updated_attitude(state, dt_s, rvx, rvy, rvz, win_e, win_n, win_u)
    _store_attitude(state, 0.5 * dt_s, x, y, z, w)
    _accumulate_sums(state, dt_s, fne, fnn, fnu, dthx, dthy, dthz, dvx, dvy, dvz, gravity)


@numba.njit(inline="always")
def _increments(state, dt_s, g0x, g0y, g0z, g1x, g1y, g1z, f0x, f0y, f0z, f1x, f1y, f1z):
    """(Δθ body rad, Δv body m/s, k): the bias-corrected increments of the step, integrated on
    the parabola through the older, start and end samples (the trapezoid on the first step),
    and the factor k of the curvature and correction terms (0 on the first step)."""
    bgx, bgy, bgz = state[GYRO_BIAS], state[GYRO_BIAS + 1], state[GYRO_BIAS + 2]
    bax, bay, baz = (
        state[ACCEL_BIAS],
        state[ACCEL_BIAS + 1],
        state[ACCEL_BIAS + 2],
    )
    half_dt = 0.5 * dt_s
    dthx = (g0x + g1x - 2.0 * bgx) * half_dt
    dthy = (g0y + g1y - 2.0 * bgy) * half_dt
    dthz = (g0z + g1z - 2.0 * bgz) * half_dt
    dvx = (f0x + f1x - 2.0 * bax) * half_dt
    dvy = (f0y + f1y - 2.0 * bay) * half_dt
    dvz = (f0z + f1z - 2.0 * baz) * half_dt
    previous_dt = state[PREVIOUS_DT]
    k = 0.0
    if previous_dt > 0.0:
        k = dt_s * dt_s / (6.0 * previous_dt * (previous_dt + dt_s))
        # Curvature of the parabola through the older, start and end samples.
        ogx, ogy, ogz = (
            state[OLDER_GYRO],
            state[OLDER_GYRO + 1],
            state[OLDER_GYRO + 2],
        )
        ofx, ofy, ofz = (
            state[OLDER_FORCE],
            state[OLDER_FORCE + 1],
            state[OLDER_FORCE + 2],
        )
        dthx -= k * ((g1x - g0x) * previous_dt + (ogx - g0x) * dt_s)
        dthy -= k * ((g1y - g0y) * previous_dt + (ogy - g0y) * dt_s)
        dthz -= k * ((g1z - g0z) * previous_dt + (ogz - g0z) * dt_s)
        dvx -= k * ((f1x - f0x) * previous_dt + (ofx - f0x) * dt_s)
        dvy -= k * ((f1y - f0y) * previous_dt + (ofy - f0y) * dt_s)
        dvz -= k * ((f1z - f0z) * previous_dt + (ofz - f0z) * dt_s)
    return dthx, dthy, dthz, dvx, dvy, dvz, k


@numba.njit(inline="always")
def _compensated_increments(
    state, k, dthx, dthy, dthz, dvx, dvy, dvz, coning_correction, sculling_correction
):
    """(body rotation vector rad, body velocity increment m/s) in the start-of-step body frame:
    the increments with the rotation of the body during the step, and the coning and sculling
    corrections from the previous step's increments."""
    rvx, rvy, rvz = dthx, dthy, dthz
    # Rotation of the body during the step: ½ Δθ × Δv + ⅙ Δθ × (Δθ × Δv), the series of
    # ∫ Exp([ωt×]) f dt to third order (the third term matters for fast rolls).
    cx = dthy * dvz - dthz * dvy
    cy = dthz * dvx - dthx * dvz
    cz = dthx * dvy - dthy * dvx
    bvx = dvx + 0.5 * cx + (dthy * cz - dthz * cy) / 6.0
    bvy = dvy + 0.5 * cy + (dthz * cx - dthx * cz) / 6.0
    bvz = dvz + 0.5 * cz + (dthx * cy - dthy * cx) / 6.0
    if state[PREVIOUS_DT] > 0.0:
        px, py, pz = (
            state[PREVIOUS_DTHETA],
            state[PREVIOUS_DTHETA + 1],
            state[PREVIOUS_DTHETA + 2],
        )
        if coning_correction:
            rvx += k * (py * dthz - pz * dthy)
            rvy += k * (pz * dthx - px * dthz)
            rvz += k * (px * dthy - py * dthx)
        if sculling_correction:
            ux, uy, uz = (
                state[PREVIOUS_DVEL],
                state[PREVIOUS_DVEL + 1],
                state[PREVIOUS_DVEL + 2],
            )
            bvx += k * (py * dvz - pz * dvy + uy * dthz - uz * dthy)
            bvy += k * (pz * dvx - px * dvz + uz * dthx - ux * dthz)
            bvz += k * (px * dvy - py * dvx + ux * dthy - uy * dthx)
    return rvx, rvy, rvz, bvx, bvy, bvz


@numba.njit(inline="always")
def _remember_step(state, dt_s, dthx, dthy, dthz, dvx, dvy, dvz, g0x, g0y, g0z, f0x, f0y, f0z):
    """Keep what the next step's curvature, coning and sculling terms need: this step's length
    (s), increments (rad, m/s) and start samples (rad/s, m/s²)."""
    state[PREVIOUS_DT] = dt_s
    (
        state[PREVIOUS_DTHETA],
        state[PREVIOUS_DTHETA + 1],
        state[PREVIOUS_DTHETA + 2],
    ) = dthx, dthy, dthz
    (
        state[PREVIOUS_DVEL],
        state[PREVIOUS_DVEL + 1],
        state[PREVIOUS_DVEL + 2],
    ) = dvx, dvy, dvz
    state[OLDER_GYRO], state[OLDER_GYRO + 1], state[OLDER_GYRO + 2] = (
        g0x,
        g0y,
        g0z,
    )
    state[OLDER_FORCE], state[OLDER_FORCE + 1], state[OLDER_FORCE + 2] = (
        f0x,
        f0y,
        f0z,
    )


@numba.njit(inline="always")
def _earth_model(state):
    """The Earth at the start-of-step position: radii of curvature (north, east; m), cos of the
    latitude, normal gravity (m/s²), Earth rate (north, up) and ω_in (ENU) (rad/s); ω_in is
    stored as the navigation-frame rate."""
    lat = state[LATITUDE]
    alt = state[ALTITUDE]
    ve, vn = state[VELOCITY], state[VELOCITY + 1]
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
        state[NAV_FRAME_RATE],
        state[NAV_FRAME_RATE + 1],
        state[NAV_FRAME_RATE + 2],
    ) = win_e, win_n, win_u
    return north_radius, east_radius, cos_lat, gravity, wie_n, wie_u, win_e, win_n, win_u


@numba.njit(inline="always")
def _update_velocity_and_position(
    state,
    dt_s,
    bvx,
    bvy,
    bvz,
    north_radius,
    east_radius,
    cos_lat,
    gravity,
    wie_n,
    wie_u,
    win_e,
    win_n,
    win_u,
):
    """Velocity and position at the end of the step from the body velocity increment (m/s) and
    the Earth model of :func:`_earth_model`; returns the specific-force velocity increment in
    ENU (m/s)."""
    half_dt = 0.5 * dt_s
    lat = state[LATITUDE]
    alt = state[ALTITUDE]
    ve, vn, vu = state[VELOCITY], state[VELOCITY + 1], state[VELOCITY + 2]
    # Specific-force velocity increment in ENU (start attitude, half the frame rotation).
    r00, r01, r02 = state[ROTATION], state[ROTATION + 1], state[ROTATION + 2]
    r10, r11, r12 = state[ROTATION + 3], state[ROTATION + 4], state[ROTATION + 5]
    r20, r21, r22 = state[ROTATION + 6], state[ROTATION + 7], state[ROTATION + 8]
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

    state[LATITUDE] = lat + (vn + new_vn) * half_dt / north_radius
    state[LONGITUDE] += (ve + new_ve) * half_dt / (east_radius * cos_lat)
    state[ALTITUDE] = alt + (vu + new_vu) * half_dt
    state[VELOCITY], state[VELOCITY + 1], state[VELOCITY + 2] = (
        new_ve,
        new_vn,
        new_vu,
    )
    return fne, fnn, fnu


@numba.njit(inline="always")
def _updated_attitude(state, dt_s, rvx, rvy, rvz, win_e, win_n, win_u):
    """The unit quaternion (x, y, z, w; w ≥ 0) of R_nb(k) = Exp(−ω_in T) · R_nb(k−1) · Exp(φ_k)
    from the body rotation vector φ_k (rad) and ω_in (ENU, rad/s)."""
    bx, by, bz, bw = _quaternion_from_rotation_vector(rvx, rvy, rvz)
    nx, ny, nz, nw = _quaternion_from_rotation_vector(-win_e * dt_s, -win_n * dt_s, -win_u * dt_s)
    ax, ay, az, aw = (
        state[ATTITUDE],
        state[ATTITUDE + 1],
        state[ATTITUDE + 2],
        state[ATTITUDE + 3],
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
    return ax / norm, ay / norm, az / norm, aw / norm


@numba.njit(inline="always")
def _store_attitude(state, half_dt, x, y, z, w):
    """Store the new attitude quaternion and its R_nb, and add the trapezoid of R_nb over the
    step (``half_dt``: half its length, s) to ∫ R_nb dt."""
    (
        state[ATTITUDE],
        state[ATTITUDE + 1],
        state[ATTITUDE + 2],
        state[ATTITUDE + 3],
    ) = x, y, z, w
    r00, r01, r02 = state[ROTATION], state[ROTATION + 1], state[ROTATION + 2]
    r10, r11, r12 = state[ROTATION + 3], state[ROTATION + 4], state[ROTATION + 5]
    r20, r21, r22 = state[ROTATION + 6], state[ROTATION + 7], state[ROTATION + 8]
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
    state[ROTATION], state[ROTATION + 1], state[ROTATION + 2] = n00, n01, n02
    state[ROTATION + 3], state[ROTATION + 4], state[ROTATION + 5] = n10, n11, n12
    state[ROTATION + 6], state[ROTATION + 7], state[ROTATION + 8] = n20, n21, n22
    state[ROTATION_SUM] += (r00 + n00) * half_dt
    state[ROTATION_SUM + 1] += (r01 + n01) * half_dt
    state[ROTATION_SUM + 2] += (r02 + n02) * half_dt
    state[ROTATION_SUM + 3] += (r10 + n10) * half_dt
    state[ROTATION_SUM + 4] += (r11 + n11) * half_dt
    state[ROTATION_SUM + 5] += (r12 + n12) * half_dt
    state[ROTATION_SUM + 6] += (r20 + n20) * half_dt
    state[ROTATION_SUM + 7] += (r21 + n21) * half_dt
    state[ROTATION_SUM + 8] += (r22 + n22) * half_dt


@numba.njit(inline="always")
def _accumulate_sums(state, dt_s, fne, fnn, fnu, dthx, dthy, dthz, dvx, dvy, dvz, gravity):
    """Add the step to the integrals of the covariance propagation: its length (s), the ENU
    specific-force increment (m/s), and the squared rates and specific-force deviations from
    the body increments (rad, m/s) and gravity (m/s²)."""
    state[DURATION] += dt_s
    state[FORCE_SUM] += fne
    state[FORCE_SUM + 1] += fnn
    state[FORCE_SUM + 2] += fnu
    inverse_dt = 1.0 / dt_s
    state[RATE_SQ_SUM] += dthx * dthx * inverse_dt
    state[RATE_SQ_SUM + 1] += dthy * dthy * inverse_dt
    state[RATE_SQ_SUM + 2] += dthz * dthz * inverse_dt
    dvz_kinematic = dvz - gravity * dt_s
    state[FORCE_DEVIATION_SQ_SUM] += dvx * dvx * inverse_dt
    state[FORCE_DEVIATION_SQ_SUM + 1] += dvy * dvy * inverse_dt
    state[FORCE_DEVIATION_SQ_SUM + 2] += dvz_kinematic * dvz_kinematic * inverse_dt
