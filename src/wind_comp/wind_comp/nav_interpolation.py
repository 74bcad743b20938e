"""Time alignment of navigation samples to wind sample stamps.

A wind sample is corrected with the navigation state interpolated at its own stamp: attitude
by spherical linear interpolation between the two bracketing navigation samples, angular rate
and velocity linearly, and so the covariances of the attitude, the velocity and the rate (a
convex combination of covariances is one). Nothing is extrapolated: a stamp that is not
bracketed, or whose bracketing samples are too far apart, is reported invalid with a reason,
and so is a stamp whose bracketing samples include one the navigation does not vouch for (an
attitude too uncertain to correct the wind with, see
:class:`wind_comp.config.CompensatorConfig`).
"""

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

    Invalid entries hold the identity attitude and NaN rate, velocity and covariances.
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
    attitude_covariance_enu_rad2: np.ndarray
    """(N, 3, 3) attitude error as a small rotation about the ENU axes, rad²."""
    velocity_covariance_enu_m2s2: np.ndarray
    """(N, 3, 3) ENU velocity error, m²/s²."""
    angular_rate_covariance_body_rad2s2: np.ndarray
    """(N, 3, 3) body rate error, body axes, rad²/s²."""

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

    One sample or many go through the same arithmetic: :meth:`append` is :meth:`extend` of
    one sample, and a single query is :meth:`interpolate` of one stamp.
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
        self._samples = _NavSamples()
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
        return len(self._samples)

    @property
    def newest_stamp_s(self) -> float:
        """Stamp of the newest sample, s (NaN when empty)."""
        return float(self._samples.stamps_s[-1]) if len(self) else np.nan

    @property
    def oldest_stamp_s(self) -> float:
        """Stamp of the oldest retained sample, s (NaN when empty)."""
        return float(self._samples.stamps_s[0]) if len(self) else np.nan

    def append(
        self,
        t_s,
        quat_xyzw,
        angular_rate_body_rad_s,
        velocity_enu_mps,
        trusted: bool = True,
        covariances=None,
    ) -> bool:
        """Add one sample; return False (and count it) when it is rejected: :meth:`extend`
        of one sample.

        Args:
            t_s: stamp, s. quat_xyzw: 4 values, body→ENU attitude, any non-zero norm.
            angular_rate_body_rad_s: 3 values, body axes. velocity_enu_mps: 3 values, ENU.
            trusted: False for a sample no wind may be corrected with (UNTRUSTED).
            covariances: (3, 3, 3) as :meth:`extend` takes them for one sample, or None.
        """
        accepted = self.extend(
            [t_s],
            [quat_xyzw],
            [angular_rate_body_rad_s],
            [velocity_enu_mps],
            [trusted],
            None if covariances is None else [covariances],
        )
        return bool(accepted[0])

    def extend(
        self,
        t_s,
        quat_xyzw,
        angular_rate_body_rad_s,
        velocity_enu_mps,
        trusted=True,
        covariances=None,
    ) -> np.ndarray:
        """Add samples in array order, exactly as appending them one by one would (a sample is
        rejected and counted when malformed or not later than the newest accepted one); returns
        the (N,) mask of the accepted ones.

        Args:
            t_s: (N,) stamps, s. quat_xyzw: (N, 4) body→ENU attitude.
            angular_rate_body_rad_s: (N, 3). velocity_enu_mps: (N, 3).
            trusted: (N,) bools or one for all, as :meth:`append` takes it.
            covariances: (N, 3, 3, 3): each sample's attitude error covariance (a rotation
                about the ENU axes, rad²), ENU velocity covariance (m²/s²) and body rate
                covariance (body axes, rad²/s²); None: zeros, no error known.
        """
        stamps, quats, rates, velocities = _validated_arrays(
            t_s, quat_xyzw, angular_rate_body_rad_s, velocity_enu_mps
        )
        covariances = _covariance_array(covariances, stamps.shape[0])
        well_formed = _well_formed(stamps, quats, rates, velocities)
        accepted = well_formed & _later_than_every_earlier(
            np.where(well_formed, stamps, -np.inf), self._newest_or_minus_inf()
        )
        n_accepted = int(np.count_nonzero(accepted))
        self.n_rejected_invalid += int(np.count_nonzero(~well_formed))
        self.n_rejected_out_of_order += int(np.count_nonzero(well_formed)) - n_accepted
        self.n_accepted += n_accepted
        trusted = np.broadcast_to(trusted, accepted.shape)
        columns = (stamps, quats, rates, velocities, trusted, covariances)
        if n_accepted < accepted.shape[0]:
            columns = tuple(column[accepted] for column in columns)
        if n_accepted:
            stamps, quats, *others = columns
            self._samples.add(stamps, _normalised(quats), *others)
        return accepted

    def forget_old_samples(self) -> None:
        """Drop the samples that no query asked as of the newest stamp or later needs."""
        if len(self):
            stamps = self._samples.stamps_s
            self._samples.drop_oldest(_first_usable(stamps, stamps[-1] - self.history_s))

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
        if as_of_newest_s is None:
            as_of_newest_s = self._newest_or_minus_inf()
        samples = self._samples
        horizons_s = np.asarray(as_of_newest_s, dtype=float) - self.history_s
        lower, upper = _bracketing_indices(samples.stamps_s, queries)
        status = _interpolation_status(
            samples,
            queries,
            lower,
            upper,
            _first_usable(samples.stamps_s, horizons_s),
            self.max_gap_s,
        )
        return _interpolated(samples, queries, lower, upper, status)

    def _newest_or_minus_inf(self) -> float:
        return float(self._samples.stamps_s[-1]) if len(self) else -np.inf


