"""Compile the suite's numba code into numba's cache once, right after an install.

Every node and offline tool builds a fusion engine and a wind pipeline when it starts, and
building them compiles the numba functions they run, or loads them from numba's cache (in the
``__pycache__`` beside each module). After a fresh install nothing is cached, so every process
started before the first one has written the cache compiles them again, about 25 s of CPU each:
the first dozen processes of a test run, started together, all did. Built once here, before
anything else runs, they are loaded from the cache everywhere.

    python -m tools.compile_ahead
"""

from __future__ import annotations

import time

from buoy_nav.config import FusionConfig
from buoy_nav.engine import FusionEngine
from buoy_nav.solution_rows import SolutionRows
from wind_comp.config import CompensatorConfig
from wind_comp.pipeline import wind_pipeline


def main() -> None:
    started_s = time.perf_counter()
    # Every aiding source's compiled model, whatever the set, and an offline run's stretches.
    FusionEngine(FusionConfig(), solution_rows=SolutionRows())
    wind_pipeline(CompensatorConfig())  # the Miller correction and its covariance
    print(f"compiled code cached in {time.perf_counter() - started_s:.0f} s")


if __name__ == "__main__":
    main()
