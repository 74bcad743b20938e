"""Sensor streams: each simulated sensor as a sequence of timestamped messages.

A stream samples the truth at its own sample times ``t_k = offset + k / rate`` (scenario time,
s) and turns the samples into contract messages. A live node advances its stream as the
simulation clock moves; the offline generator advances all streams to the end of the scenario.
Both therefore publish the same messages with the same stamps for a scenario and a seed.
"""

from __future__ import annotations

import math
from collections.abc import Iterator
from dataclasses import dataclass, field
from types import ModuleType

import numpy as np

from buoy_common.contract import (
    AHRS_TOPIC,
    DVL_TOPIC,
    GNSS_BASELINE_TERTIARY_TOPIC,
    GNSS_BASELINE_TOPIC,
    GNSS_FIX_TOPIC,
    GNSS_HEADING_TOPIC,
    GNSS_VELOCITY_TOPIC,
    IMU_RAW_TOPIC,
    MAGNETOMETER_TOPIC,
    SENSOR_MSGTYPES,
    SONIC_TEMPERATURE_TOPIC,
    TRUTH_CURRENT_TOPIC,
    TRUTH_MSGTYPES,
    TRUTH_ODOMETRY_TOPIC,
    TRUTH_WATER_VELOCITY_TOPIC,
    TRUTH_WIND_TOPIC,
    WIND_RAW_TOPIC,
)
from buoy_common.extrinsics import check_shared_fields, shared_field
from buoy_common.parameter_declarations import broken_rules, custom_rule, parameter
from buoy_common.parameters import build_config, config_parameters
from sensor_sim import messages
from sensor_sim.geodesy import geodetic_to_enu_m
from sensor_sim.motion_pack import MICROTESLA, AhrsSimulator, MagnetometerSimulator
from sensor_sim.mounting import Extrinsics
from sensor_sim.scenario import Scenario
from sensor_sim.sensor_errors import (
    AhrsErrorConfig,
    AnemometerErrorConfig,
    DvlErrorConfig,
    GnssErrorConfig,
    ImuErrorConfig,
    MagnetometerErrorConfig,
)
from sensor_sim.sensor_models import (
    AnemometerSimulator,
    DvlSimulator,
    GnssSimulator,
    ImuSimulator,
)
from sensor_sim.truth import TruthModel

SECONDS_PER_HOUR = 3600.0

# Per-sensor keys for the seed: every sensor draws its own independent random stream.
IMU_SEED_KEY, GNSS_SEED_KEY, ANEMOMETER_SEED_KEY = 1, 2, 3
MAGNETOMETER_SEED_KEY, AHRS_SEED_KEY, DVL_SEED_KEY = 4, 5, 6


@dataclass(frozen=True)
class MapOrigin:
    """Reference point of the map frame (deg, deg, m); NaN: the scenario's starting point."""

    latitude_deg: float = shared_field("origin.latitude_deg")
    longitude_deg: float = shared_field("origin.longitude_deg")
    altitude_m: float = shared_field("origin.altitude_m")

    def __post_init__(self):
        check_shared_fields(self)

    def unset(self) -> bool:
        return any(math.isnan(v) for v in (self.latitude_deg, self.longitude_deg, self.altitude_m))


@dataclass(frozen=True)
class StreamTiming:
    """Sample rate (Hz) and time offset of the first sample (s) of one sensor."""

    rate_hz: float = parameter(
        10.0,
        unit="Hz",
        meaning="sample rate; default: the scenario's sensors.rates",
        rule=custom_rule("in (0, 2000]", lambda rate: math.isfinite(rate) and 0.0 < rate <= 2000),
    )
    time_offset_s: float = parameter(
        0.0,
        unit="s",
        meaning="time of the first sample after the scenario start, so that sensors' stamps "
        "disagree as real ones do",
        rule=custom_rule("in [0, 1/rate_hz)", lambda offset: math.isfinite(offset)),
    )

    def __post_init__(self):
        for name, broken in broken_rules(self):
            raise ValueError(f"{name} must be {broken}, got {getattr(self, name)}")
        if not 0.0 <= self.time_offset_s < 1.0 / self.rate_hz:
            raise ValueError(f"time_offset_s must be in [0, 1/rate_hz) s, got {self.time_offset_s}")


