"""A bag written by a process of its own, so that packing, compressing and writing the file take
the second core instead of the offline tool's."""

from __future__ import annotations

import contextlib
import importlib
import importlib.util
import multiprocessing
import os
import queue
import shutil
import signal
import sys
import threading
import traceback
from collections import Counter
from multiprocessing.reduction import ForkingPickler
from operator import itemgetter
from pathlib import Path
from typing import TYPE_CHECKING

from buoy_common.bag_io.common import (
    BagError,
    TypeDescription,
    jazzy_typestore,
    one_line,
    type_description,
)
from buoy_common.bag_io.writing import BagOutput, BagWriter, check_bag_destination

if TYPE_CHECKING:
    # The writing process imports it (and numpy) with the first stretch it is given.
    from buoy_common.bag_io.stretch import Stretch

# Messages handed to the writing process at a time: large enough that sending costs a fraction
# of a microsecond per message, small enough to keep both processes busy.
_BATCH_MESSAGES = 2048
# Batches handed over and waiting for the pipe at most: the tool goes on while the writing
# process takes one (the pipe itself holds 64 KiB, a fraction of a batch).
_QUEUED_BATCHES = 16
# Longest wait for the writing process to exit once the bag is finished (s).
_WRITER_EXIT_TIMEOUT_S = 60.0


_TOPIC_OF = itemgetter(0)
_MSGTYPE_OF = itemgetter(1)
"""The topic and the message type of a record (topic, msgtype, log time ns, CDR bytes)."""

_CLOSE = "close"
"""The command that ends the writing process's batches: finish the bag."""
_FINISH_HOST = "finish host"
"""The command that has the writing process's host finish and report (the bag stays open)."""


class _HostStart:
    """The host the writing process runs from here on (:meth:`BackgroundBagWriter.host`)."""

    __slots__ = ("host",)

    def __init__(self, host):
        self.host = host


class _ForHost:
    """What the host takes next (:meth:`BackgroundBagWriter.to_host`)."""

    __slots__ = ("content",)

    def __init__(self, content):
        self.content = content


