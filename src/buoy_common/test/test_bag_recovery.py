"""Damaged bags are read as far as they are readable, and say so.

The expected messages of a cut file are worked out independently of the reader under test: from
the chunk index of the whole file (which the recovery never sees), every chunk that lies wholly
before the cut, read with the ``mcap`` library.
"""

from __future__ import annotations

import shutil
from pathlib import Path

import pytest
from mcap.data_stream import ReadDataStream
from mcap.reader import make_reader
from mcap.records import Chunk, Message
from mcap.stream_reader import breakup_chunk
from sensor_msgs.msg import Imu

from buoy_common.bag_io import BagError, BagReader, BagWriter

REPO = Path(__file__).resolve().parents[3]
COMMITTED_BAG = REPO / "bags" / "static"
T0_NS = 1_700_000_000_000_000_000


def read_all(path: Path) -> tuple[BagReader, list[tuple[str, int, bytes]]]:
    with BagReader(path) as reader:
        messages = [(m.topic, m.log_time_ns, m.raw) for m in reader.messages()]
    return reader, messages


def chunks_of(mcap_file: Path) -> list[tuple[int, list[tuple[str, int, bytes]]]]:
    """(end byte, (topic, log time, bytes) of each of its messages) of every chunk of the
    file, found through its chunk index, in the order of their ends."""
    chunks = []
    with mcap_file.open("rb") as stream:
        summary = make_reader(stream).get_summary()
        for index in summary.chunk_indexes:
            stream.seek(index.chunk_start_offset + 1 + 8)  # past the opcode and the length
            chunk = Chunk.read(ReadDataStream(stream))
            messages = [
                (summary.channels[record.channel_id].topic, record.log_time, record.data)
                for record in breakup_chunk(chunk, validate_crc=True)
                if isinstance(record, Message)
            ]
            chunks.append((index.chunk_start_offset + index.chunk_length, messages))
    return sorted(chunks, key=lambda chunk: chunk[0])


def messages_of_chunks_before(chunks, cut: int) -> list[tuple[str, int, bytes]]:
    """(topic, log time, bytes) of every message in a chunk of ``chunks`` (:func:`chunks_of`
    the whole file) that ends at or before byte ``cut``."""
    return [message for end, messages in chunks if end <= cut for message in messages]


def cut_copy(bag: Path, target: Path, cut: int, keep_metadata: bool) -> Path:
    shutil.copytree(bag, target)
    (mcap_file,) = target.glob("*.mcap")
    with mcap_file.open("r+b") as stream:
        stream.truncate(cut)
    if not keep_metadata:
        (target / "metadata.yaml").unlink()
    return target


@pytest.fixture(scope="module")
def committed():
    """The committed bag's MCAP file, its chunks (:func:`chunks_of`: read once, not once a
    cut) and its messages as BagReader reads the whole bag."""
    (mcap_file,) = COMMITTED_BAG.glob("*.mcap")
    _, messages = read_all(COMMITTED_BAG)
    return mcap_file, chunks_of(mcap_file), messages


