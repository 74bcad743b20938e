"""The motion pack's attitude in a compiled stretch of IMU samples (:mod:`buoy_nav.imu_stretch`).

A motion pack's attitude (:mod:`buoy_nav.aiding.ahrs_attitude`) comes with every IMU sample. In
a stretch it is queued as the engine queues a measurement in its sequence
(:func:`~buoy_nav.sequence_kernels.queued_in_sequence`), and when the filter reaches its stamp
its epoch is made with the engine's own kernels in the engine's order (:func:`pack_epoch`): the
step there with the covariance's propagation, the pack's compiled update, the injection of the
correction and its carry-over to the prediction. It returns False, with nothing changed, where
the engine must take over. The arrays it reads and writes are laid out below.
"""

import math
from typing import NamedTuple

import numba
import numpy as np

from buoy_nav.aiding.ahrs_attitude import attitude_update
from buoy_nav.epoch_kernels import corrected, stepped_to
from buoy_nav.strapdown_kernel import (
    GYRO_BIAS,
    LATITUDE,
    LONGITUDE,
)

# The motion pack's attitudes a stretch takes (the stretch's ``pack_rows``, one row each, those
# already queued first): stamp (s), the pack's attitude on true north (R_nb, 3×3 row-major), its
# covariance (3×3 ENU rad², row-major) and the sample's weight.
PACK_T, PACK_ROTATION, PACK_COVARIANCE, PACK_WEIGHT = 0, 1, 10, 19
PACK_ROW_SIZE = 20
# The pack's update and what it stops at (``pack_terms``): the lag (s) and its uncertainty
# squared (s²), the variance floor (rad²), the gate's threshold, the error states' attitude
# start, and the latitude and longitude (rad) between which the pack's true north is the one its
# rows were turned to.
(LAG, LAG_UNCERTAINTY_SQ, FLOOR, THRESHOLD, ATTITUDE_START) = range(5)
LATITUDE_LOW, LATITUDE_HIGH, LONGITUDE_LOW, LONGITUDE_HIGH = range(5, 9)
PACK_TERMS_SIZE = 9


class PackArguments(NamedTuple):
    """The arrays a stretch hands the pack's epochs (laid out above and below): its attitudes'
    rows, its sequence (:mod:`buoy_nav.sequence_kernels`), its terms, the update's Jacobian (3 ×
    error states, written in place) and room for the epochs' books."""

    rows: np.ndarray
    sequence: np.ndarray
    terms: np.ndarray
    jacobian: np.ndarray
    epochs: np.ndarray


# The epochs of the pack's attitude a stretch applied (``epochs``, a row each): stamp (s), the
# innovation (rad, 3), its NIS and S (3×3 rad², row-major), for the books.
EPOCH_T, EPOCH_INNOVATION, EPOCH_NIS, EPOCH_S = 0, 1, 4, 5
EPOCH_SIZE = 14


@numba.njit(cache=True)
def pack_epoch(
    row,
    point,
    due,
    filter_state,
    coning,
    sculling,
    covariance,
    noise_terms,
    pack_terms,
    jacobian,
    ahead_state,
    ahead_t,
    carried,
    epoch,
) -> bool:
    """The epoch of the pack's attitude ``row`` at the IMU sample ``due``, as the engine makes
    it: the filter's step there from ``point`` with the covariance's propagation, the pack's
    compiled update and, when its gate passes and the covariance after it is positive
    definite, the injection into ``filter_state``, the new ``covariance`` and (when
    ``carried``) the correction carried over to the prediction (``ahead_state``, at ``ahead_t``
    s), the gate into ``epoch``. False, with nothing changed, when the engine is to make it (the
    gate fails, the covariance needs a repair, the filter left the true north's cell)."""
    t = due[0]
    stepped, prior = stepped_to(point, due, filter_state, coning, sculling, covariance, noise_terms)
    latitude, longitude = stepped[LATITUDE], stepped[LONGITUDE]
    if not (
        pack_terms[LATITUDE_LOW] < latitude < pack_terms[LATITUDE_HIGH]
        and pack_terms[LONGITUDE_LOW] < longitude < pack_terms[LONGITUDE_HIGH]
    ):
        return False
    rate_x = due[1] - stepped[GYRO_BIAS]
    rate_y = due[2] - stepped[GYRO_BIAS + 1]
    rate_z = due[3] - stepped[GYRO_BIAS + 2]
    square = 2.0 + 0.0 * t  # a run-time exponent: the C library's pow, as the interpreter's
    lag_variance = (
        math.pow(rate_x, square) + math.pow(rate_y, square) + math.pow(rate_z, square)
    ) * pack_terms[LAG_UNCERTAINTY_SQ]
    innovation, nis, innovation_covariance, accepted, updated, correction, positive = (
        attitude_update(
            prior,
            stepped,
            row[PACK_ROTATION : PACK_ROTATION + 9].reshape(3, 3).copy(),
            rate_x,
            rate_y,
            rate_z,
            pack_terms[LAG],
            row[PACK_COVARIANCE : PACK_COVARIANCE + 9].reshape(3, 3).copy(),
            pack_terms[FLOOR],
            lag_variance,
            row[PACK_WEIGHT],
            jacobian,
            pack_terms[THRESHOLD],
            int(pack_terms[ATTITUDE_START]),
        )
    )
    if not (accepted and positive):
        return False
    corrected(
        filter_state, stepped, correction, covariance, updated, ahead_state, ahead_t, t, carried
    )
    epoch[EPOCH_T] = t
    epoch[EPOCH_INNOVATION : EPOCH_INNOVATION + 3] = innovation
    epoch[EPOCH_NIS] = nis
    epoch[EPOCH_S : EPOCH_S + 9] = innovation_covariance.reshape(9)
    return True
