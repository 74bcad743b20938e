"""What the outputs of a processed bag may say about how it was made: the north its directions
are referenced to, the sensors that were actually used, the site (only when it is known), the
span of the data and, for a bag made by ``import_records``, the record it came from (its start
and who gave it, how each field was screened). Every writer (NetCDF, CSV, the printed summary,
the report) takes these words from :class:`OutputFacts`, so that none of them claims a sensor, a
reference or a place that the run did not have.

The facts are derived from the effective parameters (the parameter files and what an imported
record contributed), the valid samples each flow sensor delivered, whether the fusion aligned and
what it accepted and suspended, and the stamps of the samples; nothing is assumed from the sensor
set the suite was designed for. A sensor is named only when its samples entered the outputs: the
navigation's only once the fusion aligned (samples that fed an alignment that never completed
entered nothing), a flow sensor's with a mark when it delivered no valid sample, the sonic
temperature only when it delivered valid samples.

The processed bag carries them too, as the MCAP metadata record :data:`OUTPUTS_METADATA_NAME`
(beside the imported record's own, :data:`~buoy_common.record_facts.RECORD_METADATA_NAME`), so
that a report of the bag alone states the same north and sensors; :func:`read_output_facts`
reads them back.
"""

from __future__ import annotations

import json
import math
from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from pathlib import Path