@dataclass
class SensorStream:
    """Base: sample-time bookkeeping shared by all streams."""

    scenario: Scenario
    truth: TruthModel
    timing: StreamTiming
    encoding: ModuleType = field(default=messages, kw_only=True, repr=False)
    """What the messages are made of: :mod:`sensor_sim.messages` (message objects, as the live
    nodes publish them) or :mod:`sensor_sim.message_bytes` (their CDR bytes, as a bag holds
    them)."""
    next_index: int = field(default=0, init=False)

    topics: dict[str, str] = field(default_factory=dict, init=False)

    def _take_times(self, until_s: float) -> np.ndarray:
        """Scenario times (s) of the samples not yet produced with t <= until_s and <= duration."""
        end_s = min(until_s, self.scenario.duration_s)
        period = 1.0 / self.timing.rate_hz
        last_index = math.floor((end_s - self.timing.time_offset_s) / period + 1e-9)
        if last_index < self.next_index:
            return np.empty(0)
        indices = np.arange(self.next_index, last_index + 1)
        self.next_index = last_index + 1
        return self.timing.time_offset_s + indices * period

    def finished(self) -> bool:
        period = 1.0 / self.timing.rate_hz
        return self.timing.time_offset_s + self.next_index * period > self.scenario.duration_s

    def _stamps(self, times_s: np.ndarray) -> list[int]:
        return [messages.stamp_ns(self.scenario.start_time_ns, t) for t in times_s]

    def advance(self, until_s: float) -> list[tuple[str, int, object]]:
        """Messages (topic, stamp_ns, message) of every sample due up to scenario time until_s."""
        times = self._take_times(until_s)
        if times.size == 0:
            return []
        return list(self._messages(times, self._stamps(times)))

    def _messages(self, times_s, stamps_ns) -> Iterator[tuple[str, int, object]]:
        raise NotImplementedError


