"""Scenario files: typed, validated configuration of one simulated run.

A scenario is a YAML file (the shipped ones live in ``sensor_sim/scenarios/``) whose keys
mirror the frozen dataclasses below. ``load_scenario`` reads it, applies ``dotted.key=value``
overrides (values parsed as YAML) and checks every key, type and range; anything wrong raises
ScenarioError naming the file or override, the key and the value. A scenario plus its seed
fully defines a run: all random parts (phases, wave and turbulence components, sensor noise)
are drawn from streams derived from the seed.

The sensors of real flux buoys are not the data sheet's, and a run can say how: a motion pack
whose attitude lags (``sensors.ahrs.lag_time_constant_s``) while its covariance claims the data
sheet's σ (``sensors.ahrs.claimed_sigma_deg``); an uncalibrated magnetometer
(``sensors.magnetometer.hard_iron_ut``, ``soft_iron``); a receiver stamping off the IMU grid
(``sensors.rates.gnss_offset_s``) with its antenna where the buoy has it
(``sensors.extrinsics``); GNSS outages in which no GNSS topic publishes
(``sensors.gnss.silent_outages_s``); no GNSS at all (``sensors.gnss.receiver: none``). Every
such option defaults to the perfect sensor. The shipped ``set_a_imperfect`` ...
``set_e_imperfect`` give each sensor set of the suite the imperfections that apply to it, and
``measured_moored_no_gnss`` / ``measured_moored_single_gnss`` are the measured moored buoys.

Conventions: angles in parameters are degrees (names end in ``_deg``); ``yaw_deg`` is ENU
yaw (0 = East, counter-clockwise); wind and wave directions are meteorological (where they come
FROM, clockwise from true North); the current direction is oceanographic (where the water flows
TOWARD, clockwise from true North).
"""

from __future__ import annotations

import dataclasses
import math
import re
import types
import typing
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from importlib import resources
from pathlib import Path
from typing import Any, Literal

import numpy as np
import yaml
from numpy.typing import ArrayLike

from sensor_sim.mounting import ScenarioExtrinsics
from sensor_sim.sensor_errors import (
    AhrsErrorConfig,
    AnemometerErrorConfig,
    DvlErrorConfig,
    GnssErrorConfig,
    ImuErrorConfig,
    InvalidConfigValueError,
    MagnetometerErrorConfig,
    check_field,
    check_non_negative,
    check_positive,
)

DEFAULT_START_TIME_NS = 1_767_225_600_000_000_000  # 2026-01-01T00:00:00Z
# Pitch must stay clear of the ZYX Euler singularity at +-90 degrees.
MAX_PITCH_EXCURSION_DEG = 80.0


class ScenarioError(ValueError):
    """A scenario cannot be loaded: unknown name, unreadable file, bad key, type or value."""


