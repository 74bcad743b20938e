"""Wind compensation engine shared by the live node and offline processing.

Both call the same object in the same order on the same header stamps: navigation samples
through :meth:`WindCompensator.add_nav`, anemometer samples through
:meth:`WindCompensator.add_wind`, and collect results from :meth:`WindCompensator.ready`.
Every anemometer sample yields exactly one :class:`CorrectedWind` with its own stamp, in input
order: either the motion-corrected wind or NaN with the reason it could not be corrected.
Whether and how a sample is corrected depends only on stamps (navigation samples at or around
it), not on when messages happen to arrive, so :func:`correct_batch` on whole arrays gives
identical numbers. The exceptions are the live-only :meth:`WindCompensator.expire` and a wind
sample lagging the navigation by more than ``nav_history_s``.
"""

import math
from collections import deque
from dataclasses import dataclass
from enum import IntEnum

import numpy as np

from buoy_common.contract import DEFAULT_PRODUCT_WINDOWS_S, Reason
from buoy_common.extrinsics import check_shared_fields, shared_field
from buoy_nav.rotations import rotation_matrix_elements
from wind_comp.miller import miller_components, mounting_rotation_from_rpy_deg
from wind_comp.nav_interpolation import InterpolationStatus, NavTrack


class ConfigError(ValueError):
    """A compensator setting is missing or malformed; the message names the field."""


class CompensatorInputError(ValueError):
    """Wind arrays given to the compensator have the wrong shape."""


@dataclass(frozen=True)
class CompensatorConfig:
    """Settings of the wind compensation.

    Attributes:
        anemometer_position_body_m: anemometer measurement centre in ``base_link``, m
            (Miller's lever arm B; parameter ``anemometer.position``).
        anemometer_rpy_deg: roll, pitch, yaw of ``anemometer_link`` relative to ``base_link``,
            deg, applied as Rz(yaw)·Ry(pitch)·Rx(roll) (parameter ``anemometer.rpy_deg``).
        max_nav_gap_s: largest spacing of the two navigation samples bracketing a wind stamp
            for which the navigation is interpolated, s.
        max_wind_speed_mps: measured wind speeds above this are rejected as absurd, m/s.
        nav_history_s: how far behind the newest navigation sample a wind stamp may lag and
            still be corrected in streaming use, s.
        product_windows_s: lengths of the averaging windows of the wind products, s
            (60 s and 600 s by default, WMO practice).
        gust_window_s: length of the running mean whose maximum is the gust, s (WMO: 3 s).
    """

    anemometer_position_body_m: tuple[float, float, float] = shared_field("anemometer.position")
    anemometer_rpy_deg: tuple[float, float, float] = shared_field("anemometer.rpy_deg")
    max_nav_gap_s: float = 0.1
    max_wind_speed_mps: float = 100.0
    nav_history_s: float = 10.0
    product_windows_s: tuple[float, ...] = DEFAULT_PRODUCT_WINDOWS_S
    gust_window_s: float = 3.0

    def __post_init__(self):
        for name in ("anemometer_position_body_m", "anemometer_rpy_deg"):
            object.__setattr__(self, name, _finite_tuple(name, getattr(self, name), length=3))
        try:
            check_shared_fields(self)
        except ValueError as error:
            raise ConfigError(str(error)) from None
        for name in ("max_nav_gap_s", "max_wind_speed_mps", "nav_history_s", "gust_window_s"):
            object.__setattr__(self, name, _positive_float(name, getattr(self, name)))
        windows = _finite_tuple("product_windows_s", self.product_windows_s, length=None)
        if not windows or min(windows) <= 0:
            raise ConfigError(f"product_windows_s must be positive window lengths, got {windows}")
        object.__setattr__(self, "product_windows_s", windows)
        if self.nav_history_s <= self.max_nav_gap_s:
            raise ConfigError(
                f"nav_history_s ({self.nav_history_s}) must exceed max_nav_gap_s "
                f"({self.max_nav_gap_s})"
            )
        if self.gust_window_s >= min(windows):
            raise ConfigError(
                f"gust_window_s ({self.gust_window_s}) must be shorter than every product window "
                f"{windows}"
            )


