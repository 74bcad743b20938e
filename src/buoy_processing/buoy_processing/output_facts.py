"""What the outputs of a processed bag may say about how it was made: the north its directions
are referenced to, the sensors that were actually used, the site (only when it is known) and the
span of the data. Every writer (NetCDF, CSV, the printed summary, the report) takes these words
from :class:`OutputFacts`, so that none of them claims a sensor, a reference or a place that the
run did not have.

The facts are derived from the effective parameters (the parameter files and what an imported
record contributed), the topics the input bag holds, what the fusion accepted and suspended, and
the stamps of the samples; nothing is assumed from the sensor set the suite was designed for.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping
from dataclasses import dataclass

from buoy_common.contract import DVL_TOPIC, SONIC_TEMPERATURE_TOPIC, WIND_RAW_TOPIC
from buoy_nav.aiding import AIDING_SOURCES
from buoy_nav.aiding.base import (
    GNSS_ANTENNA_PAIR,
    GNSS_RECEIVER,
    GNSS_THIRD_ANTENNA,
    HEADING_REFERENCE,
    MAGNETOMETER,
    MOTION_PACK,
    POSITION_REFERENCE,
)
from buoy_nav.config import FusionConfig

TRUE_NORTH = "true north"
MAGNETIC_NORTH = "magnetic north"
UNKNOWN_NORTH = "an unknown north"
"""The run gave no heading (the fusion never aligned): its directions are NaN."""

_SENSOR_WORDS = {
    GNSS_RECEIVER: "GNSS receiver (position, velocity)",
    GNSS_ANTENNA_PAIR: "dual-antenna GNSS (heading)",
    GNSS_THIRD_ANTENNA: "third GNSS antenna (roll)",
    MAGNETOMETER: "magnetometer (heading)",
    MOTION_PACK: "motion pack (its own attitude and heading)",
}
_SOURCES_BY_KIND = {source.kind: source for source in AIDING_SOURCES}


@dataclass(frozen=True)
class SourceUse:
    """What the fusion made of one aiding source over the run."""

    accepted: int
    """Measurements fused or used for the alignment."""
    suspended_at_end: bool = False
    """Suspended by its gate's record when the run ended (:mod:`buoy_nav.source_health`)."""


@dataclass(frozen=True)
class OutputFacts:
    """The facts of one processed bag that its outputs state (see the module docstring)."""

    north: str
    """:data:`TRUE_NORTH`, :data:`MAGNETIC_NORTH` or :data:`UNKNOWN_NORTH`."""
    north_basis: str
    """How the north was obtained, in words (which heading, which declination)."""
    sensors: tuple[str, ...]
    """The sensors whose data the outputs rest on, in words, IMU first."""
    site_deg: tuple[float, float] | None
    """(latitude, longitude) in degrees of the site the run was given (``site.*``, else
    ``origin.*``, from the parameter files or an imported record's facts), None when it had none
    (the position, if any, then comes from a GNSS fix)."""
    position_from_gnss: bool
    """Whether the fusion accepted GNSS fixes: the navigation's position is measured."""
    first_sample_s: float | None
    """Stamp (s since the epoch, UTC) of the first sample of the outputs; None without any."""
    last_sample_s: float | None
    """Stamp (s since the epoch, UTC) of the last sample of the outputs; None without any."""

    @property
    def position_known(self) -> bool:
        """Whether the navigation's latitude and longitude describe a real place."""
        return self.position_from_gnss or self.site_deg is not None

    def clockwise_from(self) -> str:
        """``clockwise from true north``, or from magnetic north with the declination not
        applied, for direction texts."""
        if self.north == UNKNOWN_NORTH:
            return f"clockwise from {UNKNOWN_NORTH}"
        return clockwise_from_north_text(self.north_token)

    def north_sentence(self) -> str:
        """One sentence naming the north of every direction and how it was obtained."""
        return f"Directions and headings are {self.clockwise_from()}: {self.north_basis}."

    @property
    def north_token(self) -> str:
        """The north as one word for column names: ``true_north``, ``magnetic_north``,
        ``unknown_north``."""
        return self.north.removeprefix("an ").replace(" ", "_")

    def sensor_text(self) -> str:
        """The sensors used, as one comma-separated phrase."""
        return ", ".join(self.sensors)


_NORTH_TOKENS = {"true_north": TRUE_NORTH, "magnetic_north": MAGNETIC_NORTH}


def clockwise_from_north_text(north_token: str) -> str:
    """The words of a direction's reference from :attr:`OutputFacts.north_token` (``""``: not
    known to the caller, which says so)."""
    if north_token == "magnetic_north":
        return "clockwise from magnetic north (no declination applied)"
    if north_token in _NORTH_TOKENS:
        return f"clockwise from {_NORTH_TOKENS[north_token]}"
    return "clockwise from north; which north is not recorded with these data"


def north_token_of_csv(path) -> str:
    """The north a products CSV's direction columns name (``true_north``, ...), ``""`` when
    there is no such file or column."""
    try:
        with open(path, encoding="utf8") as stream:
            header = stream.readline().strip().split(",")
    except OSError:
        return ""
    for column in header:
        if "direction_" in column and column.endswith("_north_deg"):
            return column.removesuffix("_deg").split("direction_", 1)[1]
    return ""