@dataclass
class ImuStream(SensorStream):
    """The IMU, and when the motion pack carries them its magnetometer (``imu/mag``) and its
    own AHRS attitude (``imu/data``), all at the IMU's sample times."""

    errors: ImuErrorConfig = field(default_factory=ImuErrorConfig)
    magnetometer: MagnetometerErrorConfig = field(default_factory=MagnetometerErrorConfig)
    ahrs: AhrsErrorConfig = field(default_factory=AhrsErrorConfig)

    def __post_init__(self):
        self.topics = {IMU_RAW_TOPIC: SENSOR_MSGTYPES[IMU_RAW_TOPIC]}
        seed = self.scenario.seed
        self._magnetometer = None
        self._ahrs = None
        if self.magnetometer.fitted:
            self.topics[MAGNETOMETER_TOPIC] = SENSOR_MSGTYPES[MAGNETOMETER_TOPIC]
            self._magnetometer = MagnetometerSimulator(
                self.truth, self.magnetometer, self.scenario, [seed, MAGNETOMETER_SEED_KEY]
            )
            self._magnetometer_variance_t2 = (self.magnetometer.noise_ut * MICROTESLA) ** 2
        if self.ahrs.fitted:
            self.topics[AHRS_TOPIC] = SENSOR_MSGTYPES[AHRS_TOPIC]
            self._ahrs = AhrsSimulator(
                self.truth,
                self.ahrs,
                self.scenario,
                [seed, AHRS_SEED_KEY],
                self.timing.rate_hz / self.ahrs.sample_every,
            )
        self._simulator = ImuSimulator(
            self.truth,
            self.errors,
            [self.scenario.seed, IMU_SEED_KEY],
            first_interval_s=1.0 / self.timing.rate_hz,
        )
        # Per-sample white-noise variances, advertised in the message covariances.
        gyro_density_rad_sqrt_s = math.radians(self.errors.gyro_noise_deg_sqrt_h) / 60.0
        accel_density_mps_sqrt_s = self.errors.accel_noise_mps_sqrt_h / 60.0
        self._gyro_variance = gyro_density_rad_sqrt_s**2 * self.timing.rate_hz
        self._accel_variance = accel_density_mps_sqrt_s**2 * self.timing.rate_hz

    def _every(self, times_s, stamps_ns, every: int):
        """The samples whose index (counted from the first of the run) is a multiple of
        ``every``."""
        first_index = self.next_index - len(times_s)
        keep = [k for k in range(len(times_s)) if (first_index + k) % every == 0]
        return times_s[keep], [stamps_ns[k] for k in keep]

    def _messages(self, times_s, stamps_ns):
        all_times_s, all_stamps_ns = times_s, stamps_ns
        gyro, force = self._simulator.measure(times_s)
        for stamp, message in zip(
            stamps_ns,
            self.encoding.imu_messages(
                stamps_ns, gyro, force, self._gyro_variance, self._accel_variance
            ),
            strict=True,
        ):
            yield IMU_RAW_TOPIC, stamp, message
        if self._magnetometer is not None:
            times_s, stamps_ns = self._every(times_s, stamps_ns, self.magnetometer.sample_every)
            field_body_t = self._magnetometer.measure(times_s)
            yield from (
                (MAGNETOMETER_TOPIC, stamp, message)
                for stamp, message in zip(
                    stamps_ns,
                    self.encoding.magnetic_field_messages(
                        stamps_ns, field_body_t, self._magnetometer_variance_t2
                    ),
                    strict=True,
                )
            )
        if self._ahrs is not None:
            times_s, stamps_ns = self._every(all_times_s, all_stamps_ns, self.ahrs.sample_every)
            if len(times_s) == 0:
                # A block shorter than the pack's sampling interval may hold none of its samples.
                return
            attitude, gyro, force, variance = self._ahrs.measure(times_s)
            yield from (
                (AHRS_TOPIC, stamp, message)
                for stamp, message in zip(
                    stamps_ns,
                    self.encoding.ahrs_messages(stamps_ns, attitude, gyro, force, variance),
                    strict=True,
                )
            )


@dataclass
class GnssStream(SensorStream):
    errors: GnssErrorConfig = field(default_factory=GnssErrorConfig)
    extrinsics: Extrinsics = field(default_factory=Extrinsics)

    def __post_init__(self):
        receiver_topics = {
            "dual_antenna": (
                GNSS_FIX_TOPIC,
                GNSS_VELOCITY_TOPIC,
                GNSS_HEADING_TOPIC,
                GNSS_BASELINE_TOPIC,
            ),
            "single_antenna": (GNSS_FIX_TOPIC, GNSS_VELOCITY_TOPIC),
            "none": (),
        }[self.errors.receiver]
        self.topics = {topic: SENSOR_MSGTYPES[topic] for topic in receiver_topics}
        self._simulator = GnssSimulator(
            self.truth,
            self.errors,
            np.asarray(self.extrinsics.primary_antenna_body_m),
            np.asarray(self.extrinsics.secondary_antenna_body_m),
            [self.scenario.seed, GNSS_SEED_KEY],
            np.asarray(self.extrinsics.tertiary_antenna_body_m),
        )
        # The third antenna's vector comes from a receiver that solves the first baseline too.
        if (
            self._simulator.tertiary_antenna_body_m is not None
            and GNSS_BASELINE_TOPIC in self.topics
        ):
            self.topics[GNSS_BASELINE_TERTIARY_TOPIC] = SENSOR_MSGTYPES[
                GNSS_BASELINE_TERTIARY_TOPIC
            ]

    def _messages(self, times_s, stamps_ns):
        if not self.topics:
            return
        # Measured through the silences too, so the noise of every other sample is the same
        # with or without them.
        sample = self._simulator.measure(times_s)
        silent = _in_any_interval(times_s, self.errors.silent_outages_s)
        per_topic = {
            GNSS_FIX_TOPIC: self.encoding.gnss_fix_messages(stamps_ns, sample),
            GNSS_VELOCITY_TOPIC: self.encoding.gnss_velocity_messages(stamps_ns, sample),
            GNSS_HEADING_TOPIC: self.encoding.gnss_heading_messages(stamps_ns, sample),
            GNSS_BASELINE_TOPIC: self.encoding.gnss_baseline_messages(stamps_ns, sample),
        }
        if sample.tertiary_baseline_enu_m is not None:
            per_topic[GNSS_BASELINE_TERTIARY_TOPIC] = self.encoding.gnss_baseline_tertiary_messages(
                stamps_ns, sample
            )
        per_topic = {topic: rows for topic, rows in per_topic.items() if topic in self.topics}
        rows = zip(stamps_ns, silent, *per_topic.values(), strict=True)
        for stamp, is_silent, *row in rows:
            if is_silent:
                continue
            for topic, message in zip(per_topic, row, strict=True):
                if message is not None:
                    yield topic, stamp, message


