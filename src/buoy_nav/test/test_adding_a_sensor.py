"""The worked example of docs/adding-a-sensor.md: its gyrocompass source, taken from the page
and registered from outside the package, runs in the engine and joins the lists the tools
compute from the registry."""

import dataclasses
import math
import re
import sys
import types
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest
from engine_scenario import RockingBuoy, attitude_errors_rad, deliver, engine_config, make_events
from scipy.spatial.transform import Rotation

from buoy_common.contract import Reason
from buoy_nav.aiding import (
    AIDING_SOURCES,
    TOPIC_SOURCES,
    GnssFixSource,
    GnssVelocitySource,
    topics_with_role,
)
from buoy_nav.aiding.base import HEADING_REFERENCE, LinearisationPoint
from buoy_nav.engine import FusionEngine
from buoy_nav.error_state_filter import ERROR_STATES, NavState, inject_error_state
from buoy_nav.fusion_messages import feed_message
from buoy_nav.sensor_sets import SensorSets

PAGE = Path(__file__).resolve().parents[3] / "docs" / "adding-a-sensor.md"
MODULE_PATH = "src/buoy_nav/buoy_nav/aiding/gyrocompass.py"
COMPASS_SIGMA_RAD = math.radians(0.1)


def module_from_page() -> types.ModuleType:
    """The page's source module (the Python block that opens with its path), run as a module of
    its own."""
    blocks = re.findall(r"```python\n(.*?)```", PAGE.read_text("utf8"), flags=re.DOTALL)
    (code,) = [block for block in blocks if block.startswith(f"# {MODULE_PATH}\n")]
    module = types.ModuleType("gyrocompass_example")
    sys.modules[module.__name__] = module
    exec(compile(code, str(PAGE), "exec"), module.__dict__)
    return module


gyrocompass = module_from_page()


def linearisation_point(rotation: Rotation) -> LinearisationPoint:
    state = NavState(rotation.as_quat(), np.zeros(3), 0.7, 2.0, 0.0, np.zeros(3), np.zeros(3))
    return LinearisationPoint(state, state.rotation_nb, (0.0, 0.0, 0.0), (0.0, 0.0, 0.0))


def test_the_compass_jacobian_is_the_derivative_of_its_prediction():
    source = gyrocompass.GyrocompassSource(engine_config(), ERROR_STATES)
    point = linearisation_point(Rotation.from_euler("ZYX", (2.5, 0.3, -0.4)))
    measurement = gyrocompass.CompassHeading(1.0, COMPASS_SIGMA_RAD**2)
    model = source.model(measurement, point)
    # Independent of the model: the azimuth of the rotated x axis, through scipy.
    forward = Rotation.from_quat(point.state.attitude_xyzw).apply((1.0, 0.0, 0.0))
    assert model.predicted[0] == pytest.approx(math.atan2(forward[1], forward[0]), abs=1e-12)
    step = 1e-7
    numeric = np.zeros(ERROR_STATES.dim)
    for index in range(ERROR_STATES.dim):
        error = np.zeros(ERROR_STATES.dim)
        error[index] = step
        moved = source.model(measurement, linearisation_point_of(point, error))
        numeric[index] = (moved.predicted[0] - model.predicted[0]) / step
    np.testing.assert_allclose(model.jacobian[0], numeric, atol=1e-6)


def linearisation_point_of(point: LinearisationPoint, error) -> LinearisationPoint:
    state = inject_error_state(point.state, error)
    return LinearisationPoint(state, state.rotation_nb, point.raw_gyro_rad_s, (0.0, 0.0, 0.0))


def compass_run():
    """GNSS position and velocity and the compass, 40 s of a rocking buoy: the engine, its
    solutions and the last compass message."""
    buoy = RockingBuoy()
    sources = (GnssFixSource, GnssVelocitySource, gyrocompass.GyrocompassSource)
    engine = FusionEngine(engine_config(), sources=sources)
    solutions = []
    for event in make_events(buoy, 40.0):
        t, _, kind, _ = event
        if kind != "heading":
            solutions += deliver(engine, event)
            continue
        x_axis_azimuth = buoy.euler(t)[0][0, 2]  # ZYX yaw: the azimuth of the body x axis
        message = SimpleNamespace(
            header=SimpleNamespace(stamp=SimpleNamespace(sec=int(t), nanosec=round(t % 1 * 1e9))),
            orientation=SimpleNamespace(
                x=0.0,
                y=0.0,
                z=math.sin(0.5 * x_axis_azimuth),
                w=math.cos(0.5 * x_axis_azimuth),
            ),
            orientation_covariance=[0.0] * 8 + [COMPASS_SIGMA_RAD**2],
        )
        assert feed_message(engine, "compass/heading", message) == ([], None)
    return buoy, engine, solutions, message


def test_the_compass_alone_aligns_the_fusion_and_holds_its_attitude():
    """GNSS position and velocity, no antenna heading: the compass is the heading reference."""
    buoy, engine, solutions, message = compass_run()
    bad = SimpleNamespace(
        header=message.header,
        orientation=message.orientation,
        orientation_covariance=[0.0] * 9,
    )
    assert feed_message(engine, "compass/heading", bad) == ([], Reason.NON_POSITIVE_VARIANCE)
    solutions += engine.flush()

    health = engine.health()
    counters = health.counters["gyrocompass"]
    assert health.alignments == 1
    assert counters.used_for_alignment > 0
    assert counters.accepted + counters.used_for_alignment == 400
    assert counters.rejected == {"non_positive_variance": 1}
    assert not solutions[-1].coasting_heading
    assert attitude_errors_rad(buoy, solutions).max() < math.radians(0.05)
    assert health.sensor_set == "b: single-antenna GNSS"


def test_the_registered_compass_joins_the_lists_the_tools_compute():
    registered = (*AIDING_SOURCES, gyrocompass.GyrocompassSource)
    topic_sources = (*TOPIC_SOURCES, gyrocompass.GyrocompassSource)
    assert topics_with_role(HEADING_REFERENCE, topic_sources)[-1] == "compass/heading"
    assert "compass/heading" not in topics_with_role(HEADING_REFERENCE)
    sets = SensorSets(registered)
    assert sets.label({"gyrocompass"}, set()) == "other: gyrocompass"
    assert sets.label({"gyrocompass", "gnss_fix"}, set()) == "b: single-antenna GNSS"


def test_the_compass_through_the_compiled_path_gives_the_filter_of_the_interpreted_one(
    monkeypatch,
):
    """Its compiled model takes a stamp's gates and update into one compiled call with the
    GNSS measurements; without that path every solution is the same to the bit."""
    _, engine, solutions, _ = compass_run()
    with monkeypatch.context() as patch:
        for source_class in (GnssFixSource, GnssVelocitySource, gyrocompass.GyrocompassSource):
            patch.setattr(source_class, "has_compiled_model", False)
        _, reference, expected, _ = compass_run()
    assert len(solutions) == len(expected) > 1000
    for solution, other in zip(solutions, expected, strict=True):
        for field in dataclasses.fields(solution):
            value, expected_value = getattr(solution, field.name), getattr(other, field.name)
            assert np.array_equal(value, expected_value), field.name
    assert engine.health().counters == reference.health().counters
