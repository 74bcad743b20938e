"""What the epochs a compiled stretch makes share (:mod:`buoy_nav.aiding_epoch`,
:mod:`buoy_nav.mooring_epoch`), as the engine makes them: the filter's step to the epoch's IMU
sample with the covariance's propagation, and then the correction injected and carried over to
the prediction ahead (numba, cached on disk).
"""

import numba

from buoy_nav.error_dynamics import stepped_covariance_kernel
from buoy_nav.prediction import carry_over_kernel
from buoy_nav.strapdown_kernel import (
    ALTITUDE,
    LATITUDE,
    VELOCITY,
    inject_error_state,
)


@numba.njit(cache=True)
def stepped_to(point, due, filter_state, coning, sculling, covariance, noise_terms):
    """The filter's state (``filter_state``, at the (stamp s, gyro, force) sample ``point``)
    stepped to the IMU sample ``due`` with the ``coning`` and ``sculling`` corrections or not,
    and the ``covariance`` propagated there with the process noise's ``noise_terms``, both new
    arrays: (stepped state, prior covariance)."""
    stepped = filter_state.copy()
    _, prior = stepped_covariance_kernel(
        stepped,
        covariance,
        due[0] - point[0],
        (point[1], point[2], point[3], due[1], due[2], due[3]),
        (point[4], point[5], point[6], due[4], due[5], due[6]),
        (coning, sculling),
        (
            noise_terms[0],
            noise_terms[1],
            noise_terms[2],
            noise_terms[3],
            noise_terms[4],
            noise_terms[5],
            noise_terms[6],
        ),
    )
    return stepped, prior


@numba.njit(cache=True)
def corrected(
    filter_state, stepped, correction, covariance, updated, ahead_state, ahead_t, t, carried
):
    """The epoch at stamp ``t`` (s) taken: ``filter_state`` the ``stepped`` state with the
    ``correction`` injected, ``covariance`` the ``updated`` one, and, when ``carried``, the
    correction carried over to the prediction ahead (``ahead_state``, at ``ahead_t`` s) from
    the state it was linearised at (not when the prediction is forked afresh instead)."""
    filter_state[:] = stepped
    inject_error_state(filter_state, correction)
    covariance[:, :] = updated
    if not carried:
        return
    velocity = stepped[VELOCITY : VELOCITY + 3].copy()
    latitude, altitude = stepped[LATITUDE], stepped[ALTITUDE]
    carried_correction = correction.copy()
    span = ahead_t - t
    if span > 0.0:
        carry_over_kernel(ahead_state, velocity, latitude, altitude, span, carried_correction)
    inject_error_state(ahead_state, carried_correction)