def output_facts(
    config: FusionConfig,
    input_topics: Iterable[str],
    source_use: Mapping[str, SourceUse],
    sample_stamps_s: Iterable[tuple[float, float]],
) -> OutputFacts:
    """The facts of a run: ``config`` its effective fusion parameters, ``input_topics`` the
    relative names of the input bag's topics, ``source_use`` what the fusion made of each
    aiding source (by kind), ``sample_stamps_s`` the (first, last) stamp in s of each output
    series that holds samples."""
    topics = frozenset(input_topics)
    used = {kind: use for kind, use in source_use.items() if use.accepted > 0}
    north, basis = _north_of(config, used)
    spans = [span for span in sample_stamps_s if all(math.isfinite(t) for t in span)]
    return OutputFacts(
        north=north,
        north_basis=basis,
        sensors=_sensors_of(topics, used),
        site_deg=_site_parameter_deg(config),
        position_from_gnss=any(
            POSITION_REFERENCE in _SOURCES_BY_KIND[kind].roles
            for kind in used
            if kind in _SOURCES_BY_KIND
        ),
        first_sample_s=min((span[0] for span in spans), default=None),
        last_sample_s=max((span[1] for span in spans), default=None),
    )


def source_use_of(health) -> dict[str, SourceUse]:
    """The :class:`SourceUse` of each aiding source from the fusion's
    :class:`~buoy_nav.health.EngineHealth` at the end of a run."""
    uses = {}
    for kind, counters in health.counters.items():
        status = health.source_health.get(kind)
        uses[kind] = SourceUse(
            accepted=counters.accepted + counters.used_for_alignment,
            suspended_at_end=bool(status is not None and status.suspended),
        )
    return uses


def _site_parameter_deg(config: FusionConfig) -> tuple[float, float] | None:
    """The site the parameters give (``site.*``, else ``origin.*``); NaN means not given."""
    for latitude, longitude in (
        (config.site_latitude_deg, config.site_longitude_deg),
        (config.origin_latitude_deg, config.origin_longitude_deg),
    ):
        if math.isfinite(latitude) and math.isfinite(longitude):
            return float(latitude), float(longitude)
    return None


def _north_of(config: FusionConfig, used: Mapping[str, SourceUse]) -> tuple[str, str]:
    """The north of the headings the fusion used, and how it was obtained. Headings of
    different norths fused together (a true one beside a magnetic one without declination) give
    true north, with the warning that the declination biases the result."""
    norths = []
    for kind in used:
        source = _SOURCES_BY_KIND.get(kind)
        if source is None or HEADING_REFERENCE not in source.roles:
            continue
        norths.append(_north_of_heading(config, source.sensor))
    if not norths:
        return UNKNOWN_NORTH, "the fusion used no heading, so no direction could be computed"
    references = {north for north, _ in norths}
    basis = "; ".join(dict.fromkeys(basis for _, basis in norths))
    if len(references) == 1:
        return norths[0][0], basis
    return TRUE_NORTH, (
        f"{basis}; fused together, so the heading is biased toward magnetic north by up to the "
        "declination"
    )


def _north_of_heading(config: FusionConfig, sensor: str) -> tuple[str, str]:
    if sensor == GNSS_ANTENNA_PAIR:
        return TRUE_NORTH, "the heading of the dual-antenna GNSS"
    if sensor == MOTION_PACK and config.ahrs_yaw_reference == "true_north":
        return TRUE_NORTH, "the motion pack's heading, referenced to true north by the pack"
    what = "the magnetometer's heading" if sensor == MAGNETOMETER else "the motion pack's heading"
    declination_deg = config.magnetic_declination_deg
    if math.isnan(declination_deg):
        return TRUE_NORTH, f"{what}, corrected by the World Magnetic Model's declination"
    if declination_deg == 0.0:
        return MAGNETIC_NORTH, f"{what}, magnetic; magnetic.declination_deg is 0"
    return TRUE_NORTH, (
        f"{what}, corrected by the declination magnetic.declination_deg = {declination_deg:g} deg"
    )


def _sensors_of(topics: frozenset[str], used: Mapping[str, SourceUse]) -> tuple[str, ...]:
    sensors = ["IMU"]
    for kind, use in used.items():
        source = _SOURCES_BY_KIND.get(kind)
        if source is None or source.sensor is None:
            if kind == "moored":
                sensors.append("mooring constraint (zero mean velocity)")
            continue
        words = _SENSOR_WORDS.get(source.sensor, source.sensor)
        if use.suspended_at_end:
            words += ", suspended by the end"
        if words not in sensors:
            sensors.append(words)
    if WIND_RAW_TOPIC in topics:
        with_temperature = SONIC_TEMPERATURE_TOPIC in topics
        sensors.append("sonic anemometer" + (" with temperature" if with_temperature else ""))
    if DVL_TOPIC in topics:
        sensors.append("DVL")
    return tuple(sensors)