@dataclass(frozen=True)
class MotionConfig:
    """Buoy or platform motion, built from components that add up.

    Attitude (ZYX Euler angles, degrees) = constant (roll_deg, pitch_deg, yaw_deg)
    + paper-002 sinusoids (``*_amplitude_deg``, ``*_period_s``, random phases)
    + a slow mooring yaw sinusoid (``mooring_yaw_*``)
    + a table sway on ``sway_axis`` (paper 000: +-sway_amplitude_deg at sway_rate_deg_s, rounded
      corners of corner_time_s, period sway_period_s or back-to-back ramps when null,
      sway_cycles full swings or continuous when null, starting from level)
    + a turntable rotation in yaw (0 -> rotation_range_deg -> 0 at rotation_rate_deg_s with
      rotation_dwell_s at each end)
    + static positions of a calibration table: ``positions_rpy_deg`` (roll, pitch, yaw in deg,
      added to the rest), held ``position_dwell_s`` each (the first from t = 0 to
      still_before_s), turned from one to the next in ``position_transition_s``
    + wave-following tilt from the ``waves`` section.
    Sway and rotation start after still_before_s. Translation (curvilinear east/north/up) =
    paper-002 velocity sinusoids (heave up; surge along and lateral to the left of the mean
    heading yaw_deg; amplitudes are velocity amplitudes, m/s) + wave orbital motion + drift
    with the current.
    """

    roll_deg: float = 0.0
    pitch_deg: float = 0.0
    yaw_deg: float = 0.0
    roll_amplitude_deg: float = 0.0
    roll_period_s: float = 9.0
    pitch_amplitude_deg: float = 0.0
    pitch_period_s: float = 6.0
    yaw_amplitude_deg: float = 0.0
    yaw_period_s: float = 6.0
    mooring_yaw_amplitude_deg: float = 0.0
    mooring_yaw_period_s: float = 600.0
    heave_velocity_amplitude_mps: float = 0.0
    heave_period_s: float = 7.0
    surge_velocity_amplitude_mps: float = 0.0
    surge_period_s: float = 6.0
    lateral_velocity_amplitude_mps: float = 0.0
    lateral_period_s: float = 8.0
    still_before_s: float = 0.0
    sway_axis: Literal["roll", "pitch"] = "roll"
    sway_amplitude_deg: float = 0.0
    sway_rate_deg_s: float = 5.0
    sway_period_s: float | None = None
    sway_cycles: int | None = None
    rotation_range_deg: float = 0.0
    rotation_rate_deg_s: float = 10.0
    rotation_dwell_s: float = 0.0
    corner_time_s: float = 0.5
    cruise_speed_mps: float = 0.0
    cruise_course_deg: float = 0.0
    positions_rpy_deg: tuple[tuple[float, float, float], ...] = ()
    position_dwell_s: float = 30.0
    position_transition_s: float = 10.0

    def __post_init__(self) -> None:
        check_field(
            self,
            "cruise_speed_mps",
            0.0 <= self.cruise_speed_mps <= 30.0,
            "must be within [0, 30] m/s",
        )
        check_non_negative(
            self,
            "roll_amplitude_deg",
            "pitch_amplitude_deg",
            "yaw_amplitude_deg",
            "mooring_yaw_amplitude_deg",
            "heave_velocity_amplitude_mps",
            "surge_velocity_amplitude_mps",
            "lateral_velocity_amplitude_mps",
            "still_before_s",
            "sway_amplitude_deg",
            "rotation_dwell_s",
        )
        check_positive(
            self,
            "roll_period_s",
            "pitch_period_s",
            "yaw_period_s",
            "mooring_yaw_period_s",
            "heave_period_s",
            "surge_period_s",
            "lateral_period_s",
            "sway_rate_deg_s",
            "rotation_rate_deg_s",
            "corner_time_s",
            "position_dwell_s",
            "position_transition_s",
        )
        for _roll, pitch, _yaw in self.positions_rpy_deg:
            check_field(
                self,
                "positions_rpy_deg",
                abs(pitch) <= MAX_PITCH_EXCURSION_DEG,
                f"pitch of each position must be within ±{MAX_PITCH_EXCURSION_DEG} deg",
            )
        check_field(
            self,
            "rotation_range_deg",
            abs(self.rotation_range_deg) <= 360.0,
            "must be within [-360, 360]",
        )
        check_field(self, "sway_amplitude_deg", self.sway_amplitude_deg <= 60.0, "must be <= 60")
        if self.sway_cycles is not None:
            check_field(self, "sway_cycles", self.sway_cycles >= 1, "must be >= 1 (or null)")
        if self.sway_period_s is not None:
            check_field(
                self,
                "sway_period_s",
                self.sway_period_s >= self.minimum_sway_period_s(),
                f"must be >= {self.minimum_sway_period_s():.3f} s, the time of the two ramps "
                f"at {self.sway_amplitude_deg} deg and {self.sway_rate_deg_s} deg/s",
            )

    def minimum_sway_period_s(self) -> float:
        """Shortest sway period (s): two ramps of 2*amplitude at the sway rate, no dwell."""
        travel_time = 2.0 * self.sway_amplitude_deg / self.sway_rate_deg_s
        return 2.0 * (travel_time + min(self.corner_time_s, travel_time))


@dataclass(frozen=True)
class WaveConfig:
    """Irregular waves (JONSWAP, cos-2s spreading) that the buoy follows; Hs = 0 disables.

    The buoy's heave is the surface elevation, its horizontal motion the surface orbital
    motion, its roll and pitch the surface slope along its own axes, scaled so that three
    standard deviations of the tilt, 3 sqrt(sigma_roll² + sigma_pitch²), equal max_tilt_deg.
    """

    significant_height_m: float = 0.0
    peak_period_s: float = 9.0
    peak_enhancement: float = 3.3
    spreading_exponent: float = 10.0
    direction_deg: float = 0.0
    max_tilt_deg: float = 20.0
    components: int = 120

    def __post_init__(self) -> None:
        check_non_negative(self, "significant_height_m", "max_tilt_deg")
        check_positive(self, "peak_period_s", "spreading_exponent")
        check_field(self, "peak_enhancement", self.peak_enhancement >= 1.0, "must be >= 1")
        check_field(
            self, "significant_height_m", self.significant_height_m <= 30.0, "must be <= 30"
        )
        check_field(self, "max_tilt_deg", self.max_tilt_deg <= 45.0, "must be <= 45")
        check_field(self, "components", 1 <= self.components <= 1000, "must be in [1, 1000]")