def _in_any_interval(times_s: np.ndarray, intervals_s) -> np.ndarray:
    """Whether each scenario time (s) lies inside one of the [start, end) intervals (s)."""
    inside = np.zeros(len(times_s), dtype=bool)
    for start, end in intervals_s:
        inside |= (times_s >= start) & (times_s < end)
    return inside


@dataclass
class AnemometerStream(SensorStream):
    errors: AnemometerErrorConfig = field(default_factory=AnemometerErrorConfig)
    extrinsics: Extrinsics = field(default_factory=Extrinsics)

    def __post_init__(self):
        self.topics = {WIND_RAW_TOPIC: SENSOR_MSGTYPES[WIND_RAW_TOPIC]}
        if self.truth.wind.temperature is not None:
            self.topics[SONIC_TEMPERATURE_TOPIC] = SENSOR_MSGTYPES[SONIC_TEMPERATURE_TOPIC]
        self._simulator = AnemometerSimulator(
            self.truth,
            self.errors,
            np.asarray(self.extrinsics.anemometer_position_body_m),
            np.asarray(self.extrinsics.anemometer_rpy_deg),
            [self.scenario.seed, ANEMOMETER_SEED_KEY],
        )

    def _messages(self, times_s, stamps_ns):
        wind = self._simulator.measure(times_s)
        temperature = self._simulator.measure_temperature(times_s)
        winds = self.encoding.anemometer_messages(stamps_ns, wind)
        if temperature is None:
            for stamp, message in zip(stamps_ns, winds, strict=True):
                yield WIND_RAW_TOPIC, stamp, message
            return
        temperatures = self.encoding.temperature_messages(
            stamps_ns, temperature, self.errors.temperature_noise_k**2
        )
        for stamp, message, sonic in zip(stamps_ns, winds, temperatures, strict=True):
            yield WIND_RAW_TOPIC, stamp, message
            yield SONIC_TEMPERATURE_TOPIC, stamp, sonic


@dataclass
class DvlStream(SensorStream):
    errors: DvlErrorConfig = field(default_factory=DvlErrorConfig)
    extrinsics: Extrinsics = field(default_factory=Extrinsics)

    def __post_init__(self):
        self.topics = {DVL_TOPIC: SENSOR_MSGTYPES[DVL_TOPIC]}
        self._simulator = DvlSimulator(
            self.truth,
            self.errors,
            np.asarray(self.extrinsics.dvl_position_body_m),
            np.asarray(self.extrinsics.dvl_rpy_deg),
            [self.scenario.seed, DVL_SEED_KEY],
        )

    def _messages(self, times_s, stamps_ns):
        velocity = self._simulator.measure(times_s)
        for stamp, message in zip(
            stamps_ns,
            self.encoding.dvl_messages(stamps_ns, velocity, self.errors.noise_mps**2),
            strict=True,
        ):
            yield DVL_TOPIC, stamp, message


