"""Wind compensation engine shared by the live node and offline processing.

Navigation samples (:meth:`WindCompensator.add_nav`) and anemometer samples
(:meth:`WindCompensator.add_wind`) go in, in the order they arrive; every anemometer sample
comes out exactly once (:meth:`WindCompensator.ready`), in input order, with its own stamp:
either the motion-corrected wind or NaN with the reason it could not be corrected.

Whether and how a sample is corrected depends only on stamps (the navigation samples around
it), not on when messages happen to arrive, with two exceptions. The live-only
:meth:`WindCompensator.expire` gives up on samples whose navigation is late. And a wind sample
that arrives lagging the newest navigation by more than ``nav_history_s`` finds its navigation
forgotten. Both depend on the order of arrival only, never on how often the results are
collected: samples may be added one at a time (the live node, in plain floats) or as stretches
of interleaved arrivals (:meth:`WindCompensator.add_arrivals`, offline, on columns), with
bit-identical results.
"""

import math
from dataclasses import dataclass
from enum import IntEnum

import numpy as np

from buoy_common.contract import Reason
from buoy_nav.rotations import rotation_matrix_elements
from wind_comp.config import CompensatorConfig
from wind_comp.miller import miller_components, mounting_rotation_from_rpy_deg
from wind_comp.nav_interpolation import InterpolationStatus, NavTrack


class CompensatorInputError(ValueError):
    """Wind arrays given to the compensator have the wrong shape."""


class WindStatus(IntEnum):
    """Outcome of correcting one anemometer sample."""

    VALID = 0
    NO_NAVIGATION = 1
    """No navigation sample on one side of the stamp (before the first or after the last)."""
    NAV_GAP = 2
    """The bracketing navigation samples are more than ``max_nav_gap_s`` apart."""
    NAVIGATION_TIMEOUT = 3
    """Given up by :meth:`WindCompensator.expire` before navigation caught up."""
    NAV_HISTORY_EXCEEDED = 4
    """The stamp lags the newest navigation by more than ``nav_history_s``."""
    INVALID_WIND = 5
    """The measured vector is not finite."""
    WIND_SPEED_OUT_OF_RANGE = 6
    """The measured speed exceeds ``max_wind_speed_mps``."""
    INVALID_STAMP = 7
    """The stamp is not finite, or not later than the previous wind stamp."""
    NAVIGATION_NOT_TRUSTED = 8
    """A bracketing navigation sample's attitude is more uncertain than
    ``max_attitude_sigma_deg`` (the navigation marks itself untrustworthy by its covariance)."""

    @property
    def reason(self) -> Reason:
        """Why the sample is invalid, in the contract's words (not defined for VALID)."""
        return Reason[self.name]


_PENDING = -1
_NAV_OUTCOME = {
    InterpolationStatus.OK: WindStatus.VALID,
    InterpolationStatus.BEFORE_START: WindStatus.NO_NAVIGATION,
    InterpolationStatus.AFTER_END: _PENDING,
    InterpolationStatus.GAP: WindStatus.NAV_GAP,
    InterpolationStatus.EVICTED: WindStatus.NAV_HISTORY_EXCEEDED,
    InterpolationStatus.INVALID_STAMP: WindStatus.INVALID_STAMP,
    InterpolationStatus.UNTRUSTED: WindStatus.NAVIGATION_NOT_TRUSTED,
}
_NAV_OUTCOME_BY_CODE = np.array(
    [_NAV_OUTCOME[InterpolationStatus(code)] for code in range(len(InterpolationStatus))],
    dtype=np.int8,
)


