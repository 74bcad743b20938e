"""A stretch of IMU samples and the aiding measurements among them, in one compiled call.

Most IMU samples of an aided run change nothing but the nominal states: the sample enters the
buffer, the prediction ahead steps to it and writes its solution's row
(:mod:`buoy_nav.prediction`), and the filter, ``max_measurement_delay_s`` behind, steps to the
buffered samples its horizon passed (:meth:`~buoy_nav.engine.FusionEngine._process`).
:func:`imu_stretch` does exactly that for consecutive accepted samples, with the engine's own
kernels (the strapdown step, the row writer) and in the engine's order, and stops where the
engine has more to do: a measurement due, the covariance's batch full, a gap, the rows' block
full. The engine then takes over at that sample
(:meth:`~buoy_nav.engine.FusionEngine.add_inputs`, :mod:`buoy_nav.imu_stretches`, which hands
the kernel the engine's parts and sets them from what it did), so the result is the engine's to
the bit; a test holds the two equal. Where the engine forks the prediction afresh from the filter
(once a second of stamps, :mod:`buoy_nav.prediction`) the stretch does too: the correction from
then on is not carried over, and the next sample forks the copy from the filter and steps it
through the samples buffered ahead of the filter.

The aiding measurements in between are taken too (:mod:`buoy_nav.stretched_aiding`,
:mod:`buoy_nav.aiding_epoch`): a motion pack's attitude, which comes with every IMU sample, the
magnetometer's fields and the GNSS sources' measurements. The stretch queues each as the engine
does and, when the filter reaches its stamp, makes its epoch with the engine's kernels: the step
there with the covariance's propagation, the sources' compiled models stacked, gated and applied
in one update, the injection of the correction and its carry-over to the prediction. A moored
buoy's constraint is made where it is due (:mod:`buoy_nav.mooring_epoch`), after the epoch of
the sample it shares a stamp with, the two undone together when the engine must make it. The
stretch stops before an epoch the engine must make itself (a gate that fails, a covariance to
repair, a model that does not hold, another measurement due, a constraint not taken) and where
the sources' books could change what follows (a source's health moved by a pass, the filter
distrusted, a smoother recording the epochs); the engine then keeps the books of the epochs it
made, in their order.
"""

import math

import numba
import numpy as np

from buoy_nav.aiding_epoch import (
    BOOK_SIZE,
    QUEUED,
    ROW_SIZE,
    ROW_SLOT,
    ROW_STATUS,
    ROW_T,
    TERMS_SIZE,
    AidingArguments,
    aiding_epoch,
    due_status,
    first_queued,
)
from buoy_nav.mooring_epoch import PERIOD, mooring_epoch, no_mooring
from buoy_nav.prediction import PREDICTION_RESYNC_INTERVAL_S
from buoy_nav.sequence_kernels import SEQUENCE_SIZE, queued_in_sequence
from buoy_nav.solution_rows import write_row
from buoy_nav.strapdown_kernel import DURATION, strapdown_step
from buoy_nav.strapdown_kernel import STATE_SIZE as STRAPDOWN_STATE_SIZE
from buoy_nav.stretch_screening import (
    LATEST,
    SAMPLE_INTERVAL,
    SAMPLE_SIZE,
    SCREENED_STATE_SIZE,
    SCREENING_SIZE,
    SQUARE,
    accepted,
    screened,
)

DONE = 0
"""Every sample of the stretch taken, the filter caught up to the last one's horizon."""
BEFORE_SAMPLE = 1
"""Stopped before the sample at the count returned: the engine takes it the interpreted way."""
CATCH_UP = 2
"""Stopped after the prediction of the last sample counted: the engine's filtering up to that
sample's horizon (:meth:`~buoy_nav.engine.FusionEngine.catch_up`) is left to do."""

