"""Fixed-interval Rauch–Tung–Striebel smoother of the closed-loop error-state filter.

Offline, every sample has a future: the smoother (paper 002) runs the forward filter over the
whole recording, then a backward pass that combines each epoch's filtered estimate with
everything measured after it.

**What the forward pass stores** (:class:`SmootherRecorder`, told by the engine through the
hooks of :mod:`buoy_nav.epoch_recorder`): one record per *covariance epoch* k, i.e. each
propagation of the covariance (every ``covariance_propagation_interval_s`` and at every
measurement stamp), holding its stamp t_k, the transition Φ_k from epoch k−1, the predicted
covariance P_k⁻, the correction δx̂_k injected into the nominal state at t_k (the sum of the
updates of that stamp; zero without measurements) and the covariance P_k⁺ after the updates
and their resets (taken when the next epoch starts). The integrity monitor's inflation of the
covariance is process noise at its stamp: an epoch of its own with Φ = I and P⁻ = P⁺ + the
inflation, so little of what follows reaches back across it. A reset of the nominal state that
is not a correction (a source's persistent rejection re-initialising states, such as the yaw
reset; an alignment after an IMU gap or a loss of integrity) ends a *segment*: the smoother
never smooths across one.

**The backward pass for a closed-loop filter.** After each update the filter injects δx̂_k into
the nominal state and resets its error mean to zero, so every filtered error mean is zero,
relative to the nominal state of that moment. The smoothed error of epoch k+1, δx_{k+1}^s, is
relative to the corrected nominal state x_{k+1}⁺; the nominal state propagated from x_k⁺, to
which Φ_{k+1} refers, is x_{k+1}⁻ = x_{k+1}⁺ − δx̂_{k+1}. Relative to it the smoothed error is
δx̂_{k+1} + δx_{k+1}^s (first order; the ½[δφ̂×] reset of the attitude covariance is within
the same order). The RTS recursion then reads, with zero filtered means::

    C_k      = P_k⁺ Φ_{k+1}ᵀ (P_{k+1}⁻)⁻¹
    δx_k^s   = C_k (δx̂_{k+1} + δx_{k+1}^s)
    P_k^s    = P_k⁺ + C_k (P_{k+1}^s − P_{k+1}⁻) C_kᵀ

from δx^s = 0, P^s = P⁺ at the last epoch of a segment.

**Between epochs** the nominal state runs freely (no correction), from x_k⁺ to x_{k+1}⁻: the
error of a solution at t_k ≤ t < t_{k+1} is interpolated linearly between δx_k^s (relative to
x_k⁺) and δx̂_{k+1} + δx_{k+1}^s (relative to x_{k+1}⁻); over the 0.1 s of an epoch the error
changes by the bias errors times 0.1 s, far below its σ. Its covariance is P_k^s.

**Memory.** The records go to a temporary file (:mod:`buoy_nav.spill`), not to memory: per
epoch Φ (n²) and two packed covariances (n(n+1)/2 each) plus n, 3.8 kB for n = 15, and 1.2 kB
of smoothed results; one epoch per measurement stamp (ten a second with 10 Hz GNSS), so 0.18 GB
per hour. In memory there are the epochs' stamps (16 bytes each) and blocks of a few thousand
records, so the memory stays under a few hundred MB whatever the length of the recording (the
solutions are kept alike, see :mod:`buoy_nav.smoothed_solutions`).
"""

from __future__ import annotations

from array import array

import numpy as np
from scipy.linalg import lapack

from buoy_nav.epoch_recorder import EpochRecorder
from buoy_nav.spill import BLOCK_RECORDS, SpillDirectory, SpillTable, read_rows
from buoy_nav.state_layout import StateLayout


def packed_dtype(dimension: int) -> np.dtype:
    """Record of one covariance epoch for ``dimension`` error states."""
    packed = dimension * (dimension + 1) // 2
    return np.dtype(
        [
            ("t", "f8"),
            ("segment_start", "?"),
            ("transition", "f8", (dimension, dimension)),
            ("prior", "f8", (packed,)),
            ("correction", "f8", (dimension,)),
            ("posterior", "f8", (packed,)),
        ]
    )


