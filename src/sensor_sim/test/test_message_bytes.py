"""The offline generator's CDR bytes against the live nodes' message objects: for every topic
the simulator publishes, the same messages with the same stamps, byte for byte, as the bag
writer serialises the objects."""

from __future__ import annotations

from pathlib import Path

import pytest

from buoy_common.bag_io import jazzy_typestore
from buoy_common.bag_io.conversion import serialize
from sensor_sim import message_bytes, messages
from sensor_sim.scenario import load_scenario
from sensor_sim.streams import STREAMS
from sensor_sim.truth import TruthModel

# Every message the simulator makes, and each kind of gap: a dual-antenna receiver with a third
# antenna through fix, heading and silent outages; a magnetometer and a motion pack off the
# IMU's every sample; a sonic with its temperature; a DVL losing pings; a current.
OVERRIDES = [
    "duration_s=24",
    "wind.sonic_temperature_degc=14.5",
    "sensors.gnss.fix_outages_s=[[3.0, 5.0]]",
    "sensors.gnss.heading_outages_s=[[8.0, 11.0]]",
    "sensors.gnss.silent_outages_s=[[15.0, 17.5]]",
    "sensors.magnetometer.fitted=true",
    "sensors.magnetometer.sample_every=3",
    "sensors.ahrs.fitted=true",
    "sensors.ahrs.sample_every=2",
    "sensors.dvl.ping_loss_probability=0.3",
]
PARAMETERS = {"gnss.tertiary_antenna": [-0.4, 0.9, 0.2]}
# Advances of uneven length, as a live node's clock moves, each taking at least two of the
# IMU's samples (100 Hz), so one of the motion pack's.
ADVANCE_TO_S = (0.013, 0.5, 0.525, 2.97, 7.2, 12.0, 19.93, 24.0)


def stream_output(kind: str, encoding) -> tuple[dict[str, str], list[tuple[str, int, object]]]:
    """The stream's message types by topic, and its messages (topic, stamp ns, message)."""
    scenario = load_scenario("open_ocean", OVERRIDES, None)
    stream = STREAMS[kind].build(scenario, TruthModel(scenario), PARAMETERS, encoding=encoding)
    return stream.topics, [row for until_s in ADVANCE_TO_S for row in stream.advance(until_s)]


@pytest.mark.parametrize("kind", STREAMS)
def test_bytes_are_the_serialised_messages(kind):
    types, objects = stream_output(kind, messages)
    _, written = stream_output(kind, message_bytes)
    topics = {topic for topic, _, _ in objects}
    expected_topics = {
        "imu": {"imu/data_raw", "imu/mag", "imu/data"},
        "gnss": {"gnss/fix", "gnss/vel", "gnss/heading", "gnss/baseline", "gnss/baseline_tertiary"},
        "anemometer": {"anemometer/wind", "anemometer/temperature"},
        "dvl": {"dvl/velocity"},
        "truth": {"truth/odometry", "truth/wind", "truth/current", "truth/water_velocity"},
    }[kind]
    assert topics == expected_topics
    assert [(topic, stamp) for topic, stamp, _ in written] == [
        (topic, stamp) for topic, stamp, _ in objects
    ]
    store, bag = jazzy_typestore(), Path("compared")
    for (topic, stamp, message), (_, _, raw) in zip(objects, written, strict=True):
        assert raw == serialize(store, bag, topic, types[topic], message), (topic, stamp)


def test_a_live_clock_advancing_one_imu_sample_at_a_time_gives_every_pack_sample_once():
    """A live node may advance by one IMU sample, which holds no motion-pack sample every other
    time (``sample_every=2``): the stream yields nothing for the pack then and, over the run, the
    pack's samples at every second IMU stamp."""
    scenario = load_scenario("open_ocean", OVERRIDES, None)
    stream = STREAMS["imu"].build(scenario, TruthModel(scenario), PARAMETERS, encoding=messages)
    period_s = 1.0 / scenario.sensors.rates.imu_hz
    rows = [row for k in range(1, 41) for row in stream.advance(k * period_s)]
    imu_stamps = [stamp for topic, stamp, _ in rows if topic == "imu/data_raw"]
    pack_stamps = [stamp for topic, stamp, _ in rows if topic == "imu/data"]
    assert len(imu_stamps) >= 40
    assert pack_stamps == imu_stamps[::2]