def _finite_tuple(name: str, value, length: int | None) -> tuple[float, ...]:
    try:
        numbers = tuple(float(item) for item in value)
    except (TypeError, ValueError) as error:
        raise ConfigError(f"{name} must be a sequence of numbers, got {value!r}") from error
    if length is not None and len(numbers) != length:
        raise ConfigError(f"{name} must have {length} values, got {len(numbers)}: {value!r}")
    if not all(math.isfinite(number) for number in numbers):
        raise ConfigError(f"{name} must be finite, got {value!r}")
    return numbers


def _positive_float(name: str, value) -> float:
    if isinstance(value, bool):
        raise ConfigError(f"{name} must be a number, got {value!r}")
    try:
        number = float(value)
    except (TypeError, ValueError) as error:
        raise ConfigError(f"{name} must be a number, got {value!r}") from error
    if not (math.isfinite(number) and number > 0):
        raise ConfigError(f"{name} must be positive and finite, got {value!r}")
    return number


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
}
_NAV_OUTCOME_BY_CODE = np.array(
    [_NAV_OUTCOME[InterpolationStatus(code)] for code in range(len(InterpolationStatus))],
    dtype=np.int8,
)


@dataclass(frozen=True, eq=False)
class CorrectedWind:
    """One anemometer sample after correction.

    Vectors are (3,) float arrays; the ENU ones are NaN unless ``status`` is VALID.
    """

    t_s: float
    """Header stamp of the anemometer sample, s."""
    status: WindStatus
    true_wind_enu_mps: np.ndarray
    tilt_term_enu_mps: np.ndarray
    rotation_term_enu_mps: np.ndarray
    translation_term_enu_mps: np.ndarray
    wind_sensor_mps: np.ndarray
    """The measured input, anemometer axes, m/s."""

    @property
    def valid(self) -> bool:
        return self.status == WindStatus.VALID


@dataclass(frozen=True, eq=False)
class CorrectedWindBatch:
    """Corrected wind for N anemometer samples, in input order (see :class:`CorrectedWind`)."""

    t_s: np.ndarray
    status: np.ndarray
    """(N,) int8 codes of :class:`WindStatus`."""
    true_wind_enu_mps: np.ndarray
    tilt_term_enu_mps: np.ndarray
    rotation_term_enu_mps: np.ndarray
    translation_term_enu_mps: np.ndarray
    wind_sensor_mps: np.ndarray

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


class _Corrector:
    """Navigation lookup plus Miller correction for samples that passed screening."""

    def __init__(self, config: CompensatorConfig):
        mounting_matrix_bw = mounting_rotation_from_rpy_deg(config.anemometer_rpy_deg).as_matrix()
        self._mounting_elements_bw = tuple(mounting_matrix_bw.ravel().tolist())
        self._lever_arm_elements_body_m = tuple(config.anemometer_position_body_m)

    def correct_one(self, track: NavTrack, t_s: float, wind_mps: np.ndarray):
        """:meth:`correct` of one sample in plain floats (bit-identical): its status and its
        true wind and three Miller terms as (3,) arrays, NaN unless valid."""
        code, attitude, rate, velocity = track.interpolate_one(t_s)
        status = _NAV_OUTCOME[code]
        if status != WindStatus.VALID:
            return status, tuple(np.full(3, np.nan) for _ in range(4))
        terms = miller_components(
            tuple(wind_mps.tolist()),
            rotation_matrix_elements(*attitude),
            rate,
            velocity,
            self._mounting_elements_bw,
            self._lever_arm_elements_body_m,
        )
        return status, tuple(np.array(term, dtype=float) for term in terms)

    def correct(self, track: NavTrack, stamps_s: np.ndarray, winds_mps: np.ndarray):
        """Return (N,) statuses (``_PENDING`` while navigation may still bracket a stamp) and
        (N, 3) arrays of true wind and the three Miller terms, NaN where not valid."""
        nav = track.interpolate(stamps_s)
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


