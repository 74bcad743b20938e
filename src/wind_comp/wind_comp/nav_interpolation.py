"""Time alignment of navigation samples to wind sample stamps.

A wind sample is corrected with the navigation state interpolated at its own stamp: attitude
by spherical linear interpolation between the two bracketing navigation samples, angular rate
and velocity linearly. Nothing is extrapolated: a stamp that is not bracketed, or whose
bracketing samples are too far apart, is reported invalid with a reason, and so is a stamp
whose bracketing samples include one the navigation does not vouch for (an attitude too
uncertain to correct the wind with, see :class:`wind_comp.config.CompensatorConfig`).
"""

import math
from enum import IntEnum
from typing import NamedTuple

import numpy as np
from scipy.spatial.transform import Rotation

from buoy_nav.rotations import quaternion_multiply


class NavTrackError(ValueError):
    """A navigation track was constructed or queried with malformed arguments."""


class InterpolationStatus(IntEnum):
    """Outcome of interpolating the navigation track at one stamp."""

    OK = 0
    """Bracketed by two samples at most ``max_gap_s`` apart, or exactly on a sample."""
    BEFORE_START = 1
    """Earlier than the first sample the track ever received; can never be bracketed."""
    AFTER_END = 2
    """No sample at or after the stamp yet (also for an empty track); a later sample may
    still bracket it."""
    GAP = 3
    """The bracketing samples are more than ``max_gap_s`` apart."""
    EVICTED = 4
    """The bracketing samples are older than the history kept (see :class:`NavTrack`)."""
    INVALID_STAMP = 5
    """The query stamp is not finite."""
    UNTRUSTED = 6
    """A bracketing sample is marked untrusted (its attitude is too uncertain)."""


class InterpolatedNav(NamedTuple):
    """Navigation state at N query stamps.

    Invalid entries hold the identity attitude and NaN rate and velocity.
    """

    valid: np.ndarray
    """(N,) bool."""
    status: np.ndarray
    """(N,) int8 codes of :class:`InterpolationStatus`."""
    attitude_xyzw: np.ndarray
    """(N, 4) unit body→ENU quaternions."""
    angular_rate_body_rad_s: np.ndarray
    """(N, 3) body rate, body axes, rad/s."""
    velocity_enu_mps: np.ndarray
    """(N, 3) ENU velocity of the body origin, m/s."""

    @property
    def attitude_nb(self) -> Rotation:
        """The N body→ENU attitudes as scipy rotations."""
        return Rotation.from_quat(self.attitude_xyzw)


_INITIAL_CAPACITY = 256
MIN_QUATERNION_NORM = 1e-9
"""Quaternions shorter than this cannot be normalised into an attitude."""


