"""Which navigation solutions the offline outputs carry: every one, or one per period.

``fuse_bag`` and ``process_bag`` write five ``nav/*`` messages and a ``tf`` per IMU sample, most
of their output bag. With ``--nav-rate-hz`` they write those (and the NetCDF file's navigation)
at a lower rate, while the corrections still receive every solution: the written solutions are
a subset of the full-rate ones, with the same stamps and bytes, and the corrected wind does not
change. The grid is the fusion's own output decimation (``fusion.output_rate_hz``,
:class:`buoy_nav.solution.OutputDecimation`), anchored at the first solution.
"""

from __future__ import annotations

import argparse
import math

from buoy_nav.fusion_messages import NavValues
from buoy_nav.solution import OutputDecimation

NANOSECONDS = 1_000_000_000


class NavOutputRate:
    """Decides, solution by solution in stamp order, which ones the navigation outputs carry
    at ``nav_rate_hz`` (Hz; 0: every solution). Each solution must be asked about once."""

    def __init__(self, nav_rate_hz: float = 0.0):
        if not (math.isfinite(nav_rate_hz) and nav_rate_hz >= 0.0):
            raise ValueError(f"the navigation output rate must be ≥ 0 Hz, got {nav_rate_hz}")
        self.nav_rate_hz = float(nav_rate_hz)
        self._decimation = OutputDecimation(self.nav_rate_hz)
        self._previous_stamp_ns: int | None = None

    @property
    def every_solution(self) -> bool:
        return self.nav_rate_hz == 0.0

    def due(self, values: NavValues) -> bool:
        """Whether the solution ``values`` (the next one in stamp order) is written."""
        return self.due_at(values.sec, values.nanosec)

    def due_at(self, sec: int, nanosec: int) -> bool:
        """Whether the next solution in stamp order, stamped ``sec``, ``nanosec``, is written."""
        if self.every_solution:
            return True
        stamp_ns = sec * NANOSECONDS + nanosec
        previous_ns = self._previous_stamp_ns
        # The interval to the previous solution gives the grid its tolerance (half of it).
        span_s = 0.0 if previous_ns is None else (stamp_ns - previous_ns) / NANOSECONDS
        self._previous_stamp_ns = stamp_ns
        return self._decimation.due(stamp_ns / NANOSECONDS, span_s)


NAV_RATE_HELP = (
    "write the navigation (nav/* and tf; with process_bag --netcdf, the file's navigation too) "
    "at this rate, Hz: a subset of the solutions, with their stamps and bytes; the corrections "
    "still use every solution (default 0: every solution)"
)


def _nav_rate_hz(text: str) -> float:
    """The ``--nav-rate-hz`` argument, Hz: a finite number ≥ 0 (else a usage error)."""
    try:
        value = float(text)
    except ValueError:
        value = math.nan
    if not (math.isfinite(value) and value >= 0.0):
        raise argparse.ArgumentTypeError(f"expected a number of Hz ≥ 0, got {text!r}")
    return value


def add_nav_rate_argument(parser: argparse.ArgumentParser) -> None:
    """``--nav-rate-hz HZ``, as ``fuse_bag``, ``process_bag`` and ``process_archive`` take it."""
    parser.add_argument(
        "--nav-rate-hz", type=_nav_rate_hz, default=0.0, metavar="HZ", help=NAV_RATE_HELP
    )