class _Entry:
    """An anemometer sample waiting in the output queue."""

    __slots__ = ("result", "t_s", "wind_mps")

    def __init__(self, t_s: float, wind_mps: np.ndarray):
        self.t_s = t_s
        self.wind_mps = wind_mps
        self.result: CorrectedWind | None = None


class WindCompensator:
    """Streaming wind correction: one output per anemometer sample, in input order."""

    def __init__(self, config: CompensatorConfig):
        self.config = config
        self.nav_track = NavTrack(config.max_nav_gap_s, config.nav_history_s)
        self._corrector = _Corrector(config)
        self._queue: deque[_Entry] = deque()
        self._latest_wind_stamp_s = -np.inf
        self._counts = dict.fromkeys(WindStatus, 0)

    @property
    def counts(self) -> dict[WindStatus, int]:
        """Number of output samples per status so far."""
        return dict(self._counts)

    @property
    def n_pending(self) -> int:
        """Anemometer samples received but not yet returned."""
        return len(self._queue)

    def add_nav(self, t_s, quat_xyzw, angular_rate_body_rad_s, velocity_enu_mps) -> bool:
        """Add one navigation sample (stamp s, body→ENU quaternion xyzw, body rate rad/s,
        ENU velocity m/s). Returns False when the track rejects it (counted there)."""
        return self.nav_track.append(t_s, quat_xyzw, angular_rate_body_rad_s, velocity_enu_mps)

    def add_nav_batch(self, t_s, quat_xyzw, angular_rate_body_rad_s, velocity_enu_mps) -> int:
        """:meth:`add_nav` of (N,) stamps and (N, 4), (N, 3), (N, 3) arrays, in order; returns
        the number accepted."""
        return self.nav_track.extend(t_s, quat_xyzw, angular_rate_body_rad_s, velocity_enu_mps)

    def add_wind(self, t_s, wind_sensor_mps) -> None:
        """Add one anemometer sample: stamp s, air velocity in anemometer axes m/s, (3,)."""
        wind = np.asarray(wind_sensor_mps, dtype=float)
        if wind.shape != (3,):
            raise CompensatorInputError(f"wind_sensor_mps must have shape (3,), got {wind.shape}")
        self.add_wind_batch(np.array([float(t_s)]), wind[None, :])

    def add_wind_batch(self, t_s, wind_sensor_mps) -> None:
        """:meth:`add_wind` of (N,) stamps and (N, 3) winds, in order (screened together)."""
        stamps, winds = _wind_arrays(t_s, wind_sensor_mps)
        status, self._latest_wind_stamp_s = _screen_wind(
            stamps, winds, self._latest_wind_stamp_s, self.config.max_wind_speed_mps
        )
        for stamp, wind, code in zip(stamps.tolist(), winds, status.tolist(), strict=True):
            entry = _Entry(stamp, wind.copy())
            if code != _PENDING:
                entry.result = _invalid(entry, WindStatus(code))
            self._queue.append(entry)

    def ready(self) -> list[CorrectedWind]:
        """Every sample that can now be decided, in input order."""
        self._decide()
        return self._pop_decided()

    def expire(self, before_t_s: float) -> list[CorrectedWind]:
        """Decide what can be decided, give up on samples stamped before ``before_t_s`` (s)
        as NAVIGATION_TIMEOUT, and return the decided samples in input order."""
        self._decide()
        for entry in self._queue:
            if entry.result is None and entry.t_s < before_t_s:
                entry.result = _invalid(entry, WindStatus.NAVIGATION_TIMEOUT)
        return self._pop_decided()

    def flush(self) -> list[CorrectedWind]:
        """End of data: decide every pending sample (NO_NAVIGATION where navigation never
        caught up) and return them in input order."""
        self._decide()
        for entry in self._queue:
            if entry.result is None:
                entry.result = _invalid(entry, WindStatus.NO_NAVIGATION)
        return self._pop_decided()

    def _decide(self) -> None:
        # A stamp after the newest navigation sample can only wait: no need to look it up.
        newest_nav_s = self.nav_track.newest_stamp_s
        undecided = [
            entry for entry in self._queue if entry.result is None and entry.t_s <= newest_nav_s
        ]
        if not undecided:
            return
        if len(undecided) == 1:
            # The live case: one sample, in floats, as bit-identical as the batch below.
            (entry,) = undecided
            status, terms = self._corrector.correct_one(self.nav_track, entry.t_s, entry.wind_mps)
            if status != _PENDING:
                entry.result = CorrectedWind(entry.t_s, WindStatus(status), *terms, entry.wind_mps)
            return
        stamps = np.array([entry.t_s for entry in undecided])
        winds = np.array([entry.wind_mps for entry in undecided])
        status, (true_wind, tilt, rotation, translation) = self._corrector.correct(
            self.nav_track, stamps, winds
        )
        for i, entry in enumerate(undecided):
            if status[i] != _PENDING:
                entry.result = CorrectedWind(
                    entry.t_s,
                    WindStatus(int(status[i])),
                    true_wind[i],
                    tilt[i],
                    rotation[i],
                    translation[i],
                    entry.wind_mps,
                )

    def _pop_decided(self) -> list[CorrectedWind]:
        decided = []
        while self._queue and self._queue[0].result is not None:
            result = self._queue.popleft().result
            self._counts[result.status] += 1
            decided.append(result)
        return decided


