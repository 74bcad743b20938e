"""The motion compensation from input values to output values: one object, live and offline.

:class:`CompensationPipeline` corrects the samples of one flow sensor: the anemometer's
(:func:`wind_pipeline`, the true wind of ``compensation_node``) or the DVL's
(:func:`current_pipeline`, the current of ``current_node``). It takes what the node subscribes
to, in the order it arrives, as the values :mod:`wind_comp.compensation_messages` reads from
the messages:

- ``nav/odometry``: stamp, attitude R_nb, body rate ω_ib relative to inertial space and body
  velocity, and their covariances. Each solution is converted with the latitude of the latest
  ``nav/fix`` before it: ω_nb = ω_ib − R_nbᵀ·ω_ie (the Earth's rotation, :mod:`buoy_nav.earth`,
  removed; until the first fix the rate is kept as received, an error below 3e-4 m/s at a 3 m
  lever arm), v_ENU = R_nb·v_body and its covariance R_nb·P_body·R_nbᵀ. The transport rate of
  a buoy (< 1e-7 rad/s) is neglected.
- ``nav/fix``: status and latitude; the latest valid latitude is kept while the fix is lost.
- ``anemometer/wind`` or ``dvl/velocity``: one
  :class:`~wind_comp.compensation_messages.FlowSample` each.

and returns, in the order of the sensor samples, one corrected sample per sensor sample with
its covariance (:class:`~wind_comp.compensator.CorrectedBatch`) and the products of the
averaging windows it closes. The caller pairs the corrected samples with the header stamps of
its sensor messages, first in first out.

The arrivals wait in the pipeline until results are asked for (:meth:`ready`, :meth:`expire`,
:meth:`flush`) and are then handed to the :class:`~wind_comp.compensator.FlowCompensator` in
arrival order, as columns: of one message (the live node asks after every message) or of a
whole stretch (offline processing asks every few hundred samples, or thousand without a bag).
The decisions and numbers are the same either way, by construction: the compensator decides
each sample as of its arrival, and one column arithmetic, elementwise, runs on a batch of any
length.
"""

from __future__ import annotations

import math
import operator
import struct
from array import array
from typing import NamedTuple

import numpy as np

from buoy_common.contract import Reason
from buoy_nav.earth import earth_rate_enu_components
from buoy_nav.rotations import rotate_by_quaternion_components, rotation_matrix_elements
from buoy_nav.stream_sequence import StreamSequence
from wind_comp.compensation_messages import FlowSample
from wind_comp.compensator import (
    NOTHING_DECIDED,
    CorrectedBatch,
    FlowCompensator,
    FlowSensor,
    SampleStatus,
)
from wind_comp.config import CompensatorConfig, CurrentConfig
from wind_comp.flux_products import FluxAverager, FluxProduct
from wind_comp.nav_interpolation import quaternion_norm
from wind_comp.products import CurrentAverager, WindAverager, WindowAverager


class StampOrder:
    """Tracks that the stamps of one topic strictly increase."""

    def __init__(self):
        self.latest_s = -math.inf

    def advance(self, t_s: float) -> bool:
        """True and remember ``t_s`` (s) when it is later than every earlier accepted stamp."""
        if not t_s > self.latest_s:
            return False
        self.latest_s = t_s
        return True


def level_rate_components(angular_rate_body_rad_s, quat_xyzw, latitude_deg) -> tuple:
    """Body rate relative to the local-level frame from the rate relative to inertial space:
    ω_nb = ω_ib − R_nbᵀ·ω_ie, by components.

    Args:
        angular_rate_body_rad_s: ω_ib (x, y, z), body axes, rad/s.
        quat_xyzw: body→ENU attitude (x, y, z, w), any non-zero norm.
        latitude_deg: geodetic latitude, deg; NaN where unknown, which leaves the rate as
            received.

    Each component is a float or an array, all of one shape (elementwise: one sample alone and
    a batch give bit-identical results). Returns ω_nb (x, y, z), body axes, rad/s, as arrays.
    """
    latitude_rad = np.radians(latitude_deg)
    x, y, z, w = quat_xyzw
    earth_rate_body = rotate_by_quaternion_components(
        (-x, -y, -z, w), earth_rate_enu_components(latitude_rad)
    )
    known = np.isfinite(latitude_rad)
    return tuple(
        np.where(known, rate - np.where(known, earth, 0.0), rate)
        for rate, earth in zip(angular_rate_body_rad_s, earth_rate_body, strict=True)
    )