class _NavSamples:
    """The accepted navigation samples in growable columns, oldest kept first; the columns
    are views of the samples held (index 0: the oldest still held)."""

    _COLUMNS = (
        "_stamps_s",
        "_quats_xyzw",
        "_rates_body_rad_s",
        "_velocities_enu_mps",
        "_trusted",
        "_covariances",
    )

    def __init__(self):
        self._stamps_s = np.empty(_INITIAL_CAPACITY)
        self._quats_xyzw = np.empty((_INITIAL_CAPACITY, 4))
        self._rates_body_rad_s = np.empty((_INITIAL_CAPACITY, 3))
        self._velocities_enu_mps = np.empty((_INITIAL_CAPACITY, 3))
        self._trusted = np.empty(_INITIAL_CAPACITY, dtype=bool)
        self._covariances = np.empty((_INITIAL_CAPACITY, 3, 3, 3))
        self._start = 0
        self._end = 0
        self.first_stamp_s = np.nan
        """Stamp of the first sample ever held, s (NaN before the first)."""

    def __len__(self) -> int:
        return self._end - self._start

    @property
    def stamps_s(self) -> np.ndarray:
        """(N,) increasing stamps, s."""
        return self._stamps_s[self._start : self._end]

    @property
    def quats_xyzw(self) -> np.ndarray:
        """(N, 4) unit body→ENU quaternions."""
        return self._quats_xyzw[self._start : self._end]

    @property
    def rates_body_rad_s(self) -> np.ndarray:
        """(N, 3) body rates, body axes, rad/s."""
        return self._rates_body_rad_s[self._start : self._end]

    @property
    def velocities_enu_mps(self) -> np.ndarray:
        """(N, 3) ENU velocities, m/s."""
        return self._velocities_enu_mps[self._start : self._end]

    @property
    def trusted(self) -> np.ndarray:
        """(N,) bools: False where the navigation does not vouch for the attitude."""
        return self._trusted[self._start : self._end]

    @property
    def covariances(self) -> np.ndarray:
        """(N, 3, 3, 3) covariances of the attitude (ENU, rad²), the ENU velocity (m²/s²) and
        the body rate (rad²/s²)."""
        return self._covariances[self._start : self._end]

    def add(
        self, stamps_s, quats_xyzw, rates_body_rad_s, velocities_enu_mps, trusted, covariances
    ) -> None:
        """Hold accepted samples after the newest one (stamps later, quaternions unit)."""
        n_new = stamps_s.shape[0]
        self._reserve(n_new)
        new = slice(self._end, self._end + n_new)
        for name, values in zip(
            self._COLUMNS,
            (stamps_s, quats_xyzw, rates_body_rad_s, velocities_enu_mps, trusted, covariances),
            strict=True,
        ):
            getattr(self, name)[new] = values
        self._end = new.stop
        if np.isnan(self.first_stamp_s):
            self.first_stamp_s = float(stamps_s[0])

    def drop_oldest(self, n_dropped: int) -> None:
        """Stop holding the ``n_dropped`` oldest samples."""
        self._start += int(n_dropped)

    def _reserve(self, n_more: int) -> None:
        """Make room for ``n_more`` samples after the newest one."""
        capacity = self._stamps_s.shape[0]
        if self._end + n_more <= capacity:
            return
        n_kept = len(self)
        new_capacity = max(capacity, _INITIAL_CAPACITY)
        while n_kept + n_more > new_capacity // 2:
            new_capacity *= 2
        for name in self._COLUMNS:
            old = getattr(self, name)
            new = np.empty((new_capacity, *old.shape[1:]), dtype=old.dtype)
            new[:n_kept] = old[self._start : self._end]
            setattr(self, name, new)
        self._start = 0
        self._end = n_kept


