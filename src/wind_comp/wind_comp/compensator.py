"""Motion compensation of a flow sensor, shared by the live nodes and offline processing.

A flow sensor measures the velocity of a fluid relative to itself, in its own axes, from a
moving platform: an anemometer the air's, a DVL in water track the water's (its reading is its
own velocity through the water, the negative of the water's past it). Removing the platform's
motion with the Miller correction (:mod:`wind_comp.miller`) gives the fluid's velocity over
ground, ENU: the true wind, or the current.

Navigation samples (:meth:`FlowCompensator.add_nav`) and sensor samples
(:meth:`FlowCompensator.add_sample`) go in, in the order they arrive; every sensor sample comes
out exactly once (:meth:`FlowCompensator.ready`), in input order, with its own stamp: either
the motion-corrected flow or NaN with the reason it could not be corrected. A sample held off
the sensor's sequence of stamps (:mod:`buoy_nav.stream_sequence`) waits, and the samples after
it behind it, until :meth:`FlowCompensator.settle_held` says whether it is the sensor's.

Whether and how a sample is corrected depends only on stamps (the navigation samples around
it), not on when messages happen to arrive, with two exceptions. The live-only
:meth:`FlowCompensator.expire` gives up on samples whose navigation is late. And a sample that
arrives lagging the newest navigation by more than ``nav_history_s`` finds its navigation
forgotten. Both depend on the order of arrival only, never on how often the results are
collected: samples may be added one at a time (the live nodes) or as stretches of interleaved
arrivals (:meth:`FlowCompensator.add_arrivals`, offline), with bit-identical results: both run
the same column arithmetic, on a batch of one sample or of many.
"""

import math
from dataclasses import dataclass
from enum import IntEnum
from typing import NamedTuple

import numpy as np

from buoy_common.contract import Reason
from wind_comp.correction_kernel import correct_samples
from wind_comp.flow_uncertainty import FlowCovariance, horizontal_and_vertical_sigma
from wind_comp.miller import mounting_rotation_from_rpy_deg
from wind_comp.nav_interpolation import InterpolatedNav, InterpolationStatus, NavTrack


class CompensatorInputError(ValueError):
    """Sample arrays given to the compensator have the wrong shape."""


class SampleStatus(IntEnum):
    """Outcome of correcting one sensor sample."""

    VALID = 0
    NO_NAVIGATION = 1
    """No navigation sample on one side of the stamp (before the first or after the last)."""
    NAV_GAP = 2
    """The bracketing navigation samples are more than ``max_nav_gap_s`` apart."""
    NAVIGATION_TIMEOUT = 3
    """Given up by :meth:`FlowCompensator.expire` before navigation caught up."""
    NAV_HISTORY_EXCEEDED = 4
    """The stamp lags the newest navigation by more than ``nav_history_s``."""
    INVALID_MEASUREMENT = 5
    """The measured vector is not finite (flagged invalid by the sensor, or rejected)."""
    SPEED_OUT_OF_RANGE = 6
    """The measured speed exceeds the sensor's ``max_speed_mps``."""
    INVALID_STAMP = 7
    """The stamp is not finite, or not later than the previous sample's."""
    NAVIGATION_NOT_TRUSTED = 8
    """A bracketing navigation sample's attitude is more uncertain than
    ``max_attitude_sigma_deg`` (the navigation marks itself untrustworthy by its covariance)."""
    UNCERTAINTY_TOO_LARGE = 9
    """The corrected sample's own 1σ (from the navigation's covariance and the sensor's noise)
    exceeds the sensor's :class:`SigmaLimits`, horizontally or vertically."""
    OUT_OF_SEQUENCE = 10
    """Held off the sensor's sequence of stamps (:mod:`buoy_nav.stream_sequence`) and given up
    there: a second stream on the sensor's topic (or a stray sample)."""


class SigmaLimits(NamedTuple):
    """Largest 1σ of a corrected sample that is still valid, m/s."""

    horizontal_mps: float
    """Of the horizontal vector error, √(σ_E² + σ_N²)."""
    vertical_mps: float
    """Of the vertical component."""

    def exceeded(self, covariance_enu_m2s2: np.ndarray) -> np.ndarray:
        """(N,) True where an (N, 3, 3) ENU covariance (m²/s²) is beyond the limits, or not
        known (NaN)."""
        horizontal, vertical = horizontal_and_vertical_sigma(covariance_enu_m2s2)
        return ~((horizontal <= self.horizontal_mps) & (vertical <= self.vertical_mps))


