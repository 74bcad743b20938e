"""Which sensor set the fusion is running on, from the aiding sources it is using now.

The sets (docs/sensor-sets.md): (a) IMU + dual-antenna RTK; (b) IMU + single-antenna GNSS
(+ magnetometer); (c) IMU + magnetometer, no GNSS (a moored buoy); (d) IMU + a motion pack's
attitude, with or without a magnetometer, no GNSS; (e) any of these through an outage of a GNSS
topic it had. The set is not configured: it follows from what was accepted within
``coasting_timeout_s`` (a source is *active*), and a source accepted before but not any more is
*coasting*. A set change needs no restart and makes no jump: the filter simply stops or starts
receiving a kind of measurement. :class:`AidingRecency` keeps the stamps this is judged from;
:class:`SensorSets` names the set from the ``sensor`` each aiding source declares.
"""

from __future__ import annotations

import math
from collections.abc import Iterable

from buoy_nav.aiding.base import (
    GNSS_ANTENNA_PAIR,
    GNSS_RECEIVER,
    GNSS_SENSORS,
    GNSS_THIRD_ANTENNA,
    MAGNETOMETER,
    MOTION_PACK,
    AidingSource,
)

_NAMED_SENSORS = frozenset((*GNSS_SENSORS, MAGNETOMETER, MOTION_PACK, None))
"""The sensors the sets are named after (None: a source of no sensor, such as a constraint)."""


class SensorSets:
    """The labels of the sensor sets over ``sources`` (aiding-source classes or instances),
    from the ``sensor`` each declares: no list of kinds is written out here, so a source
    registered for one of these sensors counts with it."""

    def __init__(self, sources: Iterable[AidingSource | type[AidingSource]]):
        sources = tuple(sources)
        self._kinds = {
            sensor: frozenset(source.kind for source in sources if source.sensor == sensor)
            for sensor in {source.sensor for source in sources}
        }
        self._gnss_kinds = frozenset().union(*(self.kinds_of(sensor) for sensor in GNSS_SENSORS))

    def kinds_of(self, sensor: str) -> frozenset[str]:
        """The kinds of the sources whose measurements come from ``sensor``."""
        return self._kinds.get(sensor, frozenset())

    def label(self, active: set[str], coasting: set[str]) -> str:
        """The set's label (``a``…``d``, with ``+e`` during a GNSS outage) and its sensors, for
        the ``active`` and ``coasting`` source kinds."""
        used = {sensor for sensor, kinds in self._kinds.items() if active & kinds}
        if GNSS_ANTENNA_PAIR in used:
            label = "a: dual-antenna GNSS" + _also(used, GNSS_THIRD_ANTENNA, "third antenna")
        elif GNSS_RECEIVER in used:
            label = "b: single-antenna GNSS" + _also(used, MAGNETOMETER, "magnetometer")
        elif MOTION_PACK in used:
            label = "d: motion pack" + _also(used, MAGNETOMETER, "magnetometer")
        elif MAGNETOMETER in used:
            label = "c: magnetometer, no GNSS"
        elif used - _NAMED_SENSORS:
            # A sensor none of the sets names (a source registered since): said as it is.
            label = f"other: {', '.join(sorted(used - _NAMED_SENSORS))}"
        else:
            label = "inertial only"
        outage = sorted(coasting & self._gnss_kinds)
        if outage:
            label += f" (e: outage of {', '.join(outage)})"
        return label


def _also(used: set[str], sensor: str, name: str) -> str:
    """`` + name`` when ``sensor`` is among the ``used`` ones."""
    return f" + {name}" if sensor in used else ""


class AidingRecency:
    """When each aiding source, and each aided quantity, last had a measurement accepted: what
    the sensor set and the coasting flags follow from.

    kinds: the aiding sources' kinds; quantity_count: the number of aided quantities (indexed as
    :data:`buoy_nav.aiding.base.AIDED_QUANTITIES`, fix, velocity and heading first);
    timeout_s: ``coasting_timeout_s``.
    """

    def __init__(self, kinds: Iterable[str], quantity_count: int, timeout_s: float):
        self._timeout_s = timeout_s
        self._last_accepted = dict.fromkeys(kinds, -math.inf)
        self._last_aided = [-math.inf] * quantity_count

    def accepted(self, kind: str, quantity: int, t_s: float) -> None:
        """A measurement of source ``kind`` aiding quantity index ``quantity`` was accepted at
        stamp ``t_s`` (s)."""
        self._last_accepted[kind] = t_s
        self._last_aided[quantity] = t_s

    def aided(self, quantity: int, t_s: float) -> None:
        """Quantity index ``quantity`` was set from a measurement at ``t_s`` (s): a reset."""
        self._last_aided[quantity] = t_s

    def aligned(self, t_s: float) -> None:
        """The alignment completed at ``t_s`` (s): every quantity is known there."""
        self._last_aided = [t_s] * len(self._last_aided)

    def age_s(self, quantity: int, t_s: float) -> float:
        """Time since quantity index ``quantity`` was last aided, at stamp ``t_s`` (s)."""
        return t_s - self._last_aided[quantity]

    def coasting_flags(self, t_s: float) -> tuple[bool, bool, bool]:
        """(fix, velocity, heading): no source aiding that quantity accepted for longer than
        the timeout at stamp ``t_s`` (s)."""
        timeout = self._timeout_s
        fix, velocity, heading = self._last_aided[:3]
        return t_s - fix > timeout, t_s - velocity > timeout, t_s - heading > timeout

    def sources(self, t_s: float) -> tuple[set[str], set[str]]:
        """(active, coasting) source kinds at stamp ``t_s`` (s): accepted within the timeout,
        and accepted before but not within it."""
        timeout = self._timeout_s
        active = {k for k, t in self._last_accepted.items() if t_s - t <= timeout}
        lapsed = {
            k for k, t in self._last_accepted.items() if math.isfinite(t) and t_s - t > timeout
        }
        return active, lapsed
