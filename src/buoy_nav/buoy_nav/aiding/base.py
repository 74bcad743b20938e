"""What every aiding source of the fusion provides, and the pieces they share.

An aiding source is everything the filter knows about one kind of aiding measurement; the
engine (:class:`buoy_nav.engine.FusionEngine`) is the clock that runs them. A measurement goes

1. **message → measurement**: :meth:`AidingSource.measurement_from_message` reads the contract
   message of :attr:`~AidingSource.topic` (attribute access only: rclpy and rosbags objects both
   work) into the source's measurement type, or returns the :class:`Reason` it carries none;
2. **validation**: :meth:`AidingSource.validated` turns the values into floats and float arrays
   and checks them (finite, plausible, positive variances), or returns the :class:`Reason`;
   the engine counts every rejection per source and reason and queues what passes, in stamp
   order;
3. **alignment** (before the filter runs): :meth:`AidingSource.align` hands the measurement to
   the :class:`~buoy_nav.alignment.InMotionAligner`;
4. **update**: :meth:`AidingSource.model` linearises the measurement at the nominal state
   (:class:`LinearisationPoint`) into a :class:`MeasurementModel` (predicted h, innovation,
   Jacobian H over the error states, noise R), or None when its geometry carries no
   information (counted as ``geometry``), or the :class:`Reason` the measurement contradicts
   what is known of the world at that state (an Earth's field of the wrong strength: counted
   under that reason and as a failed outcome for the source's health); the engine gates a model
   with the chi-square test at :attr:`~AidingSource.gate_probability` and applies the accepted
   measurements of one stamp in one stacked update;
5. **reset**: after :attr:`~AidingSource.reset_after_rejections` consecutive gate rejections,
   :meth:`AidingSource.reset` re-initialises the states the measurement observes
   (:class:`StateReset`), so that a filter that has lost its way follows the sensor again;
6. **health**: every gate outcome is kept by the source's
   :class:`~buoy_nav.source_health.SourceHealth`; a source that keeps failing is suspended: its
   measurements are still modelled and gated but not fused (counted as ``suspended``), they
   neither reset states nor witness the integrity, until it agrees again
   (:attr:`AidingSource.suspension_hint` says what to check);
7. **assumption**: a constraint that states something of the buoy's motion (a mooring's zero
   mean velocity) is judged against what the GNSS receiver measured of it, without the filter
   (:meth:`AidingSource.judged_by`, :mod:`buoy_nav.contradictions`): a constraint the
   measurements disprove is suspended until they no longer do.

Jacobians follow the error-injection convention of
:func:`buoy_nav.error_state_filter.inject_error_state` and address the error states by name
(:mod:`buoy_nav.state_layout`).
"""

from __future__ import annotations

import abc
import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, ClassVar, NamedTuple, Protocol

import numpy as np

from buoy_common.contract import SENSOR_MSGTYPES, Reason, header_seconds
from buoy_nav.aiding import model_kernels
from buoy_nav.config import FusionConfig
from buoy_nav.error_state_filter import NavState
from buoy_nav.rotations import (
    euler_from_rotation_matrix,
    quaternion_from_rotation_matrix,
    rotation_matrix_from_euler,
)
from buoy_nav.state_layout import UP, StateLayout

if TYPE_CHECKING:
    from buoy_nav.alignment import AlignmentResult, InMotionAligner

# What a source aids, for the solutions' coasting flags (``coasting_fix``, ...): a flag is raised
# when no source that aids its quantity was accepted for ``coasting_timeout_s``.
FIX = "fix"
VELOCITY = "velocity"
HEADING = "heading"
MOORING = "mooring"
"""The zero-mean-velocity constraint of a moored buoy: it clears no GNSS coasting flag."""
AIDED_QUANTITIES = (FIX, VELOCITY, HEADING, MOORING)

# The sensor a source's measurements come from (``sensor``): the sensor sets are named after the
# sensors whose sources are accepted (:mod:`buoy_nav.sensor_sets`).
GNSS_RECEIVER = "gnss_receiver"
"""Position and velocity of the primary antenna."""
GNSS_ANTENNA_PAIR = "gnss_antenna_pair"
"""The primary and secondary antennas: their baseline, or its azimuth."""
GNSS_THIRD_ANTENNA = "gnss_third_antenna"
MAGNETOMETER = "magnetometer"
MOTION_PACK = "motion_pack"
"""An attitude and heading reference system's own attitude solution."""
GNSS_SENSORS = (GNSS_RECEIVER, GNSS_ANTENNA_PAIR, GNSS_THIRD_ANTENNA)
"""The sensors whose lapse is a GNSS outage (sensor set e)."""

