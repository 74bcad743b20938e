"""Append-only tables of fixed-size records kept in a file, so long recordings need no memory.

The smoother stores what its backward pass needs (one record per covariance epoch, one per
navigation solution) while the forward filter runs; a day of 100 Hz data is gigabytes, which
belong on disk, not in memory. Records are buffered in blocks and written with one call per
block; a slice is read back with one positioned read (not a memory map, whose pages would count
as the process's memory until the kernel drops them: the resident memory stays at one block).
"""

from __future__ import annotations

import tempfile
from pathlib import Path

import numpy as np

BLOCK_RECORDS = 4096
"""Records buffered in memory before a write."""


class SpillTable:
    """Records of ``dtype`` appended to ``path`` (created, truncated), read back by slices."""

    def __init__(self, path: Path, dtype: np.dtype):
        self.path = Path(path)
        self.dtype = np.dtype(dtype)
        self._stream = open(self.path, "wb")  # noqa: SIM115 (closed by finish_writing)
        self._block = np.zeros(BLOCK_RECORDS, dtype=self.dtype)
        self._filled = 0
        self._written = 0

    def __len__(self) -> int:
        return self._written + self._filled

    def next_record(self) -> np.void:
        """The next record to fill in place (a view of the write buffer)."""
        if self._filled == BLOCK_RECORDS:
            self._flush()
        record = self._block[self._filled]
        self._filled += 1
        return record

    def append_rows(self, rows: np.ndarray) -> None:
        """Append whole records (an array of :attr:`dtype`)."""
        self._flush()
        rows.astype(self.dtype, copy=False).tofile(self._stream)
        self._written += len(rows)

    def _flush(self) -> None:
        if self._filled:
            self._block[: self._filled].tofile(self._stream)
            self._written += self._filled
            self._filled = 0

    def finish_writing(self) -> None:
        """Write what is buffered and close the file for writing (reading may begin)."""
        if self._stream.closed:
            return
        self._flush()
        self._stream.close()

    def rows(self, start: int, stop: int) -> np.ndarray:
        """Records ``start`` to ``stop`` (read into memory)."""
        self.finish_writing()
        return read_rows(self.path, self.dtype, start, min(stop, self._written))

    def close(self) -> None:
        self.finish_writing()


def read_rows(path: Path, dtype: np.dtype, start: int, stop: int) -> np.ndarray:
    """Records ``start`` to ``stop`` of a file of ``dtype`` records."""
    count = max(0, stop - start)
    if count == 0:
        return np.zeros(0, dtype=dtype)
    return np.fromfile(path, dtype=dtype, count=count, offset=start * dtype.itemsize)


class SpillDirectory:
    """A temporary directory for spill tables (``parent``: where to make it; None: the system's
    temporary directory). Removed by :meth:`cleanup` or on leaving the ``with`` block."""

    def __init__(self, parent: str | Path | None = None):
        self._directory = tempfile.TemporaryDirectory(prefix="buoy_smoother_", dir=parent)
        self.path = Path(self._directory.name)

    def table(self, name: str, dtype: np.dtype) -> SpillTable:
        return SpillTable(self.path / f"{name}.bin", dtype)

    def cleanup(self) -> None:
        self._directory.cleanup()

    def __enter__(self) -> SpillDirectory:
        return self

    def __exit__(self, *exc) -> None:
        self.cleanup()
