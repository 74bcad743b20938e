"""Which sensor set the fusion is running on, from the aiding sources it is using now.

The sets (README, "Sensor sets"): (a) IMU + dual-antenna RTK; (b) IMU + single-antenna GNSS
(+ magnetometer); (c) IMU + magnetometer, no GNSS (a moored buoy); (d) IMU + a motion pack's
attitude, with or without a magnetometer, no GNSS; (e) any of these through an outage of a GNSS
topic it had. The set is not configured: it follows from what was accepted within
``coasting_timeout_s`` (a source is *active*), and a source accepted before but not any more is
*coasting*. A set change needs no restart and makes no jump: the filter simply stops or starts
receiving a kind of measurement.
"""

from __future__ import annotations

DUAL_ANTENNA_KINDS = ("gnss_heading", "gnss_baseline")
TERTIARY_ANTENNA_KIND = "gnss_baseline_tertiary"
SINGLE_ANTENNA_KINDS = ("gnss_fix", "gnss_velocity")
GNSS_KINDS = (*SINGLE_ANTENNA_KINDS, *DUAL_ANTENNA_KINDS, TERTIARY_ANTENNA_KIND)
MAGNETOMETER_KIND = "magnetometer"
AHRS_KIND = "ahrs"


def sensor_set(active: set[str], coasting: set[str]) -> str:
    """The set's label (``a``…``d``, with ``+e`` during a GNSS outage) and its sensors."""
    if active & set(DUAL_ANTENNA_KINDS):
        label = "a: dual-antenna GNSS" + (
            " + third antenna" if TERTIARY_ANTENNA_KIND in active else ""
        )
    elif active & set(SINGLE_ANTENNA_KINDS):
        label = "b: single-antenna GNSS" + (
            " + magnetometer" if MAGNETOMETER_KIND in active else ""
        )
    elif AHRS_KIND in active:
        label = "d: motion pack" + (" + magnetometer" if MAGNETOMETER_KIND in active else "")
    elif MAGNETOMETER_KIND in active:
        label = "c: magnetometer, no GNSS"
    else:
        label = "inertial only"
    outage = sorted(coasting & set(GNSS_KINDS))
    if outage:
        label += f" (e: outage of {', '.join(outage)})"
    return label