from buoy_common.bag_io import BagError
from buoy_common.contract import (
    DVL_TOPIC,
    SONIC_TEMPERATURE_TOPIC,
    WIND_RAW_TOPIC,
    seconds_to_iso8601,
)
from buoy_common.record_facts import (
    RECORD_METADATA_NAME,
    ImportedRecord,
    read_imported_record,
    read_metadata_record,
)
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
"""The run gave no heading (the fusion never aligned, or used none): its directions are NaN."""
NO_NAVIGATION_BASIS = "no valid navigation (the fusion never aligned)"
"""The :attr:`OutputFacts.north_basis` of a run whose fusion never aligned."""
SITE_FROM_RECORD = "the imported record"
SITE_FROM_PARAMETERS = "the parameters"
"""Where a run's site came from (:attr:`OutputFacts.site_source`)."""
OUTPUTS_METADATA_NAME = "buoy_outputs"
"""Name of the MCAP metadata record holding a processed bag's :class:`OutputFacts`."""
OUTPUTS_METADATA_VERSION = "1"

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
    """The sensors whose data the outputs rest on, in words: the IMU first when the fusion
    aligned (none of the navigation's otherwise), a flow sensor that delivered no valid sample
    marked so."""
    site_deg: tuple[float, float] | None
    """(latitude, longitude) in degrees of the site the run was given (``site.*``, else
    ``origin.*``, from the parameter files or an imported record's facts), None when it had none
    or only its latitude (the position, if any, then comes from a GNSS fix)."""
    position_from_gnss: bool
    """Whether the fusion accepted GNSS fixes: the navigation's position is measured."""
    first_sample_s: float | None
    """Stamp (s since the epoch, UTC) of the first sample of the outputs; None without any."""
    last_sample_s: float | None
    """Stamp (s since the epoch, UTC) of the last sample of the outputs; None without any."""
    declination_deg: float | None = None
    """The declination (deg, east positive) that turned a magnetic heading to true north, when
    given as a number (``magnetic.declination_deg``); None when none was applied or it came from
    the World Magnetic Model (it varies with time and place; :attr:`north_basis` says which)."""
    site_source: str | None = None
    """:data:`SITE_FROM_RECORD` or :data:`SITE_FROM_PARAMETERS`; None without a site."""
    latitude_only_deg: float | None = None
    """The latitude (deg) the run was given without a longitude: for gravity and the Earth's
    rate, not a position."""
    record: ImportedRecord | None = None
    """The facts of the record the input bag was imported from (its start and who gave it, the
    screening of each field); None for a bag that was not imported."""
    nav_rate_hz: float = 0.0
    """Rate of the written navigation (``nav/*``, ``tf``, the NetCDF file's), Hz, a subset of
    the solutions the corrections used (``--nav-rate-hz``); 0: every solution."""

    @property
    def position_known(self) -> bool:
        """Whether the navigation's latitude and longitude describe a real place."""
        return self.position_from_gnss or self.site_deg is not None

    def clockwise_from(self) -> str:
        """``clockwise from true north``, or from magnetic north with the declination not
        applied, for direction texts."""
        return clockwise_from_north_text(self.north_token)

    def north_sentence(self) -> str:
        """One sentence naming the north of every direction and how it was obtained, or why
        there is none."""
        if self.north == UNKNOWN_NORTH:
            return f"No heading, so no direction: {self.north_basis}."
        return f"Directions and headings are {self.clockwise_from()}: {self.north_basis}."

    @property
    def north_token(self) -> str:
        """The north as one word for column names: ``true_north``, ``magnetic_north``,
        ``unknown_north``."""
        return self.north.removeprefix("an ").replace(" ", "_")

    def sensor_text(self) -> str:
        """The sensors used, as one comma-separated phrase."""
        return ", ".join(self.sensors)

    def site_text(self) -> str:
        """Where the data were taken, as far as the run knows it, in words."""
        if self.position_from_gnss:
            return "position from GNSS fixes"
        if self.site_deg is not None:
            latitude, longitude = self.site_deg
            return (
                f"position the site given by {self.site_source}, {latitude:.5f}, "
                f"{longitude:.5f} deg (not measured)"
            )
        if self.latitude_only_deg is not None:
            return f"latitude {self.latitude_only_deg:.5f} deg given for gravity; position unknown"
        return "position unknown"

    def record_text(self) -> str:
        """The imported record, its start and who gave it, in one sentence; ``""`` for a bag
        that was not imported."""
        record = self.record
        if record is None:
            return ""
        start = seconds_to_iso8601(record.start_ns / 1e9)
        return (
            f"Imported by import_records from the record {record.record} with the column map "
            f"{record.column_map}; the record starts {start} (start from the "
            f"{record.start_source})."
        )

    def screening_text(self) -> str:
        """How the imported record's fields were screened, in one sentence (``""`` for a bag
        that was not imported)."""
        record = self.record
        if record is None or not record.field_counts:
            return ""
        fields = "; ".join(
            f"{name} {counts.read}/{counts.filled}/{counts.invalid}/{counts.out_of_range}"
            for name, counts in record.field_counts.items()
        )
        return (
            "Screening of the record's samples by import_records (read/filled/invalid/out of "
            f"range): {fields}."
        )

    def to_metadata(self) -> dict[str, str]:
        """The facts as the strings of an MCAP metadata record (the record's own facts are
        stored beside them, by :meth:`ImportedRecord.to_metadata`)."""
        return {
            "version": OUTPUTS_METADATA_VERSION,
            "north": self.north,
            "north_token": self.north_token,
            "north_basis": self.north_basis,
            "sensors": json.dumps(list(self.sensors)),
            "site_deg": json.dumps(self.site_deg),
            "site_source": json.dumps(self.site_source),
            "latitude_only_deg": json.dumps(self.latitude_only_deg),
            "position_from_gnss": json.dumps(self.position_from_gnss),
            "first_sample_s": json.dumps(self.first_sample_s),
            "last_sample_s": json.dumps(self.last_sample_s),
            "declination_deg": json.dumps(self.declination_deg),
            "nav_rate_hz": json.dumps(self.nav_rate_hz),
        }

    def metadata_records(self) -> dict[str, dict[str, str]]:
        """The MCAP metadata records a processed bag stores: these facts and, for an imported
        bag, the record's own."""
        records = {OUTPUTS_METADATA_NAME: self.to_metadata()}
        if self.record is not None:
            records[RECORD_METADATA_NAME] = self.record.to_metadata()
        return records

    @classmethod
    def from_metadata(
        cls, metadata: Mapping[str, str], record: ImportedRecord | None = None
    ) -> OutputFacts:
        """The facts of a metadata record written by :meth:`to_metadata`, with the imported
        ``record`` stored beside it; KeyError or ValueError when it is not one."""
        if metadata["version"] != OUTPUTS_METADATA_VERSION:
            raise ValueError(f"version {metadata['version']!r}, this reader reads version 1")
        site = json.loads(metadata["site_deg"])
        return cls(
            north=metadata["north"],
            north_basis=metadata["north_basis"],
            sensors=tuple(json.loads(metadata["sensors"])),
            site_deg=None if site is None else (float(site[0]), float(site[1])),
            position_from_gnss=bool(json.loads(metadata["position_from_gnss"])),
            first_sample_s=json.loads(metadata["first_sample_s"]),
            last_sample_s=json.loads(metadata["last_sample_s"]),
            declination_deg=json.loads(metadata["declination_deg"]),
            site_source=json.loads(metadata["site_source"]),
            latitude_only_deg=json.loads(metadata["latitude_only_deg"]),
            record=record,
            # Stored since the rate could be lowered: a bag processed before has every solution.
            nav_rate_hz=float(json.loads(metadata.get("nav_rate_hz", "0"))),
        )


