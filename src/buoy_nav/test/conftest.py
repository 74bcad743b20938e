"""The engine tests' shared scenario: ``engine_scenario`` (importable by the test modules of this
folder, which pytest imports in importlib mode, where a test folder is not on the path) and the
rocking-buoy run many of them compare against."""

import sys
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).parent))

from engine_scenario import RockingBuoy, make_events, run


@pytest.fixture(scope="session")
def rocking_run():
    """60 s of the rocking buoy through an engine: (buoy, events, engine, solutions)."""
    buoy = RockingBuoy()
    events = make_events(buoy, 60.0)
    engine, solutions = run(events)
    return buoy, events, engine, solutions