# The roles a source plays (``roles``): the tools' lists of topics are computed from them over
# the registry (:func:`buoy_nav.aiding.topics_with_role`).
HEADING_REFERENCE = "heading_reference"
"""It can give the alignment its heading: a run needs one at least."""
POSITION_REFERENCE = "position_reference"
"""It measures the position: the alignment takes it (a configured site stands in for one)."""
VELOCITY_REFERENCE = "velocity_reference"
"""It measures the velocity over ground."""
ATTITUDE_SOURCE = "attitude_source"
"""It measures the whole attitude (roll, pitch and yaw)."""
ROLES = (HEADING_REFERENCE, POSITION_REFERENCE, VELOCITY_REFERENCE, ATTITUDE_SOURCE)

SUSPENSION_HINTS = {
    GNSS_RECEIVER: "check the antenna lever arm and the receiver",
    GNSS_ANTENNA_PAIR: "check the antenna lever arms and the receiver",
    GNSS_THIRD_ANTENNA: "check the antenna lever arms and the receiver",
    MAGNETOMETER: "run calibrate_magnetometer",
    MOTION_PACK: "check its lag and covariance",
}
"""What to check when a source of a sensor is suspended, by sensor."""


class Verdict(NamedTuple):
    """What the receiver's measurements say of a source's assumption: ``contradicted`` or
    not, and why (a sentence for the log and the summary)."""

    contradicted: bool
    reason: str


@dataclass(frozen=True)
class MeasurementModel:
    """A measurement linearised at the nominal state.

    predicted: measurement predicted from the nominal state (m,).
    innovation: measured − predicted (m,), angles wrapped to (−π, π].
    jacobian: ∂(measurement)/∂(error state), m × number of error states.
    covariance: measurement noise covariance R, m × m.
    gate_covariance: the noise one sample is gated with, when its error is shared with the
      samples around it and R weights it for that (None: R). The gate asks whether one sample
      is what the sensor claims; the update takes only its share of the information.
    """

    predicted: np.ndarray
    innovation: np.ndarray
    jacobian: np.ndarray
    covariance: np.ndarray
    gate_covariance: np.ndarray | None = None

    @property
    def gated_covariance(self) -> np.ndarray:
        """The noise the gate takes: :attr:`gate_covariance`, else R."""
        return self.covariance if self.gate_covariance is None else self.gate_covariance


class LinearisationPoint(NamedTuple):
    """The nominal state at a measurement's stamp, where its model is linearised.

    state: nominal navigation state. rotation_nb: its R_nb (3×3, body FLU → ENU).
    raw_gyro_rad_s: gyro sample at the stamp (body, rad/s; interpolated, bias not removed).
    nav_frame_rate_enu_rad_s: ω_in = ω_ie + ω_en at the nominal state (ENU, rad/s).
    """

    state: NavState
    rotation_nb: np.ndarray
    raw_gyro_rad_s: tuple[float, float, float]
    nav_frame_rate_enu_rad_s: tuple[float, float, float]


@dataclass(frozen=True)
class StateReset:
    """States re-initialised from a measurement.

    state: the nominal state with the reset states replaced. indices: the error states reset
    (from the source's layout, e.g. ``states.indices("velocity")``); they are decorrelated from
    the others and given ``variances``.
    """

    state: NavState
    indices: Sequence[int]
    variances: Sequence[float]


def yaw_reset(
    states: StateLayout, point: LinearisationPoint, body_vector, azimuth_rad: float, variance_rad2
) -> StateReset:
    """The reset of the yaw alone that turns ``body_vector`` (body axes, any unit) to the
    azimuth ``azimuth_rad`` (ENU, 0 = East, counter-clockwise) with roll and pitch kept, the
    yaw error given ``variance_rad2`` (rad²)."""
    roll, pitch, _ = euler_from_rotation_matrix(point.rotation_nb)
    levelled = rotation_matrix_from_euler(roll, pitch, 0.0) @ np.asarray(body_vector, dtype=float)
    yaw = azimuth_rad - math.atan2(levelled[1], levelled[0])
    state = point.state
    return StateReset(
        NavState(
            quaternion_from_rotation_matrix(rotation_matrix_from_euler(roll, pitch, yaw)),
            state.velocity_enu_mps,
            state.latitude_rad,
            state.longitude_rad,
            state.altitude_m,
            state.gyro_bias_rad_s,
            state.accel_bias_mps2,
        ),
        [states.index("attitude", UP)],
        [variance_rad2],
    )