class BackgroundBagWriter(BagOutput):
    """A :class:`BagWriter` in a process of its own, for the offline tools.

    Same interface and bag as :class:`BagWriter`. Messages are handed over in batches through a
    pipe, a stretch (:meth:`write_stretch`) with its columns, which the writing process
    encodes; an error of the writing process (a full disk, a type conflict, a value a message
    cannot hold) is raised as BagError at the next hand-over or at :meth:`close`. Leaving the
    ``with`` block by an exception, or the death of the tool, deletes the partial bag, as
    :class:`BagWriter` does. What is at ``path`` is checked at construction; the tool does not
    wait for the writing process to start (about a second of imports) but keeps the first
    batches until it is ready. The writing process ignores SIGINT and SIGTERM: the tool decides
    whether the bag is finished or abandoned.

    The tool describes each message type (definition, hash) to the writing process with the
    first batch that holds it: the writing process imports neither rosbags nor numpy and starts
    in a third of the time (about 0.3 s of CPU less per run); it imports numpy with the first
    stretch it is given, while it has the rest of the second core to itself.

    A tool may also have the writing process run a part of its own work beside the bag, a host
    (:meth:`host`): what follows the fusion in ``process_bag``, which writes the bag's messages
    in their order (:mod:`buoy_processing.output_side`). The tool's batches then go through the
    pipe from a thread of its own, a few of them queued, so the tool goes on while the host
    works.
    """

    def __init__(self, path: str | Path, overwrite: bool = False, preload: tuple[str, ...] = ()):
        """``preload``: modules the writing process imports before it reports ready, those of
        a host it will be given (:meth:`host`): the tool keeps its first batches meanwhile
        rather than wait on the pipe."""
        self.path = Path(path)
        check_bag_destination(self.path, overwrite)
        self._counts: Counter[str] = Counter()
        # Records (topic, msgtype, log time ns, CDR bytes) and stretches, in order.
        self._batch: list[tuple[str, str, int, bytes] | Stretch] = []
        self._batch_messages = 0
        # Types described to the writing process, and those to describe with the next batch.
        self._described: set[str] = set()
        self._descriptions: dict[str, TypeDescription] = {}
        self._waiting_batches: list[tuple[dict, list]] = []
        self._metadata_records: list[tuple[str, dict[str, str]]] = []
        self._writer_ready = False
        # Spawned, not forked: the tools may run inside processes with middleware threads.
        context = multiprocessing.get_context("spawn")
        self._connection, child_end = context.Pipe()
        self._process = context.Process(
            target=_write_bag_from_pipe,
            args=(child_end, str(self.path), overwrite, preload),
            name=f"bag writer {self.path.name}",
            daemon=True,
        )
        with _this_module_as_main():
            self._process.start()
        child_end.close()
        self._sender = _PipeSender(self._connection)
        self._open = True

    @property
    def counts(self) -> dict[str, int]:
        """Messages handed over so far, per topic (once closed, what the bag holds)."""
        return dict(self._counts)

    @property
    def closed(self) -> bool:
        return not self._open

    def write_raw(self, topic: str, msgtype: str, log_time_ns: int, raw: bytes) -> None:
        """Append one CDR-serialised message with log time ``log_time_ns`` (ns since the epoch)."""
        if not self._open:
            raise BagError(f"bag {self.path} is closed")
        self._describe(topic, msgtype)
        self._batch.append((topic, msgtype, log_time_ns, raw))
        self._counts[topic] += 1
        self._batch_messages += 1
        if self._batch_messages >= _BATCH_MESSAGES:
            self._send_batch()

    def write_stretch(self, stretch: Stretch) -> None:
        """The messages of ``stretch`` (:mod:`~buoy_common.bag_io.stretch`), in order, handed
        over as they are: the writing process encodes its columns."""
        if not self._open:
            raise BagError(f"bag {self.path} is closed")
        for group in stretch.groups:
            self._describe(group.topic, group.msgtype)
            self._counts[group.topic] += stretch.rows
        records = stretch.records
        # Checked and counted by the C loops of set and map: a stretch holds thousands.
        if not self._described.issuperset(map(_MSGTYPE_OF, records)):
            for topic, msgtype, _, _ in records:
                self._describe(topic, msgtype)
        self._counts.update(map(_TOPIC_OF, records))
        self._batch.append(stretch)
        self._batch_messages += stretch.messages
        if self._batch_messages >= _BATCH_MESSAGES:
            self._send_batch()

    def _describe(self, topic: str, msgtype: str) -> None:
        """Describe ``msgtype`` (of ``topic``) with the next batch, unless it was already."""
        if msgtype not in self._described:
            self._descriptions[msgtype] = type_description(self.path, topic, msgtype)
            self._described.add(msgtype)

    def write(self, topic: str, msgtype: str, log_time_ns: int, message) -> None:
        """Serialise ``message`` (a rosbags or an rclpy message of ``msgtype``) and append it."""
        # Imported here, not with the module, which the writing process imports too.
        from buoy_common.bag_io.conversion import serialize

        raw = serialize(jazzy_typestore(), self.path, topic, msgtype, message)
        self.write_raw(topic, msgtype, log_time_ns, raw)

    def add_metadata(self, name: str, metadata: dict[str, str]) -> None:
        """An MCAP metadata record ``name`` (a map of strings), handed over with the close, as
        :meth:`BagWriter.add_metadata` writes it when the bag is finished."""
        if not self._open:
            raise BagError(f"bag {self.path} is closed")
        self._metadata_records.append((name, dict(metadata)))

    def host(self, host) -> None:
        """Have the writing process run ``host`` (picklable) beside the bag, after everything
        handed over so far: ``host.start(writer)`` with the process's :class:`BagWriter`, then
        ``host.take(content)`` for each :meth:`to_host`, in order with the messages, and
        ``host.finish()`` at :meth:`finish_host`. What the host writes goes into the bag in the
        order it writes it; its error is raised as BagError as the writing process's are."""
        self._append(_HostStart(host), 0)

    def to_host(self, content, messages: int) -> None:
        """Hand ``content`` to the host (:meth:`host`), which will write about ``messages``
        messages of it (the hand-over's batch size counts them)."""
        self._append(_ForHost(content), messages)

    def finish_host(self):
        """Everything handed over written, the host's ``finish()`` and what it returns; the
        bag stays open (:attr:`counts` then counts what the host wrote too)."""
        if not self._open:
            raise BagError(f"bag {self.path} is closed")
        self._send_batch(wait_for_writer=True)
        self._sender.send((_FINISH_HOST,))
        reply = self._receive()
        self._end_on_error(reply)
        _, result, counts = reply
        self._counts = Counter(counts)
        return result

    def _append(self, item, messages: int) -> None:
        if not self._open:
            raise BagError(f"bag {self.path} is closed")
        self._batch.append(item)
        self._batch_messages += messages
        if self._batch_messages >= _BATCH_MESSAGES:
            self._send_batch()

    def close(self) -> None:
        """Finish the bag, move it into place and wait for the writing process."""
        if not self._open:
            return
        self._send_batch(wait_for_writer=True)
        self._finish((_CLOSE, self._metadata_records))

    def abort(self) -> None:
        """Stop writing and delete the partial bag. Never raises: it runs while an error is
        already on its way.

        The writing process is told by the end of the pipe, not by a command: the error may be
        a signal that interrupted a send and left half a batch in the pipe, after which the
        writing process would wait for the rest of it and never read a command."""
        if not self._open:
            return
        self._open = False
        self._batch.clear()
        self._batch_messages = 0
        self._waiting_batches.clear()
        # The batch on its way is finished first: the writing process then reads the end of
        # the pipe after a whole batch, never half of one.
        self._sender.abandon()
        self._connection.close()
        self._process.join(timeout=_WRITER_EXIT_TIMEOUT_S)
        if self._process.is_alive():
            self._process.kill()
            self._process.join()
            with contextlib.suppress(OSError):
                shutil.rmtree(self.path.with_name(f"{self.path.name}.partial-{self._process.pid}"))

    def _send_batch(self, wait_for_writer: bool = False) -> None:
        """Hand the batch over, or keep it while the writing process is still starting (unless
        ``wait_for_writer``)."""
        if self._batch:
            self._waiting_batches.append((self._descriptions, self._batch))
            self._descriptions, self._batch, self._batch_messages = {}, [], 0
        if not self._writer_ready:
            if not (wait_for_writer or self._connection.poll()):
                return
            self._await_writer()
        for batch in self._waiting_batches:
            self._sender.send(batch)
        self._waiting_batches.clear()
        if self._sender.failed:
            self._open = False
            self._raise_if_failed(self._receive())
            raise BagError(f"bag {self.path}: the writing process stopped")

    def _finish(self, command: tuple) -> None:
        """Send ``command`` and raise what the writing process reports, if it failed."""
        self._open = False
        if not self._writer_ready:
            self._await_writer()
        try:
            self._sender.send(command)
            reply = self._receive()
        finally:
            self._process.join(timeout=_WRITER_EXIT_TIMEOUT_S)
            if self._process.is_alive():
                self._process.kill()
            self._sender.stop()
            self._connection.close()
        self._raise_if_failed(reply)

    def _await_writer(self) -> None:
        """Wait for the writing process to report that it has created the bag; raise its
        error if it could not."""
        self._end_on_error(self._receive())
        self._writer_ready = True

    def _end_on_error(self, reply) -> None:
        """When ``reply`` is the writing process's error: the process ended, the pipe closed,
        the error raised as BagError."""
        if reply[0] == "error":
            self._open = False
            self._process.join(timeout=_WRITER_EXIT_TIMEOUT_S)
            self._sender.stop()
            self._connection.close()
            raise BagError(reply[1])

    def _receive(self):
        try:
            return self._connection.recv()
        except (EOFError, ConnectionResetError):
            self._process.join(timeout=_WRITER_EXIT_TIMEOUT_S)
            return (
                "error",
                f"bag {self.path}: the writing process ended unexpectedly (exit code "
                f"{self._process.exitcode}; what it printed is on standard error)",
            )

    @staticmethod
    def _raise_if_failed(reply) -> None:
        if reply[0] == "error":
            raise BagError(reply[1])


