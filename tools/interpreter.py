"""Which Python a benchmark ran on, for its results: the interpreted parts of the suite run
about 15 % faster on an interpreter linked statically and built with profile-guided and
link-time optimisation (Debian's ``/usr/bin/python3.11``) than on a plain source build that
loads ``libpython`` as a shared library (pyenv's default), so a figure names its interpreter."""

from __future__ import annotations

import platform
import sys
from pathlib import Path


def _libpython_loaded() -> bool:
    """Whether this process runs the interpreter from a shared ``libpython`` (Linux: read off
    the process's memory map; False where there is none to read)."""
    maps = Path("/proc/self/maps")
    if not maps.exists():
        return False
    return "libpython" in maps.read_text()


def interpreter() -> dict:
    """Version, implementation, base executable and linkage of the running interpreter."""
    return {
        "version": platform.python_version(),
        "implementation": platform.python_implementation(),
        # The interpreter a venv was made from (a venv's own executable is a link to it).
        "executable": str(Path(getattr(sys, "_base_executable", sys.executable)).resolve()),
        "libpython_shared": _libpython_loaded(),
    }


def describe(info: dict) -> str:
    """One line for a table's heading: ``Python 3.11.2 (/usr/bin/python3, linked statically)``."""
    linkage = "libpython shared" if info["libpython_shared"] else "linked statically"
    return f"{info['implementation']} {info['version']} ({info['executable']}, {linkage})"
