"""The bag writers that leave the caller's thread free: the offline tools' writer in a process
of its own, and the recorder's writer in a thread of its own. Each writes the bag
:class:`BagWriter` writes."""

from __future__ import annotations

import shutil
import struct
import subprocess
import sys
import threading
import time

import numpy as np
import pytest
from mcap.reader import make_reader
from rclpy.serialization import serialize_message
from sensor_msgs.msg import Imu, NavSatFix

from buoy_common import cdr_bulk
from buoy_common.bag_io import BackgroundBagWriter, BagError, BagReader, BagWriter
from buoy_common.bag_io.recording import RecordingBagWriter
from buoy_common.bag_io.stretch import ColumnMessages, Stretch

T0_NS = 1_700_000_000_000_000_000
IMU_TYPE = "sensor_msgs/msg/Imu"
FIX_TYPE = "sensor_msgs/msg/NavSatFix"


@pytest.fixture(scope="module")
def written_bag(tmp_path_factory):
    """(path, messages per topic) of a bag of 300 IMU samples at 100 Hz and 30 fixes at 10 Hz, each
    with its own contents, written by :class:`BagWriter`."""
    path = tmp_path_factory.mktemp("bags") / "source"
    with BagWriter(path) as writer:
        for k in range(300):
            imu = Imu()
            imu.header.frame_id = f"imu {k}"
            imu.angular_velocity.x = 0.001 * k
            writer.write("/imu/data_raw", IMU_TYPE, T0_NS + k * 10_000_000, imu)
            if k % 10 == 0:
                fix = NavSatFix()
                fix.latitude = 35.0 + 1e-6 * k
                writer.write("/gnss/fix", FIX_TYPE, T0_NS + k * 10_000_000 + 1000, fix)
    return path, {"/imu/data_raw": 300, "/gnss/fix": 30}


# -- the writer in a process of its own --------------------------------------------------------


def test_background_writer_writes_the_same_bag(written_bag, tmp_path):
    path, counts = written_bag
    copy = tmp_path / "copy"
    with BagReader(path) as reader, BackgroundBagWriter(copy) as writer:
        for message in reader.messages():
            writer.write_raw(message.topic, message.msgtype, message.log_time_ns, message.raw)
    assert writer.counts == counts
    with BagReader(path) as original, BagReader(copy) as copied:
        assert list(original.messages()) == list(copied.messages())
        assert copied.topics == original.topics


@pytest.mark.parametrize("writer_class", [BagWriter, BackgroundBagWriter])
def test_a_stretch_makes_the_bag_written_one_by_one(written_bag, tmp_path, writer_class):
    """The IMU samples as columns, one a row, the fixes between them as records: split around
    a fix written alone (the rows before it with the first part), an empty stretch too, the
    writer encodes them into the bag written one by one."""
    path, counts = written_bag
    with BagReader(path) as reader:
        messages = list(reader.messages())
    imu = [message for message in messages if message.topic == "/imu/data_raw"]
    records, records_before = [], []
    for message in messages:
        if message.topic == "/imu/data_raw":
            records_before.append(len(records))
        else:
            records.append((message.topic, message.msgtype, message.log_time_ns, message.raw))
    columns = cdr_bulk.decode(IMU_TYPE, [message.raw for message in imu]).columns
    stretch = Stretch(
        (ColumnMessages("/imu/data_raw", IMU_TYPE, columns),),
        [message.log_time_ns for message in imu],
        records,
        records_before,
    )
    first, rest = stretch.split(12)
    copy = tmp_path / "stretches"
    with writer_class(copy) as writer:
        writer.write_stretch(first)
        writer.write_raw(*records[12])
        writer.write_stretch(Stretch((), [], [], []))
        writer.write_stretch(rest)
    assert writer.counts == counts
    assert messages_in_file_order(copy) == messages_in_file_order(path)
    with BagReader(path) as original, BagReader(copy) as copied:
        assert copied.topics == original.topics


def messages_in_file_order(path) -> list[tuple[str, int, bytes]]:
    """(topic, log time ns, CDR bytes) of each message of the bag at ``path``, in the order
    its file holds them (a reader in log-time order would hide a message out of place)."""
    with open(next(path.glob("*.mcap")), "rb") as stream:
        return [
            (channel.topic, message.log_time, bytes(message.data))
            for _, channel, message in make_reader(stream).iter_messages(log_time_order=False)
        ]


def test_background_writer_stores_metadata_records_as_the_bag_writer_does(tmp_path):
    facts = {"north": "true north", "sensors": '["IMU"]'}
    for writer_class in (BagWriter, BackgroundBagWriter):
        path = tmp_path / writer_class.__name__
        with writer_class(path) as writer:
            writer.write_raw("/imu/data_raw", IMU_TYPE, T0_NS, serialize_message(Imu()))
            writer.add_metadata("buoy_outputs", facts)
        with open(next(path.glob("*.mcap")), "rb") as stream:
            records = {m.name: dict(m.metadata) for m in make_reader(stream).iter_metadata()}
        assert records["buoy_outputs"] == facts, writer_class.__name__


