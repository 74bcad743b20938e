"""The mooring's constraint in a compiled stretch of IMU samples (:mod:`buoy_nav.imu_stretch`).

A moored buoy's position is held to its slow mean once every ``moored_update_period_s``
(:mod:`buoy_nav.aiding.moored`). In a stretch, when the filter reaches the first IMU sample at
or after the constraint's due stamp, :func:`mooring_epoch` makes its epoch as the engine makes
it (``FusionEngine._apply_pseudo_measurements``): the anchor moved toward the filter's position,
the covariance propagated over the samples integrated since the last propagation, the anchor's
compiled model, its gate and update, the injection of the correction and its carry-over to the
prediction. It keeps the books the engine then keeps from what it used (the velocity and its
covariance for the mean velocity's watches, the anchor, the gate).

It returns False, with nothing changed, where the engine must make the epoch: the gate fails,
the covariance needs a repair, a block of the mean velocity's watches closes (their verdict may
change the process noise), or the mooring's innovations may have begun to widen its σ. The last
is judged as :class:`~buoy_nav.aiding.moored.InnovationWatch` judges it, on the normalised
squares of the window's horizontal innovations at the stated σ, with a margin far above the
rounding of the two formulations: an epoch the kernel makes never meets a σ the watch would
have widened.
"""

import math
from typing import NamedTuple

import numba
import numpy as np

from buoy_nav.aiding.model_kernels import enu_offset
from buoy_nav.aiding.moored import anchor_model
from buoy_nav.epoch_kernels import corrected
from buoy_nav.error_dynamics import propagated_covariance_kernel
from buoy_nav.kalman_kernel import gated_stacked_update
from buoy_nav.strapdown_kernel import ALTITUDE, DURATION, LATITUDE, LONGITUDE, VELOCITY

# The mooring's terms (``terms``): the anchor's time constant (s), the constraint's period (s),
# its gate's threshold (three dimensions), the factor on its horizontal variance, its stated
# horizontal variance (m²), the innovations' window (s) and the span of it they must cover to be
# judged (s), the largest square of their normalised RMS that surely leaves the σ unwidened, the
# blocks of the two mean-velocity watches (s), and where the error states' position, velocity
# and attitude begin.
(TIME_CONSTANT, PERIOD, THRESHOLD, VARIANCE_SCALE, HORIZONTAL_VARIANCE) = range(5)
(WINDOW, MIN_SPAN, RATIO_SQ_LIMIT, DRIFT_BLOCK, NOISE_BLOCK) = range(5, 10)
(POSITION_START, VELOCITY_START, ATTITUDE_START) = range(10, 13)
TERMS_SIZE = 13
# What the epochs move (``state``): the anchor (rad, rad, m) and its stamp (s), whether the
# innovations leave the σ as stated (1.0) or may widen it (0.0), and the start of each watch's
# block in progress (s, NaN: none).
ANCHOR, ANCHOR_T, QUIET, DRIFT_BLOCK_START, NOISE_BLOCK_START = 0, 3, 4, 5, 6
STATE_SIZE = 7
# The books of an epoch (``books``, a row each): its stamp (s), the filter's velocity (ENU m/s)
# and that velocity's covariance (3×3 m²/s², row-major) before the epoch, the anchor (rad, rad,
# m), the innovation (m, ENU), its S (3×3 m², row-major) and NIS.
BOOK_T, BOOK_VELOCITY, BOOK_VELOCITY_COVARIANCE, BOOK_ANCHOR = 0, 1, 4, 13
BOOK_INNOVATION, BOOK_S, BOOK_NIS = 16, 19, 28
BOOK_SIZE = 29
MARGIN = 1e-9
"""Share by which the kernel's judgement of the innovations' RMS errs on the side of the
engine: their rounding differs by some 1e-15."""


class MooringArguments(NamedTuple):
    """The arrays a stretch hands the mooring's epochs (laid out above): its terms, its stated
    covariance (3×3 m², ENU), its state, the stamps (s) of the innovations' window and their
    normalised squares (room for the new ones after), and room for the epochs' books (none:
    the stretch stops at the constraint)."""

    terms: np.ndarray
    covariance: np.ndarray
    state: np.ndarray
    window_stamps: np.ndarray
    window_squares: np.ndarray
    books: np.ndarray