# stamp, quaternion (4), rate (3), body velocity (3), latitude, trusted, then the covariances
# (9 each, row-major) of the attitude (ENU), the body velocity and the body rate
_NAV_FIELDS = 40
# stamp, flow (3), noise covariance (9, row-major), held off the sequence (1 or 0), confirming a
# new sequence (1 or 0)
_SAMPLE_FIELDS = 15
# A row is packed whole into the array's bytes (native doubles, as the array holds them):
# array.extend converts a tuple item by item, at twice the cost.
_NAV_ROW = struct.Struct(f"@{_NAV_FIELDS}d")
_SAMPLE_ROW = struct.Struct(f"@{_SAMPLE_FIELDS}d")
_ZEROS9 = (0.0,) * 9
_ZEROS36 = (0.0,) * 36
_LINEAR_BLOCK = operator.itemgetter(0, 1, 2, 6, 7, 8, 12, 13, 14)
"""The 3×3 linear block of a row-major 6×6 twist covariance."""
_ANGULAR_BLOCK = operator.itemgetter(21, 22, 23, 27, 28, 29, 33, 34, 35)
"""The 3×3 angular block of a row-major 6×6 covariance."""


class NavigationColumns(NamedTuple):
    """Many solutions' ``nav/odometry`` and ``nav/fix`` values, a row each, in stamp order
    (:meth:`CompensationPipeline.add_navigation_columns`)."""

    stamps_s: np.ndarray
    """(N,) header stamps, s."""
    attitude_xyzw: np.ndarray
    """(N, 4) quaternions of R_nb (body → ENU)."""
    angular_rate_body_rad_s: np.ndarray
    """(N, 3) ω_ib, body, rad/s."""
    velocity_body_mps: np.ndarray
    """(N, 3) body velocity, m/s."""
    attitude_covariance_rad2: np.ndarray
    """(N, 3, 3) attitude error covariance, ENU axes, rad²."""
    body_velocity_covariance_m2s2: np.ndarray
    """(N, 3, 3) body velocity covariance, m²/s² (the twist covariance's linear block)."""
    body_rate_covariance_rad2_s2: np.ndarray
    """(N, 3, 3) body rate covariance, rad²/s² (the twist covariance's angular block)."""
    fix_latitude_deg: np.ndarray
    """(N,) latitude of each solution's ``nav/fix`` (status: a fix), deg."""


def _largest_diagonal(covariances: np.ndarray) -> np.ndarray:
    """The largest variance of each 3×3 in ``covariances`` (N × 3 × 3), as the builtin ``max``
    of the three takes it (the first, replaced by a later one only when greater: NaN kept
    only in first place), so that a batch decides as :meth:`add_odometry` does."""
    largest = covariances[:, 0, 0].copy()
    for axis in (1, 2):
        variance = covariances[:, axis, axis]
        greater = variance > largest
        largest[greater] = variance[greater]
    return largest


NAV_SAMPLES_HELD_AT_MOST = 256
"""Navigation samples held while they can decide no sensor sample (2.56 s at 100 Hz: a sensor
that stops must not make the pipeline hold the navigation without bound)."""

VALID = "valid"
"""The outcome of a valid sample in :meth:`CompensationPipeline.status_counts`."""


class CompensationOutput(NamedTuple):
    """What the pipeline decided since it was last asked."""

    samples: CorrectedBatch
    """One corrected sample per sensor sample, in input order."""
    products: list
    """The products of the averaging windows closed, in the order they closed."""


