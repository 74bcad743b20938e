"""Where the fusion's processing stands in time: the stamp the nominal state refers to and the
raw IMU sample there, and within a step between two IMU samples, the samples at a measurement's
stamp.

A measurement whose stamp falls between two IMU samples is applied at its own stamp: the state is
integrated to it with IMU samples interpolated on the parabola through the last three samples
(the curve the strapdown integrator integrates, so splitting a step costs no accuracy).
"""

import math

from buoy_nav.mechanization import interpolate_sample


class ProcessingPoint:
    """The processing's stamp (s) and raw IMU sample (gyro body rad/s, specific force body
    m/s²), its runs of IMU samples cut by gaps longer than ``max_imu_gap_s`` (s)."""

    def __init__(self, max_imu_gap_s: float):
        self._max_gap_s = max_imu_gap_s
        self.t_s = -math.inf
        self.gyro: tuple[float, float, float] | None = None
        self.force: tuple[float, float, float] | None = None
        self.last_imu_stamp_s = -math.inf
        """Stamp of the latest IMU sample processed: a measurement up to it comes too late."""
        # The sample the current step started from, and the one before it (same run).
        self._step_start: tuple | None = None
        self._older: tuple | None = None

    @property
    def started(self) -> bool:
        """Whether an IMU sample was processed."""
        return self.gyro is not None

    def begins_run(self, t_s: float) -> bool:
        """Whether the IMU sample stamped ``t_s`` (s) begins a run: the first, or after a gap."""
        return self.gyro is None or t_s - self.t_s > self._max_gap_s

    def start_run(self, t_s: float, gyro, force) -> None:
        """The processing is at the first sample of a run, stamped ``t_s`` (s)."""
        self.moved_to(t_s, gyro, force)
        self._older = None
        self.last_imu_stamp_s = t_s

    def begin_step(self) -> None:
        """A step from the current sample to the next one begins."""
        self._step_start = (self.t_s, self.gyro, self.force)

    def samples_at(self, t_s: float, t_end_s: float, gyro_end, force_end) -> tuple[tuple, tuple]:
        """(gyro, force) interpolated at ``t_s`` (s) within the step to the sample at
        ``t_end_s``: on the parabola through the three samples, on the line through two in the
        first step of a run."""
        t0, gyro0, force0 = self._step_start
        t_older, gyro_older, force_older = self._older or (None, None, None)
        return (
            interpolate_sample(t_s, t0, gyro0, t_end_s, gyro_end, t_older, gyro_older),
            interpolate_sample(t_s, t0, force0, t_end_s, force_end, t_older, force_older),
        )

    def end_step(self) -> float:
        """The step reached its sample; returns its length (s)."""
        self._older = self._step_start
        self.last_imu_stamp_s = self.t_s
        return self.t_s - self._step_start[0]

    def stepped_through(self, before: tuple, last: tuple) -> None:
        """Steps were made up to the sample ``last`` (stamp s, gyro, force), the one before it
        ``before``, as :meth:`begin_step`, :meth:`moved_to` and :meth:`end_step` leave them
        (:mod:`buoy_nav.imu_stretch`)."""
        self.t_s, self.gyro, self.force = last
        self._step_start = self._older = before
        self.last_imu_stamp_s = last[0]

    def moved_to(self, t_s: float, gyro, force) -> None:
        """The state was integrated to ``t_s`` (s), where the raw samples are ``gyro`` and
        ``force``."""
        self.t_s, self.gyro, self.force = t_s, gyro, force