def read_output_facts(bag: str | Path) -> OutputFacts | None:
    """The :class:`OutputFacts` ``process_bag`` stored in ``bag`` (a bag directory or its MCAP
    file); None for a bag without them (recorded from the nodes, or processed before the outputs'
    facts were stored). BagError for facts that are there but unreadable."""
    metadata = read_metadata_record(bag, OUTPUTS_METADATA_NAME)
    if metadata is None:
        return None
    try:
        return OutputFacts.from_metadata(metadata, read_imported_record(bag))
    except (KeyError, ValueError, TypeError, IndexError) as error:
        raise BagError(
            f"bag {bag}: the outputs' facts ({OUTPUTS_METADATA_NAME}) are unreadable: {error}"
        ) from error


_NORTH_TOKENS = {
    "true_north": TRUE_NORTH,
    "magnetic_north": MAGNETIC_NORTH,
    "unknown_north": UNKNOWN_NORTH,
}


def clockwise_from_north_text(north_token: str) -> str:
    """The words of a direction's reference from :attr:`OutputFacts.north_token` (``""``: not
    known to the caller, which says so)."""
    if north_token == "magnetic_north":
        return "clockwise from magnetic north (no declination applied)"
    if north_token == "unknown_north":
        return f"clockwise from {UNKNOWN_NORTH} (no heading: every direction is NaN)"
    if north_token in _NORTH_TOKENS:
        return f"clockwise from {_NORTH_TOKENS[north_token]}"
    return "clockwise from north; which north is not recorded with these data"


def north_token_of_bag(bag, products_csv_suffix: str) -> str:
    """The north of a processed bag's directions: from the facts stored in the bag, else (a bag
    processed before they were stored) from the products CSV named ``bag`` +
    ``products_csv_suffix`` beside it; ``""`` when neither says (a bag recorded from the nodes)."""
    facts = read_output_facts(bag)
    if facts is not None:
        return facts.north_token
    bag = Path(bag)
    return north_token_of_csv(bag.with_name(bag.name + products_csv_suffix))