class MotionWitness(Protocol):
    """The buoy's motion as the GNSS receiver's own measurements show it, without the filter
    (:class:`buoy_nav.gnss_motion.GnssMotion`): what a source's assumption is judged by."""

    def mean_velocity(self, min_span_s: float) -> Any:
        """The mean velocity (ENU m/s) over what is kept, with its covariance (m²/s²), span (s)
        and what measured it, once the measurements span ``min_span_s`` (s); else None."""


class AidingSource(abc.ABC):
    """One aiding sensor of the fusion (see the module docstring for the life of a measurement).

    Class attributes a source defines:
      kind: its name in counters, diagnostics and the innovation log (``gnss_fix``).
      topic: the contract topic it reads (from :mod:`buoy_common.contract`).
      measurement_type: the class of its measurements; :meth:`FusionEngine.add_measurement`
        finds the source by it.
      aids: what it observes, as the coasting flag its accepted measurements clear
        (:data:`AIDED_QUANTITIES`).
      sensor: the sensor its measurements come from (``GNSS_RECEIVER`` …, None: none of the
        sensor sets'), which names the sensor set while it is accepted.
      roles: what it can stand for (:data:`ROLES`), e.g. ``HEADING_REFERENCE``: one at least
        is needed to align.
      superseded_by: kind of a source whose measurement of the same stamp carries this one's
        information and more (None: none); such a measurement is set aside and counted as
        superseded, so one observation is not fused twice.
      pseudo: True for a constraint that reads no topic (``topic`` None): the engine asks it
        for a measurement with ``pseudo_measurement(t_s, state, fix_age_s,
        velocity_covariance_m2s2)`` once an IMU sample reaches its ``next_due_s``.

    A source is built once per engine from the configuration and the engine's error-state
    layout (``states``), whose block names address the Jacobian's columns.
    """

    kind: ClassVar[str]
    topic: ClassVar[str]
    measurement_type: ClassVar[type]
    aids: ClassVar[str]
    sensor: ClassVar[str | None] = None
    roles: ClassVar[frozenset[str]] = frozenset()
    superseded_by: ClassVar[str | None] = None
    pseudo: ClassVar[bool] = False
    witnesses_integrity: ClassVar[bool] = True
    """Whether persistent gate rejections of this source mean that the filter is wrong (see
    :mod:`buoy_nav.integrity`); False for a sensor whose own disturbances are expected and
    stopped by the gate, such as a magnetometer beside a passing hull."""
    has_compiled_update: ClassVar[bool] = False
    """Whether the source makes the model, gate and update of a measurement in one compiled
    call, ``compiled_update(measurement, raw_gyro_rad_s, integrator_state, kalman)``, with the
    same arithmetic as :meth:`model` and the filter's gate and update (the engine then uses it
    for a stamp of that one measurement, and books a measurement it rejects the interpreted
    way)."""
    stretch_refusal: ClassVar[Reason | None] = None
    """The reason :meth:`model` refuses a measurement for, when its measurement function over
    arrays (``stretch_model``, :mod:`buoy_nav.aiding_epoch`) may say ``REFUSED``
    (:mod:`buoy_nav.aiding.model_kernels`)."""
    has_compiled_model: ClassVar[bool] = False
    """Whether :meth:`model` is one compiled call (:mod:`buoy_nav.aiding.model_kernels`) that keeps
    nothing between measurements (its gate may take a noise of its own, ``gate_covariance``): the
    engine then gates a stamp's measurements of such sources and applies them in one compiled call,
    and gates and books them the interpreted way when one of them fails its gate."""

    def __init__(self, config: FusionConfig, states: StateLayout):
        self.config = config
        self.states = states
        self.gate_probability = config.gate_probability
        """Probability of the chi-square innovation gate."""
        self.reset_after_rejections = config.gate_reset_count
        """Consecutive gate rejections after which :meth:`reset` is asked for a reset."""
        self.enabled = self.enabled_by(config)
        """Whether the configuration lets the fusion use this source."""
        self.configuration_problem: str | None = None
        """Why this enabled source cannot contribute with the configuration it was given (its
        measurements are then rejected, not fused), for the tools and the node to report; None
        when it can."""

    @property
    def suspension_hint(self) -> str:
        """What to check when this source is suspended (by its sensor)."""
        return SUSPENSION_HINTS.get(self.sensor, "check its configuration")

    def innovation_warning(
        self, t_s: float, innovation: np.ndarray, innovation_covariance: np.ndarray
    ) -> str | None:
        """Whether this source's gated innovations, the latest ``innovation`` (measured −
        predicted) with its covariance S = H P Hᵀ + R at stamp ``t_s`` (s), are persistently
        larger than stated: a new warning to log (rate-limited by the source), ``""`` when a
        warning no longer holds, None when nothing changed. Only sources that can tell why say
        so."""
        return None

    @property
    def watches_innovations(self) -> bool:
        """Whether :meth:`innovation_warning` can say anything: the source overrides it."""
        return type(self).innovation_warning is not AidingSource.innovation_warning

    @property
    def gyro_drift_scale(self) -> float:
        """Factor (≥ 1) on the σ of the gyro's drift that this source's innovations ask for,
        which the engine applies to the filter's process noise; 1 for a source that cannot
        tell."""
        return 1.0

    @property
    def accel_noise_scale(self) -> float:
        """Factor (≥ 1) on the σ of the accelerometer's velocity random walk that this source's
        innovations ask for, applied as the gyro drift's is; 1 for a source that cannot tell."""
        return 1.0

    def take_covariance_factor(self) -> float:
        """Factor by which this source's innovations have just found the filter's attitude and
        velocity variances too small, once (1: not found, or a source that cannot tell)."""
        return 1.0

    @classmethod
    def enabled_by(cls, config: FusionConfig) -> bool:
        """Whether ``config`` lets the fusion use this source (its measurements are otherwise
        rejected as ``disabled``, and the tools do not read its topic)."""
        return True

    @classmethod
    def msgtype(cls) -> str:
        """Message type of :attr:`topic` (from the contract)."""
        return SENSOR_MSGTYPES[cls.topic]

    @abc.abstractmethod
    def measurement_from_message(self, message) -> Any:
        """The measurement in a contract message of :attr:`topic`, or the :class:`Reason` it
        holds none. May raise AttributeError, TypeError or ValueError for a message that is not
        of the type (counted as ``malformed``)."""

    record_fields: tuple[str, ...] = ()
    """The fields of :attr:`topic`'s message that :meth:`measurement_from_record` reads, as
    the bulk decoder names its columns (:mod:`buoy_common.cdr_bulk`): the offline tools decode
    such a topic a chunk of the bag at a time. Empty: its messages are decoded one by one and
    given to :meth:`measurement_from_message`."""

    def measurement_from_record(self, t_s: float, *fields) -> Any:
        """:meth:`measurement_from_message` of a message read as its header stamp ``t_s`` (s)
        and the values of :attr:`record_fields`, in their order, as the bulk decoder gives them
        (vectors and row-major matrices as flat sequences of floats)."""
        raise NotImplementedError(f"{type(self).__name__} reads no records")

    @abc.abstractmethod
    def validated(self, measurement) -> Any:
        """``measurement`` with its values as floats and float arrays, or the :class:`Reason`
        it cannot be used (never raises for bad values)."""

    @abc.abstractmethod
    def model(self, measurement, point: LinearisationPoint) -> MeasurementModel | Reason | None:
        """The validated ``measurement`` linearised at ``point``; None when its geometry carries
        no information there; the :class:`Reason` it contradicts the world known at ``point``
        (a failed outcome for the source's health, never fused)."""

    def load_compiled_code(self) -> None:
        """Compile the compiled code of this source's model, or load it from the cache, now:
        the engine calls this when it is built, so that no measurement waits for the compiler.
        The default: a model without compiled code."""
        return None

    def reset(
        self, measurement, point: LinearisationPoint, model: MeasurementModel
    ) -> StateReset | None:
        """The states to re-initialise from a persistently rejected ``measurement`` (``model``:
        its model at ``point``); None: no reset. The default resets nothing."""
        return None

    def judged_by(self, motion: MotionWitness) -> Verdict | None:
        """What the receiver's own measurements of the buoy's motion (``motion``) say of the
        assumption this source makes, without the filter; None when they say nothing either
        way. The default: a sensor makes no assumption."""
        return None

    @abc.abstractmethod
    def align(
        self, aligner: InMotionAligner, t_s: float, measurement, raw_gyro_rad_s
    ) -> AlignmentResult | Reason | None:
        """Give the validated ``measurement`` (stamp ``t_s``; raw gyro sample there, body
        rad/s) to the aligner; the alignment result when it completes the alignment, or the
        :class:`Reason` the source refuses it for the alignment (counted as a rejection)."""


