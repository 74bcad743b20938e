"""Building the fusion engine and the wind's compensation loads every compiled function they
call, so that no sensor message of a live node waits for the compiler (up to seconds on the
first run after an install or a change of the sources).

In a fresh interpreter (another process: in this one, earlier tests have called the compiled
functions already), the engine and the wind's pipeline are built, as the nodes build them (and
the engine as the offline tools build it, its solutions written as rows), the
signatures of every compiled function of the fusion's and the compensation's modules are noted,
and engines then fuse a minute of each sensor set (the dual-antenna receiver, the receiver's
heading alone, a single antenna with a magnetometer, a moored buoy with a motion pack and a
magnetometer) and ``process_bag`` corrects the wind of ``bags/sea_state``. No compiled function
may gain a signature while they do: each was compiled or loaded from the cache when the engine
or the pipeline was built, for the argument types they are given.
"""

from __future__ import annotations

import importlib
import multiprocessing
import pkgutil
import tempfile
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

from numba.core.registry import CPUDispatcher
from test_nav_sensor_sets import calibrated_magnetometer, fuse, moored_config, scenario_messages

import buoy_nav
import buoy_nav.aiding
import wind_comp
from buoy_nav.config import FusionConfig
from buoy_nav.engine import FusionEngine
from buoy_nav.solution_rows import SolutionRows
from buoy_processing.bag_processing import process_bag
from wind_comp.config import CompensatorConfig
from wind_comp.pipeline import wind_pipeline

DURATION_S = 60.0
WIND_BAG = Path(__file__).resolve().parents[2] / "bags" / "sea_state"


def sensor_sets():
    """(scenario, its overrides, the fusion's configuration) of each set the test fuses."""
    return [
        ("sea_state", (), FusionConfig()),
        ("sea_state", (), FusionConfig(use_gnss_baseline=False)),
        (
            "sea_state",
            ("sensors.gnss.receiver=single_antenna", "sensors.magnetometer.fitted=true"),
            FusionConfig(
                site_latitude_deg=35.0, site_longitude_deg=120.0, **calibrated_magnetometer()
            ),
        ),
        ("moored_motion_pack", (), moored_config(ahrs_lag_s=0.2)),
    ]


def compiled_functions() -> dict[str, CPUDispatcher]:
    """Every compiled function of the fusion's and the compensation's modules, by qualified
    name (the nodes, which import ROS, left out: they call the engine's and the pipeline's)."""
    functions = {}
    for package in (buoy_nav, buoy_nav.aiding, wind_comp):
        for module_info in pkgutil.iter_modules(package.__path__):
            if module_info.name.endswith("_node"):
                continue
            module = importlib.import_module(f"{package.__name__}.{module_info.name}")
            for name, value in vars(module).items():
                if isinstance(value, CPUDispatcher):
                    functions[f"{module.__name__}.{name}"] = value
    return functions


def compiled_during_the_runs() -> dict[str, list[str]]:
    """The compiled functions that gained signatures while the engines fused and the wind was
    corrected, after the first engine and pipeline were built: name → the new signatures."""
    FusionEngine(FusionConfig())
    FusionEngine(FusionConfig(), solution_rows=SolutionRows())
    wind_pipeline(CompensatorConfig())
    functions = compiled_functions()
    loaded = {name: set(function.signatures) for name, function in functions.items()}
    for name, overrides, config in sensor_sets():
        scenario, _, messages = scenario_messages(name, DURATION_S, overrides)
        fuse(config, messages, scenario)
    with tempfile.TemporaryDirectory() as out:
        process_bag(
            WIND_BAG,
            Path(out) / "corrected",
            FusionConfig(),
            CompensatorConfig(),
            write_bag=False,
            say_statements=False,
        )
    return {
        name: [str(signature) for signature in set(function.signatures) - loaded[name]]
        for name, function in functions.items()
        if set(function.signatures) - loaded[name]
    }


def test_the_engine_loads_every_compiled_function_the_fusion_calls():
    context = multiprocessing.get_context("spawn")
    with ProcessPoolExecutor(max_workers=1, mp_context=context) as fresh_interpreter:
        compiled_late = fresh_interpreter.submit(compiled_during_the_runs).result()
    assert compiled_late == {}
    assert len(compiled_functions()) > 20