NO_SIGMA_LIMITS = SigmaLimits(math.inf, math.inf)


@dataclass(frozen=True)
class FlowSensor:
    """A flow sensor on the platform, as the correction sees it.

    Attributes:
        position_body_m: measurement centre in ``base_link``, m (Miller's lever arm).
        rpy_deg: roll, pitch, yaw of the sensor's axes relative to ``base_link``, deg, applied
            as Rz(yaw)·Ry(pitch)·Rx(roll).
        max_speed_mps: measured speeds above this are absurd and rejected, m/s.
        invalid_reason, speed_reason: the contract's words for INVALID_MEASUREMENT and
            SPEED_OUT_OF_RANGE of this sensor (``invalid_wind``, ``invalid_dvl``, ...).
        sigma_limits: a corrected sample beyond them is UNCERTAINTY_TOO_LARGE.
        noise_variances_m2s2: variances of one sample's noise along the sensor's x, y, z
            axes, m²/s²: of a sample that does not state its own noise.
    """

    position_body_m: tuple[float, float, float]
    rpy_deg: tuple[float, float, float]
    max_speed_mps: float
    invalid_reason: Reason
    speed_reason: Reason
    sigma_limits: SigmaLimits = NO_SIGMA_LIMITS
    noise_variances_m2s2: tuple[float, float, float] = (0.0, 0.0, 0.0)

    @property
    def noise_covariance_m2s2(self) -> tuple:
        """The noise of a sample that states none, sensor axes, m²/s², 9 row-major values:
        independent along the axes, of ``noise_variances_m2s2``."""
        x, y, z = self.noise_variances_m2s2
        return (x, 0.0, 0.0, 0.0, y, 0.0, 0.0, 0.0, z)

    def reason(self, status: SampleStatus) -> Reason:
        """Why a sample of this sensor is invalid, in the contract's words (not for VALID)."""
        if status == SampleStatus.INVALID_MEASUREMENT:
            return self.invalid_reason
        if status == SampleStatus.SPEED_OUT_OF_RANGE:
            return self.speed_reason
        return Reason[status.name]


_PENDING = -1
_HELD = -2
"""Held off the sensor's sequence until :meth:`FlowCompensator.settle_held` says whether it is
the sensor's: neither looked up nor given up by :meth:`FlowCompensator.expire`."""
_NAV_OUTCOME = {
    InterpolationStatus.OK: SampleStatus.VALID,
    InterpolationStatus.BEFORE_START: SampleStatus.NO_NAVIGATION,
    InterpolationStatus.AFTER_END: _PENDING,
    InterpolationStatus.GAP: SampleStatus.NAV_GAP,
    InterpolationStatus.EVICTED: SampleStatus.NAV_HISTORY_EXCEEDED,
    InterpolationStatus.INVALID_STAMP: SampleStatus.INVALID_STAMP,
    InterpolationStatus.UNTRUSTED: SampleStatus.NAVIGATION_NOT_TRUSTED,
}
_NAV_OUTCOME_BY_CODE = np.array(
    [_NAV_OUTCOME[InterpolationStatus(code)] for code in range(len(InterpolationStatus))],
    dtype=np.int8,
)


@dataclass(frozen=True, eq=False)
class CorrectedBatch:
    """N sensor samples after correction, in input order.

    The (N, 3) ENU vectors (m/s) and the covariances are NaN where ``status`` is not VALID;
    ``flow_enu_mps = tilt_term_enu_mps + rotation_term_enu_mps + translation_term_enu_mps``
    (see :mod:`wind_comp.miller`).
    """

    t_s: np.ndarray
    """(N,) header stamps of the sensor samples, s."""
    status: np.ndarray
    """(N,) int8 codes of :class:`SampleStatus`."""
    flow_enu_mps: np.ndarray
    """(N, 3) the fluid's velocity over ground, ENU, m/s: the true wind, or the current."""
    tilt_term_enu_mps: np.ndarray
    rotation_term_enu_mps: np.ndarray
    translation_term_enu_mps: np.ndarray
    flow_sensor_mps: np.ndarray
    """(N, 3) the inputs: the fluid's velocity relative to the sensor, sensor axes, m/s."""
    covariance: FlowCovariance
    """(N, 3, 3) ENU covariances of ``flow_enu_mps``, m²/s²: the navigation's part and the
    sensor noise's (:mod:`wind_comp.flow_uncertainty`)."""

    def __len__(self) -> int:
        return self.t_s.shape[0]

    @property
    def valid(self) -> np.ndarray:
        return self.status == SampleStatus.VALID

    def counts(self) -> dict[SampleStatus, int]:
        """Number of samples per status."""
        return {status: int(np.count_nonzero(self.status == status)) for status in SampleStatus}


