"""A moored buoy's zero mean velocity, as a pseudo-measurement of its position.

A moored buoy moves by metres per second with the waves but stays on its mooring: over minutes
its mean velocity is zero. Without GNSS velocity nothing else bounds the inertial velocity
error, which grows with every tilt and accelerometer-bias error (g·δθ per second). The constraint
is written on the position, the integral of the velocity: every ``moored_update_period_s`` the
position is measured to equal its own slow mean (the anchor, an exponential mean of the
estimated position with time constant ``moored_anchor_time_constant_s``), with a 1-σ of the wave
excursion about it (``moored_position_sigma_horizontal_m``, ``..._vertical_m``)::

    z = anchor (ENU offset 0),   h(x) = p − anchor,   H = I on the position error.

To the filter the wave excursion is measurement noise, so the constraint is a high-pass on the
inertial motion: displacements that are small against σ at wave periods pass, while a drift of
the velocity (whose position error grows without bound) is pulled back. The time scale where
the two meet is set by σ, the update period and the IMU's accelerometer noise; the bench
(``make bench``, section ``sensor_sets``) reports the wind error it leaves at wave periods and
over minutes.

It runs only while no GNSS fix has been accepted for ``coasting_timeout_s`` and only with
``moored: true`` (a drifting buoy has no zero mean velocity). It aids its own quantity,
:data:`~buoy_nav.aiding.base.MOORING`, so the fix is still reported as coasting.

A mooring set on a buoy that drifts would pass its gate (the filter's velocity follows it
through every outage) and hold the velocity near zero: the wind's σ would be far too small.
While a GNSS receiver measures the motion, the mooring is judged against it
(:meth:`MooredSource.judged_by`): over ``moored_check_window_s`` (once the measurements span a
fifth of it) the mean horizontal velocity from the fixes' displacement (or the velocities' mean)
is held against what the mooring says of it, zero with the covariance of the wave excursion at
both ends, ``2 σ_h² / T² I`` over a span T, plus the receiver's own noise. Beyond the
chi-square quantile of ``gate_probability`` (two degrees of freedom) the mooring is
contradicted and suspended; below the quantile of
:data:`~buoy_nav.chi_square.AGREEMENT_PROBABILITY` it is not (in between the verdict
stands). Without a receiver it cannot be judged; the start-up statement
(:mod:`buoy_nav.observability`) says so.

Without GNSS the mooring's own innovations still say when it is held too tight
(:class:`~buoy_nav.innovation_watch.InnovationWatch`): over ``moored_check_window_s`` the
normalised RMS of their horizontal part, ``sqrt(Σ NIS / Σ dim)``, is 1 for a consistent filter;
beyond :data:`~buoy_nav.innovation_watch.WARNING_RATIO` the filter's position wanders from its
anchor more than the stated σ and the filter's covariance together allow, because a slow tilt
error (the gyro's bias wander stated too small) drives the velocity, or because the sea moves
the buoy further than ``moored_position_sigma_horizontal_m``.
It is said (logged once a window while it holds, and in the diagnostics) and acted on: a source
that claims more than it delivers is fused with the noise its own innovations show. Beyond
that ratio the horizontal σ is widened by the factor that makes the window's
innovations consistent (bounded by ``moored_sigma_scale_limit``; 1 never widens), followed as
the window moves, back to the stated σ once the innovations are no larger than stated; the
wider σ lets the velocity's and position's covariance grow with what the mooring cannot hold.
The vertical σ, which no watch judges, stays as stated.

Offline, the compiled stretches make most of its epochs (:mod:`buoy_nav.mooring_epoch`), the
watches' among them, while the innovation watch says nothing new and the mean velocity's
watches widen or narrow no noise; its books are then kept as :meth:`MooredSource.replayed`
says, the same as the engine's to the bit.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numba
import numpy as np

from buoy_common.contract import Reason
from buoy_nav import earth
from buoy_nav.aiding.base import (
    MOORING,
    AidingSource,
    LinearisationPoint,
    MeasurementModel,
    MotionWitness,
    Verdict,
)
from buoy_nav.aiding.model_kernels import place_identity
from buoy_nav.chi_square import AGREEMENT_PROBABILITY, chi_square_quantile
from buoy_nav.innovation_watch import MIN_SPAN_OF_WINDOW, InnovationWatch, WatchArrays
from buoy_nav.mean_velocity_watch import (
    GYRO_DRIFT,
    VELOCITY_NOISE,
    BlockArrays,
    MeanVelocityWatch,
    stacked,
)


class MooringStretch(NamedTuple):
    """What the compiled stretches take of the mooring (:mod:`buoy_nav.stretched_mooring`): its
    anchor (rad, rad, m; None before one is set) and the anchor's stamp (s), time constant (s)
    and period (s); its stated covariance (3×3 m², ENU); its innovation watch, its window from
    index 0 with room after it (:meth:`~buoy_nav.innovation_watch.InnovationWatch.arrays`);
    and the mean velocity's watches, the gyro drift's and the velocity noise's, a row each
    (:attr:`~buoy_nav.mean_velocity_watch.MeanVelocityWatch.arrays`)."""

    anchor: np.ndarray | None
    anchor_t_s: float
    time_constant_s: float
    period_s: float
    covariance_m2: np.ndarray
    innovation_watch: WatchArrays
    velocity_watches: BlockArrays


class MooringAnchor(NamedTuple):
    """The slow mean position (rad, rad, m) the buoy is held to."""

    latitude_rad: float
    longitude_rad: float
    altitude_m: float


@numba.njit(cache=True)
def anchor_model(
    offset_enu_m, covariance_m2, horizontal_variance_scale, position_start, state_count
):
    """The measurement function of the anchor at ``offset_enu_m`` (ENU, m) from the nominal
    position: predicted offset 0, the innovation, the Jacobian over ``state_count`` error states
    (I on the position from ``position_start``) and R, the stated ``covariance_m2`` (m²) with
    its horizontal block multiplied by ``horizontal_variance_scale`` (the square of the factor
    the innovations widen the σ by)."""
    jacobian = np.zeros((3, state_count))
    place_identity(jacobian, position_start)
    covariance = covariance_m2.copy()
    for i in range(2):
        for j in range(2):
            covariance[i, j] *= horizontal_variance_scale
    return np.zeros(3), offset_enu_m, jacobian, covariance


class MooredSource(AidingSource):
    """Zero mean velocity of a moored buoy (see the module docstring)."""

    kind = "moored"
    topic = None
    measurement_type = MooringAnchor
    aids = MOORING
    pseudo = True
    has_compiled_model = True

    def __init__(self, config, states):
        super().__init__(config, states)
        self._period_s = config.moored_update_period_s
        self._time_constant_s = config.moored_anchor_time_constant_s
        self._covariance = np.diag(
            (
                config.moored_position_sigma_horizontal_m**2,
                config.moored_position_sigma_horizontal_m**2,
                config.moored_position_sigma_vertical_m**2,
            )
        )
        self._gnss_timeout_s = config.coasting_timeout_s
        self._excursion_sigma_m = config.moored_position_sigma_horizontal_m
        self._min_span_s = MIN_SPAN_OF_WINDOW * config.moored_check_window_s
        self._contradiction_quantile = chi_square_quantile(2, config.gate_probability)
        self._agreement_quantile = chi_square_quantile(2, AGREEMENT_PROBABILITY)
        self._watch = InnovationWatch(
            config.moored_check_window_s,
            config.moored_position_sigma_horizontal_m,
            config.moored_sigma_scale_limit,
        )
        self._position_warning = ""
        self._drift_watch = MeanVelocityWatch(
            config.moored_check_window_s,
            config.moored_position_sigma_horizontal_m,
            GYRO_DRIFT,
            config.moored_gyro_drift_scale_limit,
        )
        self._noise_watch = MeanVelocityWatch(
            config.moored_check_window_s,
            config.moored_position_sigma_horizontal_m,
            VELOCITY_NOISE,
            config.moored_velocity_noise_scale_limit,
        )
        self._watches_changed = False
        self._anchor: np.ndarray | None = None
        self._anchor_t_s = -math.inf
        self.next_due_s = -math.inf
        """Stamp (s) from which the engine asks for the next pseudo-measurement."""

    @classmethod
    def enabled_by(cls, config) -> bool:
        return config.moored

    @property
    def suspension_hint(self) -> str:
        return (
            "fusion.moored is wrong for this buoy, or fusion.moored_position_sigma_horizontal_m "
            "too small"
        )

    def judged_by(self, motion: MotionWitness) -> Verdict | None:
        """The receiver's mean horizontal velocity against the mooring's zero mean (see the
        module docstring); None before the measurements span enough or while the drift is
        between the two quantiles."""
        mean = motion.mean_velocity(self._min_span_s)
        if mean is None:
            return None
        drift = mean.velocity_enu_mps[:2]
        stated_variance = 2.0 * self._excursion_sigma_m**2 / mean.span_s**2
        covariance = mean.covariance_m2s2[:2, :2] + stated_variance * np.eye(2)
        normalised_squared = float(drift @ np.linalg.solve(covariance, drift))
        said = (
            f"GNSS ({mean.measured_by}) shows a mean drift of {np.linalg.norm(drift):.2f} m/s "
            f"over {mean.span_s:.0f} s, {math.sqrt(normalised_squared):.1f}σ from a mooring's "
            f"zero (σ {math.sqrt(stated_variance):.3f} m/s from "
            f"moored_position_sigma_horizontal_m)"
        )
        if normalised_squared > self._contradiction_quantile:
            return Verdict(True, said)
        if normalised_squared < self._agreement_quantile:
            return Verdict(False, said)
        return None

    def innovation_warning(
        self, t_s: float, innovation: np.ndarray, innovation_covariance: np.ndarray
    ) -> str | None:
        """The horizontal innovation to :class:`InnovationWatch`, with the filter's part of its
        covariance (S less the mooring's σ it was fused with): the vertical one, of a σ the
        heave rarely fills, would dilute what the tilt error does to the horizontal. Said with
        what the mean velocity's watches say, joined, whenever one of them changed."""
        scale = self._watch.scale
        fused_variance = scale * scale * self._covariance[0, 0]
        filter_covariance = innovation_covariance[:2, :2] - fused_variance * np.eye(2)
        position_warning = self._watch.add(t_s, innovation[:2], filter_covariance)
        if position_warning is not None:
            self._position_warning = position_warning
        elif not self._watches_changed:
            return None
        self._watches_changed = False
        return "; ".join(
            w
            for w in (
                self._position_warning,
                self._drift_watch.warning,
                self._noise_watch.warning,
            )
            if w
        )

    @property
    def gyro_drift_scale(self) -> float:
        """Factor on the gyro drift's σ the blocks' mean velocity asks for
        (:mod:`buoy_nav.mean_velocity_watch`)."""
        return self._drift_watch.scale

    def take_covariance_factor(self) -> float:
        """The larger of the two watches' variance factors found since last asked."""
        return max(
            self._drift_watch.take_covariance_factor(),
            self._noise_watch.take_covariance_factor(),
        )

    @property
    def accel_noise_scale(self) -> float:
        """Factor on the velocity noise's σ its 10-s blocks ask for."""
        return self._noise_watch.scale

    def restart(self) -> None:
        """Forget the anchor and the mean velocity's blocks in progress (after a realignment);
        the gyro's drift and the velocity's noise stay as widened, properties of the sensors."""
        self._anchor = None
        self._drift_watch.restart()
        self._noise_watch.restart()
        self.next_due_s = -math.inf

    def pseudo_measurement(
        self, t_s: float, state, fix_age_s: float, velocity_covariance_m2s2: np.ndarray
    ) -> MooringAnchor | None:
        """The anchor at ``t_s`` for the nominal ``state``; None while GNSS fixes are accepted
        (``fix_age_s``: time since the last one, s). Moves the anchor toward the state, and
        gives the state's velocity with its covariance (m²/s², ENU 3×3) to the mean velocity's
        watch."""
        self.next_due_s = t_s + self._period_s
        position = np.array((state.latitude_rad, state.longitude_rad, state.altitude_m))
        if self._anchor is None or fix_age_s <= self._gnss_timeout_s:
            self._anchor = position
            self._anchor_t_s = t_s
            self._drift_watch.restart()
            self._noise_watch.restart()
            return None
        self._watch_velocity(t_s, state.velocity_enu_mps, velocity_covariance_m2s2)
        weight = -math.expm1(-(t_s - self._anchor_t_s) / self._time_constant_s)
        return self._anchored(t_s, self._anchor + weight * (position - self._anchor))

    def replayed(
        self, t_s: float, velocity_enu_mps, velocity_covariance_m2s2, anchor
    ) -> MooringAnchor:
        """The books of the epoch a compiled stretch made at ``t_s`` (s), as
        :meth:`pseudo_measurement` keeps them: the filter's velocity (m/s ENU) and its
        covariance (3×3 m²/s²) then to the mean velocity's watches, whose blocks the stretch
        closes only with a verdict that changes nothing, and the ``anchor`` (rad, rad, m) it
        moved to."""
        self.next_due_s = t_s + self._period_s
        if self._watch_velocity(t_s, velocity_enu_mps, velocity_covariance_m2s2):
            raise RuntimeError("a mooring's mean velocity block changed a noise in a stretch")
        return self._anchored(t_s, np.array(anchor))

    def stretch(self, room: int) -> MooringStretch:
        """What the compiled stretches take of the mooring now, with room for ``room`` of its
        epochs."""
        return MooringStretch(
            self._anchor,
            self._anchor_t_s,
            self._time_constant_s,
            self._period_s,
            self._covariance,
            self._watch.arrays(room),
            stacked([self._drift_watch.arrays, self._noise_watch.arrays]),
        )

    @property
    def anchored(self) -> bool:
        """Whether the anchor is set."""
        return self._anchor is not None

    def fixes_reset(self, fix_age_s: float) -> bool:
        """Whether a fix of age ``fix_age_s`` (s) resets the anchor instead of the constraint
        holding to it."""
        return fix_age_s <= self._gnss_timeout_s

    def _watch_velocity(self, t_s: float, velocity_enu_mps, velocity_covariance_m2s2) -> bool:
        """The velocity (m/s ENU) and its covariance (3×3 m²/s²) at ``t_s`` (s) to the mean
        velocity's watches; whether either changed what it widens."""
        changed = False
        if self._drift_watch.add(t_s, velocity_enu_mps, velocity_covariance_m2s2):
            changed = True
        if self._noise_watch.add(t_s, velocity_enu_mps, velocity_covariance_m2s2):
            changed = True
        if changed:
            self._watches_changed = True
        return changed

    def _anchored(self, t_s: float, anchor: np.ndarray) -> MooringAnchor:
        """The anchor (rad, rad, m) moved at ``t_s`` (s)."""
        self._anchor = anchor
        self._anchor_t_s = t_s
        return MooringAnchor(*anchor)

    def measurement_from_message(self, message) -> Reason:
        return Reason.MALFORMED

    def validated(self, measurement: MooringAnchor) -> MooringAnchor:
        return measurement

    def model(self, measurement: MooringAnchor, point: LinearisationPoint) -> MeasurementModel:
        state = point.state
        offset = np.array(
            earth.enu_offset_scalar(
                state.latitude_rad,
                state.longitude_rad,
                state.altitude_m,
                measurement.latitude_rad,
                measurement.longitude_rad,
                measurement.altitude_m,
            )
        )
        states, scale = self.states, self._watch.scale
        return MeasurementModel(
            *anchor_model(
                offset, self._covariance, scale * scale, states.position.start, states.dim
            )
        )

    def load_compiled_code(self) -> None:
        states = self.states
        anchor_model(np.zeros(3), self._covariance, 1.0, states.position.start, states.dim)
        self._watch.load_compiled_code()
        self._drift_watch.load_compiled_code()

    def align(self, aligner, t_s: float, measurement, raw_gyro_rad_s) -> None:
        return None