# The state handed in and out (:func:`imu_stretch`'s ``state``): where the samples (SAMPLE_SIZE
# each, :mod:`buoy_nav.stretch_screening`) the filter's and the prediction's states are at
# begin, then the stamp of the latest sample predicted (s), the output decimation's next output
# stamp (s), the rows written, the filter stamp the prediction was last forked from (s) and
# whether it is to be forked afresh at the next sample (1.0) or not (0.0).
POINT = 0
AHEAD = 7
LAST_PREDICTED_T = 14
NEXT_OUTPUT_T = 15
ROWS = 16
FORKED_AT = 17
FORK_DUE = 18
STATE_SIZE = 19
# The limits handed in (:func:`imu_stretch`'s ``limits``).
DELAY, MAX_GAP, PROPAGATION_INTERVAL, NEXT_MEASUREMENT, OUTPUT_PERIOD = range(5)
DISTRUSTED, ATTITUDE_VARIANCE, VELOCITY_VARIANCE, CONSTRAINT_DUE = range(5, 9)
LIMITS_SIZE = 9
# How far a stretch went (``counts``): the IMU samples it took; where the queued aiding
# measurements begin and end in the aiding rows, and the books of their epochs; the mooring's
# epochs, and where its innovations' window begins and ends.
IMU_TAKEN, AIDING_HEAD, AIDING_TAIL, AIDING_BOOKS = range(4)
MOORING_EPOCHS, WINDOW_FIRST, WINDOW_END = range(4, 7)
COUNTS_SIZE = 7


@numba.njit(cache=True)
def imu_stretch(
    raw,
    order,
    screening,
    screened_state,
    samples,
    buffered,
    state,
    limits,
    filter_state,
    filter_coning,
    filter_sculling,
    ahead_state,
    ahead_coning,
    ahead_sculling,
    rows_block,
    plane_terms,
    covariance,
    block_indices,
    row_written,
    noise_terms,
    aiding,
    mooring,
    counts,
):
    """Take the inputs in ``order`` (an IMU sample's index in ``raw``, or −1 − the index of an
    aiding measurement's row) as the engine's ``add_imu``,
    ``add_measurement`` and ``catch_up`` would, until one needs the engine; the filter may also
    reach the ``buffered`` IMU samples ahead of it (k × 7, oldest first).

    Each IMU sample (n × 7: header stamp s, ω_ib body rad/s, specific force body m/s²) is
    screened (``screening``, ``screened_state``; into ``samples``, re-stamped and calibrated),
    predicted ahead with its row (:func:`_predicted`) and the filter stepped to its horizon
    (:func:`_filtered`); each measurement is queued (:func:`_queued`) and its epoch made when
    the filter reaches it, the process noise's ``noise_terms`` and the ``aiding`` arrays
    (:class:`~buoy_nav.aiding_epoch.AidingArguments`); the ``mooring``'s constraint is applied
    where it is due (:class:`~buoy_nav.mooring_epoch.MooringArguments`; no room for its books:
    the stretch stops there). The layouts are this module's constants and
    those modules'; ``state``, the strapdown states, ``covariance`` and ``counts`` are updated in
    place, ``row_written`` set for each sample whose row was written.

    Returns (inputs taken, buffered samples the filter stepped to, :data:`DONE`,
    :data:`BEFORE_SAMPLE` or :data:`CATCH_UP`).
    """
    # Integer bounds: a slice object held globally would be unpickled at each call.
    point = state[POINT : POINT + SAMPLE_SIZE]
    stepped = 0
    for item in range(order.shape[0]):
        position = order[item]
        if position < 0:
            if not _queued(-1 - position, aiding, point, screened_state, counts):
                return item, stepped, BEFORE_SAMPLE
            continue
        index = counts[IMU_TAKEN]
        sample = samples[index]
        if not _taken(raw[position], screening, screened_state, sample, state, limits, rows_block):
            return item, stepped, BEFORE_SAMPLE
        counts[IMU_TAKEN] += 1
        row_written[index] = _predicted(
            index,
            stepped,
            buffered,
            samples,
            state,
            limits,
            filter_state,
            ahead_state,
            ahead_coning,
            ahead_sculling,
            rows_block,
            plane_terms,
            covariance,
            block_indices,
        )
        stepped = _filtered(
            sample[0] - limits[DELAY],
            stepped,
            buffered.shape[0] + index + 1,
            buffered,
            samples,
            point,
            limits,
            filter_state,
            filter_coning,
            filter_sculling,
            covariance,
            noise_terms,
            ahead_state,
            state,
            aiding,
            mooring,
            counts,
        )
        if stepped < 0:
            return item + 1, -1 - stepped, CATCH_UP
    return order.shape[0], stepped, DONE