@dataclass(frozen=True)
class WindConfig:
    """True wind: mean speed and meteorological direction plus Kaimal turbulence.

    turbulence_intensity = sigma_u / speed_mps (0 = steady wind); sigma_v and sigma_w follow from
    the ratios (IEC 61400-1 defaults 0.8 and 0.5); height_m sets the Kaimal length scales.

    Fluxes: momentum_flux_correlation is the correlation of the along-wind and the vertical
    turbulence (negative: momentum carried down, u'w' = corr sigma_u sigma_w). A finite
    sonic_temperature_degc gives the anemometer a sonic temperature (anemometer/temperature):
    that mean plus fluctuations of temperature_sigma_k whose correlation with the vertical wind is
    heat_flux_correlation (w'T' = corr sigma_w sigma_T; positive: an unstable, heated surface
    layer); NaN (the default): no temperature.
    """

    speed_mps: float = 5.0
    direction_deg: float = 0.0
    turbulence_intensity: float = 0.0
    lateral_intensity_ratio: float = 0.8
    vertical_intensity_ratio: float = 0.5
    height_m: float = 4.0
    turbulence_components: int = 96
    turbulence_max_frequency_hz: float = 10.0
    momentum_flux_correlation: float = 0.0
    sonic_temperature_degc: float = math.nan
    temperature_sigma_k: float = 0.1
    heat_flux_correlation: float = 0.0

    def __post_init__(self) -> None:
        check_non_negative(
            self,
            "speed_mps",
            "turbulence_intensity",
            "lateral_intensity_ratio",
            "vertical_intensity_ratio",
            "temperature_sigma_k",
        )
        for key in ("momentum_flux_correlation", "heat_flux_correlation"):
            check_field(self, key, -1.0 <= getattr(self, key) <= 1.0, "must be in [-1, 1]")
        check_field(
            self,
            "sonic_temperature_degc",
            math.isnan(self.sonic_temperature_degc) or -60.0 <= self.sonic_temperature_degc <= 60.0,
            "must be NaN (no sonic temperature) or in [-60, 60]",
        )
        check_positive(self, "height_m", "turbulence_max_frequency_hz")
        check_field(self, "speed_mps", self.speed_mps <= 100.0, "must be <= 100")
        check_field(self, "turbulence_intensity", self.turbulence_intensity <= 1.0, "must be <= 1")
        check_field(
            self,
            "turbulence_components",
            0 <= self.turbulence_components <= 1000,
            "must be in [0, 1000]",
        )
        if self.turbulence_intensity > 0.0:
            check_field(self, "speed_mps", self.speed_mps > 0.0, "must be > 0 for turbulence")


@dataclass(frozen=True)
class CurrentConfig:
    """Surface current: a mean and one tidal constituent (sensor_sim.current_field).

    Directions are oceanographic: where the water flows TOWARD, clockwise from true North.
    The tidal current is tidal_amplitude_mps along tidal_direction_deg (the flood direction)
    and tidal_minor_amplitude_mps along the axis 90 deg counter-clockwise of it, in quadrature
    (positive: the current vector turns counter-clockwise; 0: a rectilinear tide), with period
    tidal_period_s (M2 by default) and phase tidal_phase_deg at t = 0 (0: full flood).
    platform_drifts: the platform moves with the current (a drifting buoy); false: it keeps
    its own track over ground (a ship under way, a buoy on a taut mooring).
    """

    speed_mps: float = 0.0
    direction_deg: float = 0.0
    tidal_amplitude_mps: float = 0.0
    tidal_minor_amplitude_mps: float = 0.0
    tidal_direction_deg: float = 0.0
    tidal_period_s: float = 44714.2
    tidal_phase_deg: float = 0.0
    platform_drifts: bool = True

    def __post_init__(self) -> None:
        check_non_negative(self, "speed_mps", "tidal_amplitude_mps")
        check_positive(self, "tidal_period_s")
        check_field(self, "speed_mps", self.speed_mps <= 5.0, "must be <= 5")
        check_field(self, "tidal_amplitude_mps", self.tidal_amplitude_mps <= 5.0, "must be <= 5")
        check_field(
            self,
            "tidal_minor_amplitude_mps",
            abs(self.tidal_minor_amplitude_mps) <= self.tidal_amplitude_mps,
            "must be within +-tidal_amplitude_mps (the minor axis of the tidal ellipse)",
        )


