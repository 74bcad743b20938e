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
from buoy_nav.aiding.model_kernels import HOLDS, LEFT_TO_THE_ENGINE, NO_GEOMETRY, REFUSED
from buoy_nav.epoch_kernels import corrected, stepped_to
from buoy_nav.kalman_kernel import gated_stacked_update, innovation_test
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
# A suspended source's measurement, watched and not fused: gated, without the geometry to be
# modelled, or refused by its model.
WATCHED, WATCHED_NO_GEOMETRY, WATCHED_REFUSED = 4.0, 5.0, 6.0
# Each source's terms (``aiding_terms``, a row a slot): the index of its model in MODELS, its
# order in the registry (the order the engine stacks a stamp's measurements in), the slot of the
# source that supersedes it (−1: none), its gate's thresholds for 1, 2 and 3 dimensions, then
# its model's own terms (the source's ``stretch_terms``).
TERM_MODEL, TERM_ORDER, TERM_SUPERSEDED_BY, TERM_THRESHOLDS = range(4)
TERM_VALUES = TERM_THRESHOLDS + 3
TERMS_SIZE = TERM_VALUES + 16
# The books of an epoch (``aiding_books``, a row a measurement applied, set aside or watched, an
# epoch's in its order): its row in ``aiding_rows``, what became of it (its row's status), its
# dimension, its NIS, its innovation and its S (row-major), the dimension's share of each.
BOOK_ROW, BOOK_STATUS, BOOK_DIMENSION, BOOK_NIS, BOOK_INNOVATION = range(5)
BOOK_S = BOOK_INNOVATION + 3
BOOK_SIZE = BOOK_S + 9


class AidingArguments(NamedTuple):
    """What a stretch hands the aiding epochs (laid out above): the measurements' rows, each
    source's sequence (:mod:`buoy_nav.sequence_kernels`), each source's terms, room for the
    epochs' books, the error states' attitude start and, for each source, how many of its
    measurements may be watched (``watch``; 0: a source not suspended, whose measurements are
    fused)."""

    rows: np.ndarray
    sequences: np.ndarray
    terms: np.ndarray
    books: np.ndarray
    attitude_start: int
    watch: np.ndarray
    """The outcomes of each suspended source that cannot resume it, whatever they are: the
    stretch books no more (it counts them down)."""


_rotation_matrix_elements = numba.njit(cache=True)(rotation_matrix_elements)