def sensor_text_of_bag(bag) -> str:
    """The sensors a processed bag's outputs rest on, as :meth:`OutputFacts.sensor_text` stored
    them in the bag; ``""`` for a bag without its outputs' facts."""
    facts = read_output_facts(bag)
    return "" if facts is None else facts.sensor_text()


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
    valid_flow_samples: Mapping[str, int],
    source_use: Mapping[str, SourceUse],
    sample_stamps_s: Iterable[tuple[float, float]],
    record: ImportedRecord | None = None,
    aligned: bool = True,
    nav_rate_hz: float = 0.0,
) -> OutputFacts:
    """The facts of a run: ``config`` its effective fusion parameters, ``valid_flow_samples``
    the number of valid samples each flow sensor topic of the input bag delivered, by relative
    name (``anemometer/wind``, ``anemometer/temperature``, ``dvl/velocity``; a topic the bag
    lacks is absent), ``source_use`` what the fusion made of each aiding source (by kind),
    ``sample_stamps_s`` the (first, last) stamp in s of each output series that holds samples,
    ``record`` the facts of the record the bag was imported from (None: not imported),
    ``aligned`` whether the fusion completed an alignment (without one no navigation sensor
    entered the outputs, whatever its samples fed), ``nav_rate_hz`` the rate of the written
    navigation, Hz (0: every solution)."""
    used = {kind: use for kind, use in source_use.items() if aligned and use.accepted > 0}
    position_from_gnss = any(
        POSITION_REFERENCE in _SOURCES_BY_KIND[kind].roles
        for kind in used
        if kind in _SOURCES_BY_KIND
    )
    site = config.site_position_deg
    site_source = _site_source(site, record)
    wmm_position = _wmm_position_text(position_from_gnss, site, site_source)
    north, basis = _north_of(config, used, aligned, wmm_position)
    spans = [span for span in sample_stamps_s if all(math.isfinite(t) for t in span)]
    return OutputFacts(
        north=north,
        north_basis=basis,
        sensors=_sensors_of(valid_flow_samples, used, aligned),
        site_deg=site,
        site_source=site_source,
        latitude_only_deg=config.site_latitude_only_deg,
        declination_deg=_declination_applied_deg(config, used),
        record=record,
        position_from_gnss=position_from_gnss,
        first_sample_s=min((span[0] for span in spans), default=None),
        last_sample_s=max((span[1] for span in spans), default=None),
        nav_rate_hz=float(nav_rate_hz),
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


def _site_source(site_deg, record: ImportedRecord | None) -> str | None:
    """Whether the run's site is the imported record's or the parameters' own."""
    if site_deg is None:
        return None
    if record is not None and record.site_deg == site_deg:
        return SITE_FROM_RECORD
    return SITE_FROM_PARAMETERS


def _declination_applied_deg(config: FusionConfig, used: Mapping[str, SourceUse]) -> float | None:
    """The declination given as a number that turned a heading the fusion used from magnetic
    to true north; None when none did (a declination of 0 turns nothing)."""
    declination_deg = config.magnetic_declination_deg
    if not math.isfinite(declination_deg) or declination_deg == 0.0:
        return None
    magnetic_sensors = {MAGNETOMETER}
    if config.ahrs_yaw_reference != "true_north":
        magnetic_sensors.add(MOTION_PACK)
    headings = (_SOURCES_BY_KIND.get(kind) for kind in used)
    if any(h and HEADING_REFERENCE in h.roles and h.sensor in magnetic_sensors for h in headings):
        return float(declination_deg)
    return None


def _wmm_position_text(
    position_from_gnss: bool, site_deg: tuple[float, float] | None, site_source: str | None
) -> str:
    """Where the World Magnetic Model's declination was taken (deg for the site)."""
    if position_from_gnss:
        return "the positions of the GNSS fixes"
    if site_deg is not None:
        latitude, longitude = site_deg
        return f"{latitude:.5f}, {longitude:.5f} deg (the site given by {site_source})"
    # Unreached by a run that aligned: the alignment needs a GNSS fix or a site.
    return "the navigation's position"


def _north_of(
    config: FusionConfig, used: Mapping[str, SourceUse], aligned: bool, wmm_position: str
) -> tuple[str, str]:
    """The north of the headings the fusion used, and how it was obtained (``wmm_position``:
    where a declination from the World Magnetic Model was taken). Headings of different norths
    fused together (a true one beside a magnetic one without declination) give true north, with
    the warning that the declination biases the result."""
    if not aligned:
        return UNKNOWN_NORTH, NO_NAVIGATION_BASIS
    norths = []
    for kind in used:
        source = _SOURCES_BY_KIND.get(kind)
        if source is None or HEADING_REFERENCE not in source.roles:
            continue
        norths.append(_north_of_heading(config, source.sensor, wmm_position))
    if not norths:
        return UNKNOWN_NORTH, "the fusion aligned but used no heading source"
    references = {north for north, _ in norths}
    basis = "; ".join(dict.fromkeys(basis for _, basis in norths))
    if len(references) == 1:
        return norths[0][0], basis
    return TRUE_NORTH, (
        f"{basis}; fused together, so the heading is biased toward magnetic north by up to the "
        "declination"
    )


def _north_of_heading(config: FusionConfig, sensor: str, wmm_position: str) -> tuple[str, str]:
    if sensor == GNSS_ANTENNA_PAIR:
        return TRUE_NORTH, "the heading of the dual-antenna GNSS"
    if sensor == MOTION_PACK and config.ahrs_yaw_reference == "true_north":
        return TRUE_NORTH, "the motion pack's heading, referenced to true north by the pack"
    what = "the magnetometer's heading" if sensor == MAGNETOMETER else "the motion pack's heading"
    declination_deg = config.magnetic_declination_deg
    if math.isnan(declination_deg):
        return TRUE_NORTH, (
            f"{what}, corrected by the declination of the World Magnetic Model at {wmm_position}"
        )
    if declination_deg == 0.0:
        return MAGNETIC_NORTH, f"{what}, magnetic; magnetic.declination_deg is 0"
    return TRUE_NORTH, (
        f"{what}, corrected by the declination magnetic.declination_deg = {declination_deg:g} deg"
    )


def _sensors_of(
    valid_flow_samples: Mapping[str, int], used: Mapping[str, SourceUse], aligned: bool
) -> tuple[str, ...]:
    sensors = ["IMU"] if aligned else []
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
    if WIND_RAW_TOPIC in valid_flow_samples:
        sensors.append(_sonic_words(valid_flow_samples))
    if DVL_TOPIC in valid_flow_samples:
        sensors.append("DVL" if valid_flow_samples[DVL_TOPIC] else "DVL (no valid sample)")
    return tuple(sensors)


def _sonic_words(valid_flow_samples: Mapping[str, int]) -> str:
    """The sonic anemometer, with its temperature only when that delivered valid samples."""
    if not valid_flow_samples[WIND_RAW_TOPIC]:
        return "sonic anemometer (no valid wind sample)"
    if valid_flow_samples.get(SONIC_TEMPERATURE_TOPIC, 0) > 0:
        return "sonic anemometer with temperature"
    return "sonic anemometer"