class NavTrack:
    """Bounded, time-ordered history of navigation samples with vectorised interpolation.

    Samples are appended in strictly increasing stamp order; a sample whose stamp is not later
    than the newest accepted one is rejected and counted, as is a sample with a non-finite
    value or a zero quaternion.

    The history is bounded to ``history_s``: a query is answered from the samples needed for
    stamps at or after ``newest - history_s`` (the last sample at or before that horizon and
    every later one); a stamp whose bracketing samples are older is EVICTED. ``newest`` is the
    newest stamp when the query was asked: :meth:`interpolate` takes it per query
    (``as_of_newest_s``), so that queries asked while samples kept arriving are answered as
    they would have been at the time, whenever they are evaluated. The samples themselves are
    dropped only by :meth:`forget_old_samples`, which frees what no query asked from then on
    needs.
    """

    def __init__(self, max_gap_s: float = 0.1, history_s: float = np.inf):
        """Args:
        max_gap_s: largest spacing of two bracketing samples that still allows
            interpolation, s.
        history_s: how far back from the newest sample queries are answered, s (``inf``
            keeps everything).
        """
        if not (np.isfinite(max_gap_s) and max_gap_s > 0):
            raise NavTrackError(f"max_gap_s must be a positive number of seconds, got {max_gap_s}")
        if not history_s > 0:
            raise NavTrackError(f"history_s must be positive (s), got {history_s}")
        self.max_gap_s = float(max_gap_s)
        self.history_s = float(history_s)
        self._stamps_s = np.empty(_INITIAL_CAPACITY)
        self._quats_xyzw = np.empty((_INITIAL_CAPACITY, 4))
        self._rates_body_rad_s = np.empty((_INITIAL_CAPACITY, 3))
        self._velocities_enu_mps = np.empty((_INITIAL_CAPACITY, 3))
        self._trusted = np.empty(_INITIAL_CAPACITY, dtype=bool)
        self._start = 0
        self._end = 0
        self._first_stamp_s = np.nan
        self.n_accepted = 0
        self.n_rejected_out_of_order = 0
        self.n_rejected_invalid = 0

    @classmethod
    def from_arrays(
        cls,
        t_s,
        quat_xyzw,
        angular_rate_body_rad_s,
        velocity_enu_mps,
        max_gap_s: float = 0.1,
    ) -> "NavTrack":
        """Build an unbounded track from whole arrays, applying the same acceptance rules as
        appending the samples one by one in array order.

        Args:
            t_s: (N,) stamps, s. quat_xyzw: (N, 4) body→ENU attitude.
            angular_rate_body_rad_s: (N, 3). velocity_enu_mps: (N, 3).
        """
        track = cls(max_gap_s=max_gap_s)
        track.extend(t_s, quat_xyzw, angular_rate_body_rad_s, velocity_enu_mps)
        return track

    def __len__(self) -> int:
        return self._end - self._start

    @property
    def newest_stamp_s(self) -> float:
        """Stamp of the newest sample, s (NaN when empty)."""
        return float(self._stamps_s[self._end - 1]) if len(self) else np.nan

    @property
    def oldest_stamp_s(self) -> float:
        """Stamp of the oldest retained sample, s (NaN when empty)."""
        return float(self._stamps_s[self._start]) if len(self) else np.nan

    def append(
        self, t_s, quat_xyzw, angular_rate_body_rad_s, velocity_enu_mps, trusted: bool = True
    ) -> bool:
        """Add one sample; return False (and count it) when it is rejected. Exactly
        :meth:`extend` of one sample, in plain floats: the live path, one sample at a time.

        Args:
            t_s: stamp, s. quat_xyzw: 4 values, body→ENU attitude, any non-zero norm.
            angular_rate_body_rad_s: 3 values, body axes. velocity_enu_mps: 3 values, ENU.
            trusted: False for a sample no wind may be corrected with (UNTRUSTED).
        """
        stamp = float(t_s)
        quat = _floats("quat_xyzw", quat_xyzw, 4)
        rate = _floats("angular_rate_body_rad_s", angular_rate_body_rad_s, 3)
        velocity = _floats("velocity_enu_mps", velocity_enu_mps, 3)
        norm = quaternion_norm(*quat)
        if not (
            math.isfinite(stamp)
            and all(math.isfinite(value) for value in (*quat, *rate, *velocity))
            and norm > MIN_QUATERNION_NORM
        ):
            self.n_rejected_invalid += 1
            return False
        if len(self) and not stamp > self._stamps_s[self._end - 1]:
            self.n_rejected_out_of_order += 1
            return False
        self._reserve(1)
        end = self._end
        self._stamps_s[end] = stamp
        self._quats_xyzw[end] = [component / norm for component in quat]
        self._rates_body_rad_s[end] = rate
        self._velocities_enu_mps[end] = velocity
        self._trusted[end] = trusted
        self._end = end + 1
        if math.isnan(self._first_stamp_s):
            self._first_stamp_s = stamp
        self.n_accepted += 1
        return True

    def extend(
        self, t_s, quat_xyzw, angular_rate_body_rad_s, velocity_enu_mps, trusted=True
    ) -> np.ndarray:
        """Add samples in array order, exactly as appending them one by one would (a sample is
        rejected and counted when malformed or not later than the newest accepted one); returns
        the (N,) mask of the accepted ones.

        Args:
            t_s: (N,) stamps, s. quat_xyzw: (N, 4) body→ENU attitude.
            angular_rate_body_rad_s: (N, 3). velocity_enu_mps: (N, 3).
            trusted: (N,) bools or one for all, as :meth:`append` takes it.
        """
        stamps, quats, rates, velocities = _validated_arrays(
            t_s, quat_xyzw, angular_rate_body_rad_s, velocity_enu_mps
        )
        well_formed = _well_formed(stamps, quats, rates, velocities)
        newest = self.newest_stamp_s if len(self) else -np.inf
        candidate_stamps = np.where(well_formed, stamps, -np.inf)
        latest_before = np.maximum.accumulate(np.concatenate(([newest], candidate_stamps)))[:-1]
        accepted = well_formed & (stamps > latest_before)
        n_accepted = int(np.count_nonzero(accepted))
        self.n_rejected_invalid += int(np.count_nonzero(~well_formed))
        self.n_rejected_out_of_order += int(np.count_nonzero(well_formed & ~accepted))
        if n_accepted == 0:
            return accepted
        self._reserve(n_accepted)
        end = self._end + n_accepted
        self._stamps_s[self._end : end] = stamps[accepted]
        self._quats_xyzw[self._end : end] = _normalised(quats[accepted])
        self._rates_body_rad_s[self._end : end] = rates[accepted]
        self._velocities_enu_mps[self._end : end] = velocities[accepted]
        self._trusted[self._end : end] = np.broadcast_to(trusted, accepted.shape)[accepted]
        self._end = end
        if np.isnan(self._first_stamp_s):
            self._first_stamp_s = float(stamps[accepted][0])
        self.n_accepted += n_accepted
        return accepted

    def forget_old_samples(self) -> None:
        """Drop the samples that no query asked as of the newest stamp or later needs."""
        if len(self):
            self._discard_before(self._stamps_s[self._end - 1] - self.history_s)

    def interpolate(self, t_query_s, as_of_newest_s=None) -> InterpolatedNav:
        """Navigation state at the (N,) query stamps, s; see :class:`InterpolationStatus`.

        A query exactly on a sample stamp returns that sample. Otherwise the bracketing pair is
        the last sample before and the first sample after the query; attitude is slerped along
        the shortest arc between them, rate and velocity are linear in time.

        ``as_of_newest_s``: (N,) or scalar newest stamp (s) when each query was asked, which
        bounds the history it is answered from (-inf: no sample yet); default: the newest now.
        Samples dropped by :meth:`forget_old_samples` answer no query any more.
        """
        queries = np.asarray(t_query_s, dtype=float)
        if queries.ndim != 1:
            raise NavTrackError(f"t_query_s must have shape (N,), got {queries.shape}")
        n_queries = queries.shape[0]
        stamps = self._stamps_s[self._start : self._end]
        n_samples = stamps.shape[0]
        kept_from = self._kept_from(stamps, as_of_newest_s)

        status = np.full(n_queries, InterpolationStatus.OK, dtype=np.int8)
        lower = np.searchsorted(stamps, queries, side="right") - 1
        finite = np.isfinite(queries)
        lower_c = np.clip(lower, 0, max(n_samples - 1, 0))
        exact = finite & (lower >= 0) & (n_samples > 0)
        if n_samples:
            exact &= stamps[lower_c] == queries
        upper = np.where(exact, lower, lower + 1)
        upper_c = np.clip(upper, 0, max(n_samples - 1, 0))

        before_track = finite & (lower < kept_from) & (n_samples > 0)
        never_received = queries < self._first_stamp_s
        status[before_track & never_received] = InterpolationStatus.BEFORE_START
        status[before_track & ~never_received] = InterpolationStatus.EVICTED
        status[finite & ~before_track & (upper >= n_samples)] = InterpolationStatus.AFTER_END
        bracketed = finite & ~before_track & (upper < n_samples)
        if n_samples:
            spacing = stamps[upper_c] - stamps[lower_c]
            status[bracketed & (spacing > self.max_gap_s)] = InterpolationStatus.GAP
            trusted = self._trusted[self._start : self._end]
            untrusted = ~(trusted[lower_c] & trusted[upper_c])
            status[bracketed & (spacing <= self.max_gap_s) & untrusted] = (
                InterpolationStatus.UNTRUSTED
            )
        status[~finite] = InterpolationStatus.INVALID_STAMP
        valid = status == InterpolationStatus.OK

        rates = np.full((n_queries, 3), np.nan)
        velocities = np.full((n_queries, 3), np.nan)
        quats = np.tile([0.0, 0.0, 0.0, 1.0], (n_queries, 1))
        if np.any(valid):
            lo = lower_c[valid] + self._start
            hi = upper_c[valid] + self._start
            span = self._stamps_s[hi] - self._stamps_s[lo]
            fraction = np.divide(
                queries[valid] - self._stamps_s[lo],
                span,
                out=np.zeros_like(span),
                where=span > 0,
            )[:, None]
            rates[valid] = self._rates_body_rad_s[lo] + fraction * (
                self._rates_body_rad_s[hi] - self._rates_body_rad_s[lo]
            )
            velocities[valid] = self._velocities_enu_mps[lo] + fraction * (
                self._velocities_enu_mps[hi] - self._velocities_enu_mps[lo]
            )
            quats[valid] = slerp(self._quats_xyzw[lo], self._quats_xyzw[hi], fraction[:, 0])
        return InterpolatedNav(valid, status, quats, rates, velocities)

    def interpolate_one(
        self, t_query_s: float, as_of_newest_s: float | None = None
    ) -> tuple[int, tuple, tuple, tuple]:
        """:meth:`interpolate` at one stamp (s), in plain floats: (status code, attitude
        (x, y, z, w), body rate (3,) rad/s, ENU velocity (3,) m/s), bit-identical to the
        batch; the live path, where numpy's per-call cost would dominate."""
        t_s = float(t_query_s)
        if not math.isfinite(t_s):
            return InterpolationStatus.INVALID_STAMP, *_INVALID_NAV
        start, end = self._start, self._end
        if start == end:
            return InterpolationStatus.AFTER_END, *_INVALID_NAV
        stamps = self._stamps_s
        lower = int(np.searchsorted(stamps[start:end], t_s, side="right")) - 1 + start
        if lower < start + self._kept_from(stamps[start:end], as_of_newest_s):
            if t_s < self._first_stamp_s:
                return InterpolationStatus.BEFORE_START, *_INVALID_NAV
            return InterpolationStatus.EVICTED, *_INVALID_NAV
        upper = lower if stamps[lower] == t_s else lower + 1
        if upper >= end:
            return InterpolationStatus.AFTER_END, *_INVALID_NAV
        lower_stamp_s, upper_stamp_s = float(stamps[lower]), float(stamps[upper])
        span_s = upper_stamp_s - lower_stamp_s
        if span_s > self.max_gap_s:
            return InterpolationStatus.GAP, *_INVALID_NAV
        if not (self._trusted[lower] and self._trusted[upper]):
            return InterpolationStatus.UNTRUSTED, *_INVALID_NAV
        fraction = (t_s - lower_stamp_s) / span_s if span_s > 0 else 0.0
        rates, velocities = self._rates_body_rad_s, self._velocities_enu_mps
        rate = _lerp(rates[lower].tolist(), rates[upper].tolist(), fraction)
        velocity = _lerp(velocities[lower].tolist(), velocities[upper].tolist(), fraction)
        quats = self._quats_xyzw
        attitude = slerp_components(quats[lower].tolist(), quats[upper].tolist(), fraction)
        return InterpolationStatus.OK, tuple(map(float, attitude)), rate, velocity

    def _kept_from(self, stamps: np.ndarray, as_of_newest_s):
        """Index into ``stamps`` (the samples held) of the first sample that a query asked as of
        ``as_of_newest_s`` (s, scalar or (N,); None: the newest now) may use."""
        if as_of_newest_s is None:
            if not stamps.shape[0]:
                return 0
            as_of_newest_s = float(stamps[-1])
        if isinstance(as_of_newest_s, float):
            horizon_s = as_of_newest_s - self.history_s
            # The common case, live: nothing held is older than the query may use.
            if stamps.shape[0] < 2 or not horizon_s >= stamps[1]:
                return 0
            return int(np.searchsorted(stamps, horizon_s, side="right")) - 1
        horizons_s = np.asarray(as_of_newest_s, dtype=float) - self.history_s
        return np.maximum(np.searchsorted(stamps, horizons_s, side="right") - 1, 0)

    def _discard_before(self, horizon_s: float) -> None:
        """Drop samples not needed to answer queries at or after ``horizon_s``: keep the last
        sample at or before the horizon and everything after it."""
        stamps = self._stamps_s[self._start : self._end]
        keep_from = int(np.searchsorted(stamps, horizon_s, side="right")) - 1
        if keep_from > 0:
            self._start += keep_from

    def _reserve(self, n_more: int) -> None:
        """Make room for ``n_more`` samples after the newest one."""
        capacity = self._stamps_s.shape[0]
        if self._end + n_more <= capacity:
            return
        n_kept = len(self)
        new_capacity = max(capacity, _INITIAL_CAPACITY)
        while n_kept + n_more > new_capacity // 2:
            new_capacity *= 2
        for name in (
            "_stamps_s",
            "_quats_xyzw",
            "_rates_body_rad_s",
            "_velocities_enu_mps",
            "_trusted",
        ):
            old = getattr(self, name)
            new = np.empty((new_capacity, *old.shape[1:]), dtype=old.dtype)
            new[:n_kept] = old[self._start : self._end]
            setattr(self, name, new)
        self._start = 0
        self._end = n_kept