@numba.njit(cache=True)
def _taken(raw_sample, screening, screened_state, sample, state, limits, rows_block) -> bool:
    """Whether the stretch takes ``raw_sample``: screened as :func:`_screened` screens it, not
    beyond a gap from the prediction ahead (``state``'s :data:`AHEAD`), with room in the rows'
    block; the screening then accepts it into ``sample``."""
    if not screened(raw_sample, screening, screened_state, sample):
        return False
    if sample[0] - state[AHEAD] > limits[MAX_GAP] or state[ROWS] >= rows_block.shape[0]:
        return False
    accepted(screening, screened_state, sample)
    return True


@numba.njit(cache=True)
def _forked(
    state, buffered, samples, stepped, index, filter_state, ahead_state, coning, sculling
) -> None:
    """The prediction ahead forked afresh from the filter (``filter_state``, at ``state``'s
    :data:`POINT`) and stepped through the samples buffered ahead of it (of the ``buffered``
    ones, then the taken ``samples``, the first ``stepped`` reached by the filter) up to the
    taken sample ``index``, which it is then predicted to. Each of them was predicted before:
    none writes a row again."""
    ahead = state[AHEAD : AHEAD + SAMPLE_SIZE]
    ahead_state[:] = filter_state
    ahead_state[DURATION:] = 0.0
    ahead[:] = state[POINT : POINT + SAMPLE_SIZE]
    state[FORKED_AT] = ahead[0]
    state[FORK_DUE] = 0.0
    n_buffered = buffered.shape[0]
    for k in range(stepped, n_buffered + index):
        due = buffered[k] if k < n_buffered else samples[k - n_buffered]
        _step(ahead_state, due[0] - ahead[0], ahead, due, coning, sculling)
        ahead[:] = due


@numba.njit(cache=True)
def _predicted(
    index,
    stepped,
    buffered,
    samples,
    state,
    limits,
    filter_state,
    ahead_state,
    coning,
    sculling,
    rows_block,
    plane_terms,
    covariance,
    block_indices,
) -> bool:
    """The prediction ahead (``ahead_state``, at ``state``'s :data:`AHEAD` sample; forked
    afresh first when due, :func:`_forked`) stepped to the accepted IMU sample ``index`` of
    ``samples`` and, when the output is due there, its solution's row written; whether it was
    (``state``'s :data:`ROWS`, :data:`LAST_PREDICTED_T` and the decimation's next stamp
    follow)."""
    if state[FORK_DUE] != 0.0:
        _forked(
            state, buffered, samples, stepped, index, filter_state, ahead_state, coning, sculling
        )
    sample = samples[index]
    ahead = state[AHEAD : AHEAD + SAMPLE_SIZE]
    t = sample[0]
    span = t - ahead[0]
    _step(ahead_state, span, ahead, sample, coning, sculling)
    ahead[:] = sample
    written = t > state[LAST_PREDICTED_T] and _due(state, t, span, limits[OUTPUT_PERIOD])
    if written:
        write_row(
            rows_block,
            int(state[ROWS]),
            t,
            ahead_state,
            sample[1],
            sample[2],
            sample[3],
            sample[4],
            sample[5],
            sample[6],
            plane_terms,
            covariance,
            block_indices,
            limits[DISTRUSTED] != 0.0,
            limits[ATTITUDE_VARIANCE],
            limits[VELOCITY_VARIANCE],
        )
        state[ROWS] += 1
    state[LAST_PREDICTED_T] = t
    return written


