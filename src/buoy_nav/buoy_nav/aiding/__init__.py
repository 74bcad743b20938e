"""The aiding sources of the fusion, one module each, and their registry.

Each source (:class:`~buoy_nav.aiding.base.AidingSource`) owns everything the filter knows about
one aiding sensor: message conversion and validation, the measurement model (h, H, R), its
gate, its reset after persistent rejection and its role in the alignment. The engine runs the
sources listed in :data:`AIDING_SOURCES`; adding a sensor is a new module here and one line in
that list (``docs/adding-a-sensor.md``). What the tools and the diagnostics list by sensor (the
heading references a run needs, the sensors of a sensor set) is computed from what each source
declares (``topic``, ``aids``, ``sensor``, ``roles``), never written out by hand.
"""

from collections.abc import Iterable

from buoy_nav.aiding.ahrs_attitude import AhrsAttitude, AhrsAttitudeSource
from buoy_nav.aiding.base import HEADING_REFERENCE, ROLES, AidingSource
from buoy_nav.aiding.gnss_baseline import GnssBaseline, GnssBaselineSource
from buoy_nav.aiding.gnss_baseline_tertiary import GnssBaselineTertiary, GnssBaselineTertiarySource
from buoy_nav.aiding.gnss_fix import GnssFix, GnssFixSource
from buoy_nav.aiding.gnss_heading import GnssHeading, GnssHeadingSource
from buoy_nav.aiding.gnss_velocity import GnssVelocity, GnssVelocitySource
from buoy_nav.aiding.magnetometer import MagneticField, MagnetometerSource
from buoy_nav.aiding.moored import MooredSource, MooringAnchor
from buoy_nav.config import FusionConfig

AIDING_SOURCES: tuple[type[AidingSource], ...] = (
    GnssFixSource,
    GnssVelocitySource,
    GnssBaselineSource,
    GnssBaselineTertiarySource,
    GnssHeadingSource,
    MagnetometerSource,
    AhrsAttitudeSource,
    MooredSource,
)
"""The sources the fusion runs. Measurements that share a stamp are applied in this order; the
heading references, which may complete the alignment, come last, the antennas first among them
(the magnetometer and the motion pack align only a run without them)."""

TOPIC_SOURCES = tuple(source for source in AIDING_SOURCES if not source.pseudo)
"""The sources that read a topic (the others are constraints the engine asks for)."""


def topics_with_role(
    role: str, sources: Iterable[type[AidingSource]] = TOPIC_SOURCES
) -> tuple[str, ...]:
    """The topics of the ``sources`` that play ``role`` (one of
    :data:`~buoy_nav.aiding.base.ROLES`), in the order of the registry."""
    if role not in ROLES:
        raise ValueError(f"'{role}' is not one of the roles {ROLES}")
    return tuple(source.topic for source in sources if role in source.roles and not source.pseudo)


HEADING_REFERENCE_TOPICS = topics_with_role(HEADING_REFERENCE)
"""The topics of the heading references: a run needs one at least, without it the fusion cannot
align (what ``bag_fusion`` asks a bag for)."""


def disabled_topics(config: FusionConfig) -> frozenset[str]:
    """Topics of the registered sources that ``config`` switches off (not to be read)."""
    return frozenset(source.topic for source in TOPIC_SOURCES if not source.enabled_by(config))


__all__ = [
    "AIDING_SOURCES",
    "HEADING_REFERENCE_TOPICS",
    "TOPIC_SOURCES",
    "AhrsAttitude",
    "AhrsAttitudeSource",
    "AidingSource",
    "GnssBaseline",
    "GnssBaselineSource",
    "GnssBaselineTertiary",
    "GnssBaselineTertiarySource",
    "GnssFix",
    "GnssFixSource",
    "GnssHeading",
    "GnssHeadingSource",
    "GnssVelocity",
    "GnssVelocitySource",
    "MagneticField",
    "MagnetometerSource",
    "MooredSource",
    "MooringAnchor",
    "disabled_topics",
    "topics_with_role",
]