def committed_cuts():
    """(byte at which the MCAP file is cut, whether metadata.yaml stays): spread over the file,
    plus its ends (the header alone; into the summary)."""
    size = next(COMMITTED_BAG.glob("*.mcap")).stat().st_size
    cuts = [8 + 9, *(size * k // 5 for k in range(1, 5)), size - 100]
    return [(cut, index % 2 == 0) for index, cut in enumerate(cuts)]


@pytest.mark.parametrize(
    ("cut", "keep_metadata"), committed_cuts(), ids=[str(c) for c, _ in committed_cuts()]
)
def test_cut_committed_bag_yields_every_message_of_its_complete_chunks(
    committed, tmp_path, cut, keep_metadata
):
    _, chunks, whole = committed
    bag = cut_copy(COMMITTED_BAG, tmp_path / "cut", cut, keep_metadata)
    reader, recovered = read_all(bag)
    expected = messages_of_chunks_before(chunks, cut)
    assert sorted(recovered) == sorted(expected)
    times = [time_ns for _, time_ns, _ in recovered]
    assert times == sorted(times)
    # Log-time order with ties in file order: the whole bag's order, restricted.
    expected_set = set(expected)
    assert recovered == [m for m in whole if m in expected_set]
    recovery = reader.recovery
    assert recovery is not None and recovery.truncated
    assert recovery.messages == len(expected)
    assert recovery.listed_messages == (len(whole) if keep_metadata else None)
    assert sum(info.count for info in reader.topics.values()) == len(expected)
    text = recovery.describe(bag)
    assert str(bag) in text and f"recovered {len(expected)} messages" in text


def test_cut_exactly_at_a_chunk_end_keeps_that_chunk(committed, tmp_path):
    _, chunks, _ = committed
    chunk_ends = [end for end, _ in chunks]
    for number, cut in enumerate((chunk_ends[2], chunk_ends[2] - 1)):
        bag = cut_copy(COMMITTED_BAG, tmp_path / f"cut{number}", cut, keep_metadata=False)
        _, recovered = read_all(bag)
        assert sorted(recovered) == sorted(messages_of_chunks_before(chunks, cut))
    assert len(messages_of_chunks_before(chunks, chunk_ends[2])) > len(
        messages_of_chunks_before(chunks, chunk_ends[2] - 1)
    )


def test_half_a_committed_bag_is_recovered_up_to_its_last_complete_chunk(committed, tmp_path):
    mcap_file, _, whole = committed
    cut = mcap_file.stat().st_size // 2
    bag = cut_copy(COMMITTED_BAG, tmp_path / "half", cut, keep_metadata=True)
    reader, recovered = read_all(bag)
    assert 0.4 * len(whole) < len(recovered) < 0.6 * len(whole)
    assert reader.start_ns == whole[0][1]
    assert reader.end_ns == max(time_ns for _, time_ns, _ in recovered)
    with BagReader(bag) as again:
        imu = [again.decode(m) for m in again.messages(["imu/data_raw"])]
    assert 9.0 < imu[-1].linear_acceleration.z < 10.6


def test_bag_without_metadata_is_read_whole_from_its_mcap_file(tmp_path):
    bag = tmp_path / "no_metadata"
    shutil.copytree(COMMITTED_BAG, bag)
    (bag / "metadata.yaml").unlink()
    reader, messages = read_all(bag)
    original, whole = read_all(COMMITTED_BAG)
    assert messages == whole
    assert reader.topics == original.topics
    assert (reader.start_ns, reader.end_ns) == (original.start_ns, original.end_ns)
    assert reader.recovery is not None and not reader.recovery.truncated
    assert "no metadata.yaml" in reader.recovery.describe(bag)
    assert reader.recovery.messages == len(whole)


def test_flushed_messages_survive_any_cut(tmp_path):
    """What a recorder flushed is readable from a file cut anywhere after the flush."""
    bag = tmp_path / "recording"
    writer = BagWriter(bag, in_place=True)
    flushed_at = []  # (file size after the flush, messages written before it)
    written = 0
    for batch in range(12):
        for _ in range(40 + 25 * batch):
            message = Imu()
            message.header.frame_id = f"imu {written}"
            writer.write("/imu/data_raw", "sensor_msgs/msg/Imu", T0_NS + written * 10**7, message)
            written += 1
        if batch < 11:
            writer.flush()
            flushed_at.append((next(bag.glob("*.mcap")).stat().st_size, written))
    # What a process killed now leaves: no summary, no metadata.yaml, the last batch unwritten.
    data = next(bag.glob("*.mcap")).read_bytes()
    assert not (bag / "metadata.yaml").exists()
    writer.close()
    for cut in range(17, len(data) + 1, 997):
        copy = tmp_path / f"cut_{cut}"
        copy.mkdir()
        (copy / "recording.mcap").write_bytes(data[:cut])
        safe = max((n for size, n in flushed_at if size <= cut), default=0)
        _, recovered = read_all(copy)
        assert len(recovered) >= safe, cut
        assert [t for _, t, _ in recovered] == [T0_NS + k * 10**7 for k in range(len(recovered))]
        shutil.rmtree(copy)


def test_a_file_that_is_no_mcap_is_refused(tmp_path):
    bag = tmp_path / "bag"
    bag.mkdir()
    (bag / "bag.mcap").write_bytes(b"PK\x03\x04 a zip file, not a bag")
    with pytest.raises(BagError, match="not an MCAP file"):
        BagReader(bag)


def test_an_empty_unfinished_mcap_file_reads_as_an_empty_bag(tmp_path):
    bag = tmp_path / "bag"
    bag.mkdir()
    (bag / "bag.mcap").write_bytes(b"\x89MCAP0\r\n")
    reader, messages = read_all(bag)
    assert messages == [] and reader.topics == {}
    assert reader.recovery.truncated and reader.recovery.messages == 0