# Acceptance of navigation samples: the same rules for one sample and many.


def _validated_arrays(t_s, quat_xyzw, angular_rate_body_rad_s, velocity_enu_mps):
    """Convert to float arrays of matching length N, raising on wrong shapes."""
    stamps = _float_array("t_s", t_s)
    quats = _float_array("quat_xyzw", quat_xyzw)
    rates = _float_array("angular_rate_body_rad_s", angular_rate_body_rad_s)
    velocities = _float_array("velocity_enu_mps", velocity_enu_mps)
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


def _covariance_array(covariances, n_samples: int) -> np.ndarray:
    """(N, 3, 3, 3) float covariances of N samples, zeros for None; raises on a wrong shape."""
    if covariances is None:
        return np.zeros((n_samples, 3, 3, 3))
    covariances = _float_array("covariances", covariances)
    if covariances.shape != (n_samples, 3, 3, 3):
        raise NavTrackError(
            f"covariances must have shape ({n_samples}, 3, 3, 3) to match the stamps, "
            f"got {covariances.shape}"
        )
    return covariances


def _float_array(name: str, values) -> np.ndarray:
    try:
        return np.asarray(values, dtype=float)
    except (TypeError, ValueError) as error:
        raise NavTrackError(f"{name} must be numbers, got {values!r}") from error


def _well_formed(stamps, quats, rates, velocities) -> np.ndarray:
    """(N,) True where every value is finite and the quaternion is not zero."""
    finite = np.isfinite(np.column_stack((stamps, quats, rates, velocities))).all(axis=1)
    return finite & (
        quaternion_norm(*np.where(finite[:, None], quats, 0.0).T) > MIN_QUATERNION_NORM
    )


def _later_than_every_earlier(stamps_s: np.ndarray, newest_s: float) -> np.ndarray:
    """(N,) True where a stamp is later than ``newest_s`` and every earlier stamp (-inf
    stamps are never later)."""
    running_newest = np.maximum.accumulate(np.concatenate(([newest_s], stamps_s)))
    return stamps_s > running_newest[:-1]


# Interpolation at query stamps, on columns of any length.


def _first_usable(stamps_s: np.ndarray, horizon_s):
    """Index into ``stamps_s`` of the first sample a query with history horizon ``horizon_s``
    (s, scalar or (N,)) may use: the last one at or before the horizon, else the first."""
    return np.maximum(np.searchsorted(stamps_s, horizon_s, side="right") - 1, 0)