def smoothed_dtype(dimension: int) -> np.dtype:
    """Record of one smoothed epoch: δx^s (relative to x_k⁺), δx̂_k + δx^s (relative to
    x_k⁻) and the packed P^s."""
    packed = dimension * (dimension + 1) // 2
    return np.dtype(
        [
            ("error", "f8", (dimension,)),
            ("error_before_correction", "f8", (dimension,)),
            ("covariance", "f8", (packed,)),
        ]
    )


class SymmetricPacking:
    """Upper triangles of symmetric n×n matrices as flat vectors and back."""

    def __init__(self, dimension: int):
        self.dimension = dimension
        self.rows, self.columns = np.triu_indices(dimension)

    def pack(self, matrix: np.ndarray) -> np.ndarray:
        return matrix[..., self.rows, self.columns]

    def unpack(self, packed: np.ndarray) -> np.ndarray:
        n = self.dimension
        matrix = np.zeros((*packed.shape[:-1], n, n))
        matrix[..., self.rows, self.columns] = packed
        matrix[..., self.columns, self.rows] = packed
        return matrix


class SmootherRecorder(EpochRecorder):
    """Stores the forward filter's epochs for the backward pass (see the module docstring).

    The engine calls the hooks of :class:`~buoy_nav.epoch_recorder.EpochRecorder`; ``spill`` is
    the temporary directory the records go to.
    """

    def __init__(self, states: StateLayout, spill: SpillDirectory):
        self.states = states
        self.packing = SymmetricPacking(states.dim)
        self.epochs: SpillTable = spill.table("epochs", packed_dtype(states.dim))
        self._smoothed_path = spill.path / "smoothed.bin"
        self._pending: np.void | None = None
        self._times = array("d")  # 8 bytes per epoch, not a Python float's 32
        self._segment_starts = array("q")
        self._identity = np.eye(states.dim)
        self.smoothed_epochs: SmoothedEpochs | None = None

    # ------------------------------------------------------------ engine hooks
    def begin_segment(self, t_s: float, covariance: np.ndarray) -> None:
        self._close_pending(covariance)
        self._segment_starts.append(len(self._times))
        self._open(t_s, self._identity, covariance, segment_start=True)

    def propagated(
        self,
        t_s: float,
        transition: np.ndarray,
        prior_covariance: np.ndarray,
        previous_posterior: np.ndarray,
    ) -> None:
        self._close_pending(previous_posterior)
        self._open(t_s, transition, prior_covariance, segment_start=False)

    def corrected(self, correction: np.ndarray) -> None:
        if self._pending is not None:
            self._pending["correction"] += correction

    def noise_added(
        self, t_s: float, covariance_before: np.ndarray, covariance: np.ndarray
    ) -> None:
        # An epoch of zero duration: Φ = I, P⁻ = P⁺ + the added noise.
        self._close_pending(covariance_before)
        self._open(t_s, self._identity, covariance, segment_start=False)

    def end_segment(self, covariance: np.ndarray | None) -> None:
        if covariance is not None:
            self._close_pending(covariance)

    # ------------------------------------------------------------ storage
    def _open(self, t_s, transition, prior, segment_start: bool) -> None:
        record = self.epochs.next_record()
        record["t"] = t_s
        record["segment_start"] = segment_start
        record["transition"] = transition
        record["prior"] = self.packing.pack(prior)
        record["correction"] = 0.0
        self._pending = record
        self._times.append(t_s)

    def _close_pending(self, posterior: np.ndarray) -> None:
        if self._pending is not None:
            self._pending["posterior"] = self.packing.pack(posterior)
            self._pending = None

    # ------------------------------------------------------------ backward pass
    def smooth(self) -> SmoothedEpochs:
        """Run the backward pass over every recorded epoch (call after the last
        :meth:`end_segment`)."""
        if self._pending is not None:
            raise RuntimeError("the last segment was not ended")
        count = len(self.epochs)
        packing = self.packing
        n = self.states.dim
        identity = np.eye(n)
        # The recursion's state carried from epoch k+1 to epoch k.
        next_error = np.zeros(n)
        next_covariance = np.zeros((n, n))
        next_transition = identity
        next_prior = identity
        next_continues = False  # epoch k+1 exists and is in the segment of epoch k
        smoothed_records = smoothed_dtype(n)
        smoothed = open(self._smoothed_path, "wb")  # noqa: SIM115 (closed below)
        stop = count
        while stop > 0:
            start = max(0, stop - BLOCK_RECORDS)
            rows = self.epochs.rows(start, stop)
            posterior_all = packing.unpack(rows["posterior"])
            prior_all = packing.unpack(rows["prior"])
            block = np.zeros(stop - start, dtype=smoothed_records)
            for i in range(stop - start - 1, -1, -1):
                posterior = posterior_all[i]
                if next_continues:
                    # C = P⁺ Φᵀ (P⁻)⁻¹, from (P⁻) Cᵀ = Φ P⁺.
                    factor, info = lapack.dpotrf(next_prior)
                    if info != 0:
                        raise np.linalg.LinAlgError("predicted covariance not positive definite")
                    gain_t, _ = lapack.dpotrs(factor, next_transition @ posterior)
                    gain = gain_t.T
                    error = gain @ next_error
                    covariance = posterior + gain @ (next_covariance - next_prior) @ gain_t
                    covariance = 0.5 * (covariance + covariance.T)
                else:
                    error = np.zeros(n)
                    covariance = posterior
                record = block[i]
                record["error"] = error
                error_before = error + rows["correction"][i]
                record["error_before_correction"] = error_before
                record["covariance"] = packing.pack(covariance)
                next_error = error_before
                next_covariance = covariance
                next_transition = rows["transition"][i]
                next_prior = prior_all[i]
                next_continues = not rows["segment_start"][i]
            # Made last block first; each goes to its place in the file.
            smoothed.seek(start * smoothed_records.itemsize)
            block.tofile(smoothed)
            stop = start
        smoothed.close()
        self.epochs.close()
        self.smoothed_epochs = SmoothedEpochs(
            np.frombuffer(self._times, dtype=np.float64),
            np.frombuffer(self._segment_starts, dtype=np.int64),
            self,
        )
        return self.smoothed_epochs

    def smoothed_rows(self, start: int, stop: int) -> np.ndarray:
        """Smoothed epochs ``start`` to ``stop`` (:func:`smoothed_dtype` records, a copy)."""
        return read_rows(self._smoothed_path, smoothed_dtype(self.states.dim), start, stop)