def _invalid(entry: _Entry, status: WindStatus) -> CorrectedWind:
    nan = np.full(3, np.nan)
    return CorrectedWind(entry.t_s, status, nan, nan, nan, nan, entry.wind_mps)


def correct_batch(
    config: CompensatorConfig,
    nav_t_s,
    nav_quat_xyzw,
    nav_angular_rate_body_rad_s,
    nav_velocity_enu_mps,
    wind_t_s,
    wind_sensor_mps,
) -> CorrectedWindBatch:
    """Correct a whole recording at once; identical to streaming every navigation sample and
    every wind sample in array order through :class:`WindCompensator` and flushing.

    Args:
        config: compensation settings.
        nav_t_s: (M,) navigation stamps, s, in arrival order.
        nav_quat_xyzw: (M, 4) body→ENU attitude.
        nav_angular_rate_body_rad_s: (M, 3) body rate, body axes, rad/s.
        nav_velocity_enu_mps: (M, 3) ENU velocity of the body origin, m/s.
        wind_t_s: (N,) anemometer stamps, s, in arrival order.
        wind_sensor_mps: (N, 3) measured air velocity, anemometer axes, m/s.
    """
    track = NavTrack.from_arrays(
        nav_t_s,
        nav_quat_xyzw,
        nav_angular_rate_body_rad_s,
        nav_velocity_enu_mps,
        max_gap_s=config.max_nav_gap_s,
    )
    stamps, winds = _wind_arrays(wind_t_s, wind_sensor_mps)
    status, _ = _screen_wind(stamps, winds, -np.inf, config.max_wind_speed_mps)
    outputs = [np.full((stamps.shape[0], 3), np.nan) for _ in range(4)]
    screened = status == _PENDING
    nav_status, nav_outputs = _Corrector(config).correct(track, stamps[screened], winds[screened])
    nav_status[nav_status == _PENDING] = WindStatus.NO_NAVIGATION
    status[screened] = nav_status
    for output, nav_output in zip(outputs, nav_outputs, strict=True):
        output[screened] = nav_output
    true_wind, tilt, rotation, translation = outputs
    return CorrectedWindBatch(
        stamps.copy(), status, true_wind, tilt, rotation, translation, winds.copy()
    )


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