@numba.njit(cache=True)
def _filtered(
    horizon_s,
    stepped,
    reachable,
    buffered,
    samples,
    point,
    limits,
    filter_state,
    coning,
    sculling,
    covariance,
    noise_terms,
    ahead_state,
    state,
    aiding,
    mooring,
    counts,
) -> int:
    """The filter (``filter_state`` at ``point``) stepped through the samples it has not reached of
    the first ``reachable`` (the ``buffered`` ones, then the taken ``samples``) up to ``horizon_s``
    (s), the epoch of each stamp with queued aiding measurements made there (:func:`_epoch_made`)
    and then the mooring's where it is due (:func:`_sample_reached`): how many samples it has
    reached in all, or −1 − that when it stopped where the engine must go on (a gap, a measurement
    due, the covariance's batch full, an epoch it cannot make)."""
    n_buffered = buffered.shape[0]
    while stepped < reachable:
        due = buffered[stepped] if stepped < n_buffered else samples[stepped - n_buffered]
        t_due = due[0]
        if t_due > horizon_s:
            break
        # A gap, or a sample predicted before (above), the prediction meets first and the
        # engine takes; the stretch still never steps across one.
        if due[0] - point[0] > limits[MAX_GAP] or limits[NEXT_MEASUREMENT] <= t_due:
            return -1 - stepped
        if not _sample_reached(
            due,
            point,
            limits,
            filter_state,
            coning,
            sculling,
            covariance,
            noise_terms,
            ahead_state,
            state,
            aiding,
            mooring,
            counts,
        ):
            return -1 - stepped
        point[:] = due
        stepped += 1
    return stepped


@numba.njit(cache=True)
def _sample_reached(
    due,
    point,
    limits,
    filter_state,
    coning,
    sculling,
    covariance,
    noise_terms,
    ahead_state,
    state,
    aiding,
    mooring,
    counts,
) -> bool:
    """The filter (``filter_state`` at ``point``) stepped to the IMU sample ``due`` with the
    epochs there (:func:`_stepped`), and then, when due, the mooring's
    (:func:`~buoy_nav.mooring_epoch.mooring_epoch`); False, with nothing changed, where the
    engine must take the sample."""
    mooring_due = limits[CONSTRAINT_DUE] <= due[0]
    if mooring_due and mooring.books.shape[0] <= counts[MOORING_EPOCHS]:
        return False
    # Both epochs of the sample or neither: what the first moved comes back when the second
    # is the engine's.
    saved = _saved(mooring_due, filter_state, covariance, ahead_state, counts, state, aiding)
    stepped = _stepped(
        due,
        point,
        limits,
        filter_state,
        coning,
        sculling,
        covariance,
        noise_terms,
        ahead_state,
        state,
        aiding,
        counts,
    )
    if not mooring_due:
        return stepped
    if stepped and _mooring_made(
        due[0], filter_state, covariance, noise_terms, ahead_state, state, mooring, counts
    ):
        limits[CONSTRAINT_DUE] = due[0] + mooring.terms[PERIOD]
        return True
    saved_filter, saved_covariance, saved_ahead, saved_counts, saved_fork, saved_status, watch = (
        saved
    )
    filter_state[:], covariance[:, :], ahead_state[:] = saved_filter, saved_covariance, saved_ahead
    counts[:], state[FORK_DUE] = saved_counts, saved_fork
    aiding.rows[:, ROW_STATUS] = saved_status
    aiding.watch[:] = watch
    return False