@dataclass(frozen=True)
class SampleRates:
    """Sample rates of the simulated sensors and the truth, Hz (a node's rate_hz overrides).

    ``gnss_offset_s``: time of the receiver's first solution (s, in [0, 1/gnss_hz); a node's
    time_offset_s overrides): a receiver stamps its solutions on its own second, not on the
    IMU's sample grid (0.31 s puts a 1 Hz receiver between the samples of a 50 Hz IMU).
    """

    imu_hz: float = 100.0
    gnss_hz: float = 10.0
    anemometer_hz: float = 20.0
    dvl_hz: float = 1.0
    truth_hz: float = 50.0
    gnss_offset_s: float = 0.0

    def __post_init__(self) -> None:
        for key in ("imu_hz", "gnss_hz", "anemometer_hz", "dvl_hz", "truth_hz"):
            check_field(self, key, 0.0 < getattr(self, key) <= 2000.0, "must be in (0, 2000]")
        check_field(
            self,
            "gnss_offset_s",
            0.0 <= self.gnss_offset_s < 1.0 / self.gnss_hz,
            "must be in [0, 1/gnss_hz) s",
        )


@dataclass(frozen=True)
class SensorErrorConfigs:
    """Error budgets of the simulated sensors, their sample rates and where they sit. An
    anemometer or a DVL set to null is not on the platform (the default: an anemometer, no
    DVL). ``extrinsics`` (sensor_sim.mounting): the antennas', anemometer's and DVL's places
    on the buoy; null (the default): the contract's defaults."""

    imu: ImuErrorConfig = field(default_factory=ImuErrorConfig)
    gnss: GnssErrorConfig = field(default_factory=GnssErrorConfig)
    anemometer: AnemometerErrorConfig | None = field(default_factory=AnemometerErrorConfig)
    dvl: DvlErrorConfig | None = None
    magnetometer: MagnetometerErrorConfig = field(default_factory=MagnetometerErrorConfig)
    ahrs: AhrsErrorConfig = field(default_factory=AhrsErrorConfig)
    rates: SampleRates = field(default_factory=SampleRates)
    extrinsics: ScenarioExtrinsics | None = None


@dataclass(frozen=True)
class Scenario:
    """One simulated run. Time t = 0 is start_time_ns on the sensor clock; the base_link origin
    is at the origin_* geodetic position at t = 0. ``name`` is the file's stem."""

    name: str
    description: str = ""
    seed: int = 0
    duration_s: float = 600.0
    start_time_ns: int = DEFAULT_START_TIME_NS
    origin_latitude_deg: float = 38.9
    origin_longitude_deg: float = 117.7
    origin_altitude_m: float = 0.0
    motion: MotionConfig = field(default_factory=MotionConfig)
    waves: WaveConfig = field(default_factory=WaveConfig)
    wind: WindConfig = field(default_factory=WindConfig)
    current: CurrentConfig | None = None
    sensors: SensorErrorConfigs = field(default_factory=SensorErrorConfigs)

    def __post_init__(self) -> None:
        check_positive(self, "duration_s")
        check_field(self, "seed", self.seed >= 0, "must be >= 0")
        check_field(self, "start_time_ns", self.start_time_ns >= 0, "must be >= 0")
        check_field(
            self,
            "origin_latitude_deg",
            abs(self.origin_latitude_deg) <= 85.0,
            "must be within [-85, 85] (the local ENU frame degenerates at the poles)",
        )
        check_field(
            self,
            "origin_longitude_deg",
            abs(self.origin_longitude_deg) <= 180.0,
            "must be within [-180, 180]",
        )
        check_field(
            self,
            "origin_altitude_m",
            -1000.0 <= self.origin_altitude_m <= 10000.0,
            "must be within [-1000, 10000]",
        )
        motion = self.motion
        sway_pitch = motion.sway_amplitude_deg if motion.sway_axis == "pitch" else 0.0
        wave_tilt = 1.5 * self.waves.max_tilt_deg if self.waves.significant_height_m > 0 else 0.0
        pitch_reach = abs(motion.pitch_deg) + motion.pitch_amplitude_deg + sway_pitch + wave_tilt
        if pitch_reach > MAX_PITCH_EXCURSION_DEG:
            raise InvalidConfigValueError(
                "motion.pitch_amplitude_deg",
                motion.pitch_amplitude_deg,
                f"pitch could reach {pitch_reach:.1f} deg (pitch_deg + pitch_amplitude_deg + "
                f"pitch sway + 1.5 x waves.max_tilt_deg); keep it <= {MAX_PITCH_EXCURSION_DEG}",
            )

    def stamps_ns(self, t_s: ArrayLike) -> np.ndarray:
        """Sensor-clock stamps (int64 ns) of scenario times t_s (s)."""
        return self.start_time_ns + np.round(np.asarray(t_s, dtype=float) * 1e9).astype(np.int64)


