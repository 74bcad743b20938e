"""Reading a bag a batch at a time and decoding each batch by topic: the same messages in the
same order as one at a time, whichever way the bag is read, and each topic's columns those of
its messages."""

from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np
import pytest
from std_msgs.msg import String

from buoy_common import cdr_bulk
from buoy_common.bag_io import BagError, BagReader, BagWriter, batch_columns
from buoy_common.bag_io.indexed import IndexedMcap

BAGS = Path(__file__).resolve().parents[3] / "bags"
COMMITTED = sorted(path for path in BAGS.iterdir() if (path / "metadata.yaml").is_file())


def flattened(batches) -> list:
    return [message for batch in batches for message in batch]


@pytest.fixture(params=["chunk index", "rosbags"])
def reading(request, monkeypatch):
    """Each way BagReader reads a sound bag: through its chunk index, or through rosbags."""
    if request.param == "rosbags":
        monkeypatch.setattr(IndexedMcap, "open", classmethod(lambda cls, *args: None))
    return request.param


# Through rosbags (a few seconds a bag) one bag does: batching a message stream is the same
# code for every bag.
CASES = [
    *(pytest.param(bag, "chunk index", id=f"chunk index-{bag.name}") for bag in COMMITTED),
    pytest.param(BAGS / "static", "rosbags", id="rosbags-static"),
]


@pytest.mark.parametrize(("bag", "reading"), CASES, indirect=["reading"])
def test_batches_hold_the_messages_in_order(bag, reading):
    with BagReader(bag) as reader:
        assert (reader._indexed is not None) == (reading == "chunk index")
        one_at_a_time = list(reader.messages())
        batches = list(reader.message_batches())
        selected = list(reader.message_batches(["imu/data_raw", "/anemometer/wind"]))
        selected_one_at_a_time = list(reader.messages(["imu/data_raw", "/anemometer/wind"]))
    assert len(batches) > 1
    assert flattened(batches) == one_at_a_time
    assert flattened(selected) == selected_one_at_a_time


def test_batches_of_a_bag_cut_short_raise_bag_error(tmp_path, reading):
    target = tmp_path / "understated"
    shutil.copytree(BAGS / "static", target)
    metadata = target / "metadata.yaml"
    with BagReader(target) as reader:
        count = reader.topics["/gnss/fix"].count
    text = metadata.read_text().replace(
        f"message_count: {count}\n", f"message_count: {count + 1}\n"
    )
    metadata.write_text(text)
    with pytest.raises(BagError, match="counts differ"), BagReader(target) as reader:
        for _ in reader.message_batches():
            pass


def test_columns_of_each_topic_of_a_batch(tmp_path):
    """open_ocean's topics of fixed layouts, and a topic of another type decoded into objects."""
    bag = tmp_path / "with_text"
    with BagReader(BAGS / "open_ocean") as source, BagWriter(bag) as writer:
        for index, message in enumerate(source.messages()):
            writer.write_raw(message.topic, message.msgtype, message.log_time_ns, message.raw)
            if index % 50 == 0:
                writer.write(
                    "/notes", "std_msgs/msg/String", message.log_time_ns, String(data=str(index))
                )
    with BagReader(bag) as reader:
        for batch in reader.message_batches():
            decoded = batch_columns(reader, batch)
            positions = np.concatenate([topic.positions for topic in decoded.values()])
            assert sorted(positions.tolist()) == list(range(len(batch)))
            for topic, columns in decoded.items():
                messages = [batch[position] for position in columns.positions]
                assert {m.topic for m in messages} == {topic}
                assert columns.log_time_ns.tolist() == [m.log_time_ns for m in messages]
                if topic == "/notes":
                    assert columns.columns is None
                    assert [o.data for o in columns.objects] == [
                        reader.decode(m).data for m in messages
                    ]
                    continue
                assert columns.objects is None
                expected = cdr_bulk.decode(columns.msgtype, [m.raw for m in messages])
                assert columns.columns.valid.all()
                for name, values in expected.columns.items():
                    assert np.array_equal(columns.columns[name], values), name