def _measurement_status(flows_mps: np.ndarray, max_speed_mps: float) -> np.ndarray:
    """(N,) status of (N, 3) measured flows (m/s, sensor axes) from their values alone:
    ``_PENDING`` (navigation decides), INVALID_MEASUREMENT or SPEED_OUT_OF_RANGE."""
    finite_flow = np.all(np.isfinite(flows_mps), axis=1)
    speed = np.sqrt(np.sum(np.where(finite_flow[:, None], flows_mps, 0.0) ** 2, axis=1))
    status = np.full(flows_mps.shape[0], _PENDING, dtype=np.int8)
    status[speed > max_speed_mps] = SampleStatus.SPEED_OUT_OF_RANGE
    status[~finite_flow] = SampleStatus.INVALID_MEASUREMENT
    return status


def _screen_samples(
    stamps_s: np.ndarray,
    flows_mps: np.ndarray,
    held: np.ndarray,
    confirming: np.ndarray,
    latest_stamp_s: float,
    max_speed_mps: float,
) -> tuple[np.ndarray, float]:
    """Status of each sample from its own values and stamp order alone.

    Returns (N,) statuses (``_PENDING`` where navigation decides, ``_HELD`` where ``held``) and
    the latest accepted stamp. A stamp is accepted when it is finite, later than every earlier
    accepted stamp, and of a sample in the sensor's sequence (``held`` (N,) False) or of the
    held sample that confirms a new sequence (``confirming`` (N,) True: the latest of it).
    """
    finite_stamp = np.isfinite(stamps_s)
    candidates = np.where(finite_stamp & (~held | confirming), stamps_s, -np.inf)
    running_latest = np.maximum.accumulate(np.concatenate(([latest_stamp_s], candidates)))
    stamp_ok = finite_stamp & (stamps_s > running_latest[:-1])
    status = _measurement_status(flows_mps, max_speed_mps)
    status[~stamp_ok] = SampleStatus.INVALID_STAMP
    status[held] = _HELD
    return status, float(running_latest[-1])


_N_OUTPUTS = 4
"""Output vectors per sample: the corrected flow and its three Miller terms."""
_N_COVARIANCES = 2
"""Output covariances per sample: the navigation's part and the sensor noise's."""
_ROW_SHAPES = ((4,), (3,), (3,), (3, 3), (3, 3), (3, 3), (3,), (3, 3))
"""Shape of one row of each per-sample argument of the compiled correction: attitude, rate,
velocity, their three covariances, the flow and its noise covariance."""