@numba.njit(cache=True)
def _saved(wanted, filter_state, covariance, ahead_state, counts, state, aiding):
    """Copies of what an epoch moves, when ``wanted`` (else empty arrays): the filter's
    state, the covariance, the prediction's state, the ``counts``, whether the prediction is
    to be forked afresh, what became of each of the ``aiding`` rows and the watches left."""
    if wanted:
        return (
            filter_state.copy(),
            covariance.copy(),
            ahead_state.copy(),
            counts.copy(),
            state[FORK_DUE],
            aiding.rows[:, ROW_STATUS].copy(),
            aiding.watch.copy(),
        )
    return (
        np.empty(0),
        np.empty((0, 0)),
        np.empty(0),
        np.empty(0, np.int64),
        state[FORK_DUE],
        np.empty(0),
        np.empty(0),
    )


@numba.njit(cache=True)
def _mooring_made(t, filter_state, covariance, noise_terms, ahead_state, state, mooring, counts):
    """The mooring's epoch at the IMU sample stamped ``t`` (s) made, its books counted and its
    correction carried over as :func:`_carried` says; False, with nothing changed, when the
    engine is to make it."""
    carried = _carried(state, t)
    made = mooring_epoch(
        t,
        filter_state,
        covariance,
        noise_terms,
        ahead_state,
        state[AHEAD],
        carried,
        mooring,
        counts[WINDOW_FIRST : WINDOW_END + 1],
        mooring.books[counts[MOORING_EPOCHS]],
    )
    if made:
        counts[MOORING_EPOCHS] += 1
        if not carried:
            state[FORK_DUE] = 1.0
    return made


@numba.njit(cache=True)
def _carried(state, t) -> bool:
    """Whether the correction of an epoch at ``t`` (s) is carried over to the prediction ahead
    (``state``'s :data:`AHEAD`), or the prediction forked afresh at the next sample instead
    (a second of stamps after its fork, as the engine does)."""
    return state[FORK_DUE] == 0.0 and t < state[FORKED_AT] + PREDICTION_RESYNC_INTERVAL_S


@numba.njit(cache=True)
def _stepped(
    due,
    point,
    limits,
    filter_state,
    coning,
    sculling,
    covariance,
    noise_terms,
    ahead_state,
    state,
    aiding,
    counts,
) -> bool:
    """The filter (``filter_state`` at ``point``) stepped to the IMU sample ``due``, with the
    epoch there of the queued aiding measurements (:func:`_epoch_made`);
    False, with nothing changed, where the engine must take the sample."""
    t_due = due[0]
    dt = t_due - point[0]
    aiding_due = due_status(aiding.rows, counts[AIDING_HEAD], counts[AIDING_TAIL], t_due)
    if aiding_due:
        return dt > 0.0 and _epoch_made(
            aiding_due,
            point,
            due,
            filter_state,
            coning,
            sculling,
            covariance,
            noise_terms,
            ahead_state,
            state,
            aiding,
            counts,
        )
    if dt > 0.0:
        if filter_state[DURATION] + dt >= limits[PROPAGATION_INTERVAL]:
            return False
        _step(filter_state, dt, point, due, coning, sculling)
    return True


@numba.njit(cache=True)
def _queued(measurement, aiding, point, screened_state, counts) -> bool:
    """Whether the engine would queue the ``measurement`` th of the ``aiding`` rows with
    nothing else to do; its source's sequence then follows it, the row is marked queued and
    ``counts`` take it."""
    rows = aiding.rows
    sequence = aiding.sequences[int(rows[measurement, ROW_SLOT])]
    if not queued_in_sequence(rows[measurement, ROW_T], sequence, point[0], screened_state[LATEST]):
        return False
    rows[measurement, ROW_STATUS] = QUEUED
    counts[AIDING_TAIL] = measurement + 1
    return True