def available_scenarios() -> list[str]:
    """Names of the shipped scenario files (without .yaml), sorted."""
    folder = resources.files("sensor_sim") / "scenarios"
    return sorted(
        entry.name[: -len(".yaml")] for entry in folder.iterdir() if entry.name.endswith(".yaml")
    )


def load_scenario(
    name_or_path: str, overrides: Sequence[str] = (), seed: int | None = None
) -> Scenario:
    """Load a shipped scenario by name, or a scenario YAML file by path, and validate it.

    overrides: "dotted.key=value" strings, value parsed as YAML (e.g. "wind.speed_mps=15",
    "motion.sway_amplitude_deg=0", "current=null"), applied in order. seed, when given,
    replaces the file's seed. Raises ScenarioError for any problem.
    """
    text, source, name = _read_scenario_text(str(name_or_path))
    try:
        raw = yaml.safe_load(text)
    except yaml.YAMLError as error:
        raise ScenarioError(f"{source}: malformed YAML: {error}") from None
    if raw is None:
        raw = {}
    if not isinstance(raw, dict):
        raise ScenarioError(
            f"{source}: the top level must be a mapping of keys, got {type(raw).__name__}"
        )
    if "name" in raw:
        raise ScenarioError(f"{source}: key 'name' is not allowed (the name is the file's stem)")

    sources: dict[str, str] = {}
    for override in overrides:
        key, value = _parse_override(override)
        _set_dotted(raw, key, value)
        sources[key] = f"override {override!r}"
    if seed is not None:
        raw["seed"] = seed
        sources["seed"] = f"seed argument {seed!r}"

    def source_of(key: str) -> str:
        parts = re.sub(r"\[\d+\]", "", key).split(".")
        for length in range(len(parts), 0, -1):
            prefix = ".".join(parts[:length])
            if prefix in sources:
                return sources[prefix]
        return source

    return _build(Scenario, {**raw, "name": name}, "", source_of)


def _read_scenario_text(name_or_path: str) -> tuple[str, str, str]:
    """(YAML text, human description of where it came from, scenario name)."""
    looks_like_path = name_or_path.endswith((".yaml", ".yml")) or any(
        separator in name_or_path for separator in ("/", "\\")
    )
    if looks_like_path:
        path = Path(name_or_path)
        source = f"scenario file '{path}'"
        try:
            return path.read_text(encoding="utf-8"), source, path.stem
        except (OSError, UnicodeDecodeError) as error:
            raise ScenarioError(f"{source}: cannot read: {error}") from None
    if name_or_path not in available_scenarios():
        raise ScenarioError(
            f"unknown scenario {name_or_path!r}; shipped scenarios: "
            f"{', '.join(available_scenarios())} (or give a path to a .yaml file)"
        )
    resource = resources.files("sensor_sim") / "scenarios" / f"{name_or_path}.yaml"
    return resource.read_text(encoding="utf-8"), f"scenario '{name_or_path}'", name_or_path


