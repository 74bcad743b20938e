"""The IMU samples the fusion accepts, and why it refuses the others.

A raw sample passes, in this order: three finite numbers each for ω_ib and the specific force
(else ``malformed`` or ``non_finite``); the ``calibrate_imu`` biases and scale removed; magnitudes
a sensor can report (``out_of_range``); its stamp put back on the aiding sources' clock after a
step of the IMU's clock (:mod:`buoy_nav.imu_clock`); a stamp that follows the accepted sequence
at the IMU's rate, else held until it proves to start the IMU's new sequence and given up when the
accepted one goes on (:mod:`buoy_nav.stream_sequence`: ``out_of_sequence``, or behind the latest
accepted stamp ``duplicate_stamp``, ``stamp_not_increasing``); a change from the last accepted
sample that a platform can make (``implausible_change``, :mod:`buoy_nav.imu_screening`).
"""

import math

import numpy as np

from buoy_common.contract import Reason
from buoy_nav.config import FusionConfig
from buoy_nav.imu_clock import ImuClock
from buoy_nav.imu_screening import ImuPlausibility
from buoy_nav.sequence_kernels import RING_SIZE, intervals_of, ring_of
from buoy_nav.stream_sequence import HeldSequence

Triple = tuple[float, float, float]
Sample = tuple[float, Triple, Triple]