@numba.njit(cache=True)
def _epoch_made(
    aiding_due,
    point,
    due,
    filter_state,
    coning,
    sculling,
    covariance,
    noise_terms,
    ahead_state,
    state,
    aiding,
    counts,
) -> bool:
    """The epoch at the IMU sample ``due`` of the queued aiding measurements (``aiding_due``,
    :func:`~buoy_nav.aiding_epoch.due_status`) made with the engine's kernels, ``counts``
    following it, and its correction carried over to the prediction ahead (``ahead_state``) as
    :func:`_carried` says; False, with nothing changed, when the engine is to make it (a
    stamp between two IMU samples, an epoch the kernels leave to it)."""
    if aiding_due != 1:
        return False
    carried = _carried(state, due[0])
    written, made_correction = aiding_epoch(
        aiding.rows,
        counts[AIDING_HEAD],
        counts[AIDING_TAIL],
        point,
        due,
        filter_state,
        coning,
        sculling,
        covariance,
        noise_terms,
        aiding.terms,
        aiding.watch,
        aiding.attitude_start,
        ahead_state,
        state[AHEAD],
        carried,
        aiding.books,
        counts[AIDING_BOOKS],
    )
    if written < 0:
        return False
    counts[AIDING_BOOKS] += written
    counts[AIDING_HEAD] = first_queued(aiding.rows, counts[AIDING_HEAD], counts[AIDING_TAIL])
    if made_correction and not carried:
        state[FORK_DUE] = 1.0
    return True


@numba.njit(cache=True)
def _step(state, dt_s, start, end, coning, sculling):
    """The strapdown step of ``state`` over ``dt_s`` (s) from the (stamp, gyro, force) sample
    ``start`` to ``end``, with the ``coning`` and ``sculling`` corrections or not."""
    strapdown_step(
        state,
        dt_s,
        start[1],
        start[2],
        start[3],
        end[1],
        end[2],
        end[3],
        start[4],
        start[5],
        start[6],
        end[4],
        end[5],
        end[6],
        coning,
        sculling,
    )


@numba.njit(cache=True)
def _due(state, t, span, period_s):
    """:meth:`~buoy_nav.solution.OutputDecimation.due` on the decimation's next output stamp
    in ``state``."""
    if period_s == 0.0:
        return True
    if t + 0.5 * span < state[NEXT_OUTPUT_T]:
        return False
    following = state[NEXT_OUTPUT_T] + period_s
    state[NEXT_OUTPUT_T] = following if following > t else t + period_s
    return True


def load_compiled_imu_stretch() -> None:
    """Compile the stretch, or load it from the cache, now (see
    :func:`buoy_nav.mechanization.load_compiled_kernels`)."""
    state = np.zeros(STATE_SIZE)
    state[AHEAD] = -1.0
    state[LAST_PREDICTED_T] = -math.inf
    limits = np.zeros(LIMITS_SIZE)
    limits[[DELAY, MAX_GAP, PROPAGATION_INTERVAL]] = (0.3, 0.5, 0.1)
    limits[[NEXT_MEASUREMENT, CONSTRAINT_DUE]] = math.inf
    strapdown = np.zeros(STRAPDOWN_STATE_SIZE)
    screening = np.zeros(SCREENING_SIZE)
    screening[SAMPLE_INTERVAL] = 0.01
    screening[SQUARE] = 2.0
    screened_state = np.zeros(SCREENED_STATE_SIZE)
    screened_state[LATEST] = -1.0
    imu_stretch(
        np.zeros((1, SAMPLE_SIZE)),
        np.zeros(1, dtype=np.int64),
        screening,
        screened_state,
        np.zeros((1, SAMPLE_SIZE)),
        np.zeros((0, SAMPLE_SIZE)),
        state,
        limits,
        strapdown,
        True,
        True,
        strapdown.copy(),
        True,
        True,
        np.zeros((4, 56)),
        np.zeros(12),
        np.eye(15),
        np.arange(36, dtype=np.int64).reshape(4, 3, 3),
        np.zeros(1, dtype=np.bool_),
        np.zeros(7),
        AidingArguments(
            np.zeros((0, ROW_SIZE)),
            np.zeros((0, SEQUENCE_SIZE)),
            np.zeros((0, TERMS_SIZE)),
            np.zeros((0, BOOK_SIZE)),
            0,
            np.zeros(0),
        ),
        no_mooring(),
        np.zeros(COUNTS_SIZE, dtype=np.int64),
    )