class _PipeSender:
    """Sends what the tool hands over from a thread of its own: the tool pickles a batch and
    goes on while the writing process takes the one before (up to :data:`_QUEUED_BATCHES`
    wait). Once the pipe broke (the writing process stopped) it sends nothing more and says so
    (:attr:`failed`); the tool then reads why."""

    def __init__(self, connection):
        self._connection = connection
        self._queue: queue.Queue[bytes | None] = queue.Queue(maxsize=_QUEUED_BATCHES)
        self.failed = False
        self._thread = threading.Thread(target=self._run, name="bag batches", daemon=True)
        self._thread.start()

    def send(self, item) -> None:
        """Queue ``item`` for the pipe, pickled here; wait while the queue is full."""
        self._queue.put(ForkingPickler.dumps(item))

    def stop(self) -> None:
        """Send what is queued (or drop it, once failed) and end the thread."""
        self._queue.put(None)
        self._thread.join(timeout=_WRITER_EXIT_TIMEOUT_S)

    def abandon(self) -> None:
        """Drop what is queued, the batch being sent finished, and end the thread."""
        self.failed = True
        self.stop()

    def _run(self) -> None:
        while True:
            data = self._queue.get()
            if data is None:
                return
            if self.failed:
                continue
            try:
                self._connection.send_bytes(data)
            except OSError:
                self.failed = True