@numba.njit(cache=True)
def _modelled(model, values, state, rotation_nb, raw_gyro_rad_s, terms):
    """The measurement function :data:`MODELS` [``model``] of ``values`` at the strapdown
    ``state`` vector, its R_nb and the raw gyro sample there (body rad/s), with the source's
    ``terms``: (innovation, Jacobian, R, the gate's noise, its fate,
    :mod:`buoy_nav.aiding.model_kernels`)."""
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
    return nu, h, r, r, HOLDS if holds else LEFT_TO_THE_ENGINE


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
def _rotation_nb(state):
    """R_nb of the strapdown ``state`` vector's attitude."""
    elements = _rotation_matrix_elements(
        state[ATTITUDE], state[ATTITUDE + 1], state[ATTITUDE + 2], state[ATTITUDE + 3]
    )
    rotation_nb = np.empty((3, 3))
    for index in range(9):
        rotation_nb[index // 3, index % 3] = elements[index]
    return rotation_nb


@numba.njit(cache=True)
def _row_model(rows, k, terms, state, rotation_nb, raw_gyro_rad_s):
    """:func:`_modelled` of the row ``k``."""
    row = rows[k]
    slot = int(row[ROW_SLOT])
    return _modelled(
        int(terms[slot, TERM_MODEL]),
        row[ROW_VALUES:].copy(),
        state,
        rotation_nb,
        raw_gyro_rad_s,
        terms[slot, TERM_VALUES:].copy(),
    )


@numba.njit(cache=True)
def _stacked_models(rows, kept, terms, state, rotation_nb, raw_gyro_rad_s, state_count):
    """The models of the ``kept`` rows at the strapdown ``state`` (its ``rotation_nb``;
    ``state_count`` error states) stacked as the engine stacks them: whether each holds, then
    ν, H, R and the gates' noise (block-diagonal; 0 × 0 when it is R), each one's end in the
    stack and its gate's threshold."""
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
        slot = int(rows[kept[i], ROW_SLOT])
        nu, h, r, gate_r, fate = _row_model(
            rows, kept[i], terms, state, rotation_nb, raw_gyro_rad_s
        )
        holds = holds and fate == HOLDS
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
def _watched_models(rows, watched, terms, watch, state, rotation_nb, raw_gyro_rad_s, prior):
    """The ``watched`` rows (of suspended sources) modelled at the strapdown ``state`` (its
    ``rotation_nb``) and each one gated alone against the ``prior`` covariance, as the engine
    gates them: whether the stretch may book them all (each model's fate leaves it to the
    stretch, and each source's ``watch`` lets it book one more outcome), each one's fate, NIS,
    innovation and S."""
    count = watched.shape[0]
    fates = np.empty(count, np.int64)
    nis = np.full(count, np.nan)
    innovations = np.zeros((count, 3))
    gate_s = np.zeros((count, 3, 3))
    dimensions = np.zeros(count, np.int64)
    for i in range(count):
        nu, h, _, gate_r, fate = _row_model(
            rows, watched[i], terms, state, rotation_nb, raw_gyro_rad_s
        )
        judged = fate != NO_GEOMETRY  # a health outcome
        if fate == LEFT_TO_THE_ENGINE or (judged and watch[int(rows[watched[i], ROW_SLOT])] < 1):
            return False, fates, nis, innovations, gate_s, dimensions
        fates[i] = fate
        if fate == HOLDS:
            dimension = nu.shape[0]
            nis[i], s = innovation_test(prior, nu, h, gate_r)
            innovations[i, :dimension] = nu
            gate_s[i, :dimension, :dimension] = s
            dimensions[i] = dimension
    return True, fates, nis, innovations, gate_s, dimensions


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
    watch,
    attitude_start,
    ahead_state,
    ahead_t,
    carried,
    books,
    book_count,
):
    """The epoch of the measurements queued at the IMU sample ``due`` (``rows`` from ``head``
    to ``tail``) as the engine makes it: the filter's step there from ``point`` with the
    covariance's propagation; the suspended sources' measurements (``watch``) modelled and
    gated alone, counted down in ``watch``; the others' stacked models, gates and update and,
    when every gate passes and the covariance after it is positive definite, the injection
    into ``filter_state``, the new ``covariance``, (when ``carried``) the correction carried
    over to the prediction (``ahead_state``, at ``ahead_t`` s); the rows' status and their
    books from ``book_count`` in ``books``. The books written (−1, with nothing changed, when
    the engine is to make it) and whether a correction was made."""
    t = due[0]
    superseded, ordered = _stamp_rows(rows, head, tail, t, terms)
    is_watched = np.zeros(ordered.shape[0], np.bool_)
    for i in range(ordered.shape[0]):
        is_watched[i] = watch[int(rows[ordered[i], ROW_SLOT])] > 0
    kept, watched = ordered[~is_watched], ordered[is_watched]
    stepped, prior = stepped_to(point, due, filter_state, coning, sculling, covariance, noise_terms)
    rotation_nb = _rotation_nb(stepped)
    raw_gyro = due[1:4].copy()
    bookable, fates, watched_nis, watched_innovations, watched_s, watched_dimensions = (
        _watched_models(rows, watched, terms, watch, stepped, rotation_nb, raw_gyro, prior)
    )
    if not bookable:
        return -1, False
    holds, innovation, jacobian, measurement_covariance, gate_covariance, ends, thresholds = (
        _stacked_models(rows, kept, terms, stepped, rotation_nb, raw_gyro, covariance.shape[0])
    )
    if not holds:
        return -1, False
    if kept.shape[0]:
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
            return -1, False
        corrected(
            filter_state, stepped, correction, covariance, updated, ahead_state, ahead_t, t, carried
        )
    else:  # the step to the stamp alone, as the engine's when it fuses none of them
        nis, innovation_covariance = np.empty(0), np.empty((0, 0))
        filter_state[:] = stepped
        covariance[:, :] = prior
    count = _booked(
        rows, superseded, kept, ends, nis, innovation, innovation_covariance, books, book_count
    )
    _watch_booked(
        rows,
        watched,
        watch,
        fates,
        watched_nis,
        watched_innovations,
        watched_s,
        watched_dimensions,
        books,
        book_count + count,
    )
    count += watched.shape[0]
    _in_registry_order(books[book_count + superseded.shape[0] : book_count + count], rows, terms)
    return count, kept.shape[0] > 0


@numba.njit(cache=True)
def _watch_booked(rows, watched, watch, fates, nis, innovations, gate_s, dimensions, books, first):
    """The ``watched`` rows marked with their fates, their sources' ``watch`` counted down for
    each one judged (a health outcome), and their books written from ``first``."""
    for i in range(watched.shape[0]):
        k = watched[i]
        fate = fates[i]
        if fate == HOLDS:
            status = WATCHED
        elif fate == REFUSED:
            status = WATCHED_REFUSED
        else:
            status = WATCHED_NO_GEOMETRY
        if fate != NO_GEOMETRY:
            watch[int(rows[k, ROW_SLOT])] -= 1
        rows[k, ROW_STATUS] = status
        book = books[first + i]
        book[BOOK_ROW] = k
        book[BOOK_STATUS] = status
        dimension = dimensions[i]
        book[BOOK_DIMENSION] = dimension
        book[BOOK_NIS] = nis[i]
        for a in range(dimension):
            book[BOOK_INNOVATION + a] = innovations[i, a]
            for b in range(dimension):
                book[BOOK_S + dimension * a + b] = gate_s[i, a, b]


@numba.njit(cache=True)
def _in_registry_order(books, rows, terms):
    """The ``books`` of an epoch's measurements applied and watched put in the sources'
    registry order, the order the engine books them in (an insertion sort: a few rows)."""
    for i in range(1, books.shape[0]):
        book = books[i].copy()
        order = terms[int(rows[int(book[BOOK_ROW]), ROW_SLOT]), TERM_ORDER]
        place = i
        while (
            place > 0
            and terms[int(rows[int(books[place - 1, BOOK_ROW]), ROW_SLOT]), TERM_ORDER] > order
        ):
            books[place] = books[place - 1]
            place -= 1
        books[place] = book


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