@dataclass
class TruthStream(SensorStream):
    """The truth topics: the bag carries its own answer.

    ``truth/current`` (when the scenario has a current) is the mean and tidal current, uniform
    over the top layer, so also the current at the DVL's place and depth. ``truth/water_velocity``
    (when the platform carries a DVL) is the water's velocity at the DVL (``dvl.position``):
    the current plus the waves' orbital velocity at the DVL's depth, what the DVL's single
    pings measure against.
    """

    map_origin: MapOrigin = field(default_factory=lambda: MapOrigin())
    extrinsics: Extrinsics = field(default_factory=Extrinsics)

    def __post_init__(self):
        names = [TRUTH_ODOMETRY_TOPIC, TRUTH_WIND_TOPIC]
        if self.scenario.current is not None:
            names.append(TRUTH_CURRENT_TOPIC)
        if self.scenario.sensors.dvl is not None:
            names.append(TRUTH_WATER_VELOCITY_TOPIC)
        self.topics = {topic: TRUTH_MSGTYPES[topic] for topic in names}

    def _messages(self, times_s, stamps_ns):
        state = self.truth.evaluate(times_s)
        position_map = self._position_in_map(state)
        streams = [
            (
                TRUTH_ODOMETRY_TOPIC,
                self.encoding.truth_odometry_messages(stamps_ns, state, position_map),
            ),
            (TRUTH_WIND_TOPIC, self.encoding.enu_vector_messages(stamps_ns, state.wind_enu_mps)),
        ]
        if TRUTH_CURRENT_TOPIC in self.topics:
            streams.append(
                (
                    TRUTH_CURRENT_TOPIC,
                    self.encoding.enu_vector_messages(stamps_ns, state.current_enu_mps),
                )
            )
        if TRUTH_WATER_VELOCITY_TOPIC in self.topics:
            water = self.truth.water_at(state, self.extrinsics.dvl_position_body_m)
            streams.append(
                (
                    TRUTH_WATER_VELOCITY_TOPIC,
                    self.encoding.enu_vector_messages(stamps_ns, water.velocity_enu_mps),
                )
            )
        topics = [topic for topic, _ in streams]
        for stamp, *row in zip(stamps_ns, *(s for _, s in streams), strict=True):
            for topic, message in zip(topics, row, strict=True):
                yield topic, stamp, message

    def _position_in_map(self, state) -> np.ndarray:
        """base_link position in map: the scenario origin unless origin parameters say otherwise."""
        origin = self.map_origin
        if origin.unset():
            return state.position_enu_m
        return geodetic_to_enu_m(
            state.latitude_deg,
            state.longitude_deg,
            state.altitude_m,
            origin.latitude_deg,
            origin.longitude_deg,
            origin.altitude_m,
        )


def merged_messages(streams: list[SensorStream], until_s: float):
    """All streams' messages up to until_s, in stamp order (ties: stream order, then topic)."""
    rows = []
    for order, stream in enumerate(streams):
        rows.extend(
            (stamp, order, topic, message) for topic, stamp, message in stream.advance(until_s)
        )
    rows.sort(key=lambda row: (row[0], row[1]))
    return [(topic, stamp, message) for stamp, _, topic, message in rows]