@contextlib.contextmanager
def _this_module_as_main():
    """Name this module as the main module while the writing process is spawned.

    A spawned process first runs the main module of the process that spawned it. The main module of
    an offline tool is its console script, which imports the whole tool (numpy, numba, rosbags, the
    fusion: about 1.5 s of CPU) that the writing process never uses. Named by this module's spec,
    the writing process runs this module instead, which it imports anyway.
    """
    main = sys.modules["__main__"]
    own_spec = getattr(main, "__spec__", None)
    main.__spec__ = importlib.util.find_spec(__name__)
    try:
        yield
    finally:
        main.__spec__ = own_spec


def _write_bag_from_pipe(connection, path: str, overwrite: bool, preload: tuple[str, ...]) -> None:
    """The writing process: a BagWriter fed batches of records until the close, which brings the
    bag's metadata records. If the tool closes the pipe instead (it abandons the bag, or dies),
    the partial bag is deleted."""
    # The tool decides: a signal to the whole process group (Ctrl-C, a service stop) reaches
    # the tool, which finishes or abandons the bag; the end of the pipe ends this process.
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.signal(signal.SIGTERM, signal.SIG_IGN)
    for module in preload:
        importlib.import_module(module)
    try:
        writer = BagWriter(path, overwrite=overwrite)
    except BagError as error:
        with contextlib.suppress(OSError):
            connection.send(("error", str(error)))
        return
    try:
        connection.send(("ok",))
        host = None
        while True:
            batch = connection.recv()
            if batch[0] == _CLOSE:
                for name, metadata in batch[1]:
                    writer.add_metadata(name, metadata)
                break
            if batch[0] == _FINISH_HOST:
                connection.send(("ok", host.finish(), writer.counts))
                continue
            descriptions, records = batch
            writer.describe(descriptions)
            host = _write_records(writer, records, host)
        writer.close()
    except (EOFError, BrokenPipeError, ConnectionResetError):
        # The tool abandoned the bag (or died).
        writer.abort()
        return
    except Exception as error:  # reported to the tool, which raises it as a BagError
        if not isinstance(error, BagError):
            # A host's failure is a program's: its whole story, for whoever reads the log.
            traceback.print_exc()
        writer.abort()
        with contextlib.suppress(OSError):
            connection.send(("error", f"bag {path}: {type(error).__name__}: {one_line(error)}"))
        return
    with contextlib.suppress(OSError):
        connection.send(("ok",))
    # The bag is in place and the tool told, which waits for this process to end: leave
    # without the interpreter's teardown of what a host imported (numba's, llvm's), 0.3 s.
    sys.stdout.flush()
    sys.stderr.flush()
    os._exit(0)


def _write_records(writer: BagWriter, records: list, host):
    """The batch's ``records`` into ``writer``, in order: a record, a stretch, a host to run
    or what it takes; the host running after them."""
    for record in records:
        kind = type(record)
        if kind is tuple:
            writer.write_raw(*record)
        elif kind is _ForHost:
            host.take(record.content)
        elif kind is _HostStart:
            host = record.host
            host.start(writer)
        else:
            writer.write_stretch(record)
    return host
