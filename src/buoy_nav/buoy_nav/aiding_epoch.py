"""The epoch of one stamp's aiding measurements in a compiled stretch of IMU samples
(:mod:`buoy_nav.imu_stretch`).

The motion pack, the magnetometer and the GNSS sources (fix, velocity, heading, antenna
baselines) each give their measurement function over arrays (``stretch_model``, in
:data:`MODELS`). In a stretch their measurements are queued as the engine queues them
(:func:`~buoy_nav.sequence_kernels.queued_in_sequence`), and when the filter reaches a stamp
that has some, :func:`aiding_epoch` makes its epoch as the engine makes it
(``FusionEngine._handle_measurements``): a measurement another of the stamp supersedes set
aside, the others in the sources' registry order, the step there with the covariance's
propagation, each one modelled and gated (with its own noise, as the magnetometer's field whose
calibration error its neighbours share) and all of them applied in one stacked update, the
correction injected and carried over to the prediction. That is the arithmetic of the engine's
compiled stacked update, of its interpreted gates and update, and of the pack's compiled update
for an attitude alone. It returns −1, with nothing changed, where the engine must make the
epoch itself: a model that does not hold, a gate that fails, a covariance to repair.

A source whose measurement function is not in :data:`MODELS` is not taken in stretches: its
measurements stop them and the engine applies them. The arrays are laid out below.
"""

from typing import NamedTuple

import numba
import numpy as np

from buoy_nav.aiding.ahrs_attitude import attitude_stretch_model
from buoy_nav.aiding.dual_antenna import baseline_stretch_model
from buoy_nav.aiding.gnss_fix import fix_stretch_model
from buoy_nav.aiding.gnss_heading import heading_stretch_model
from buoy_nav.aiding.gnss_velocity import velocity_stretch_model
from buoy_nav.aiding.magnetometer import magnetometer_stretch_model
from buoy_nav.epoch_kernels import corrected, stepped_to
from buoy_nav.kalman_kernel import gated_stacked_update
from buoy_nav.rotations import rotation_matrix_elements
from buoy_nav.strapdown_kernel import (
    ATTITUDE,
)

MODELS = (
    fix_stretch_model,
    velocity_stretch_model,
    heading_stretch_model,
    baseline_stretch_model,
    magnetometer_stretch_model,
    attitude_stretch_model,
)
"""The measurement functions a stretch applies, in the order :func:`_modelled` calls them by."""

# The aiding measurements a stretch takes (``aiding_rows``, one row each, those already queued
# first): stamp (s), the source's slot (its row of ``aiding_terms``), what became of it, then
# the numbers its model reads (the source's ``stretch_values``).
ROW_T, ROW_SLOT, ROW_STATUS, ROW_VALUES = range(4)
ROW_SIZE = ROW_VALUES + 23
PENDING, QUEUED, APPLIED, SUPERSEDED = 0.0, 1.0, 2.0, 3.0
# Each source's terms (``aiding_terms``, a row a slot): the index of its model in MODELS, its
# order in the registry (the order the engine stacks a stamp's measurements in), the slot of the
# source that supersedes it (−1: none), its gate's thresholds for 1, 2 and 3 dimensions, then
# its model's own terms (the source's ``stretch_terms``).
TERM_MODEL, TERM_ORDER, TERM_SUPERSEDED_BY, TERM_THRESHOLDS = range(4)
TERM_VALUES = TERM_THRESHOLDS + 3
TERMS_SIZE = TERM_VALUES + 16
# The books of an epoch (``aiding_books``, a row a measurement applied or set aside, an
# epoch's in its order): its row in ``aiding_rows``, APPLIED or SUPERSEDED, its dimension, its
# NIS, its innovation and its S (row-major), the dimension's share of each.
BOOK_ROW, BOOK_STATUS, BOOK_DIMENSION, BOOK_NIS, BOOK_INNOVATION = range(5)
BOOK_S = BOOK_INNOVATION + 3
BOOK_SIZE = BOOK_S + 9


class AidingArguments(NamedTuple):
    """What a stretch hands the aiding epochs (laid out above): the measurements' rows, each
    source's sequence (:mod:`buoy_nav.sequence_kernels`), each source's terms, room for the
    epochs' books and the error states' attitude start."""

    rows: np.ndarray
    sequences: np.ndarray
    terms: np.ndarray
    books: np.ndarray
    attitude_start: int


