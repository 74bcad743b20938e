"""The mooring's constraint in a compiled stretch of IMU samples (:mod:`buoy_nav.imu_stretch`).

A moored buoy's position is held to its slow mean once every ``moored_update_period_s``
(:mod:`buoy_nav.aiding.moored`). In a stretch, when the filter reaches the first IMU sample at
or after the constraint's due stamp, :func:`mooring_epoch` makes its epoch as the engine makes
it (``FusionEngine._apply_pseudo_measurements``): the anchor moved toward the filter's position,
the covariance propagated over the samples integrated since the last propagation, the anchor's
compiled model, its gate and update, the injection of the correction and its carry-over to the
prediction. It keeps the books the engine then keeps from what it used (the velocity and its
covariance for the mean velocity's watches, the anchor, the gate).

Its watches are the engine's own compiled ones on the same windows: the innovation watch
(:func:`~buoy_nav.innovation_watch.watched`), whose σ widened or narrowed moves the next
epochs' noise in the stretch as it does in the engine, and the mean velocity's
(:func:`~buoy_nav.mean_velocity_watch.velocity_added`), whose blocks the stretch adds to and
closes.

It returns False, with nothing changed, where the engine must make the epoch: the gate fails,
the covariance needs a repair, a mean velocity's block closes with a verdict that widens or
narrows a process noise, or the innovation watch has something to say (a warning, or that one
no longer holds: the engine logs it).
"""

import math
from typing import NamedTuple

import numba
import numpy as np

from buoy_nav.aiding.model_kernels import enu_offset
from buoy_nav.aiding.moored import anchor_model
from buoy_nav.epoch_kernels import corrected
from buoy_nav.error_dynamics import propagated_covariance_kernel
from buoy_nav.innovation_watch import SAYS_NOTHING, SCALE, WatchArrays, unwatched, watched
from buoy_nav.kalman_kernel import gated_stacked_update
from buoy_nav.mean_velocity_watch import KEEPS, BlockArrays, unwatched_blocks, velocity_added
from buoy_nav.strapdown_kernel import ALTITUDE, DURATION, LATITUDE, LONGITUDE, VELOCITY

# The mooring's terms (``terms``): the anchor's time constant (s), the constraint's period (s),
# its gate's threshold (three dimensions), and where the error states' position, velocity and
# attitude begin.
TIME_CONSTANT, PERIOD, THRESHOLD, POSITION_START, VELOCITY_START, ATTITUDE_START = range(6)
TERMS_SIZE = 6
# What the epochs move (``state``) besides the watches: the anchor (rad, rad, m) and its stamp
# (s).
ANCHOR, ANCHOR_T = 0, 3
STATE_SIZE = 4
# The books of an epoch (``books``, a row each): its stamp (s), the filter's velocity (ENU m/s)
# and that velocity's covariance (3×3 m²/s², row-major) before the epoch, the anchor (rad, rad,
# m), the innovation (m, ENU), its S (3×3 m², row-major) and NIS.
BOOK_T, BOOK_VELOCITY, BOOK_VELOCITY_COVARIANCE, BOOK_ANCHOR = 0, 1, 4, 13
BOOK_INNOVATION, BOOK_S, BOOK_NIS = 16, 19, 28
BOOK_SIZE = 29


class MooringArguments(NamedTuple):
    """The arrays a stretch hands the mooring's epochs (laid out above): its terms, its stated
    covariance (3×3 m², ENU), its state, its innovation watch (its window from index 0, room
    for the new innovations after), the mean velocity's watches (a row each) and room for the
    epochs' books (none: the stretch stops at the constraint)."""

    terms: np.ndarray
    covariance: np.ndarray
    state: np.ndarray
    watch: WatchArrays
    velocity_watches: BlockArrays
    books: np.ndarray


def no_mooring() -> MooringArguments:
    """The arguments of a stretch that stops at the constraint: no room for its epochs."""
    return MooringArguments(
        np.zeros(TERMS_SIZE),
        np.zeros((3, 3)),
        np.zeros(STATE_SIZE),
        unwatched(),
        unwatched_blocks(),
        np.zeros((0, BOOK_SIZE)),
    )


