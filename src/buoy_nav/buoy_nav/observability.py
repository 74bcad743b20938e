"""What the configured and present aiding sources leave unobserved, and what follows for the
wind, said once when the fusion starts (``fusion_node``, ``fuse_bag``, ``process_bag``).

Each source declares what it aids (``aids``, :data:`~buoy_nav.aiding.base.AIDED_QUANTITIES`);
the quantities the wind correction needs are

- the **heading**: without a heading reference the fusion cannot align, so there is no
  navigation and no wind;
- the **velocity** over ground: a GNSS velocity, a fix (whose change over time gives it) or the
  mooring's zero-mean constraint. Without one the inertial velocity drifts without bound, and so
  does the corrected wind's horizontal σ: its samples are invalid;
- the **position**: only a GNSS fix observes it. Without one the position is the configured
  site's and drifts with the velocity; the wind does not depend on it.

An assumption is said too when nothing present can check it: the mooring's zero mean velocity
is judged against a GNSS fix or velocity (:mod:`buoy_nav.aiding.moored`); without either it is
unverified, and a buoy that in fact drifts would have its velocity held near zero and its
wind's σ too small.
"""

from collections.abc import Collection, Iterable

from buoy_nav.aiding import AIDING_SOURCES
from buoy_nav.aiding.base import (
    FIX,
    GNSS_ANTENNA_PAIR,
    GNSS_RECEIVER,
    GNSS_THIRD_ANTENNA,
    HEADING,
    MAGNETOMETER,
    MOORING,
    MOTION_PACK,
    VELOCITY,
    AidingSource,
)
from buoy_nav.config import FusionConfig

SENSOR_NAMES = {
    GNSS_RECEIVER: "GNSS",
    GNSS_ANTENNA_PAIR: "dual-antenna GNSS",
    GNSS_THIRD_ANTENNA: "third GNSS antenna",
    MAGNETOMETER: "magnetometer",
    MOTION_PACK: "motion pack",
}
"""How the sentences name the sensor of a source (a constraint without one by its kind)."""

# Quantity → (what aids it, its name in the sentence, what follows for the wind).
_OBSERVERS = (
    (
        (HEADING,),
        "heading",
        "the fusion cannot align: no navigation and no wind",
    ),
    (
        (VELOCITY, FIX, MOORING),
        "velocity",
        "the wind's horizontal σ will grow without bound and its samples will be invalid",
    ),
    (
        (FIX,),
        "position",
        "the position is the configured site's and drifts with the velocity; the wind does "
        "not depend on it",
    ),
)


_MOORING_JUDGES = (VELOCITY, FIX)
"""What the GNSS measures of the motion, which the mooring is judged against."""
_UNVERIFIED_MOORING = (
    "mooring unverified: no GNSS fix or velocity to judge fusion.moored against — if the buoy "
    "drifts, its velocity is held near zero and the wind's σ is too small"
)


def unobserved_quantities(
    config: FusionConfig,
    present_topics: Collection[str] | None = None,
    sources: Iterable[type[AidingSource]] = AIDING_SOURCES,
) -> list[str]:
    """One sentence per quantity that none of the ``sources`` that ``config`` enables and whose
    topic is in ``present_topics`` observes (None: every topic is taken as present, as for a
    live node before any message), e.g. ``no velocity reference: no GNSS or moored constraint
    (switched off) — …``, and one for a mooring nothing present can judge (``mooring
    unverified: …``); empty when everything the wind needs is observed and checked."""
    sources = list(sources)
    usable = [
        source
        for source in sources
        if source.enabled_by(config)
        and (source.pseudo or present_topics is None or source.topic in present_topics)
    ]
    sentences = []
    for aids, quantity, consequence in _OBSERVERS:
        if any(source.aids in aids for source in usable):
            continue
        missing = _names(config, (source for source in sources if source.aids in aids))
        sentences.append(f"no {quantity} reference: no {missing} — {consequence}")
    if any(source.aids == MOORING for source in usable) and not any(
        source.aids in _MOORING_JUDGES for source in usable
    ):
        sentences.append(_UNVERIFIED_MOORING)
    return sentences


def _names(config: FusionConfig, sources: Iterable[type[AidingSource]]) -> str:
    """The sensors (or constraints) of ``sources``, once each, joined with "or"; those
    ``config`` switches off said so."""
    names = []
    for source in sources:
        name = SENSOR_NAMES.get(source.sensor, f"{source.kind} constraint")
        if not source.enabled_by(config):
            name += " (switched off)"
        if name not in names:
            names.append(name)
    if not names:
        return "source registered for it"
    return ", ".join(names[:-1]) + f" or {names[-1]}" if len(names) > 1 else names[0]