_rotation_matrix_elements = numba.njit(cache=True)(rotation_matrix_elements)


@numba.njit(cache=True)
def _modelled(model, values, state, rotation_nb, raw_gyro_rad_s, terms):
    """The measurement function :data:`MODELS` [``model``] of ``values`` at the strapdown
    ``state`` vector, its R_nb and the raw gyro sample there (body rad/s), with the source's
    ``terms``: (innovation, Jacobian, R, the gate's noise, whether the model holds)."""
    if model == 4:
        return magnetometer_stretch_model(values, state, rotation_nb, raw_gyro_rad_s, terms)
    if model == 0:
        nu, h, r, holds = fix_stretch_model(values, state, rotation_nb, raw_gyro_rad_s, terms)
    elif model == 1:
        nu, h, r, holds = velocity_stretch_model(values, state, rotation_nb, raw_gyro_rad_s, terms)
    elif model == 2:
        nu, h, r, holds = heading_stretch_model(values, state, rotation_nb, raw_gyro_rad_s, terms)
    elif model == 5:
        nu, h, r, holds = attitude_stretch_model(values, state, rotation_nb, raw_gyro_rad_s, terms)
    else:
        nu, h, r, holds = baseline_stretch_model(values, state, rotation_nb, raw_gyro_rad_s, terms)
    return nu, h, r, r, holds


@numba.njit(cache=True)
def due_status(rows, head, tail, t_due) -> int:
    """Whether queued measurements (``rows`` from ``head`` to ``tail``) are due at the IMU
    stamp ``t_due`` (s): 0 none, 1 some stamped there and none earlier, 2 some earlier (the
    engine applies them between two IMU samples)."""
    status = 0
    for k in range(head, tail):
        if rows[k, ROW_STATUS] == QUEUED and rows[k, ROW_T] <= t_due:
            if rows[k, ROW_T] < t_due:
                return 2
            status = 1
    return status


@numba.njit(cache=True)
def first_queued(rows, head, tail) -> int:
    """The first row from ``head`` to ``tail`` still queued (``tail``: none)."""
    while head < tail and rows[head, ROW_STATUS] != QUEUED:
        head += 1
    return head


@numba.njit(cache=True)
def _stamp_rows(rows, head, tail, t, terms):
    """The rows queued at stamp ``t`` (s): those superseded by another source's of the stamp,
    and the others in the sources' registry order."""
    group = np.empty(tail - head, np.int64)
    count = 0
    for k in range(head, tail):
        if rows[k, ROW_STATUS] == QUEUED and rows[k, ROW_T] == t:
            group[count] = k
            count += 1
    kept = np.empty(count, np.int64)
    superseded = np.empty(count, np.int64)
    n_kept = n_superseded = 0
    for i in range(count):
        by = terms[int(rows[group[i], ROW_SLOT]), TERM_SUPERSEDED_BY]
        set_aside = False
        for j in range(count):
            set_aside = set_aside or (by >= 0.0 and rows[group[j], ROW_SLOT] == by)
        if set_aside:
            superseded[n_superseded] = group[i]
            n_superseded += 1
            continue
        place = n_kept  # insertion by registry order
        order = terms[int(rows[group[i], ROW_SLOT]), TERM_ORDER]
        while place > 0 and terms[int(rows[kept[place - 1], ROW_SLOT]), TERM_ORDER] > order:
            kept[place] = kept[place - 1]
            place -= 1
        kept[place] = group[i]
        n_kept += 1
    return superseded[:n_superseded], kept[:n_kept]