# The quaternion arithmetic below is written elementwise, component by component, on floats or
# equally shaped arrays: a sample then gives bit-identical results whether it is interpolated
# alone (floats, live) or in a batch (arrays, offline), and a single sample costs microseconds.


def slerp(start_xyzw: np.ndarray, end_xyzw: np.ndarray, fraction: np.ndarray) -> np.ndarray:
    """:func:`slerp_components` of (N, 4) unit xyzw quaternions at (N,) fractions."""
    return np.stack(slerp_components(tuple(start_xyzw.T), tuple(end_xyzw.T), fraction), axis=1)


def slerp_components(start_xyzw, end_xyzw, fraction) -> tuple:
    """Spherical interpolation along the shortest arc between unit quaternions given as
    (x, y, z, w) components, at ``fraction`` of the way (0: start, 1: end):
    start ⊗ exp(fraction · log(start* ⊗ end)). Components and fraction are floats or arrays
    of one shape."""
    x, y, z, w = start_xyzw
    step_x, step_y, step_z, step_w = quaternion_multiply((-x, -y, -z, w), end_xyzw)
    # q and −q are the same rotation; the one with w ≥ 0 is the short way round.
    sign = np.where(step_w < 0.0, -1.0, 1.0)
    step_x, step_y, step_z, step_w = step_x * sign, step_y * sign, step_z * sign, step_w * sign
    sin_half_angle = np.sqrt(step_x * step_x + step_y * step_y + step_z * step_z)
    partial_half_angle = fraction * np.arctan2(sin_half_angle, step_w)
    # sin(f·θ/2) / sin(θ/2) → f as θ → 0; the vector part is zero there anyway.
    turning = sin_half_angle > 0.0
    vector_scale = np.where(
        turning, np.sin(partial_half_angle) / np.where(turning, sin_half_angle, 1.0), fraction
    )
    partial = (
        step_x * vector_scale,
        step_y * vector_scale,
        step_z * vector_scale,
        np.cos(partial_half_angle),
    )
    return quaternion_multiply(start_xyzw, partial)