def test_background_writer_reports_errors_of_the_writing_process(tmp_path):
    with (
        pytest.raises(BagError, match="holds sensor_msgs/msg/Imu"),
        BackgroundBagWriter(tmp_path / "types") as writer,
    ):
        writer.write("/imu/data_raw", "sensor_msgs/msg/Imu", T0_NS, Imu())
        writer.write_raw("/imu/data_raw", "sensor_msgs/msg/NavSatFix", T0_NS, b"\x00\x01")
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("writer_class", [BagWriter, BackgroundBagWriter])
def test_a_stretch_its_writer_cannot_encode_is_refused_and_the_bag_abandoned(
    tmp_path, writer_class
):
    """A stamp no header can hold (beyond 2038): the error names the field, raised where the
    stretch is encoded (the writing process's at the close), and no partial bag is left."""
    columns = cdr_bulk.decode(IMU_TYPE, [serialize_message(Imu())] * 2).columns
    columns["sec"] = np.array([1_700_000_000, 2**33])
    stretch = Stretch(
        (ColumnMessages("/imu/data_raw", IMU_TYPE, columns),), [T0_NS, T0_NS + 1], [], [0, 0]
    )
    with (
        pytest.raises((BagError, ValueError), match="sec"),
        writer_class(tmp_path / "bag") as writer,
    ):
        writer.write_stretch(stretch)
    assert list(tmp_path.iterdir()) == []


def test_background_writer_that_cannot_create_its_bag_says_so(tmp_path):
    # The writing process creates the bag while the tool goes on: its failure surfaces at the
    # next hand-over or, as here, when the bag is closed; no message is taken for written.
    (tmp_path / "a_file").write_text("not a directory")
    path = tmp_path / "a_file" / "bag"
    with (
        pytest.raises(BagError, match=f"bag {path}: cannot create"),
        BackgroundBagWriter(path) as writer,
    ):
        writer.write("/imu/data_raw", "sensor_msgs/msg/Imu", T0_NS, Imu())
    assert writer.closed


@pytest.mark.parametrize("messages", [0, 3, 5000])
def test_background_writer_keeps_what_it_is_given_while_its_process_starts(tmp_path, messages):
    path = tmp_path / "kept"
    with BackgroundBagWriter(path) as writer:
        for k in range(messages):
            writer.write("/imu/data_raw", "sensor_msgs/msg/Imu", T0_NS + k, Imu())
    with BagReader(path) as reader:
        assert [m.log_time_ns for m in reader.messages()] == [T0_NS + k for k in range(messages)]


def test_background_writer_whose_process_dies_says_how_it_ended(tmp_path):
    """Killed (or failing before it could report, as a script without a main guard makes a
    spawned process fail), the writing process leaves the tool an error with its exit code."""
    writer = BackgroundBagWriter(tmp_path / "killed")
    writer.write("/imu/data_raw", IMU_TYPE, T0_NS, Imu())
    writer._send_batch(wait_for_writer=True)
    writer._process.kill()
    with pytest.raises(BagError, match="ended unexpectedly \\(exit code -9;"):
        writer.close()


def test_background_writer_aborts_after_a_batch_cut_off_mid_send(tmp_path):
    """A signal can interrupt the tool while it sends a batch, leaving half of it in the pipe.
    Abandoning the bag then still ends the writing process promptly and leaves nothing."""
    path = tmp_path / "cut"
    writer = BackgroundBagWriter(path)
    writer.write_raw("/imu/data_raw", IMU_TYPE, T0_NS, serialize_message(Imu()))
    writer._send_batch(wait_for_writer=True)
    # What an interrupted send leaves: the length of a message and only the start of it.
    writer._connection._send(struct.pack("!i", 100_000) + b"\x80\x05")
    aborting = threading.Thread(target=writer.abort, daemon=True)
    aborting.start()
    aborting.join(timeout=30.0)
    assert not aborting.is_alive(), "abort waited for a writing process that waits for bytes"
    assert writer.closed
    assert list(tmp_path.iterdir()) == []


# -- a recorder's writer, fed from one thread and written by another ---------------------------


def test_recording_writer_writes_the_same_bag(written_bag, tmp_path):
    path, counts = written_bag
    copy = tmp_path / "copy"
    writer = RecordingBagWriter(copy, flush_period_s=0.01)
    with BagReader(path) as reader:
        for message in reader.messages():
            writer.write_raw(message.topic, message.msgtype, message.log_time_ns, message.raw)
    writer.close()
    assert writer.counts == counts and writer.backlog == 0
    with BagReader(path) as original, BagReader(copy) as copied:
        assert list(original.messages()) == list(copied.messages())
        assert copied.recovery is None


