"""The ``mcap`` library's writer with a leaner path for messages.

The offline tools write several messages per IMU sample (``nav/*``, ``tf``, the copied inputs),
and ``mcap.writer.Writer.add_message`` spends about 7 µs on each: a ``Message`` record object,
six small writes into the chunk buffer and a seek back to patch the record length. That made
the writing process a tenth of ``process_bag``'s CPU time. :class:`McapWriter` packs the record
in one ``struct`` call instead (about 2 µs) and keeps everything else (chunks and their
compression, CRCs, message indexes, statistics, summary) to the library: the file is the same,
byte for byte, as the library writes it (``test_bag_io`` holds the two equal).

It updates the writer's statistics and chunk builder as ``add_message`` does, so it depends on
the internals of the pinned ``mcap`` version; the test above fails if they change. When a chunk
is closed, each channel's message index is written with its entries packed in one ``struct``
call too: the library writes two records a message there, a quarter of the writing process's
time (the same bytes; the same test).
"""

from __future__ import annotations

import itertools
import struct

from mcap.data_stream import RecordBuilder
from mcap.opcode import Opcode
from mcap.records import MessageIndex
from mcap.writer import Writer

# A message record: opcode, record length, then channel id, sequence, log time and publish time
# ahead of the data (MCAP specification, "Message").
_MESSAGE_RECORD = struct.Struct("<BQHIQQ")
_MESSAGE_FIELDS_SIZE = _MESSAGE_RECORD.size - 9
_OPCODE_MESSAGE = int(Opcode.MESSAGE)


class _PackedMessageIndex(MessageIndex):
    """A chunk's index of one channel's messages (log time, offset in the chunk), written as
    the library writes it, its entries packed in one call."""

    def write(self, stream: RecordBuilder) -> None:
        stream.start_record(Opcode.MESSAGE_INDEX)
        stream.write2(self.channel_id)
        stream.write4(len(self.records) * 16)
        stream.write(
            struct.pack(f"<{2 * len(self.records)}Q", *itertools.chain.from_iterable(self.records))
        )
        stream.finish_record()


class McapWriter(Writer):
    """``mcap.writer.Writer`` for chunked files (``use_chunking``, the default), whose
    :meth:`add_message` writes the records the library writes at a third of the cost."""

    def add_message(
        self, channel_id: int, log_time: int, data: bytes, publish_time: int, sequence: int = 0
    ) -> None:
        """As ``Writer.add_message``: one message of ``channel_id`` with ``log_time`` and
        ``publish_time`` (ns), into the chunk being built."""
        statistics = self._Writer__statistics
        if statistics.message_count == 0 or log_time < statistics.message_start_time:
            statistics.message_start_time = log_time
        if log_time > statistics.message_end_time:
            statistics.message_end_time = log_time
        statistics.channel_message_counts[channel_id] += 1
        statistics.message_count += 1

        chunk = self._Writer__chunk_builder
        if chunk.num_messages == 0 or log_time < chunk.message_start_time:
            chunk.message_start_time = log_time
        if log_time > chunk.message_end_time:
            chunk.message_end_time = log_time
        buffer = chunk.record_writer._buffer
        offset = buffer.tell()
        index = chunk.message_indices.get(channel_id)
        if index is None:
            index = chunk.message_indices[channel_id] = _PackedMessageIndex(channel_id, [])
        index.records.append((log_time, offset))
        chunk.num_messages += 1
        buffer.write(
            _MESSAGE_RECORD.pack(
                _OPCODE_MESSAGE,
                _MESSAGE_FIELDS_SIZE + len(data),
                channel_id,
                sequence,
                log_time,
                publish_time,
            )
        )
        buffer.write(data)
        if buffer.tell() > self._Writer__chunk_size:
            self._Writer__finalize_chunk()
