"""A short soak: 20 simulated seconds of sea through the live nodes at twice real time, every
anemometer sample out on ``wind/true`` (the full day is the opt-in ``soak`` section of
``tools/bench.py``, tools/soak.py).
How many come out corrected depends on how busy the machine is (a sample whose navigation is
later than the latency budget is published invalid): the figures, not this test, say it.
The samples before the first pair the soak's listener sees are judged apart: DDS gives a
message only to the subscriptions matched when it is sent, so a busy machine may let the
simulation start a moment before every subscriber has joined; no more than a second of them
may go so."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

pytestmark = [pytest.mark.ros, pytest.mark.long]

REPO = Path(__file__).resolve().parents[2]
SIMULATED_S = 20.0  # the alignment, then 10 s of corrected wind
SIMULATED_HOURS = SIMULATED_S / 3600.0
RATE_FACTOR = 2.0
ANEMOMETER_RATE_HZ = 20.0
MAX_SAMPLES_BEFORE_THE_FIRST_PAIR = int(1.0 * ANEMOMETER_RATE_HZ)


def test_short_soak_loses_no_sample(tmp_path, ros_env):
    figures = tmp_path / "soak.json"
    result = subprocess.run(
        [
            sys.executable,
            "-m",
            "tools.soak",
            "--hours",
            str(SIMULATED_HOURS),
            "--rate-factor",
            str(RATE_FACTOR),
            "--rss-period-s",
            "1",
            "--json",
            str(figures),
        ],
        env=ros_env,
        cwd=REPO,
        capture_output=True,
        text=True,
        timeout=600,
    )
    assert result.returncode == 0, result.stdout + result.stderr
    counts = json.loads(figures.read_text())["counts"]
    assert counts["wind/true without its input"] == 0, counts
    assert counts["anemometer/wind without output"] == 0, counts
    before_first_pair = (
        counts["before the first pair: wind/true alone"]
        + counts["before the first pair: anemometer/wind alone"]
    )
    assert before_first_pair <= MAX_SAMPLES_BEFORE_THE_FIRST_PAIR, counts
    paired = counts["wind/true out"] - counts["before the first pair: wind/true alone"]
    assert paired == (
        counts["anemometer/wind in"] - counts["before the first pair: anemometer/wind alone"]
    ), counts
    assert paired >= 0.95 * SIMULATED_S * ANEMOMETER_RATE_HZ, counts