class _Corrector:
    """Navigation lookup plus Miller correction of samples that passed screening, with the
    covariance of each corrected sample and its test against the sensor's limits: the one
    correction every path runs, on a batch of any length (one sample, live)."""

    def __init__(self, sensor: FlowSensor):
        mounting_matrix = mounting_rotation_from_rpy_deg(sensor.rpy_deg).as_matrix()
        self._mounting_matrix = mounting_matrix
        self._mounting_elements = tuple(mounting_matrix.ravel().tolist())
        self._lever_arm_elements_body_m = tuple(float(c) for c in sensor.position_body_m)
        self._sigma_limits = sensor.sigma_limits
        # The compiled correction is built (or loaded from numba's cache) now, when a node
        # starts, so that no sample waits for the compiler.
        self._correct_rows(*(np.empty((0, *shape)) for shape in _ROW_SHAPES))

    def correct(self, track: NavTrack, stamps_s, flows_mps, noises_m2s2, as_of_newest_s):
        """Return (N,) statuses (``_PENDING`` while navigation may still bracket a stamp), a
        (4, N, 3) array of the flow and the three Miller terms, ENU m/s, and a (2, N, 3, 3)
        array of the flow's covariance, navigation and sensor parts, ENU m²/s², both NaN where
        not valid.

        ``stamps_s``: (N,) s; ``flows_mps``: (N, 3) the fluid's velocity relative to the sensor,
        sensor axes, m/s; ``noises_m2s2``: (N, 3, 3) their noise covariances, sensor axes,
        m²/s²; ``as_of_newest_s``: the newest navigation stamp when each sample arrived, s (see
        :meth:`NavTrack.interpolate`)."""
        nav = track.interpolate(stamps_s, as_of_newest_s)
        status = _NAV_OUTCOME_BY_CODE[nav.status]
        outputs = np.full((_N_OUTPUTS, stamps_s.shape[0], 3), np.nan)
        covariances = np.full((_N_COVARIANCES, stamps_s.shape[0], 3, 3), np.nan)
        if np.any(nav.valid):
            rows = np.flatnonzero(nav.valid)
            terms, covariance = self._corrected(flows_mps[rows], noises_m2s2[rows], nav, rows)
            beyond = self._sigma_limits.exceeded(covariance[0] + covariance[1])
            status[rows[beyond]] = SampleStatus.UNCERTAINTY_TOO_LARGE
            kept = rows[~beyond]
            outputs[:, kept] = terms[:, ~beyond]
            covariances[:, kept] = covariance[:, ~beyond]
        return status, outputs, covariances

    def _corrected(self, flows_mps, noises_m2s2, nav: InterpolatedNav, rows):
        """The Miller terms (4, M, 3: the flow over ground and the tilt, rotation and
        translation terms, ENU m/s) and the covariance (2, M, 3, 3: navigation and sensor parts,
        ENU m²/s²) of (M, 3) flows in sensor axes with noise covariances (M, 3, 3, sensor axes,
        m²/s²), corrected with the navigation's ``rows`` (:mod:`wind_comp.correction_kernel`)."""
        return self._correct_rows(
            nav.attitude_xyzw[rows],
            nav.angular_rate_body_rad_s[rows],
            nav.velocity_enu_mps[rows],
            nav.attitude_covariance_enu_rad2[rows],
            nav.velocity_covariance_enu_m2s2[rows],
            nav.angular_rate_covariance_body_rad2s2[rows],
            flows_mps,
            np.ascontiguousarray(noises_m2s2),
        )

    def _correct_rows(self, *rows) -> tuple[np.ndarray, np.ndarray]:
        """:func:`~wind_comp.correction_kernel.correct_samples` of M rows of each per-sample
        argument (in its order, shapes :data:`_ROW_SHAPES`) with this sensor's mounting and
        lever arm: the terms (4, M, 3) and the covariances (2, M, 3, 3)."""
        n_rows = rows[0].shape[0]
        terms = np.empty((_N_OUTPUTS, n_rows, 3))
        covariance = np.empty((_N_COVARIANCES, n_rows, 3, 3))
        correct_samples(
            *rows,
            self._mounting_matrix,
            self._mounting_elements,
            self._lever_arm_elements_body_m,
            terms,
            covariance,
        )
        return terms, covariance


NOTHING_DECIDED = CorrectedBatch(
    np.empty(0),
    np.empty(0, dtype=np.int8),
    *(np.empty((0, 3)) for _ in range(5)),
    FlowCovariance(np.empty((0, 3, 3)), np.empty((0, 3, 3))),
)
"""The batch of no samples."""
_INITIAL_CAPACITY = 64


