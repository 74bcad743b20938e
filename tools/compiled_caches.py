"""The caches of the suite's compiled code: numba's (``*.nbi``/``*.nbc``) and Python's bytecode,
both in the ``__pycache__`` beside each source module.

A cold start-up is measured by removing them; afterwards they are built again as an install
builds them (``tools.compile_ahead``, ``compileall``), so that a bench run does not leave the
working tree to the next ``make test`` without them: every process that test run starts at once
would otherwise compile the same numba code (about 25 s of CPU each).
"""

from __future__ import annotations

import shutil
import subprocess
import sys

from tools.bench_plan import REPO


def remove() -> None:
    """Delete the ``__pycache__`` directories of the project's sources (not the libraries')."""
    for cache in (REPO / "src").glob("*/*/**/__pycache__"):
        shutil.rmtree(cache, ignore_errors=True)


def rebuild() -> None:
    """Compile the numba code and the bytecode again, each in a process of its own (code this
    process already compiled would not be written to the cache again)."""
    for command in (
        [sys.executable, "-m", "tools.compile_ahead"],
        [sys.executable, "-m", "compileall", "-q", "src"],
    ):
        subprocess.run(command, cwd=REPO, check=True, stdout=subprocess.DEVNULL)
