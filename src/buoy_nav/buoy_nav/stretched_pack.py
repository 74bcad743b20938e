"""The motion pack's attitudes in the compiled stretches (:mod:`buoy_nav.imu_stretches`,
:mod:`buoy_nav.pack_epoch`): when the stretches may take them, the kernel's arguments for them,
and the books of what a stretch did with them, kept as the engine keeps them.

The pack's attitudes are taken while a pass of its gate cannot move its health, none of them is
held off its sequence, the filter is trusted and no smoother records the epochs: the epochs a
stretch makes then move nothing else the engine keeps.
"""

import math
from collections.abc import Callable

import numpy as np

from buoy_nav.aiding.ahrs_attitude import AhrsAttitudeSource
from buoy_nav.error_state_filter import GateResult
from buoy_nav.imu_stretch import EPOCHS, QUEUE_HEAD, QUEUE_TAIL
from buoy_nav.pack_epoch import (
    EPOCH_INNOVATION,
    EPOCH_NIS,
    EPOCH_S,
    EPOCH_SIZE,
    EPOCH_T,
    PACK_ROW_SIZE,
    PACK_TERMS_SIZE,
    THRESHOLD,
    PackArguments,
)
from buoy_nav.sequence_kernels import SEQUENCE_LATEST, SEQUENCE_SIZE, sequence_of

NO_TERMS = (0.0, 0.0, 0.0, 0.0, -math.inf, math.inf, -math.inf, math.inf)
"""The pack's terms when there is no pack (:meth:`AhrsAttitudeSource.stretch_terms`)."""


class StretchedPack:
    """The motion pack's attitude source (None: no pack) in the stretches, with the engine's
    ``parts`` (:class:`~buoy_nav.imu_stretches.EngineParts`) it is booked in and the error
    states' ``attitude_start``."""

    def __init__(self, parts, attitude_start: int):
        self._parts = parts
        self._attitude_start = attitude_start
        pack = parts.pack
        # Writable, as the compiled stretch is loaded for.
        self._jacobian = np.zeros((3, 1)) if pack is None else pack.jacobian.copy()
        self.none = PackArguments(
            np.zeros((0, PACK_ROW_SIZE)),
            np.zeros(SEQUENCE_SIZE),
            np.zeros(PACK_TERMS_SIZE),
            self._jacobian,
            np.zeros((0, EPOCH_SIZE)),
        )
        """The arguments of a stretch that takes no attitude."""

    @property
    def source(self) -> AhrsAttitudeSource | None:
        """The pack's attitude source whose attitudes the stretches take (None: none)."""
        return self._parts.pack

    def ready(self, nav) -> bool:
        """Whether a stretch may apply the pack's attitudes as the engine would, with the aided
        navigation ``nav`` (see the module docstring)."""
        parts = self._parts
        pack = parts.pack
        return (
            pack is not None
            and parts.gates.unmoved_by_passes(pack.kind)
            and parts.sequences[pack.kind].steady
            and parts.integrity.trusted
            and not nav.records_epochs
        )

    def queued(self) -> bool:
        """Whether the engine's queue holds some of the pack's attitudes."""
        pack = self._parts.pack
        return any(entry[3] is pack for entry in self._parts.queue.heap)

    def arguments(self, rows: np.ndarray, pack_terms: tuple | None) -> PackArguments:
        """The kernel's arguments for the pack's ``rows`` and its terms ``pack_terms`` (None: no
        pack)."""
        return PackArguments(
            rows,
            self._sequence(),
            self._terms(pack_terms),
            self._jacobian,
            np.empty((len(rows), EPOCH_SIZE)),
        )

    def _sequence(self) -> np.ndarray:
        """The kernel's ``pack_sequence`` from the pack's sequence."""
        parts = self._parts
        if parts.pack is None:
            sequence = np.zeros(SEQUENCE_SIZE)
            sequence[SEQUENCE_LATEST] = math.inf
            return sequence
        return sequence_of(parts.sequences[parts.pack.kind])

    def _terms(self, pack_terms: tuple | None) -> np.ndarray:
        """The kernel's ``pack_terms`` (:mod:`buoy_nav.pack_epoch`'s layout)."""
        lag, lag_uncertainty_sq, floor, threshold, *bounds = pack_terms or NO_TERMS
        return np.array(
            (
                lag,
                lag_uncertainty_sq,
                floor,
                threshold,
                float(self._attitude_start),
                *bounds,
            )
        )

    def book(
        self,
        pack_terms: tuple,
        measurements: list,
        first_new: int,
        counts,
        epochs,
        book_before: Callable[[float], object],
    ):
        """Keep the books of what the stretch did with the pack's ``measurements`` (those
        queued before it first, the new ones from ``first_new``; ``pack_terms`` they held with)
        as the engine keeps them: its sequence and the IMU's clock follow the new ones it
        queued, each epoch it applied (``epochs``) is observed and booked as passed by its gate
        (after ``book_before`` its stamp, which books the other epochs stamped before it), and
        the attitudes still queued go back to the queue."""
        parts = self._parts
        pack = parts.pack
        head, tail, applied = int(counts[QUEUE_HEAD]), int(counts[QUEUE_TAIL]), int(counts[EPOCHS])
        queued = [measurement.t_s for measurement in measurements[first_new:tail]]
        parts.sequences[pack.kind].followed(queued)
        if queued:
            parts.imu_input.clock.aiding_stamp(queued[-1])
        threshold = pack_terms[THRESHOLD]
        for epoch, measurement in zip(epochs[:applied].tolist(), measurements, strict=False):
            t = epoch[EPOCH_T]
            book_before(t)
            parts.contradictions.observe(t, measurement)
            gate = GateResult(
                True,
                epoch[EPOCH_NIS],
                threshold,
                np.array(epoch[EPOCH_S : EPOCH_S + 9]).reshape(3, 3),
            )
            innovation = np.array(epoch[EPOCH_INNOVATION : EPOCH_INNOVATION + 3])
            fused, outcome = parts.gates.passed(pack, t, innovation, gate)
            if not fused:
                raise RuntimeError(f"{pack.kind}: an attitude the stretch applied was not fused")
            parts.transitions.extend(outcome.transitions)
        for measurement in measurements[head:tail]:
            parts.queue.push(pack, measurement.t_s, measurement)