def _bracketing_indices(stamps_s: np.ndarray, queries_s: np.ndarray):
    """(N,) indices of the last sample at or before each query and of the sample after it
    (the same sample for a query exactly on it); -1 and ``len(stamps_s)`` stand for none."""
    lower = np.searchsorted(stamps_s, queries_s, side="right") - 1
    exact = np.zeros(queries_s.shape, dtype=bool)
    if stamps_s.shape[0]:
        exact = (lower >= 0) & (stamps_s[np.maximum(lower, 0)] == queries_s)
    return lower, np.where(exact, lower, lower + 1)


def _interpolation_status(samples, queries_s, lower, upper, kept_from, max_gap_s):
    """(N,) :class:`InterpolationStatus` codes of the queries bracketed by ``lower`` and
    ``upper``; ``kept_from``: the first sample index each query may use."""
    n_samples = len(samples)
    status = np.full(queries_s.shape[0], InterpolationStatus.OK, dtype=np.int8)
    finite = np.isfinite(queries_s)
    before_track = finite & (lower < kept_from) & (n_samples > 0)
    never_received = queries_s < samples.first_stamp_s
    status[before_track & never_received] = InterpolationStatus.BEFORE_START
    status[before_track & ~never_received] = InterpolationStatus.EVICTED
    status[finite & ~before_track & (upper >= n_samples)] = InterpolationStatus.AFTER_END
    bracketed = finite & ~before_track & (upper < n_samples)
    if n_samples:
        lower_c, upper_c = np.clip(lower, 0, n_samples - 1), np.clip(upper, 0, n_samples - 1)
        too_far_apart = samples.stamps_s[upper_c] - samples.stamps_s[lower_c] > max_gap_s
        untrusted = ~(samples.trusted[lower_c] & samples.trusted[upper_c])
        status[bracketed & too_far_apart] = InterpolationStatus.GAP
        status[bracketed & ~too_far_apart & untrusted] = InterpolationStatus.UNTRUSTED
    status[~finite] = InterpolationStatus.INVALID_STAMP
    return status


def _interpolated(samples, queries_s, lower, upper, status) -> InterpolatedNav:
    """The navigation at the queries whose ``status`` is OK, between the samples ``lower`` and
    ``upper``; the identity attitude and NaN elsewhere."""
    n_queries = queries_s.shape[0]
    valid = status == InterpolationStatus.OK
    rates = np.full((n_queries, 3), np.nan)
    velocities = np.full((n_queries, 3), np.nan)
    covariances = np.full((n_queries, 3, 3, 3), np.nan)
    quats = np.tile([0.0, 0.0, 0.0, 1.0], (n_queries, 1))
    if np.any(valid):
        lo, hi = lower[valid], upper[valid]
        stamps = samples.stamps_s
        span = stamps[hi] - stamps[lo]
        fraction = np.divide(
            queries_s[valid] - stamps[lo], span, out=np.zeros_like(span), where=span > 0
        )
        rates[valid] = _lerp(samples.rates_body_rad_s, lo, hi, fraction)
        velocities[valid] = _lerp(samples.velocities_enu_mps, lo, hi, fraction)
        covariances[valid] = _lerp(samples.covariances, lo, hi, fraction)
        quats[valid] = slerp(samples.quats_xyzw[lo], samples.quats_xyzw[hi], fraction)
    return InterpolatedNav(valid, status, quats, rates, velocities, *covariances.swapaxes(0, 1))


def _lerp(values: np.ndarray, lower, upper, fraction: np.ndarray) -> np.ndarray:
    """Rows ``lower`` of ``values`` moved ``fraction`` of the way to rows ``upper``."""
    weights = fraction.reshape(-1, *(1,) * (values.ndim - 1))
    return values[lower] + weights * (values[upper] - values[lower])


# Quaternion maths. Written elementwise, component by component, on floats or equally shaped
# arrays: what a sample gives does not depend on the other samples of its batch.


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


def quaternion_norm(x, y, z, w):
    """|q| of components (floats or arrays), written out so that one sample and a batch agree
    bit for bit."""
    return np.sqrt(x * x + y * y + z * z + w * w)


def _normalised(quats: np.ndarray) -> np.ndarray:
    return quats / quaternion_norm(*quats.T)[:, None]
