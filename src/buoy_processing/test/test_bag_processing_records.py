"""The sonic temperature read a chunk at a time: ``process_bag`` takes each
``anemometer/temperature`` message from its chunk's record where the bulk decoder reads it, and
accepts, rejects and counts every message, and writes every output, exactly as reading the
messages one at a time does."""

from __future__ import annotations

import math
from pathlib import Path

import pytest
import xarray as xr
from mcap.reader import make_reader

from buoy_common.bag_io import BagReader, BagWriter, jazzy_typestore
from buoy_common.contract import ANEMOMETER_FRAME, TEMPERATURE_MSGTYPE
from buoy_nav.config import fusion_config_from_files
from buoy_processing import bag_processing
from buoy_processing.bag_processing import ANEMOMETER_RECORD_FIELDS, BagCorrections, process_bag
from wind_comp.config import compensator_config_from_files

REPO = Path(__file__).resolve().parents[3]
SOURCE_BAG = REPO / "bags" / "open_ocean"
PARAMETERS = [
    str(REPO / "src/buoy_common/config/buoy.yaml"),
    str(REPO / "src/buoy_nav/config/fusion.yaml"),
]
WIND = "/anemometer/wind"
TEMPERATURE = "/anemometer/temperature"
SECONDS = 60.0


def temperature_raw(sec: int, nanosec: int, frame_id: str, value: float, little_endian=True):
    """A ``sensor_msgs/Temperature`` (°C) as CDR bytes."""
    store = jazzy_typestore()
    message = store.types[TEMPERATURE_MSGTYPE](
        header=store.types["std_msgs/msg/Header"](
            stamp=store.types["builtin_interfaces/msg/Time"](sec=sec, nanosec=nanosec),
            frame_id=frame_id,
        ),
        temperature=value,
        variance=0.0,
    )
    return bytes(store.serialize_cdr(message, TEMPERATURE_MSGTYPE, little_endian=little_endian))


# What some temperature messages are, by their number: rejected values, and big-endian bytes
# the bulk decoder leaves to the per-message path (one of them rejected there).
ODD_TEMPERATURES = {
    40: {"value": math.nan},
    80: {"frame_id": "sonic_link"},
    120: {"little_endian": False},
    160: {"little_endian": False, "frame_id": "sonic_link"},
    200: {"value": -math.inf},
}


@pytest.fixture(scope="module")
def bag_with_temperature(tmp_path_factory) -> Path:
    """The first minute of ``open_ocean`` with a sonic temperature beside each wind sample."""
    bag = tmp_path_factory.mktemp("records") / "with_temperature"
    with BagReader(SOURCE_BAG) as reader, BagWriter(bag) as writer:
        end_ns = reader.start_ns + round(SECONDS * 1e9)
        number = 0
        for message in reader.messages():
            if message.log_time_ns >= end_ns:
                break
            writer.write_raw(message.topic, message.msgtype, message.log_time_ns, message.raw)
            if message.topic != WIND:
                continue
            stamp = reader.decode(message).header.stamp
            fields = {"frame_id": ANEMOMETER_FRAME, "value": 15.0 + 0.01 * (number % 50)}
            fields |= ODD_TEMPERATURES.get(number, {})
            raw = temperature_raw(stamp.sec, stamp.nanosec, **fields)
            writer.write_raw(TEMPERATURE, TEMPERATURE_MSGTYPE, message.log_time_ns, raw)
            number += 1
    return bag


def run(bag: Path, out: Path, in_background: bool = False, netcdf_path: Path | None = None):
    """``process_bag``'s summary and every message of its bag (topic, log time, bytes) in the
    order the file holds them; the bag written here, or by a process of its own."""
    configs = (fusion_config_from_files(PARAMETERS), compensator_config_from_files(PARAMETERS))
    summary = process_bag(
        bag, out, *configs, write_in_background=in_background, netcdf_path=netcdf_path
    )
    with open(next(out.glob("*.mcap")), "rb") as stream:
        messages = [
            (channel.topic, message.log_time, message.data)
            for _, channel, message in make_reader(stream).iter_messages(log_time_order=False)
        ]
    return summary, messages


def test_temperatures_from_chunk_records_equal_those_read_one_at_a_time(
    bag_with_temperature, tmp_path, monkeypatch
):
    records_read = []
    take_temperature = bag_processing.OfflineCorrection.add_temperature

    def add_temperature(self, reader, message, record=None):
        records_read.append(record is not None)
        take_temperature(self, reader, message, record)

    monkeypatch.setattr(bag_processing.OfflineCorrection, "add_temperature", add_temperature)
    summary, messages = run(bag_with_temperature, tmp_path / "in_chunks")
    assert records_read.count(False) == 2, "the big-endian ones are read alone"
    records_read.clear()
    monkeypatch.setattr(
        BagCorrections,
        "record_fields",
        property(lambda corrections: {corrections.flows.wind: ANEMOMETER_RECORD_FIELDS}),
    )
    expected_summary, expected_messages = run(bag_with_temperature, tmp_path / "alone")
    assert not any(records_read)

    wind, expected = summary.wind, expected_summary.wind
    assert (
        wind.rejected_temperatures
        == expected.rejected_temperatures
        == {
            "non_finite": 2,
            "wrong_frame": 2,
        }
    )
    assert summary.facts.metadata_records() == expected_summary.facts.metadata_records()
    assert wind.status_counts == expected.status_counts
    assert wind.status_counts["valid"] > 0, "the fusion aligned and the wind was corrected"
    assert len(wind.fluxes) == 1 and wind.fluxes[0].n_temperature > 0
    assert repr(wind.fluxes) == repr(expected.fluxes)
    assert repr(wind.products) == repr(expected.products)
    assert messages == expected_messages


def test_the_writing_process_corrects_as_this_process_does(bag_with_temperature, tmp_path):
    """With the bag written by a process of its own, the corrections run there
    (:mod:`buoy_processing.output_side`), the temperatures the bulk decoder leaves decoded from
    the bag that process opens: the same bag, message by message in the file's order, the same
    products, fluxes and facts, CSV files and NetCDF file."""
    here, here_messages = run(
        bag_with_temperature, tmp_path / "here" / "bag", False, tmp_path / "here.nc"
    )
    there, there_messages = run(
        bag_with_temperature, tmp_path / "there" / "bag", True, tmp_path / "there.nc"
    )
    assert there_messages == here_messages
    assert there.topic_counts == here.topic_counts
    assert there.wind.status_counts == here.wind.status_counts
    assert there.wind.status_counts["valid"] > 0, "the fusion aligned and the wind was corrected"
    assert there.wind.rejected_temperatures == here.wind.rejected_temperatures
    assert repr(there.wind.fluxes) == repr(here.wind.fluxes)
    assert repr(there.wind.products) == repr(here.wind.products)
    assert there.facts.metadata_records() == here.facts.metadata_records()
    for name in ("bag_wind_products.csv", "bag_wind_fluxes.csv"):
        assert (tmp_path / "there" / name).read_bytes() == (tmp_path / "here" / name).read_bytes()
    with (
        xr.open_dataset(tmp_path / "here.nc") as expected,
        xr.open_dataset(tmp_path / "there.nc") as written,
    ):
        assert written.equals(expected)
