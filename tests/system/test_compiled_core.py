"""The compiled hot path computes what its source says.

The strapdown step runs compiled (numba). With numba's JIT disabled the same functions run in the
interpreter, line by line as written, so the two runs must agree: ``process_bag`` on committed bags
with motion (and on the buoy whose geometry is unlike the shipped one) gives the same
``nav/odometry`` and ``wind/true`` both ways, every stamp, NaN and number within 1e-9.
"""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest
from live_replay import differences_from_offline

from processed_bags import CASES, processed_bag

PROCESS_BAG = Path(sys.executable).parent / "process_bag"


# off_axis exercises every lever arm and mounting angle, so `make test` runs it; sea_state, the
# shipped geometry's, is a long run.
@pytest.mark.parametrize("name", [pytest.param("sea_state", marks=pytest.mark.long), "off_axis"])
def test_compiled_run_equals_the_interpreted_source(tmp_path_factory, tmp_path, name):
    compiled = processed_bag(tmp_path_factory, name)
    case = CASES[name]
    interpreted = tmp_path / "interpreted"
    parameters = [f"--params-file={path}" for path in case.parameter_files(tmp_path)]
    completed = subprocess.run(
        [str(PROCESS_BAG), str(case.bag_path), str(interpreted), *parameters],
        env={**os.environ, "NUMBA_DISABLE_JIT": "1"},
        capture_output=True,
        text=True,
        timeout=600,
    )
    assert completed.returncode == 0, completed.stderr
    assert differences_from_offline(interpreted, compiled) == []
