"""A batch of bag messages decoded a topic at a time: the topics of fixed-layout types into
numpy columns (:mod:`buoy_common.cdr_bulk`), the others into message objects.

What an engine that works on arrays reads: :meth:`~buoy_common.bag_io.BagReader.message_batches`
hands over the messages of a chunk of the bag, :func:`batch_columns` decodes each topic's
messages of it together. The positions kept with each topic's messages merge the topics back
into the bag's log-time order.
"""

from __future__ import annotations

from collections import defaultdict
from typing import NamedTuple

import numpy as np

from buoy_common import cdr_bulk
from buoy_common.bag_io.common import BagMessage


class TopicColumns(NamedTuple):
    """One topic's messages of a batch."""

    msgtype: str
    positions: np.ndarray
    """Where each message is in the batch (int64, increasing)."""
    log_time_ns: np.ndarray
    """Log time of each message, int64 ns since the epoch."""
    columns: cdr_bulk.MessageColumns | None
    """The messages' fields when their type has a fixed layout (see ``columns.valid`` and
    ``columns.rejected`` for the messages that could not be decoded), else None."""
    objects: list | None
    """The messages as rosbags message objects (:meth:`BagReader.decode`) when their type has
    no fixed layout, else None."""


def batch_columns(reader, batch: list[BagMessage]) -> dict[str, TopicColumns]:
    """The messages of ``batch`` (from ``reader``'s
    :meth:`~buoy_common.bag_io.BagReader.message_batches`) decoded by topic."""
    positions_of: dict[str, list[int]] = defaultdict(list)
    for position, message in enumerate(batch):
        positions_of[message.topic].append(position)
    decoded = {}
    for topic, positions in positions_of.items():
        messages = [batch[position] for position in positions]
        msgtype = messages[0].msgtype
        log_time_ns = np.fromiter((m.log_time_ns for m in messages), np.int64, len(messages))
        if cdr_bulk.handles(msgtype):
            columns = cdr_bulk.decode(msgtype, [message.raw for message in messages])
            objects = None
        else:
            columns, objects = None, [reader.decode(message) for message in messages]
        decoded[topic] = TopicColumns(
            msgtype, np.asarray(positions, dtype=np.int64), log_time_ns, columns, objects
        )
    return decoded