@numba.njit(cache=True)
def mooring_epoch(
    t, filter_state, covariance, noise_terms, ahead_state, ahead_t, carried, mooring, window, book
) -> bool:
    """The mooring's epoch at the IMU sample stamped ``t`` (s), the filter (``filter_state``)
    already there, as the engine makes it: the anchor moved, the ``covariance`` propagated with
    the process noise's ``noise_terms`` when samples were integrated since, the model, gate and
    update and, when the gate passes, the covariance after it is positive definite and the
    innovation watch has nothing to say, the injection, the new covariance, (when ``carried``)
    the correction carried over to the prediction (``ahead_state``, at ``ahead_t`` s), the
    ``mooring``'s state and watch moved (``window``: the watch's first and past-last index) and
    the ``book`` written. False, with nothing changed, when the engine is to make it (see the
    module docstring)."""
    terms, state = mooring.terms, mooring.state
    kept, blocks, squares = _velocity_watched(
        mooring.velocity_watches, terms, t, filter_state, covariance
    )
    if not kept:
        return False
    anchor = _anchor_moved(state, terms, filter_state, t)
    offset = enu_offset(
        filter_state[LATITUDE],
        filter_state[LONGITUDE],
        filter_state[ALTITUDE],
        anchor[0],
        anchor[1],
        anchor[2],
    )
    scale = mooring.watch.status[SCALE]
    variance_scale = scale * scale
    _, innovation, jacobian, measurement_covariance = anchor_model(
        np.array(offset),
        mooring.covariance,
        variance_scale,
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
    says, watch_status, watch_window = _watch_tried(
        mooring.watch,
        window,
        t,
        innovation,
        innovation_covariance,
        variance_scale * mooring.covariance[0, 0],
    )
    if says != SAYS_NOTHING:
        return False
    _write_book(book, t, filter_state, covariance, terms, anchor, innovation, innovation_covariance)
    book[BOOK_NIS] = nis[0]
    corrected(
        filter_state, stepped, correction, covariance, updated, ahead_state, ahead_t, t, carried
    )
    state[ANCHOR : ANCHOR + 3] = anchor
    state[ANCHOR_T] = t
    mooring.watch.status[:] = watch_status
    window[:] = watch_window
    mooring.velocity_watches.block[:] = blocks
    mooring.velocity_watches.squares[:] = squares
    return True


@numba.njit(cache=True)
def _anchor_moved(state, terms, filter_state, t):
    """The anchor (rad, rad, m) moved toward the filter's position at ``t`` (s), with the
    anchor's time constant."""
    weight = -math.expm1(-(t - state[ANCHOR_T]) / terms[TIME_CONSTANT])
    anchor = np.empty(3)
    for i in range(3):
        anchor[i] = state[ANCHOR + i] + weight * (filter_state[LATITUDE + i] - state[ANCHOR + i])
    return anchor


@numba.njit(cache=True)
def _watch_tried(watch, window, t, innovation, innovation_covariance, fused_variance):
    """The innovation watch's verdict on the epoch's horizontal innovation (m, ENU), with the
    filter's part of its covariance (S less the ``fused_variance`` m² of the mooring's σ), tried
    on copies of its status and of the window's bounds (``window``): what it says, the status
    and the bounds. Its row is written past the window's end, where nothing reads it before the
    bounds move there."""
    filter_covariance = np.empty((2, 2))
    for i in range(2):
        for j in range(2):
            identity = 1.0 if i == j else 0.0
            filter_covariance[i, j] = innovation_covariance[i, j] - fused_variance * identity
    tried = WatchArrays(
        watch.terms, watch.status.copy(), watch.stamps, watch.projected, watch.eigenvalues
    )
    bounds = window.copy()
    says = watched(tried, bounds, t, innovation[:2].copy(), filter_covariance)
    return says, tried.status, bounds


@numba.njit(cache=True)
def _velocity_watched(watches, terms, t, filter_state, covariance):
    """The mean velocity's watches (``watches``, a row each) after the filter's velocity and
    its covariance at ``t`` (s), tried on copies of their blocks and windows: whether every
    closed block's verdict keeps the process noise as it is, and the blocks and windows."""
    blocks, squares = watches.block.copy(), watches.squares.copy()
    velocity = int(terms[VELOCITY_START])
    velocity_covariance = covariance[velocity : velocity + 2, velocity : velocity + 2].copy()
    for row in range(blocks.shape[0]):
        verdict, _ = velocity_added(
            watches.terms[row],
            blocks[row],
            squares[row],
            t,
            filter_state[VELOCITY : VELOCITY + 2],
            velocity_covariance,
        )
        if verdict != KEEPS:
            return False, blocks, squares
    return True, blocks, squares


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