# -- validation helpers ----------------------------------------------------------------------


def as_floats(*values) -> tuple[float, ...] | Reason:
    """Scalar inputs as floats, or the reason one is malformed or not finite."""
    try:
        numbers = tuple(map(float, values))
    except (TypeError, ValueError):
        return Reason.MALFORMED
    if not all(map(math.isfinite, numbers)):
        return Reason.NON_FINITE
    return numbers


def as_float_array(values, shape: tuple[int, ...]) -> np.ndarray | Reason:
    """An input as a float array of ``shape`` (a matrix may come row-major flat), or the reason
    it is malformed or not finite."""
    try:
        array = np.array(values, dtype=float)
    except (TypeError, ValueError):
        return Reason.MALFORMED
    if array.size == math.prod(shape) and array.ndim == 1:
        array = array.reshape(shape)
    if array.shape != shape:
        return Reason.MALFORMED
    if not model_kernels.all_finite(array):
        return Reason.NON_FINITE
    return array


def has_non_positive_variance(covariance: np.ndarray) -> bool:
    """True when a variance on the diagonal of the square float matrix ``covariance`` (an
    array of :func:`as_float_array`) is zero or negative."""
    return model_kernels.has_non_positive_diagonal(covariance)


ORIENTATION_RECORD_FIELDS = ("orientation", "orientation_covariance")
"""The fields a source reads of a sensor_msgs/Imu that carries an attitude or a heading."""