def test_recording_writer_flushes_while_it_records(tmp_path):
    """What was handed over is on the disk, readable as a killed recorder leaves it, before the
    bag is finished."""
    bag = tmp_path / "recording"
    writer = RecordingBagWriter(bag, flush_period_s=0.05)
    for k in range(50):
        writer.write_raw("/imu/data_raw", IMU_TYPE, T0_NS + k, serialize_message(Imu()))
    copy = tmp_path / "what_a_killed_recorder_leaves"
    deadline_s = time.monotonic() + 30.0
    recovered = []
    while len(recovered) < 50 and time.monotonic() < deadline_s:
        time.sleep(0.05)
        shutil.rmtree(copy, ignore_errors=True)
        shutil.copytree(bag, copy)
        with BagReader(copy) as reader:
            recovered = [m.log_time_ns for m in reader.messages()]
            assert reader.recovery is not None
    assert recovered == [T0_NS + k for k in range(50)]
    writer.close()


def test_recording_writer_reports_a_failure_at_close_with_what_it_lost(tmp_path):
    writer = RecordingBagWriter(tmp_path / "types", flush_period_s=1.0)
    raw = serialize_message(Imu())
    writer.write_raw("/imu/data_raw", IMU_TYPE, T0_NS, raw)
    writer.write_raw("/imu/data_raw", "sensor_msgs/msg/NavSatFix", T0_NS + 1, b"\x00\x01")
    writer.write_raw("/imu/data_raw", IMU_TYPE, T0_NS + 2, raw)
    with pytest.raises(BagError, match=r"holds sensor_msgs/msg/Imu.*; 2 messages were not written"):
        writer.close()
    assert writer.closed and writer.lost == 2
    with BagReader(tmp_path / "types") as reader:
        assert [m.log_time_ns for m in reader.messages()] == [T0_NS]
    with pytest.raises(BagError, match="is closed"):
        writer.write_raw("/imu/data_raw", IMU_TYPE, T0_NS + 3, raw)


def test_the_writing_process_starts_without_rosbags_or_numpy():
    """What a tool's writing process imports (the module of its entry point): not the reader,
    the type system or numpy, which would cost it a third of a second of CPU at every run."""
    loaded = subprocess.run(
        [
            sys.executable,
            "-c",
            "import sys, buoy_common.bag_io.background; print(' '.join(sorted(sys.modules)))",
        ],
        capture_output=True,
        text=True,
        check=True,
    ).stdout.split()
    heavy = [m for m in loaded if m.split(".")[0] in ("rosbags", "numpy", "scipy", "tqdm")]
    assert heavy == []
    assert "mcap.writer" in loaded


class EchoHost:
    """A host for the writing process: writes each batch it takes as IMU messages, and says at
    the end how many it wrote."""

    def __init__(self, topic: str):
        self.topic = topic
        self.written = 0

    def start(self, writer):
        self.writer = writer

    def take(self, content):
        for log_time_ns, raw in content:
            if raw is None:
                raise ValueError(f"no message at {log_time_ns} ns")
            self.writer.write_raw(self.topic, IMU_TYPE, log_time_ns, raw)
            self.written += 1

    def finish(self):
        return self.written


def test_a_host_in_the_writing_process_writes_in_its_turn(tmp_path):
    """What the host writes lies between the messages handed over before and after it, and
    what its finish returns comes back; the bag stays open for more."""
    raw = serialize_message(Imu())
    with BackgroundBagWriter(tmp_path / "hosted", preload=(__name__,)) as writer:
        writer.write_raw("/first", IMU_TYPE, T0_NS, raw)
        writer.host(EchoHost("/hosted"))
        writer.to_host([(T0_NS + 1, raw), (T0_NS + 2, raw)], 2)
        writer.write_raw("/between", IMU_TYPE, T0_NS + 3, raw)
        writer.to_host([(T0_NS + 4, raw)], 1)
        assert writer.finish_host() == 3
        assert writer.counts == {"/first": 1, "/hosted": 3, "/between": 1}
        writer.write_raw("/last", IMU_TYPE, T0_NS + 5, raw)
    topics = [topic for topic, _, _ in messages_in_file_order(tmp_path / "hosted")]
    assert topics == ["/first", "/hosted", "/hosted", "/between", "/hosted", "/last"]


def test_a_host_that_fails_abandons_the_bag_and_says_why(tmp_path):
    raw = serialize_message(Imu())
    with (
        pytest.raises(BagError, match="ValueError: no message at 7 ns"),
        BackgroundBagWriter(tmp_path / "hosted", preload=(__name__,)) as writer,
    ):
        writer.host(EchoHost("/hosted"))
        writer.to_host([(5, raw), (7, None)], 2)
        writer.finish_host()
    assert list(tmp_path.iterdir()) == []