class FlowCompensator:
    """Streaming motion correction of one flow sensor: one output per sensor sample, in input
    order.

    The sensor samples wait in a queue of columns: stamp, measured flow, its noise covariance,
    the newest navigation stamp when the sample arrived, status (``_PENDING`` until decided),
    the four output vectors and the two parts of the output's covariance. Samples before
    ``_first_pending`` are decided, those from ``_head`` on not yet returned.
    """

    def __init__(self, sensor: FlowSensor, max_nav_gap_s: float, nav_history_s: float):
        """sensor: the flow sensor; max_nav_gap_s: widest spacing of the navigation samples
        around a stamp that is still interpolated, s; nav_history_s: how far a sample may lag
        the newest navigation sample and still be corrected, s."""
        self.sensor = sensor
        self.nav_track = NavTrack(max_nav_gap_s, nav_history_s)
        self._corrector = _Corrector(sensor)
        self._latest_sample_stamp_s = -np.inf
        self._counts = dict.fromkeys(SampleStatus, 0)
        self._t_s = np.empty(_INITIAL_CAPACITY)
        self._flow_mps = np.empty((_INITIAL_CAPACITY, 3))
        self._noise_m2s2 = np.empty((_INITIAL_CAPACITY, 3, 3))
        self._as_of_nav_s = np.empty(_INITIAL_CAPACITY)
        self._status = np.empty(_INITIAL_CAPACITY, dtype=np.int8)
        self._terms = np.empty((_N_OUTPUTS, _INITIAL_CAPACITY, 3))
        self._covariances = np.empty((_N_COVARIANCES, _INITIAL_CAPACITY, 3, 3))
        self._default_noise_m2s2 = np.reshape(sensor.noise_covariance_m2s2, (3, 3))
        self._head = self._first_pending = self._tail = 0
        self._n_returned = 0
        """Samples returned so far: the number of the sample at ``_head``."""

    @property
    def counts(self) -> dict[SampleStatus, int]:
        """Number of output samples per status so far."""
        return dict(self._counts)

    @property
    def n_pending(self) -> int:
        """Sensor samples received but not yet returned."""
        return self._tail - self._head

    @property
    def first_undecided_stamp_s(self) -> float:
        """Stamp (s) of the oldest sample still waiting for navigation (inf when none waits):
        navigation stamped before it can decide nothing that could be returned."""
        if self._first_pending == self._tail:
            return math.inf
        return float(self._t_s[self._first_pending])

    def add_nav(
        self,
        t_s,
        quat_xyzw,
        angular_rate_body_rad_s,
        velocity_enu_mps,
        trusted: bool = True,
        covariances=None,
    ) -> bool:
        """Add one navigation sample (stamp s, body→ENU quaternion xyzw, body rate rad/s,
        ENU velocity m/s; ``trusted`` False: no sample is corrected with it; ``covariances``
        as :meth:`NavTrack.append` takes them). Returns False when the track rejects it
        (counted there)."""
        return self.nav_track.append(
            t_s, quat_xyzw, angular_rate_body_rad_s, velocity_enu_mps, trusted, covariances
        )

    def add_sample(self, t_s, flow_sensor_mps, noise_covariance_m2s2=None) -> None:
        """Add one sensor sample: stamp s, the fluid's velocity relative to the sensor in its
        axes m/s, (3,), and its noise covariance in those axes, m²/s², (3, 3) (None: the
        sensor's): :meth:`add_arrivals` of one sample after the navigation so far."""
        noises = None if noise_covariance_m2s2 is None else [noise_covariance_m2s2]
        self._enqueue(
            *_sample_arrays([t_s], [flow_sensor_mps]),
            self._newest_nav_s(),
            self._noises(noises, 1),
            np.zeros(1, dtype=bool),
            np.zeros(1, dtype=bool),
        )

    def add_arrivals(
        self,
        nav,
        sample_t_s,
        flow_sensor_mps,
        nav_before_sample,
        noise_covariances_m2s2=None,
        held=None,
        confirming=None,
    ) -> int:
        """Navigation and sensor samples that arrived interleaved: exactly :meth:`add_nav`
        of each navigation sample in order, with :meth:`add_sample` of sensor sample ``i``
        right after the first ``nav_before_sample[i]`` of them.

        Args:
            nav: (t_s, quat_xyzw, angular_rate_body_rad_s, velocity_enu_mps[, trusted[,
                covariances]]) of M navigation samples: (M,) stamps, s, (M, 4), (M, 3), (M, 3)
                arrays, (M,) bools and (M, 3, 3, 3) covariances of what :meth:`add_nav` takes.
            sample_t_s, flow_sensor_mps: (N,) stamps and (N, 3) flows, as
                :meth:`add_sample` takes them one by one.
            nav_before_sample: (N,) non-decreasing counts, 0 to M.
            noise_covariances_m2s2: (N, 3, 3) as :meth:`add_sample` takes them (None: the
                sensor's for all).
            held: (N,) True for a sample held off the sensor's sequence
                (:mod:`buoy_nav.stream_sequence`): it waits, its stamp not taken, until
                :meth:`settle_held` says whether it is the sensor's (None: none is held).
            confirming: (N,) True for the held sample whose arrival confirmed the held ones
                as the sensor's new sequence: the latest of them, its stamp taken (None: none).

        Returns the number of navigation samples accepted.
        """
        stamps, flows = _sample_arrays(sample_t_s, flow_sensor_mps)
        none = np.zeros(stamps.shape[0], dtype=bool)
        newest_before = self._newest_nav_s()
        nav_t_s = np.asarray(nav[0], dtype=float)
        accepted = self.nav_track.extend(*nav) if nav_t_s.shape[0] else np.zeros(0, dtype=bool)
        if stamps.shape[0]:
            # Newest accepted navigation stamp after each number of navigation arrivals.
            newest_after = np.maximum.accumulate(
                np.concatenate(([newest_before], np.where(accepted, nav_t_s, -np.inf)))
            )
            self._enqueue(
                stamps,
                flows,
                newest_after[np.asarray(nav_before_sample, dtype=np.intp)],
                self._noises(noise_covariances_m2s2, stamps.shape[0]),
                none if held is None else np.asarray(held, dtype=bool),
                none if confirming is None else np.asarray(confirming, dtype=bool),
            )
        return int(np.count_nonzero(accepted))

    def settle_held(self, sequence_numbers, released) -> None:
        """Settle held samples: those numbered ``sequence_numbers`` ((K,) ints, counting every
        sample added from 0) are the sensor's (``released`` (K,) True: corrected like the
        others, once navigation covers them) or not (OUT_OF_SEQUENCE). Only held samples not
        yet settled may be named."""
        rows = self._head + np.asarray(sequence_numbers, dtype=np.intp) - self._n_returned
        released = np.asarray(released, dtype=bool)
        if np.any(self._status[rows] != _HELD):
            raise ValueError("only held samples not yet settled can be settled")
        self._status[rows[~released]] = SampleStatus.OUT_OF_SEQUENCE
        kept = rows[released]
        self._status[kept] = _measurement_status(self._flow_mps[kept], self.sensor.max_speed_mps)
        self._advance_first_pending()

    def ready(self) -> CorrectedBatch:
        """Every sample that can now be decided, in input order."""
        self._decide()
        return self._pop_decided()

    def expire(self, before_t_s: float) -> CorrectedBatch:
        """Decide what can be decided, give up on samples stamped before ``before_t_s`` (s)
        that wait for navigation as NAVIGATION_TIMEOUT (held samples wait for their sequence,
        not for navigation: not given up), and return the decided samples in input order."""
        self._decide()
        self._give_up(
            self._t_s[self._first_pending : self._tail] < before_t_s,
            SampleStatus.NAVIGATION_TIMEOUT,
        )
        return self._pop_decided()

    def flush(self) -> CorrectedBatch:
        """End of data: decide every pending sample (NO_NAVIGATION where navigation never
        caught up, OUT_OF_SEQUENCE where still held) and return them in input order."""
        self._decide()
        self._give_up(True, SampleStatus.NO_NAVIGATION)
        self._give_up(True, SampleStatus.OUT_OF_SEQUENCE, _HELD)
        return self._pop_decided()

    def _newest_nav_s(self) -> float:
        return self.nav_track.newest_stamp_s if len(self.nav_track) else -math.inf

    def _noises(self, noise_covariances_m2s2, n_samples: int) -> np.ndarray:
        """(N, 3, 3) noise covariances of N samples, the sensor's where None."""
        if noise_covariances_m2s2 is None:
            return np.broadcast_to(self._default_noise_m2s2, (n_samples, 3, 3))
        noises = np.asarray(noise_covariances_m2s2, dtype=float)
        if noises.shape != (n_samples, 3, 3):
            raise CompensatorInputError(
                f"noise covariances must have shape ({n_samples}, 3, 3), got {noises.shape}"
            )
        return noises

    def _enqueue(
        self, stamps: np.ndarray, flows: np.ndarray, as_of_nav_s, noises, held, confirming
    ) -> None:
        """Screen and queue (N,) stamps (s), (N, 3) flows (m/s, sensor axes) and their (N, 3, 3)
        noise covariances (m²/s², sensor axes) that arrived when the newest navigation stamp
        was ``as_of_nav_s`` (s, scalar or (N,)); (N,) ``held`` and ``confirming`` as
        :meth:`add_arrivals` takes them."""
        status, self._latest_sample_stamp_s = _screen_samples(
            stamps,
            flows,
            held,
            confirming,
            self._latest_sample_stamp_s,
            self.sensor.max_speed_mps,
        )
        self._reserve(stamps.shape[0])
        new = slice(self._tail, self._tail + stamps.shape[0])
        self._t_s[new] = stamps
        self._flow_mps[new] = flows
        self._noise_m2s2[new] = noises
        self._as_of_nav_s[new] = as_of_nav_s
        self._status[new] = status
        self._terms[:, new] = np.nan
        self._covariances[:, new] = np.nan
        self._tail = new.stop
        self._advance_first_pending()

    def _decide(self) -> None:
        """Correct the pending samples that the navigation now brackets (or never will)."""
        first, tail = self._first_pending, self._tail
        if first == tail:
            self.nav_track.forget_old_samples()
            return
        # A stamp after the newest navigation sample can only wait: no need to look it up.
        undecided = first + np.flatnonzero(
            (self._status[first:tail] == _PENDING) & (self._t_s[first:tail] <= self._newest_nav_s())
        )
        if len(undecided):
            (
                self._status[undecided],
                self._terms[:, undecided],
                self._covariances[:, undecided],
            ) = self._corrector.correct(
                self.nav_track,
                self._t_s[undecided],
                self._flow_mps[undecided],
                self._noise_m2s2[undecided],
                self._as_of_nav_s[undecided],
            )
        self._advance_first_pending()
        # Every sample still pending is stamped after the newest navigation sample: the
        # samples around it stay held (see NavTrack.forget_old_samples).
        self.nav_track.forget_old_samples()

    def _give_up(self, which, status: SampleStatus, waiting: int = _PENDING) -> None:
        """Decide as ``status`` the samples from ``_first_pending`` on that wait as ``waiting``
        (for navigation: ``_PENDING``, or held: ``_HELD``) where ``which`` (a mask over them,
        or True for all) holds."""
        if self._first_pending == self._tail:
            return
        pending = self._status[self._first_pending : self._tail]
        pending[(pending == waiting) & which] = status
        self._advance_first_pending()

    def _advance_first_pending(self) -> None:
        first, tail = self._first_pending, self._tail
        # _PENDING and _HELD, the undecided codes, are the negative ones.
        if first < tail and self._status[first] < 0:
            return
        pending = np.flatnonzero(self._status[first:tail] < 0)
        self._first_pending = first + int(pending[0]) if pending.size else tail

    def _pop_decided(self) -> CorrectedBatch:
        if self._head == self._first_pending:
            return NOTHING_DECIDED
        done = slice(self._head, self._first_pending)
        self._n_returned += self._first_pending - self._head
        self._head = self._first_pending
        status = self._status[done].copy()
        for code, count in enumerate(np.bincount(status, minlength=len(SampleStatus)).tolist()):
            self._counts[SampleStatus(code)] += count
        flow, tilt, rotation, translation = self._terms[:, done].copy()
        return CorrectedBatch(
            self._t_s[done].copy(),
            status,
            flow,
            tilt,
            rotation,
            translation,
            self._flow_mps[done].copy(),
            FlowCovariance(*self._covariances[:, done].copy()),
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
        for name in ("_t_s", "_flow_mps", "_noise_m2s2", "_as_of_nav_s", "_status"):
            old = getattr(self, name)
            new = np.empty((new_capacity, *old.shape[1:]), dtype=old.dtype)
            new[:n_kept] = old[kept]
            setattr(self, name, new)
        for name in ("_terms", "_covariances"):
            old = getattr(self, name)
            new = np.empty((old.shape[0], new_capacity, *old.shape[2:]))
            new[:, :n_kept] = old[:, kept]
            setattr(self, name, new)
        self._first_pending -= self._head
        self._head, self._tail = 0, n_kept


def _sample_arrays(t_s, flow_sensor_mps) -> tuple[np.ndarray, np.ndarray]:
    """(N,) stamps (s) and (N, 3) flows (m/s) as float arrays; CompensatorInputError if their
    shapes do not match."""
    try:
        stamps = np.asarray(t_s, dtype=float)
        flows = np.asarray(flow_sensor_mps, dtype=float)
    except (TypeError, ValueError) as error:
        raise CompensatorInputError(
            f"t_s and flow_sensor_mps must be numbers, got {t_s!r} and {flow_sensor_mps!r}"
        ) from error
    if stamps.ndim != 1 or flows.shape != (stamps.shape[0], 3):
        raise CompensatorInputError(
            f"t_s and flow_sensor_mps must have shapes (N,) and (N, 3), got {stamps.shape} "
            f"and {flows.shape}"
        )
    return stamps, flows
