"""The aiding sources of the fusion, one module each, and their registry.

Each source (:class:`~buoy_nav.aiding.base.AidingSource`) owns everything the filter knows about
one aiding sensor: message conversion and validation, the measurement model (h, H, R), its
gate, its reset after persistent rejection and its role in the alignment. The engine runs the
sources listed in :data:`AIDING_SOURCES`; adding a sensor is a new module here and one line in
that list (see "Adding a sensor" in the README).
"""

from buoy_nav.aiding.base import AidingSource
from buoy_nav.aiding.gnss_baseline import GnssBaseline, GnssBaselineSource
from buoy_nav.aiding.gnss_baseline_tertiary import GnssBaselineTertiary, GnssBaselineTertiarySource
from buoy_nav.aiding.gnss_fix import GnssFix, GnssFixSource
from buoy_nav.aiding.gnss_heading import GnssHeading, GnssHeadingSource
from buoy_nav.aiding.gnss_velocity import GnssVelocity, GnssVelocitySource
from buoy_nav.config import FusionConfig

AIDING_SOURCES: tuple[type[AidingSource], ...] = (
    GnssFixSource,
    GnssVelocitySource,
    GnssBaselineSource,
    GnssBaselineTertiarySource,
    GnssHeadingSource,
)
"""The sources the fusion runs. Measurements that share a stamp are applied in this order; the
antenna attitude, which may complete the alignment, comes last."""


def disabled_topics(config: FusionConfig) -> frozenset[str]:
    """Topics of the registered sources that ``config`` switches off (not to be read)."""
    return frozenset(source.topic for source in AIDING_SOURCES if not source.enabled_by(config))


__all__ = [
    "AIDING_SOURCES",
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
    "disabled_topics",
]