class SmoothedEpochs:
    """The smoothed error at any stamp, interpolated between the epochs (module docstring)."""

    def __init__(self, times_s: np.ndarray, segment_starts: np.ndarray, recorder):
        self.times_s = times_s
        self._is_segment_start = np.zeros(times_s.size + 1, dtype=bool)
        self._is_segment_start[segment_starts] = True
        # A sentinel "segment" after the last epoch: nothing to interpolate towards.
        self._is_segment_start[times_s.size] = True
        self._recorder = recorder
        self.packing = recorder.packing

    def at(self, t_s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Smoothed error states (N × n, relative to the forward nominal state at each stamp)
        and their covariances (N × n × n) at increasing stamps ``t_s`` (s) of forward
        solutions."""
        t_s = np.asarray(t_s, dtype=float)
        if t_s.size == 0:
            n = self.packing.dimension
            return np.zeros((0, n)), np.zeros((0, n, n))
        epoch = np.searchsorted(self.times_s, t_s, side="right") - 1
        if epoch[0] < 0:
            raise ValueError("a solution precedes the first epoch of the filter")
        first, last = int(epoch[0]), int(epoch[-1])
        rows = self._recorder.smoothed_rows(first, min(last + 2, self.times_s.size))
        local = epoch - first
        following = np.minimum(local + 1, len(rows) - 1)
        continues = ~self._is_segment_start[epoch + 1]
        t0 = self.times_s[epoch]
        t1 = self.times_s[np.minimum(epoch + 1, self.times_s.size - 1)]
        span = np.where(continues, t1 - t0, 1.0)
        weight = np.where(continues & (span > 0.0), (t_s - t0) / np.where(span > 0, span, 1.0), 0.0)
        weight = np.clip(weight, 0.0, 1.0)[:, None]
        error = (1.0 - weight) * rows["error"][local] + weight * rows["error_before_correction"][
            following
        ]
        covariance = self.packing.unpack(rows["covariance"][local])
        return error, covariance