@dataclass(frozen=True, eq=False)
class CorrectedWindBatch:
    """N anemometer samples after correction, in input order.

    The (N, 3) ENU vectors (m/s) are NaN where ``status`` is not VALID;
    ``true_wind_enu_mps = tilt_term_enu_mps + rotation_term_enu_mps + translation_term_enu_mps``
    (see :mod:`wind_comp.miller`).
    """

    t_s: np.ndarray
    """(N,) header stamps of the anemometer samples, s."""
    status: np.ndarray
    """(N,) int8 codes of :class:`WindStatus`."""
    true_wind_enu_mps: np.ndarray
    tilt_term_enu_mps: np.ndarray
    rotation_term_enu_mps: np.ndarray
    translation_term_enu_mps: np.ndarray
    wind_sensor_mps: np.ndarray
    """(N, 3) the measured inputs, anemometer axes, m/s."""

    def __len__(self) -> int:
        return self.t_s.shape[0]

    @property
    def valid(self) -> np.ndarray:
        return self.status == WindStatus.VALID

    def counts(self) -> dict[WindStatus, int]:
        """Number of samples per status."""
        return {status: int(np.count_nonzero(self.status == status)) for status in WindStatus}


def _screen_wind(
    stamps_s: np.ndarray, winds_mps: np.ndarray, latest_stamp_s: float, max_speed_mps: float
) -> tuple[np.ndarray, float]:
    """Status of each sample from its own values and stamp order alone.

    Returns (N,) statuses (``_PENDING`` where navigation decides) and the latest accepted stamp.
    A stamp is accepted when it is finite and later than every earlier accepted stamp.
    """
    finite_stamp = np.isfinite(stamps_s)
    candidates = np.where(finite_stamp, stamps_s, -np.inf)
    running_latest = np.maximum.accumulate(np.concatenate(([latest_stamp_s], candidates)))
    stamp_ok = finite_stamp & (stamps_s > running_latest[:-1])
    finite_wind = np.all(np.isfinite(winds_mps), axis=1)
    speed = np.sqrt(np.sum(np.where(finite_wind[:, None], winds_mps, 0.0) ** 2, axis=1))
    status = np.full(stamps_s.shape[0], _PENDING, dtype=np.int8)
    status[speed > max_speed_mps] = WindStatus.WIND_SPEED_OUT_OF_RANGE
    status[~finite_wind] = WindStatus.INVALID_WIND
    status[~stamp_ok] = WindStatus.INVALID_STAMP
    return status, float(running_latest[-1])


def _screen_one_wind(
    t_s: float, x: float, y: float, z: float, latest_stamp_s: float, max_speed_mps: float
) -> tuple[int, float]:
    """:func:`_screen_wind` of one sample in plain floats (the same decisions)."""
    finite_stamp = math.isfinite(t_s)
    stamp_ok = finite_stamp and t_s > latest_stamp_s
    if finite_stamp:
        latest_stamp_s = max(latest_stamp_s, t_s)
    if not stamp_ok:
        return WindStatus.INVALID_STAMP, latest_stamp_s
    if not (math.isfinite(x) and math.isfinite(y) and math.isfinite(z)):
        return WindStatus.INVALID_WIND, latest_stamp_s
    if math.sqrt(x * x + y * y + z * z) > max_speed_mps:
        return WindStatus.WIND_SPEED_OUT_OF_RANGE, latest_stamp_s
    return _PENDING, latest_stamp_s


