"""A recorder's bag, written and flushed by a thread of its own.

A recorder stamps each message with the time it arrives. Compressing a full chunk and handing
the file to the disk (fsync) take milliseconds, on a busy disk a tenth of a second; done where
messages are received, they would hold the reception back and every message waiting meanwhile
would be stamped late. Here the receiving thread only queues the message; the writing thread
packs, compresses, writes and flushes (zstd and fsync release the GIL).
"""

from __future__ import annotations

import queue
import threading
import time
from collections import Counter
from pathlib import Path

from buoy_common.bag_io.common import BagError, one_line
from buoy_common.bag_io.writing import BagWriter

# Queued item that tells the writing thread to finish the bag.
_FINISH = None


class RecordingBagWriter:
    """An ``in_place`` :class:`BagWriter` fed through a queue and flushed every
    ``flush_period_s`` seconds of wall time by a thread of its own.

    :meth:`write_raw` never blocks and never raises for a failure of the writing thread; the
    failure is kept in :attr:`failure` (the messages queued after it are counted in
    :attr:`lost`) and raised as BagError by :meth:`close`. A failed flush is kept in
    :attr:`flush_failure` and writing goes on.
    """

    def __init__(self, path: str | Path, flush_period_s: float):
        self._writer = BagWriter(path, in_place=True)
        self.path = self._writer.path
        self._flush_period_s = flush_period_s
        self._queue: queue.SimpleQueue = queue.SimpleQueue()
        self._queued: Counter[str] = Counter()
        self._closed = False
        self.failure: BagError | None = None
        self.flush_failure: str | None = None
        self.lost = 0
        self._thread = threading.Thread(
            target=self._write_from_queue, name=f"bag writer {self.path.name}", daemon=True
        )
        self._thread.start()

    @property
    def closed(self) -> bool:
        return self._closed

    @property
    def counts(self) -> dict[str, int]:
        """Messages handed over so far, per topic (written, or waiting to be)."""
        return dict(self._queued)

    @property
    def backlog(self) -> int:
        """Messages handed over and not yet written."""
        return self._queue.qsize()

    def write_raw(self, topic: str, msgtype: str, log_time_ns: int, raw: bytes) -> None:
        """Queue one CDR-serialised message with log time ``log_time_ns`` (ns since the epoch)."""
        if self._closed:
            raise BagError(f"bag {self.path} is closed")
        self._queued[topic] += 1
        self._queue.put((topic, msgtype, log_time_ns, raw))

    def close(self) -> None:
        """Write what is queued, finish the bag and wait for the writing thread. Idempotent.
        Raises BagError if writing failed."""
        if not self._closed:
            self._closed = True
            self._queue.put(_FINISH)
            self._thread.join()
        if self.failure is not None:
            raise self.failure

    def _write_from_queue(self) -> None:
        # The bag is finished whatever happens here, so that what was written stays readable.
        try:
            next_flush_s = time.monotonic() + self._flush_period_s
            while True:
                try:
                    item = self._queue.get(timeout=max(next_flush_s - time.monotonic(), 0.0))
                except queue.Empty:
                    item = ()
                if item is _FINISH:
                    break
                if item:
                    self._write(*item)
                if time.monotonic() >= next_flush_s:
                    self._flush()
                    next_flush_s = time.monotonic() + self._flush_period_s
        finally:
            self._finish()

    def _write(self, topic: str, msgtype: str, log_time_ns: int, raw: bytes) -> None:
        if self.failure is not None:
            self.lost += 1
            return
        try:
            self._writer.write_raw(topic, msgtype, log_time_ns, raw)
        # Any failure: the thread must go on taking (and counting) what the recorder hands over.
        except Exception as error:
            self.failure = BagError(f"bag {self.path}: writing stopped: {one_line(error)}")
            self.lost += 1

    def _flush(self) -> None:
        if self.failure is not None:
            return
        try:
            self._writer.flush()
            self.flush_failure = None
        except Exception as error:
            self.flush_failure = one_line(error)

    def _finish(self) -> None:
        try:
            self._writer.close()
        except Exception as error:
            if self.failure is None:
                self.failure = (
                    error
                    if isinstance(error, BagError)
                    else BagError(f"bag {self.path}: failed to finish: {one_line(error)}")
                )
        if self.lost and self.failure is not None:
            self.failure = BagError(f"{self.failure}; {self.lost} messages were not written")