def orientation_record(message) -> tuple[float, tuple[float, float, float, float], object]:
    """What a source of :data:`ORIENTATION_RECORD_FIELDS` reads of a sensor_msgs/Imu
    ``message``: its header stamp (s), orientation quaternion (x, y, z, w) as floats and
    orientation covariance (9, row-major), the arguments of its ``measurement_from_record``."""
    q = message.orientation
    return (
        header_seconds(message.header),
        (float(q.x), float(q.y), float(q.z), float(q.w)),
        message.orientation_covariance,
    )


def vector_of(message_vector) -> tuple[float, float, float]:
    """(x, y, z) of a geometry_msgs/Vector3 as floats."""
    return float(message_vector.x), float(message_vector.y), float(message_vector.z)


def samples_per_correlation_time(interval_s: float, correlation_time_s: float) -> float:
    """Variance multiplier of one sample whose error it shares with the samples of
    ``correlation_time_s`` (s) around it, ``interval_s`` (s) apart: so many samples inform as
    one. 1 for an unknown interval (the first sample)."""
    if not (math.isfinite(interval_s) and interval_s > 0.0):
        return 1.0
    return max(1.0, correlation_time_s / interval_s)


def samples_per_correlation_times(intervals_s: np.ndarray, correlation_time_s: float) -> np.ndarray:
    """:func:`samples_per_correlation_time` of each of ``intervals_s`` (s): the same numbers."""
    known = np.isfinite(intervals_s) & (intervals_s > 0.0)
    with np.errstate(divide="ignore", invalid="ignore"):
        ratios = correlation_time_s / intervals_s
    # ``max(1.0, ratio)`` keeps 1.0 unless the ratio is larger.
    return np.where(known & (ratios > 1.0), ratios, 1.0)


def floored_covariance(covariance, variance_floor: float) -> np.ndarray:
    """Symmetrised covariance (a square matrix, or a variance) whose diagonal is raised to at
    least ``variance_floor``: :func:`buoy_nav.aiding.model_kernels.floored_covariance`, which the
    sources' compiled measurement functions call."""
    return model_kernels.floored_covariance(
        np.array(covariance, dtype=float, ndmin=2), float(variance_floor)
    )