class _Corrector:
    """Navigation lookup plus Miller correction for samples that passed screening."""

    def __init__(self, config: CompensatorConfig):
        mounting_matrix_bw = mounting_rotation_from_rpy_deg(config.anemometer_rpy_deg).as_matrix()
        self._mounting_elements_bw = tuple(mounting_matrix_bw.ravel().tolist())
        self._lever_arm_elements_body_m = tuple(config.anemometer_position_body_m)

    def correct_one(self, track: NavTrack, t_s: float, wind_mps, as_of_newest_s: float):
        """:meth:`correct` of one sample in plain floats (bit-identical): its status and its
        true wind and three Miller terms as tuples, NaN unless valid."""
        code, attitude, rate, velocity = track.interpolate_one(t_s, as_of_newest_s)
        status = _NAV_OUTCOME[code]
        if status != WindStatus.VALID:
            return status, _NAN_TERMS
        terms = miller_components(
            tuple(wind_mps),
            rotation_matrix_elements(*attitude),
            rate,
            velocity,
            self._mounting_elements_bw,
            self._lever_arm_elements_body_m,
        )
        return status, terms

    def correct(self, track: NavTrack, stamps_s, winds_mps, as_of_newest_s):
        """Return (N,) statuses (``_PENDING`` while navigation may still bracket a stamp) and
        (N, 3) arrays of true wind and the three Miller terms, NaN where not valid.

        ``as_of_newest_s``: the newest navigation stamp when each sample arrived (see
        :meth:`NavTrack.interpolate`)."""
        nav = track.interpolate(stamps_s, as_of_newest_s)
        status = _NAV_OUTCOME_BY_CODE[nav.status]
        outputs = [np.full((stamps_s.shape[0], 3), np.nan) for _ in range(4)]
        valid = nav.valid
        if np.any(valid):
            # The arithmetic of correct_one, on the columns of the valid samples.
            terms = miller_components(
                tuple(winds_mps[valid].T),
                rotation_matrix_elements(*nav.attitude_xyzw[valid].T),
                tuple(nav.angular_rate_body_rad_s[valid].T),
                tuple(nav.velocity_enu_mps[valid].T),
                self._mounting_elements_bw,
                self._lever_arm_elements_body_m,
            )
            for output, term in zip(outputs, terms, strict=True):
                output[valid] = np.stack(term, axis=-1)
        return status, outputs


_NAN_TERMS = ((math.nan,) * 3,) * 4
_NOTHING_DECIDED = CorrectedWindBatch(
    np.empty(0), np.empty(0, dtype=np.int8), *(np.empty((0, 3)) for _ in range(5))
)
_INITIAL_CAPACITY = 64