@numba.njit(cache=True)
def mooring_epoch(
    t, filter_state, covariance, noise_terms, ahead_state, ahead_t, carried, mooring, window, book
) -> bool:
    """The mooring's epoch at the IMU sample stamped ``t`` (s), the filter (``filter_state``)
    already there, as the engine makes it: the anchor moved, the ``covariance`` propagated with
    the process noise's ``noise_terms`` when samples were integrated since, the model, gate and
    update and, when the gate passes and the covariance after it is positive definite, the
    injection, the new covariance, (when ``carried``) the correction carried over to the
    prediction (``ahead_state``, at ``ahead_t`` s), the ``mooring``'s state moved, the window's
    bounds (``window``: its first and past-last index) and the ``book`` written. False, with
    nothing changed, when the engine is to make it (see the module docstring)."""
    terms, state = mooring.terms, mooring.state
    if state[QUIET] == 0.0 or _block_closes(state, terms, t):
        return False
    weight = -math.expm1(-(t - state[ANCHOR_T]) / terms[TIME_CONSTANT])
    anchor = np.empty(3)
    for i in range(3):
        anchor[i] = state[ANCHOR + i] + weight * (filter_state[LATITUDE + i] - state[ANCHOR + i])
    offset = enu_offset(
        filter_state[LATITUDE],
        filter_state[LONGITUDE],
        filter_state[ALTITUDE],
        anchor[0],
        anchor[1],
        anchor[2],
    )
    _, innovation, jacobian, measurement_covariance = anchor_model(
        np.array(offset),
        mooring.covariance,
        terms[VARIANCE_SCALE],
        int(terms[POSITION_START]),
        covariance.shape[0],
    )
    stepped = filter_state.copy()
    prior = covariance
    if stepped[DURATION] > 0.0:
        _, prior = propagated_covariance_kernel(stepped, covariance, noise_terms)
    nis, innovation_covariance, accepted, updated, correction, positive = gated_stacked_update(
        prior,
        innovation,
        jacobian,
        measurement_covariance,
        np.array((3,)),
        np.array((terms[THRESHOLD],)),
        int(terms[ATTITUDE_START]),
        np.zeros((0, 0)),
    )
    if not (accepted and positive):
        return False
    _write_book(book, t, filter_state, covariance, terms, anchor, innovation, innovation_covariance)
    book[BOOK_NIS] = nis[0]
    corrected(
        filter_state, stepped, correction, covariance, updated, ahead_state, ahead_t, t, carried
    )
    _moved(state, terms, t, anchor)
    judged(mooring, window, t, innovation, innovation_covariance)
    return True


@numba.njit(cache=True)
def _block_closes(state, terms, t) -> bool:
    """Whether a mean-velocity watch's block in progress closes at ``t`` (s)."""
    for start, length in (
        (state[DRIFT_BLOCK_START], terms[DRIFT_BLOCK]),
        (state[NOISE_BLOCK_START], terms[NOISE_BLOCK]),
    ):
        if not math.isnan(start) and t - start >= length:
            return True
    return False


@numba.njit(cache=True)
def _write_book(
    book, t, filter_state, covariance, terms, anchor, innovation, innovation_covariance
):
    """The epoch's books but its NIS: what the engine's watches and gate book take."""
    velocity = int(terms[VELOCITY_START])
    book[BOOK_T] = t
    for i in range(3):
        book[BOOK_VELOCITY + i] = filter_state[VELOCITY + i]
        book[BOOK_ANCHOR + i] = anchor[i]
        book[BOOK_INNOVATION + i] = innovation[i]
        for j in range(3):
            book[BOOK_VELOCITY_COVARIANCE + 3 * i + j] = covariance[velocity + i, velocity + j]
            book[BOOK_S + 3 * i + j] = innovation_covariance[i, j]


@numba.njit(cache=True)
def _moved(state, terms, t, anchor) -> None:
    """The mooring's state after its epoch at ``t`` (s): the new ``anchor``, the watches'
    blocks begun."""
    state[ANCHOR : ANCHOR + 3] = anchor
    state[ANCHOR_T] = t
    for block_start in (DRIFT_BLOCK_START, NOISE_BLOCK_START):
        if math.isnan(state[block_start]):
            state[block_start] = t


@numba.njit(cache=True)
def judged(mooring, window, t, innovation, innovation_covariance) -> None:
    """The horizontal innovation's normalised square at the stated σ added to the window (the
    ``mooring``'s, ``window`` its bounds) and the window judged: no longer quiet once the
    squares' mean could reach :data:`RATIO_SQ_LIMIT`."""
    terms = mooring.terms
    stated = terms[HORIZONTAL_VARIANCE]
    # The filter's part of S, with the σ the watch judges at instead of the one fused.
    shift = stated - terms[VARIANCE_SCALE] * stated
    a = innovation_covariance[0, 0] + shift
    b = innovation_covariance[0, 1]
    d = innovation_covariance[1, 1] + shift
    east, north = innovation[0], innovation[1]
    square = (d * east * east - 2.0 * b * east * north + a * north * north) / (a * d - b * b)
    stamps, squares = mooring.window_stamps, mooring.window_squares
    end = window[1]
    stamps[end], squares[end] = t, square
    window[1] = end + 1
    while stamps[window[0]] < t - terms[WINDOW]:
        window[0] += 1
    if t - stamps[window[0]] < terms[MIN_SPAN]:
        return
    count = window[1] - window[0]
    if np.sum(squares[window[0] : window[1]]) > terms[RATIO_SQ_LIMIT] * 2.0 * count:
        mooring.state[QUIET] = 0.0