_INVALID_NAV = ((0.0, 0.0, 0.0, 1.0), (math.nan,) * 3, (math.nan,) * 3)


def _lerp(start: list[float], end: list[float], fraction: float) -> tuple[float, ...]:
    return tuple(a + fraction * (b - a) for a, b in zip(start, end, strict=True))


def _floats(name: str, values, length: int) -> tuple[float, ...]:
    """``values`` as a tuple of ``length`` floats; NavTrackError naming ``name`` otherwise."""
    try:
        numbers = tuple(map(float, values))
    except (TypeError, ValueError) as error:
        raise NavTrackError(f"{name} must be {length} numbers, got {values!r}") from error
    if len(numbers) != length:
        raise NavTrackError(f"{name} must be {length} numbers, got {len(numbers)}")
    return numbers


def _validated_arrays(t_s, quat_xyzw, angular_rate_body_rad_s, velocity_enu_mps):
    """Convert to float arrays of matching length N, raising on wrong shapes."""
    stamps = np.asarray(t_s, dtype=float)
    quats = np.asarray(quat_xyzw, dtype=float)
    rates = np.asarray(angular_rate_body_rad_s, dtype=float)
    velocities = np.asarray(velocity_enu_mps, dtype=float)
    if stamps.ndim != 1:
        raise NavTrackError(f"navigation stamps must have shape (N,), got {stamps.shape}")
    n_samples = stamps.shape[0]
    for name, array, width in (
        ("quat_xyzw", quats, 4),
        ("angular_rate_body_rad_s", rates, 3),
        ("velocity_enu_mps", velocities, 3),
    ):
        if array.shape != (n_samples, width):
            raise NavTrackError(
                f"{name} must have shape ({n_samples}, {width}) to match the stamps, "
                f"got {array.shape}"
            )
    return stamps, quats, rates, velocities


def _well_formed(stamps, quats, rates, velocities) -> np.ndarray:
    """(N,) True where every value is finite and the quaternion is not zero."""
    finite = (
        np.isfinite(stamps)
        & np.all(np.isfinite(quats), axis=1)
        & np.all(np.isfinite(rates), axis=1)
        & np.all(np.isfinite(velocities), axis=1)
    )
    return finite & (
        quaternion_norm(*np.where(finite[:, None], quats, 0.0).T) > MIN_QUATERNION_NORM
    )


def quaternion_norm(x, y, z, w):
    """|q| of components (floats or arrays), written out so that one sample and a batch agree
    bit for bit."""
    return np.sqrt(x * x + y * y + z * z + w * w)


def _normalised(quats: np.ndarray) -> np.ndarray:
    return quats / quaternion_norm(*quats.T)[:, None]