class WindCompensator:
    """Streaming wind correction: one output per anemometer sample, in input order.

    The anemometer samples wait in a queue of columns: stamp, measured wind, the newest
    navigation stamp when the sample arrived, status (``_PENDING`` until decided) and the four
    output vectors. Samples before ``_first_pending`` are decided, those from ``_head`` on not
    yet returned.
    """

    def __init__(self, config: CompensatorConfig):
        self.config = config
        self.nav_track = NavTrack(config.max_nav_gap_s, config.nav_history_s)
        self._corrector = _Corrector(config)
        self._latest_wind_stamp_s = -np.inf
        self._counts = dict.fromkeys(WindStatus, 0)
        self._t_s = np.empty(_INITIAL_CAPACITY)
        self._wind_mps = np.empty((_INITIAL_CAPACITY, 3))
        self._as_of_nav_s = np.empty(_INITIAL_CAPACITY)
        self._status = np.empty(_INITIAL_CAPACITY, dtype=np.int8)
        self._terms = np.empty((4, _INITIAL_CAPACITY, 3))
        self._head = self._first_pending = self._tail = 0

    @property
    def counts(self) -> dict[WindStatus, int]:
        """Number of output samples per status so far."""
        return dict(self._counts)

    @property
    def n_pending(self) -> int:
        """Anemometer samples received but not yet returned."""
        return self._tail - self._head

    def add_nav(
        self, t_s, quat_xyzw, angular_rate_body_rad_s, velocity_enu_mps, trusted: bool = True
    ) -> bool:
        """Add one navigation sample (stamp s, body→ENU quaternion xyzw, body rate rad/s,
        ENU velocity m/s; ``trusted`` False: no wind is corrected with it). Returns False when
        the track rejects it (counted there)."""
        return self.nav_track.append(
            t_s, quat_xyzw, angular_rate_body_rad_s, velocity_enu_mps, trusted
        )

    def add_wind(self, t_s, wind_sensor_mps) -> None:
        """Add one anemometer sample: stamp s, air velocity in anemometer axes m/s, (3,).
        In plain floats: the live path; :meth:`add_arrivals` takes stretches of samples."""
        try:
            x, y, z = (float(component) for component in wind_sensor_mps)
        except (TypeError, ValueError) as error:
            raise CompensatorInputError(
                f"wind_sensor_mps must be three numbers, got {wind_sensor_mps!r}"
            ) from error
        t_s = float(t_s)
        status, self._latest_wind_stamp_s = _screen_one_wind(
            t_s, x, y, z, self._latest_wind_stamp_s, self.config.max_wind_speed_mps
        )
        self._reserve(1)
        i = self._tail
        self._t_s[i] = t_s
        self._wind_mps[i] = x, y, z
        self._as_of_nav_s[i] = self._newest_nav_s()
        self._status[i] = status
        self._terms[:, i] = math.nan
        self._tail = i + 1
        self._advance_first_pending()

    def add_arrivals(self, nav, wind_t_s, wind_sensor_mps, nav_before_wind) -> int:
        """Navigation and anemometer samples that arrived interleaved: exactly :meth:`add_nav`
        of each navigation sample in order, with :meth:`add_wind` of wind sample ``i`` right
        after the first ``nav_before_wind[i]`` of them.

        Args:
            nav: (t_s, quat_xyzw, angular_rate_body_rad_s, velocity_enu_mps[, trusted]) of M
                navigation samples: (M,) stamps, s, (M, 4), (M, 3), (M, 3) arrays and (M,)
                bools of what :meth:`add_nav` takes.
            wind_t_s, wind_sensor_mps: (N,) stamps and (N, 3) winds, as :meth:`add_wind` takes
                them one by one.
            nav_before_wind: (N,) non-decreasing counts, 0 to M.

        Returns the number of navigation samples accepted.
        """
        stamps, winds = _wind_arrays(wind_t_s, wind_sensor_mps)
        newest_before = self._newest_nav_s()
        accepted = self.nav_track.extend(*nav)
        nav_t_s = np.asarray(nav[0], dtype=float)
        # Newest accepted navigation stamp after each number of navigation arrivals.
        newest_after = np.maximum.accumulate(
            np.concatenate(([newest_before], np.where(accepted, nav_t_s, -np.inf)))
        )
        self._enqueue(stamps, winds, newest_after[np.asarray(nav_before_wind, dtype=np.intp)])
        return int(np.count_nonzero(accepted))

    def ready(self) -> CorrectedWindBatch:
        """Every sample that can now be decided, in input order."""
        self._decide()
        return self._pop_decided()

    def expire(self, before_t_s: float) -> CorrectedWindBatch:
        """Decide what can be decided, give up on samples stamped before ``before_t_s`` (s)
        as NAVIGATION_TIMEOUT, and return the decided samples in input order."""
        self._decide()
        self._give_up(
            self._t_s[self._first_pending : self._tail] < before_t_s,
            WindStatus.NAVIGATION_TIMEOUT,
        )
        return self._pop_decided()

    def flush(self) -> CorrectedWindBatch:
        """End of data: decide every pending sample (NO_NAVIGATION where navigation never
        caught up) and return them in input order."""
        self._decide()
        self._give_up(True, WindStatus.NO_NAVIGATION)
        return self._pop_decided()

    def _newest_nav_s(self) -> float:
        return self.nav_track.newest_stamp_s if len(self.nav_track) else -math.inf

    def _enqueue(self, stamps: np.ndarray, winds: np.ndarray, as_of_nav_s: np.ndarray) -> None:
        status, self._latest_wind_stamp_s = _screen_wind(
            stamps, winds, self._latest_wind_stamp_s, self.config.max_wind_speed_mps
        )
        self._reserve(stamps.shape[0])
        new = slice(self._tail, self._tail + stamps.shape[0])
        self._t_s[new] = stamps
        self._wind_mps[new] = winds
        self._as_of_nav_s[new] = as_of_nav_s
        self._status[new] = status
        self._terms[:, new] = np.nan
        self._tail = new.stop
        self._advance_first_pending()

    def _decide(self) -> None:
        """Correct the pending samples that the navigation now brackets (or never will)."""
        first, tail = self._first_pending, self._tail
        newest_nav_s = self._newest_nav_s()
        if tail - first == 1:
            # The live case: only the newest sample waits (the one at _first_pending is).
            undecided = [first] if self._t_s[first] <= newest_nav_s else []
        else:
            # A stamp after the newest navigation sample can only wait: no need to look it up.
            undecided = first + np.flatnonzero(
                (self._status[first:tail] == _PENDING) & (self._t_s[first:tail] <= newest_nav_s)
            )
        if len(undecided) == 1:
            # One sample: in floats, bit-identical to the batch below.
            i = int(undecided[0])
            status, terms = self._corrector.correct_one(
                self.nav_track,
                float(self._t_s[i]),
                self._wind_mps[i].tolist(),
                float(self._as_of_nav_s[i]),
            )
            self._status[i] = status
            self._terms[:, i] = terms
        elif len(undecided):
            status, terms = self._corrector.correct(
                self.nav_track,
                self._t_s[undecided],
                self._wind_mps[undecided],
                self._as_of_nav_s[undecided],
            )
            self._status[undecided] = status
            self._terms[:, undecided] = terms
        self._advance_first_pending()
        # Every sample still pending is stamped after the newest navigation sample: the
        # samples around it stay held (see NavTrack.forget_old_samples).
        self.nav_track.forget_old_samples()

    def _give_up(self, which, status: WindStatus) -> None:
        """Decide as ``status`` the pending samples from ``_first_pending`` on where ``which``
        (a mask over them, or True for all) holds."""
        if self._first_pending == self._tail:
            return
        pending = self._status[self._first_pending : self._tail]
        pending[(pending == _PENDING) & which] = status
        self._advance_first_pending()

    def _advance_first_pending(self) -> None:
        first, tail = self._first_pending, self._tail
        if first < tail and self._status[first] == _PENDING:
            return
        pending = np.flatnonzero(self._status[first:tail] == _PENDING)
        self._first_pending = first + int(pending[0]) if pending.size else tail

    def _pop_decided(self) -> CorrectedWindBatch:
        if self._head == self._first_pending:
            return _NOTHING_DECIDED
        done = slice(self._head, self._first_pending)
        self._head = self._first_pending
        status = self._status[done].copy()
        for code, count in enumerate(np.bincount(status, minlength=len(WindStatus)).tolist()):
            self._counts[WindStatus(code)] += count
        true_wind, tilt, rotation, translation = self._terms[:, done].copy()
        return CorrectedWindBatch(
            self._t_s[done].copy(),
            status,
            true_wind,
            tilt,
            rotation,
            translation,
            self._wind_mps[done].copy(),
        )

    def _reserve(self, n_more: int) -> None:
        """Make room for ``n_more`` samples after the newest one, dropping the returned ones."""
        capacity = self._t_s.shape[0]
        if self._tail + n_more <= capacity:
            return
        kept = slice(self._head, self._tail)
        n_kept = self._tail - self._head
        new_capacity = max(capacity, _INITIAL_CAPACITY)
        while n_kept + n_more > new_capacity // 2:
            new_capacity *= 2
        for name in ("_t_s", "_wind_mps", "_as_of_nav_s", "_status"):
            old = getattr(self, name)
            new = np.empty((new_capacity, *old.shape[1:]), dtype=old.dtype)
            new[:n_kept] = old[kept]
            setattr(self, name, new)
        terms = np.empty((4, new_capacity, 3))
        terms[:, :n_kept] = self._terms[:, kept]
        self._terms = terms
        self._first_pending -= self._head
        self._head, self._tail = 0, n_kept


def _wind_arrays(t_s, wind_sensor_mps) -> tuple[np.ndarray, np.ndarray]:
    """(N,) stamps (s) and (N, 3) winds (m/s) as float arrays; CompensatorInputError if their
    shapes do not match."""
    stamps = np.asarray(t_s, dtype=float)
    winds = np.asarray(wind_sensor_mps, dtype=float)
    if stamps.ndim != 1 or winds.shape != (stamps.shape[0], 3):
        raise CompensatorInputError(
            f"stamps and winds must have shapes (N,) and (N, 3), got {stamps.shape} and "
            f"{winds.shape}"
        )
    return stamps, winds