class CompensationPipeline:
    """Navigation and flow-sensor samples in, corrected samples and their products out."""

    def __init__(
        self,
        sensor: FlowSensor,
        max_nav_gap_s: float,
        nav_history_s: float,
        max_attitude_sigma_deg: float,
        averagers: list[WindowAverager],
        flux_averagers: list[FluxAverager] = (),
    ):
        """sensor, max_nav_gap_s, nav_history_s: as :class:`FlowCompensator` takes them;
        max_attitude_sigma_deg: navigation whose attitude 1σ exceeds it corrects no sample,
        deg; averagers: one per product window, fed the corrected samples; flux_averagers:
        the eddy-covariance fluxes of the corrected samples and the sonic temperature."""
        self.sensor = sensor
        self.compensator = FlowCompensator(sensor, max_nav_gap_s, nav_history_s)
        self.averagers = averagers
        self.flux_averagers = list(flux_averagers)
        self.latitude_deg = math.nan
        """Latitude of the latest valid ``nav/fix``, deg (NaN before the first)."""
        self._nav_order = StampOrder()
        self._max_attitude_variance_rad2 = math.radians(max_attitude_sigma_deg) ** 2
        self._sample_order = StampOrder()
        self._sample_sequence = StreamSequence()
        self._n_samples = 0
        """Sensor samples added so far: the number of the next, as
        :meth:`FlowCompensator.settle_held` counts them."""
        self._n_held = 0
        """Held samples not yet settled."""
        self._n_given_up = 0
        """Held samples given up since :meth:`take_given_up` was last asked."""
        # Held samples settled since the last hand-over: their numbers, and True where released.
        self._settled: list[int] = []
        self._released: list[bool] = []
        # Arrivals not yet handed to the compensator: the navigation samples' numbers in a row
        # (_NAV_FIELDS per sample: stamp, quaternion, rate, body velocity, latitude, trusted,
        # covariances), the sensor samples', and for each sensor sample the number of
        # navigation samples before it.
        self._nav = array("d")
        self._samples = array("d")
        self._nav_before_sample: list[int] = []

    @property
    def counts(self) -> dict[SampleStatus, int]:
        """Corrected samples returned so far, per status."""
        return self.compensator.counts

    def status_counts(self) -> dict[str, int]:
        """:attr:`counts` by name: ``valid`` or the contract's reason of the invalid ones."""
        return {
            VALID if status == SampleStatus.VALID else self.sensor.reason(status): n
            for status, n in self.counts.items()
        }

    @property
    def latest_navigation_stamp_s(self) -> float:
        """The latest ``nav/odometry`` stamp taken, s (-inf before the first)."""
        return self._nav_order.latest_s

    @property
    def latest_sample_stamp_s(self) -> float:
        """The latest sensor stamp accepted in order, s (-inf before the first)."""
        return self._sample_order.latest_s

    @property
    def n_navigation_held(self) -> int:
        """Navigation samples received but not yet handed to the compensator."""
        return len(self._nav) // _NAV_FIELDS

    @property
    def n_pending(self) -> int:
        """Sensor samples received but not yet returned."""
        return len(self._nav_before_sample) + self.compensator.n_pending

    def add_fix(self, status: int, latitude_deg: float) -> str | None:
        """One ``nav/fix`` (status, latitude deg). Returns why it is rejected (a latitude not
        finite or beyond ±90° while it reports a fix), None when taken. A fix reporting no
        fix (status < 0) leaves the latitude as it was."""
        if status < 0:
            return None
        if not math.isfinite(latitude_deg):
            return Reason.NON_FINITE
        if abs(latitude_deg) > 90.0:
            return Reason.LATITUDE_OUT_OF_RANGE
        self.latitude_deg = latitude_deg
        return None

    def add_odometry(
        self,
        t_s: float,
        quat_xyzw,
        angular_rate_body_rad_s,
        velocity_body_mps,
        attitude_variance_rad2: float = 0.0,
        attitude_covariance_rad2=_ZEROS9,
        twist_covariance=_ZEROS36,
    ):
        """One ``nav/odometry`` (stamp s, attitude (x, y, z, w), ω_ib (3,) rad/s, body velocity
        (3,) m/s, largest attitude error variance rad², the attitude covariance (9 row-major,
        ENU axes, rad²) and the twist covariance (36 row-major: body velocity m²/s², body rate
        rad²/s²)), as :func:`~wind_comp.compensation_messages.odometry_fields` reads it. A
        sample whose attitude variance exceeds ``max_attitude_sigma_deg``² corrects no sample
        (NAVIGATION_NOT_TRUSTED). Returns why it is rejected (a stamp not later than the
        previous one), None when taken; ValueError for vectors of the wrong length."""
        if not t_s > self._nav_order.latest_s:
            return Reason.STAMP_NOT_INCREASING
        if len(twist_covariance) != 36:
            raise ValueError("odometry needs a twist covariance of 36 values")
        row = (
            t_s,
            *quat_xyzw,
            *angular_rate_body_rad_s,
            *velocity_body_mps,
            self.latitude_deg,
            float(attitude_variance_rad2 <= self._max_attitude_variance_rad2),
            *attitude_covariance_rad2,
            *_LINEAR_BLOCK(twist_covariance),
            *_ANGULAR_BLOCK(twist_covariance),
        )
        if len(row) != _NAV_FIELDS:
            raise ValueError(
                "odometry needs a quaternion of 4 values, vectors of 3 and an attitude "
                "covariance of 9"
            )
        self._nav.frombytes(_NAV_ROW.pack(*row))
        self._nav_order.advance(t_s)
        return None

    def add_navigation_columns(self, columns: NavigationColumns) -> None:
        """Many ``nav/odometry`` and ``nav/fix`` at once, each solution's odometry then its fix
        in stamp order, as :meth:`add_odometry` and :meth:`add_fix` take them one by one: the
        same rows to the bit (a run that writes no bag hands its navigation over in bulk). An
        odometry whose stamp is not later than every earlier one is left out, as
        :meth:`add_odometry` rejects it; its fix still counts."""
        count = len(columns.stamps_s)
        if count == 0:
            return
        stamps = np.asarray(columns.stamps_s, dtype=float)
        # Later than every stamp before it, kept or not: the kept ones increase, and one left
        # out is no later than the latest kept (a NaN, never kept, moves nothing).
        previous_latest = np.fmax.accumulate(np.concatenate(([self._nav_order.latest_s], stamps)))
        kept = stamps > previous_latest[:-1]
        latitude_before = self._latitudes_before(columns.fix_latitude_deg)
        attitude_covariance = np.asarray(columns.attitude_covariance_rad2, dtype=float)
        rows = np.column_stack(
            (
                stamps,
                columns.attitude_xyzw,
                columns.angular_rate_body_rad_s,
                columns.velocity_body_mps,
                latitude_before,
                _largest_diagonal(attitude_covariance) <= self._max_attitude_variance_rad2,
                attitude_covariance.reshape(count, 9),
                np.asarray(columns.body_velocity_covariance_m2s2, dtype=float).reshape(count, 9),
                np.asarray(columns.body_rate_covariance_rad2_s2, dtype=float).reshape(count, 9),
            )
        )
        self._nav.frombytes(rows[kept].tobytes())
        if kept.any():
            self._nav_order.advance(float(stamps[kept][-1]))

    def _latitudes_before(self, fix_latitude_deg) -> np.ndarray:
        """The latitude each odometry of a batch is converted with (deg): that of the latest
        valid fix before it, as :meth:`add_fix` keeps it; the pipeline's latitude then
        follows the batch's fixes."""
        latitudes = np.empty(len(fix_latitude_deg))
        latitude = self.latitude_deg
        for index, fix_latitude in enumerate(fix_latitude_deg):
            latitudes[index] = latitude
            if math.isfinite(fix_latitude) and abs(fix_latitude) <= 90.0:
                latitude = fix_latitude
        self.latitude_deg = latitude
        return latitudes

    def add_temperature(self, t_s: float, temperature_degc: float) -> list[FluxProduct]:
        """One ``anemometer/temperature`` (stamp s, °C) for the fluxes; returns the flux
        windows it lets close (:class:`~wind_comp.flux_products.FluxAverager`)."""
        products = []
        for averager in self.flux_averagers:
            products += averager.add_temperature(t_s, temperature_degc)
        return products

    def add_sample(self, sample: FlowSample, navigation_held_back: int = 0) -> str | None:
        """One ``anemometer/wind`` or ``dvl/velocity``. Returns why it is rejected (the
        message's own ``rejection``, or a stamp not later than the previous one), None when
        accepted or held off the sensor's sequence (settled later; the held samples given up
        are counted by :meth:`take_given_up`). Every sample, rejected or not, gets its (then
        invalid) output, in input order. navigation_held_back: navigation samples that
        arrived before this sample but that the caller hands over later
        (:meth:`add_navigation_columns`, before it asks for results)."""
        x, y, z = sample.flow_sensor_mps
        held, confirming = self._screen_sequence(sample)
        stamp_increases = (not held or confirming) and self._sample_order.advance(sample.t_s)
        noise = sample.noise_covariance_m2s2
        self._samples.frombytes(
            _SAMPLE_ROW.pack(
                sample.t_s,
                x,
                y,
                z,
                *(self.sensor.noise_covariance_m2s2 if noise is None else noise),
                float(held),
                float(confirming),
            )
        )
        self._nav_before_sample.append(len(self._nav) // _NAV_FIELDS + navigation_held_back)
        self._n_samples += 1
        if sample.rejection is not None:
            return sample.rejection
        return None if held or stamp_increases else Reason.STAMP_NOT_INCREASING

    def _screen_sequence(self, sample: FlowSample) -> tuple[bool, bool]:
        """Whether ``sample`` is held off the sensor's sequence of stamps
        (:mod:`buoy_nav.stream_sequence`), and whether it confirms the held samples as the
        sensor's new sequence (after an outage or a step of its clock). A held sample waits in
        the compensator, output withheld, until the sequence tells it apart from a second
        stream's. Samples the sensor flags invalid are still its own; another frame's are
        not."""
        if sample.rejection == Reason.WRONG_FRAME or not math.isfinite(sample.t_s):
            return False, False
        screening = self._sample_sequence.screen(sample.t_s, self._n_samples)
        if screening.given_up:
            self._settle(screening.given_up, released=False)
        if not screening.held:
            return False, False
        self._n_held += 1
        confirming = bool(screening.taken)
        if confirming:
            self._settle(screening.taken, released=True)
        return True, confirming

    def _settle(self, sample_numbers: list[int], released: bool) -> None:
        self._settled += sample_numbers
        self._released += [released] * len(sample_numbers)
        self._n_held -= len(sample_numbers)
        if not released:
            self._n_given_up += len(sample_numbers)

    def take_given_up(self) -> int:
        """Held samples given up (their outputs OUT_OF_SEQUENCE: a second stream's) since last
        asked: the sensor's rejections that are decided after the sample's arrival."""
        given_up, self._n_given_up = self._n_given_up, 0
        return given_up

    @property
    def second_stream(self) -> tuple[int, float]:
        """(samples of a second stream on the sensor's topic rejected so far, how far the last
        ran ahead of the sensor's own in s)."""
        sequence = self._sample_sequence
        return sequence.second_stream_samples, sequence.second_stream_lead_s

    def ready(self) -> CompensationOutput:
        """Every sample that can now be decided, in input order, and the windows it closes."""
        # Navigation stamped before every waiting sample decides nothing: it waits here, up to
        # a stretch, and goes to the compensator with what can decide a sample (the decisions
        # depend on the order of arrival, not on when results are asked for: see the module
        # docstring), sparing the live node a hand-over per navigation message.
        if (
            not self._samples
            and len(self._nav) < NAV_SAMPLES_HELD_AT_MOST * _NAV_FIELDS
            and self._newest_nav_held_s() < self.compensator.first_undecided_stamp_s
        ):
            return CompensationOutput(NOTHING_DECIDED, [])
        self._hand_over()
        return self._output(self.compensator.ready())

    def _newest_nav_held_s(self) -> float:
        """Stamp (s) of the newest navigation sample not yet handed over (-inf: none)."""
        return self._nav[-_NAV_FIELDS] if self._nav else -math.inf

    @property
    def n_nav_accepted(self) -> int:
        """Navigation samples accepted so far (those still held here included)."""
        self._hand_over()
        return self.compensator.nav_track.n_accepted

    def expire(self, before_t_s: float) -> CompensationOutput:
        """:meth:`ready`, giving up on samples stamped before ``before_t_s`` (s) that still
        wait for navigation (NAVIGATION_TIMEOUT): the live node's latency budget."""
        self._hand_over()
        return self._output(self.compensator.expire(before_t_s))

    def flush(self) -> CompensationOutput:
        """End of the data: every sample decided (NO_NAVIGATION where navigation never caught
        up) and every averaging window closed, partial ones included."""
        self._hand_over()
        # Held samples never confirmed as the sensor's are given up.
        self._n_given_up += self._n_held
        self._n_held = 0
        output = self._output(self.compensator.flush())
        for averager in (*self.averagers, *self.flux_averagers):
            output.products.extend(averager.flush())
        return output

    def _hand_over(self) -> None:
        """Give the arrivals so far to the compensator, in their order."""
        nav, samples, nav_before_sample = self._nav, self._samples, self._nav_before_sample
        if not nav and not samples:
            return
        self._nav, self._samples, self._nav_before_sample = array("d"), array("d"), []
        flows = np.frombuffer(samples, dtype=float).reshape(-1, _SAMPLE_FIELDS)
        self.compensator.add_arrivals(
            _navigation_columns(np.frombuffer(nav, dtype=float).reshape(-1, _NAV_FIELDS)),
            flows[:, 0],
            flows[:, 1:4],
            nav_before_sample,
            flows[:, 4:13].reshape(-1, 3, 3),
            flows[:, 13] == 1.0,
            flows[:, 14] == 1.0,
        )
        # Settling a held sample only changes what navigation it waits for, and no sample is
        # looked up before the hand-over: settled here, as at its arrival.
        if self._settled:
            self.compensator.settle_held(self._settled, self._released)
            self._settled, self._released = [], []

    def _output(self, corrected: CorrectedBatch) -> CompensationOutput:
        products = []
        if len(corrected):
            for averager in self.averagers:
                products += averager.add_batch(
                    corrected.t_s, corrected.flow_enu_mps, corrected.covariance
                )
            # The translation term is the platform velocity each sample was corrected with:
            # what the fluxes' "motion left" test looks for in the corrected w.
            platform_up_mps = corrected.translation_term_enu_mps[:, 2]
            for averager in self.flux_averagers:
                products += averager.add_batch(
                    corrected.t_s, corrected.flow_enu_mps, platform_up_mps
                )
        # A sample closes the windows it is the first of, in averager order: the windows
        # closed by one sample share their last sample.
        products.sort(key=lambda product: product.last_sample_s)
        return CompensationOutput(corrected, products)


def _navigation_columns(odometry: np.ndarray) -> tuple:
    """What :meth:`FlowCompensator.add_arrivals` takes of the navigation, from (M, 40) rows
    of stamp s, attitude xyzw, ω_ib rad/s (body), body velocity m/s, latitude deg, trusted
    (1 or 0) and the covariances of the attitude (ENU, rad²), the body velocity (m²/s²) and
    the body rate (rad²/s²): stamps, attitudes, ω_nb (body, rad/s), ENU velocities (m/s),
    trusted, and the (M, 3, 3, 3) covariances with the velocity's turned to ENU."""
    quats, rates, velocities_body = odometry[:, 1:5], odometry[:, 5:8], odometry[:, 8:11]
    covariances = odometry[:, 13:40].reshape(-1, 3, 3, 3).copy()
    trusted = odometry[:, 12] == 1.0
    if not odometry.shape[0]:
        return odometry[:, 0], quats, rates, velocities_body, trusted, covariances
    rates_nb = level_rate_components(rates.T, quats.T, odometry[:, 11])
    velocities_enu = rotate_by_quaternion_components(quats.T, velocities_body.T)
    unit_quats = quats / quaternion_norm(*quats.T)[:, None]
    rotation_nb = np.stack(rotation_matrix_elements(*unit_quats.T), axis=-1).reshape(-1, 3, 3)
    covariances[:, 1] = rotation_nb @ covariances[:, 1] @ np.swapaxes(rotation_nb, -1, -2)
    return (
        odometry[:, 0],
        quats,
        np.stack(rates_nb, axis=-1),
        np.stack(velocities_enu, axis=-1),
        trusted,
        covariances,
    )


def wind_pipeline(config: CompensatorConfig) -> CompensationPipeline:
    """The pipeline of ``compensation_node``: the anemometer's samples corrected into the true
    wind, averaged into the wind products."""
    return CompensationPipeline(
        config.flow_sensor(),
        config.max_nav_gap_s,
        config.nav_history_s,
        config.max_attitude_sigma_deg,
        [WindAverager(window_s, config.gust_window_s) for window_s in config.product_windows_s],
        [
            FluxAverager(
                config.flux_window_s,
                config.planar_fit(),
                config.air_pressure_pa,
                config.flux_despike,
                config.motion_left_thresholds(),
                config.flux_quality_limits(),
            )
        ],
    )


def current_pipeline(config: CurrentConfig) -> CompensationPipeline:
    """The pipeline of ``current_node``: the DVL's samples corrected into the current,
    averaged into the current products."""
    return CompensationPipeline(
        config.flow_sensor(),
        config.max_nav_gap_s,
        config.nav_history_s,
        config.max_attitude_sigma_deg,
        [CurrentAverager(window_s) for window_s in config.product_windows_s],
    )


MOSTLY_INVALID_FRACTION = 0.5
"""A run whose outputs are invalid in more than this fraction ends with a loud warning (and
``process_bag`` with exit code 4): a wrong frame or a dead sensor must not look like a
successful run."""


def mostly_invalid_warning(status_counts: dict[str, int], samples_name: str) -> str | None:
    """The warning for a run in which most samples came out invalid, None otherwise.

    ``status_counts`` are the outcomes of the run (:meth:`CompensationPipeline.status_counts`)
    of samples called ``samples_name`` (``wind``, ``DVL``); the warning names the most frequent
    reason."""
    total = sum(status_counts.values())
    invalid = {reason: n for reason, n in status_counts.items() if reason != VALID and n}
    n_invalid = sum(invalid.values())
    if total == 0 or n_invalid <= MOSTLY_INVALID_FRACTION * total:
        return None
    main_reason = max(invalid, key=invalid.get)
    return (
        f"most {samples_name} samples are invalid: {n_invalid} of {total} "
        f"(mostly {main_reason}: {invalid[main_reason]})"
    )


def wrong_frame_message(topic: str, frame_id: str, expected_frame_id: str, parameter: str) -> str:
    """The error for a sensor message on ``topic`` in an unexpected frame; ``parameter`` is
    the one naming the frame expected (``compensation.anemometer_frame_id``, ...)."""
    return (
        f"{topic} in frame '{frame_id}', expected '{expected_frame_id}': its samples are "
        f"rejected (wrong_frame); set {parameter} if the driver names the sensor's frame so"
    )