class ImuInput:
    """Screens raw IMU samples for the engine; holds the newest accepted stamp."""

    def __init__(self, config: FusionConfig):
        self._calibration = config.imu_calibration
        self._max_rate_sq = config.max_angular_rate_rad_s**2
        self._max_force_sq = config.max_specific_force_mps2**2
        self._max_gap_s = config.max_imu_gap_s
        self.clock = ImuClock(config.max_imu_gap_s)
        """The IMU clock's steps, and the aiding stamps it tells them from outages by."""
        self._plausibility = ImuPlausibility(
            config.max_angular_acceleration_rad_s2,
            config.max_jerk_mps3,
            math.radians(config.gyro_noise_deg_sqrt_h) / 60.0,
            config.accel_noise_mps_sqrt_h / 60.0,
        )
        self.latest_stamp_s = -math.inf
        """Stamp of the newest accepted sample (s, on the aiding sources' clock)."""
        # The latest stamp of the accepted sequence, accepted or not (a spike the screening
        # rejects is still the IMU's sample): the next one follows it.
        self._sequence_last_s = -math.inf
        self._held = HeldSequence()
        # The newest aiding stamp (s) when the first held sample came.
        self._held_since_aiding_s = -math.inf
        self._given_up: list[Reason] = []
        self.second_stream_samples = 0
        """Held samples given up because the accepted sequence went on: a second stream's."""
        self.second_stream_lead_s = math.nan
        """The last of them less the latest accepted stamp (s): how far the second stream runs
        ahead of the IMU's (negative: behind)."""

    def accept(self, t_s: float, gyro_rad_s, specific_force_mps2) -> list[Sample] | Reason:
        """The samples (stamp s, ω_ib body rad/s, specific force body m/s²) the fusion takes,
        calibrated and re-stamped, now that the one stamped ``t_s`` (s) came: that one, none (it
        is held, :mod:`buoy_nav.stream_sequence`) or the held ones of a new sequence; or the reason
        it is refused. Held samples given up on the way are in :meth:`take_given_up`."""
        try:
            t = float(t_s)
            gx, gy, gz = _float_triple(gyro_rad_s)
            fx, fy, fz = _float_triple(specific_force_mps2)
        except (TypeError, ValueError):
            return Reason.MALFORMED
        # A sample refused for its values is still the IMU's: the sequence goes on through it
        # (and a valid sample of its stamp is still in sequence).
        stamp = self.clock.restamp(t)
        last = self._sequence_last_s
        in_sequence = stamp > self.latest_stamp_s and (
            stamp == last or self.clock.follows(stamp, last)
        )
        if in_sequence:
            self._sequence_goes_on(stamp)
        if not (math.isfinite(t) and math.isfinite(gx + gy + gz) and math.isfinite(fx + fy + fz)):
            return Reason.NON_FINITE
        if self._calibration is not None:
            (bgx, bgy, bgz), (bax, bay, baz), (sx, sy, sz) = self._calibration
            gx, gy, gz = gx - bgx, gy - bgy, gz - bgz
            fx, fy, fz = (fx - bax) / sx, (fy - bay) / sy, (fz - baz) / sz
        if (
            gx * gx + gy * gy + gz * gz > self._max_rate_sq
            or fx * fx + fy * fy + fz * fz > self._max_force_sq
        ):
            return Reason.OUT_OF_RANGE
        sample = (stamp, (gx, gy, gz), (fx, fy, fz))
        if not in_sequence:
            return self._hold(sample)
        screened = self._screened(sample)
        return screened if isinstance(screened, Reason) else [screened]

    def steady_screening(self) -> tuple[np.ndarray, np.ndarray] | None:
        """The screening's limits and state as :func:`~buoy_nav.imu_stretch.imu_stretch` takes
        them (its ``screening`` and ``screened_state``), or None while it is not in its steady
        course (samples held, a sample refused since the last accepted one, the sample interval
        not learnt yet): :meth:`accept` then takes the next sample itself."""
        plausibility = self._plausibility
        if self._held.samples or not plausibility.steady:
            return None
        calibrated = self._calibration is not None
        (bgx, bgy, bgz), (bax, bay, baz), (sx, sy, sz) = (
            self._calibration if calibrated else ((0.0,) * 3, (0.0,) * 3, (1.0,) * 3)
        )
        screening = np.array(
            (
                self.clock.offset_s,
                self._max_rate_sq,
                self._max_force_sq,
                self._max_gap_s,
                1.0 if calibrated else 0.0,
                bgx,
                bgy,
                bgz,
                bax,
                bay,
                baz,
                sx,
                sy,
                sz,
                *plausibility.limits(),
                2.0,
            ),
            dtype=float,
        )
        last_t, last_gyro, last_force = plausibility.last
        screened_state = np.array(
            (
                self.latest_stamp_s,
                self._sequence_last_s,
                self.clock.interval_s,
                last_t,
                *last_gyro,
                *last_force,
                *ring_of(self.clock.intervals.values_s),
            ),
            dtype=float,
        )
        return screening, screened_state

    def screened_through(self, screened_state: np.ndarray, last: Sample) -> None:
        """Samples were screened and accepted as :meth:`accept` does, up to ``last``, by
        :func:`~buoy_nav.imu_stretch.imu_stretch`, which left the ``screened_state``."""
        latest, sequence_last = screened_state[:2].tolist()
        self.latest_stamp_s = latest
        self._sequence_last_s = sequence_last
        self.clock.intervals.restart(intervals_of(screened_state[-RING_SIZE:]))
        self._plausibility.last = last

    def _sequence_goes_on(self, t_s: float) -> None:
        """A sample of the accepted sequence stamped ``t_s`` (s) came: the held samples were a
        second stream's (or stale ones)."""
        held = self._held.samples
        if held:
            self.second_stream_samples += len(held)
            self.second_stream_lead_s = held[-1][0] - self.latest_stamp_s
        self._give_up_held()
        self._sequence_last_s = t_s

    @property
    def newest_stamp_s(self) -> float:
        """The newest stamp of the IMU's samples, accepted or held (s): while samples are held
        the IMU runs on, and the measurements are not ahead of it."""
        held = self._held.samples
        return max(self.latest_stamp_s, held[-1][0]) if held else self.latest_stamp_s

    def take_given_up(self) -> list[Reason]:
        """Why each held sample given up since the last call was rejected."""
        given_up, self._given_up = self._given_up, []
        return given_up

    def give_up(self) -> None:
        """Give up the held samples (end of data)."""
        self._give_up_held()

    def _hold(self, sample: Sample) -> list[Sample]:
        """Hold ``sample``, out of the accepted sequence; the held samples once they make the
        IMU's new sequence (re-stamped after a step), else none."""
        held = self._held
        if held.samples and not self.clock.follows(sample[0], held.samples[-1][0]):
            self._give_up_held()
        if not held.samples:
            self._held_since_aiding_s = self.clock.newest_aiding_s
        held.samples.append(sample)
        if not held.confirmed():
            return []
        samples = held.take()
        step = self.clock.new_sequence(
            samples[0][0], self.latest_stamp_s, self._held_since_aiding_s
        )
        if step is None:
            held.samples = samples
            self._give_up_held()
            return []
        released = []
        for t, gyro, force in samples:
            screened = self._screened((t - step, gyro, force))
            if isinstance(screened, Reason):
                self._given_up.append(screened)
            else:
                released.append(screened)
            self._sequence_last_s = t - step
        return released

    def _give_up_held(self) -> None:
        """Count the held samples rejected: another stream's, or stale ones."""
        latest = self.latest_stamp_s
        for t, _, _ in self._held.take():
            if t > latest:
                self._given_up.append(Reason.OUT_OF_SEQUENCE)
            else:
                self._given_up.append(
                    Reason.DUPLICATE_STAMP if t == latest else Reason.STAMP_NOT_INCREASING
                )

    def _screened(self, sample: Sample) -> Sample | Reason:
        """``sample`` if its stamp follows the latest accepted one and its change from it is
        one a platform can make (it becomes the latest), else the reason it is refused."""
        t, gyro, force = sample
        latest = self.latest_stamp_s
        if t <= latest:
            return Reason.DUPLICATE_STAMP if t == latest else Reason.STAMP_NOT_INCREASING
        if t - latest > self._max_gap_s:
            self._plausibility.restart()
        if not self._plausibility.plausible(t, gyro, force):
            return Reason.IMPLAUSIBLE_CHANGE
        self.clock.accepted(t, latest)
        self.latest_stamp_s = t
        return sample


def _float_triple(values) -> Triple:
    """Three floats from a 3-element array or sequence (ValueError/TypeError otherwise)."""
    if isinstance(values, np.ndarray) and values.dtype == np.float64:
        x, y, z = values.tolist()
        return x, y, z
    x, y, z = values
    return float(x), float(y), float(z)