@numba.njit(cache=True)
def _stacked_models(rows, kept, terms, state, raw_gyro_rad_s, state_count):
    """The models of the ``kept`` rows at the strapdown ``state`` (``state_count`` error
    states) stacked as the engine stacks them: whether each holds, then ν, H, R and the
    gates' noise (block-diagonal; 0 × 0 when it is R), each one's end in the stack and its
    gate's threshold."""
    elements = _rotation_matrix_elements(
        state[ATTITUDE], state[ATTITUDE + 1], state[ATTITUDE + 2], state[ATTITUDE + 3]
    )
    rotation_nb = np.empty((3, 3))
    for index in range(9):
        rotation_nb[index // 3, index % 3] = elements[index]
    count = kept.shape[0]
    size = 3 * count
    innovation = np.empty(size)
    jacobian = np.empty((size, state_count))
    covariance = np.zeros((size, size))
    gate_covariance = np.zeros((size, size))
    ends = np.empty(count, np.int64)
    thresholds = np.empty(count)
    end = 0
    holds = True
    for i in range(count):
        row = rows[kept[i]]
        slot = int(row[ROW_SLOT])
        nu, h, r, gate_r, model_holds = _modelled(
            int(terms[slot, TERM_MODEL]),
            row[ROW_VALUES:].copy(),
            state,
            rotation_nb,
            raw_gyro_rad_s,
            terms[slot, TERM_VALUES:].copy(),
        )
        holds = holds and model_holds
        dimension = nu.shape[0]
        innovation[end : end + dimension] = nu
        jacobian[end : end + dimension, :] = h
        covariance[end : end + dimension, end : end + dimension] = r
        gate_covariance[end : end + dimension, end : end + dimension] = gate_r
        thresholds[i] = terms[slot, TERM_THRESHOLDS + dimension - 1]
        end += dimension
        ends[i] = end
    covariance = covariance[:end, :end].copy()
    gate_covariance = gate_covariance[:end, :end].copy()
    if np.array_equal(gate_covariance, covariance):  # S is then formed once
        gate_covariance = np.zeros((0, 0))
    return (
        holds,
        innovation[:end].copy(),
        jacobian[:end].copy(),
        covariance,
        gate_covariance,
        ends,
        thresholds,
    )


@numba.njit(cache=True)
def aiding_epoch(
    rows,
    head,
    tail,
    point,
    due,
    filter_state,
    coning,
    sculling,
    covariance,
    noise_terms,
    terms,
    attitude_start,
    ahead_state,
    ahead_t,
    carried,
    books,
    book_count,
) -> int:
    """The epoch of the measurements queued at the IMU sample ``due`` (``rows`` from ``head``
    to ``tail``) as the engine makes it: the filter's step there from ``point`` with the
    covariance's propagation, the stacked models, gates and update and, when every gate passes
    and the covariance after it is positive definite, the injection into ``filter_state``, the
    new ``covariance``, (when ``carried``) the correction carried over to the prediction
    (``ahead_state``, at ``ahead_t`` s), the rows' status and their books from ``book_count``
    in ``books``. The books written, or −1 with nothing changed when the engine is to make
    it."""
    t = due[0]
    superseded, kept = _stamp_rows(rows, head, tail, t, terms)
    stepped, prior = stepped_to(point, due, filter_state, coning, sculling, covariance, noise_terms)
    holds, innovation, jacobian, measurement_covariance, gate_covariance, ends, thresholds = (
        _stacked_models(rows, kept, terms, stepped, due[1:4].copy(), covariance.shape[0])
    )
    if not holds:
        return -1
    nis, innovation_covariance, accepted, updated, correction, positive = gated_stacked_update(
        prior,
        innovation,
        jacobian,
        measurement_covariance,
        ends,
        thresholds,
        attitude_start,
        gate_covariance,
    )
    if not (accepted and positive):
        return -1
    corrected(
        filter_state, stepped, correction, covariance, updated, ahead_state, ahead_t, t, carried
    )
    return _booked(
        rows, superseded, kept, ends, nis, innovation, innovation_covariance, books, book_count
    )


@numba.njit(cache=True)
def _booked(rows, superseded, kept, ends, nis, innovation, innovation_covariance, books, first):
    """The rows set aside and applied marked so, and their books written from ``first``:
    how many."""
    count = first
    for k in superseded:
        rows[k, ROW_STATUS] = SUPERSEDED
        books[count, BOOK_ROW] = k
        books[count, BOOK_STATUS] = SUPERSEDED
        count += 1
    start = 0
    for i in range(kept.shape[0]):
        k = kept[i]
        end = ends[i]
        dimension = end - start
        rows[k, ROW_STATUS] = APPLIED
        book = books[count]
        book[BOOK_ROW] = k
        book[BOOK_STATUS] = APPLIED
        book[BOOK_DIMENSION] = dimension
        book[BOOK_NIS] = nis[i]
        for a in range(dimension):
            book[BOOK_INNOVATION + a] = innovation[start + a]
            for b in range(dimension):
                book[BOOK_S + dimension * a + b] = innovation_covariance[start + a, start + b]
        start = end
        count += 1
    return count - first