@dataclass(frozen=True)
class StreamSpec:
    """How one sensor stream is configured: its node, its rate in the scenario's
    ``sensors.rates`` and its parameter groups.

    ``configs`` maps a stream field to (configuration type, parameter prefix, renamed fields).
    ``sensor``: the scenario's ``sensors`` entry that says whether the platform carries the
    sensor (a null entry: it does not) and gives its error budget; None for the truth.
    """

    node_name: str
    stream_type: type
    rate_key: str
    configs: dict[str, tuple[type, str, dict[str, str]]]
    sensor: str | None = None

    def carried(self, scenario: Scenario) -> bool:
        """Whether the scenario's platform carries this sensor (the truth always exists)."""
        return self.sensor is None or getattr(scenario.sensors, self.sensor) is not None

    def default_rate_hz(self, scenario: Scenario) -> float:
        return getattr(scenario.sensors.rates, self.rate_key)

    def default_time_offset_s(self, scenario: Scenario) -> float:
        """The scenario's time of this sensor's first sample (s; ``sensors.rates.*_offset_s``,
        0 for a sensor it gives none): stamps off the other sensors' grids."""
        offset_key = self.rate_key.removesuffix("_hz") + "_offset_s"
        return getattr(scenario.sensors.rates, offset_key, 0.0)

    def parameters(self, scenario: Scenario) -> list[tuple[str, object]]:
        """(parameter name, default) of every parameter of this stream's node.

        Sample rates and sensor error defaults are the scenario's (``sensors.*`` in its file),
        so a scenario and a seed define a run; parameters override them.
        """
        names = [
            ("rate_hz", float(self.default_rate_hz(scenario))),
            ("time_offset_s", float(self.default_time_offset_s(scenario))),
        ]
        for field_name, (config_type, prefix, renamed) in self.configs.items():
            base = self._scenario_default(scenario, field_name)
            names += [
                (p, d) for _, p, d in config_parameters(config_type, prefix, renamed, (), base)
            ]
        return names

    def _scenario_default(self, scenario: Scenario, field_name: str):
        if field_name == "errors":
            return getattr(scenario.sensors, self.sensor)
        return getattr(scenario.sensors, field_name, None)

    def build(
        self,
        scenario: Scenario,
        truth: TruthModel,
        values: dict,
        encoding: ModuleType = messages,
    ) -> SensorStream:
        """The stream configured by parameter ``values`` (absent ones: the scenario's values),
        making its messages with ``encoding`` (:attr:`SensorStream.encoding`)."""
        defaults = {
            "rate_hz": self.default_rate_hz(scenario),
            "time_offset_s": self.default_time_offset_s(scenario),
        }
        timing = build_config(StreamTiming, {**defaults, **values}, renamed={})
        configs = {
            field_name: build_config(
                config_type,
                values,
                prefix,
                renamed,
                base=self._scenario_default(scenario, field_name),
            )
            for field_name, (config_type, prefix, renamed) in self.configs.items()
        }
        return self.stream_type(scenario, truth, timing, encoding=encoding, **configs)


_EXTRINSICS = (Extrinsics, "", {})

STREAMS = {
    "imu": StreamSpec(
        "imu_sim_node",
        ImuStream,
        "imu_hz",
        {
            "errors": (ImuErrorConfig, "imu.", {}),
            "magnetometer": (MagnetometerErrorConfig, "magnetometer.", {}),
            "ahrs": (AhrsErrorConfig, "motion_pack.", {}),
        },
        "imu",
    ),
    "gnss": StreamSpec(
        "gnss_sim_node",
        GnssStream,
        "gnss_hz",
        {"errors": (GnssErrorConfig, "gnss.", {}), "extrinsics": _EXTRINSICS},
        "gnss",
    ),
    "anemometer": StreamSpec(
        "anemometer_sim_node",
        AnemometerStream,
        "anemometer_hz",
        {"errors": (AnemometerErrorConfig, "anemometer.", {}), "extrinsics": _EXTRINSICS},
        "anemometer",
    ),
    "dvl": StreamSpec(
        "dvl_sim_node",
        DvlStream,
        "dvl_hz",
        {"errors": (DvlErrorConfig, "dvl.", {}), "extrinsics": _EXTRINSICS},
        "dvl",
    ),
    "truth": StreamSpec(
        "truth_node",
        TruthStream,
        "truth_hz",
        {"map_origin": (MapOrigin, "", {}), "extrinsics": _EXTRINSICS},
    ),
}
