"""The interpreter a benchmark names: what the loader says of the executable, not what the
build's configuration claims (Debian's says ``--enable-shared`` of an interpreter it links
statically)."""

import platform
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from tools.interpreter import describe, interpreter


@pytest.mark.skipif(shutil.which("ldd") is None, reason="needs ldd")
def test_the_linkage_is_the_loaders():
    info = interpreter()
    linked = subprocess.run(
        ["ldd", info["executable"]], capture_output=True, text=True, check=True
    ).stdout
    assert info["libpython_shared"] == ("libpython" in linked)
    assert ("linked statically" in describe(info)) == (not info["libpython_shared"])


def test_the_version_and_executable_are_this_processs():
    info = interpreter()
    assert info["version"] == platform.python_version()
    assert Path(info["executable"]).samefile(Path(sys.executable).resolve())