def _parse_override(override: str) -> tuple[str, Any]:
    key, separator, text = str(override).partition("=")
    key = key.strip()
    if not separator or not key:
        raise ScenarioError(f"override {override!r}: expected the form dotted.key=value")
    try:
        value = yaml.safe_load(text)
    except yaml.YAMLError as error:
        raise ScenarioError(f"override {override!r}: value is not valid YAML: {error}") from None
    schema: type = Scenario
    parts = key.split(".")
    for depth, part in enumerate(parts):
        fields = {f.name: f for f in dataclasses.fields(schema) if f.name != "name"}
        if part not in fields:
            where = ".".join(parts[:depth]) or "the top level"
            raise ScenarioError(
                f"override {override!r}: unknown key {key!r} ({part!r} is not a key of {where}; "
                f"known: {', '.join(sorted(fields))})"
            )
        if depth < len(parts) - 1:
            nested = _dataclass_of(typing.get_type_hints(schema)[part])
            if nested is None:
                raise ScenarioError(
                    f"override {override!r}: unknown key {key!r} ({'.'.join(parts[: depth + 1])} "
                    "is a value, not a section)"
                )
            schema = nested
    return key, value


def _set_dotted(raw: dict, key: str, value: Any) -> None:
    parts = key.split(".")
    node = raw
    for part in parts[:-1]:
        if not isinstance(node.get(part), dict):
            node[part] = {}
        node = node[part]
    node[parts[-1]] = value


def _dataclass_of(annotation: Any) -> type | None:
    """The dataclass in an annotation such as ``X`` or ``X | None``, else None."""
    if dataclasses.is_dataclass(annotation):
        return annotation
    if _is_union(annotation):
        for argument in typing.get_args(annotation):
            if dataclasses.is_dataclass(argument):
                return argument
    return None


def _is_union(annotation: Any) -> bool:
    return typing.get_origin(annotation) in (typing.Union, types.UnionType)


def _build(schema: type, raw: Any, prefix: str, source_of) -> Any:
    section = prefix.rstrip(".") or "the top level"
    if not isinstance(raw, Mapping):
        raise ScenarioError(
            f"{source_of(prefix.rstrip('.'))}: {section} must be a mapping, got {raw!r}"
        )
    hints = typing.get_type_hints(schema)
    known = {f.name for f in dataclasses.fields(schema)}
    values = {}
    for key, value in raw.items():
        dotted = f"{prefix}{key}"
        if key not in known:
            raise ScenarioError(
                f"{source_of(dotted)}: unknown key {dotted!r} in {section}; known keys: "
                f"{', '.join(sorted(known - {'name'}))}"
            )
        values[key] = _convert(hints[key], value, dotted, source_of)
    try:
        return schema(**values)
    except InvalidConfigValueError as error:
        dotted = error.key if "." in error.key else f"{prefix}{error.key}"
        raise ScenarioError(
            f"{source_of(dotted)}: {dotted} = {error.value!r}: {error.requirement}"
        ) from None


def _convert(annotation: Any, value: Any, key: str, source_of) -> Any:
    def fail(expected: str) -> ScenarioError:
        return ScenarioError(f"{source_of(key)}: {key} = {value!r}: expected {expected}")

    if _is_union(annotation):
        arguments = [a for a in typing.get_args(annotation) if a is not type(None)]
        if value is None:
            return None
        return _convert(arguments[0], value, key, source_of)
    if dataclasses.is_dataclass(annotation):
        return _build(annotation, value, f"{key}.", source_of)
    origin = typing.get_origin(annotation)
    if origin is Literal:
        choices = typing.get_args(annotation)
        if value not in choices:
            raise fail(f"one of {', '.join(map(repr, choices))}")
        return value
    if origin is tuple:
        arguments = typing.get_args(annotation)
        if not isinstance(value, list | tuple):
            raise fail("a list")
        if len(arguments) == 2 and arguments[1] is Ellipsis:
            return tuple(
                _convert(arguments[0], item, f"{key}[{i}]", source_of)
                for i, item in enumerate(value)
            )
        if len(value) != len(arguments):
            raise fail(f"a list of {len(arguments)} items")
        return tuple(
            _convert(argument, item, f"{key}[{i}]", source_of)
            for i, (argument, item) in enumerate(zip(arguments, value, strict=True))
        )
    if annotation is bool:
        if not isinstance(value, bool):
            raise fail("true or false")
        return value
    if annotation is int:
        if isinstance(value, bool) or not isinstance(value, int):
            raise fail("an integer")
        return value
    if annotation is float:
        if isinstance(value, bool) or not isinstance(value, int | float):
            raise fail("a number")
        if not math.isfinite(value):
            raise fail("a finite number")
        return float(value)
    if annotation is str:
        if not isinstance(value, str):
            raise fail("a string")
        return value
    raise TypeError(f"unsupported annotation {annotation!r} for {key}")
