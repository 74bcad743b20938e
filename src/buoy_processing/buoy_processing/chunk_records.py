"""The sensor-rate messages of a chunk of the bag read together: their fields decoded into
columns at once (:mod:`buoy_common.cdr_bulk`), handed back one record per message.

The offline run reads the bag a chunk at a time
(:meth:`~buoy_common.bag_io.BagReader.message_batches`, the messages of
:meth:`~buoy_common.bag_io.BagReader.messages` in the same order) and feeds each message in that
order, as before: only the decoding is done a topic of the chunk at a time. A
record holds the fields its consumer reads (header stamp first), the values of the bytes the
per-message CDR readers (:mod:`buoy_common.cdr`) read. A message without a record is read
alone, as before, by the per-message path, which accepts or rejects it with its own reason:
those cdr_bulk cannot decode, and the big-endian ones the per-message readers leave to rosbags.
"""

from __future__ import annotations

from collections import defaultdict

import numpy as np

from buoy_common import cdr_bulk
from buoy_common.bag_io import BagMessage

_LITTLE_ENDIAN_HEADER = b"\x00\x01"


def chunk_records(
    batch: list[BagMessage], fields_of_topic: dict[str, tuple[str, ...]]
) -> dict[int, tuple]:
    """Position in ``batch`` → record ``(sec, nanosec, *fields)`` of each message of a topic of
    ``fields_of_topic`` (stored name → the cdr_bulk columns to read, each row as a list) that
    decodes in bulk; the other messages have none."""
    positions_of: dict[str, list[int]] = defaultdict(list)
    for position, message in enumerate(batch):
        if message.topic in fields_of_topic:
            positions_of[message.topic].append(position)
    records: dict[int, tuple] = {}
    for topic, positions in positions_of.items():
        records.update(_topic_records(batch, positions, fields_of_topic[topic]))
    return records


def _topic_records(
    batch: list[BagMessage], positions: list[int], field_names: tuple[str, ...]
) -> dict[int, tuple]:
    """The records of the messages of one topic at ``positions`` of ``batch``."""
    raws = [batch[position].raw for position in positions]
    decoded = cdr_bulk.decode(batch[positions[0]].msgtype, raws)
    little_endian = np.fromiter(
        (raw[:2] == _LITTLE_ENDIAN_HEADER for raw in raws), dtype=bool, count=len(raws)
    )
    usable = decoded.valid & little_endian
    columns = [decoded[name][usable].tolist() for name in ("sec", "nanosec", *field_names)]
    kept = np.asarray(positions)[usable].tolist()
    return dict(zip(kept, zip(*columns, strict=True), strict=True))
