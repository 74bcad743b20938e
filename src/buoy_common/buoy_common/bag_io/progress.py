"""Progress of a tool through a bag, in bag seconds, as a tqdm bar."""

from __future__ import annotations

import math
import sys

from buoy_common.bag_io.reading import BagReader


class BagProgress:
    """A tqdm bar over the span of ``reader``'s bag (on stderr, and only on a terminal)."""

    def __init__(self, reader: BagReader, description: str):
        self._start_ns = reader.start_ns
        self._bar = None
        if sys.stderr is not None and sys.stderr.isatty():
            # Imported only for a bar that shows: tqdm costs a tenth of a second of start-up,
            # paid by every run of a tool (and by its writing process) in a script or a batch.
            from tqdm import tqdm

            self._bar = tqdm(total=math.ceil(reader.duration_s), desc=description, unit="bag s")

    def __enter__(self) -> BagProgress:
        return self

    def __exit__(self, *exc_info) -> None:
        if self._bar is not None:
            self._bar.close()

    def reached(self, log_time_ns: int) -> None:
        """The tool has handled the bag up to log time ``log_time_ns`` (ns)."""
        if self._bar is not None:
            self._bar.update(int((log_time_ns - self._start_ns) * 1e-9) - self._bar.n)

    def done(self) -> None:
        """The whole bag is handled."""
        if self._bar is not None:
            self._bar.update(self._bar.total - self._bar.n)
