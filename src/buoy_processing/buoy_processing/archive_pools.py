"""Where the bags of an archive run: a local process pool, or the workers of a Dask scheduler.

Both pools take :class:`~buoy_processing.archive.BagJob` s and give back
:class:`~buoy_processing.archive.BagOutcome` s as the bags finish, and both turn a worker that died
under a bag (killed, out of memory) into a ``failed`` outcome of that bag.

- :class:`LocalPool`: ``concurrent.futures.ProcessPoolExecutor``, one bag per process at a
  time, processes started by ``spawn`` (a fork of a process with threads is unsafe). Ctrl-C
  reaches the workers as it reaches the tool (one process group): a bag in progress is
  abandoned, its partial outputs deleted.
- :class:`DaskPool`: ``distributed.Client(address)``, one task per bag. Dask cannot stop a task
  that is running: on Ctrl-C the bags not started are cancelled and those running finish on
  their workers, complete and marked, for the next run to skip.
"""

from __future__ import annotations

import concurrent.futures
import multiprocessing
import os
import signal
from collections.abc import Callable, Iterator

from buoy_processing.archive import ArchiveError, BagJob, BagOutcome, prepare_pool_worker

# How long to wait for a Dask scheduler to answer before giving up (s).
SCHEDULER_TIMEOUT_S = 30.0


def default_workers() -> int:
    """The cores this process may run on."""
    return len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count()


def _died(job: BagJob, error: BaseException) -> BagOutcome:
    return BagOutcome(job.relative, "failed", f"its worker died ({type(error).__name__}: {error})")


class LocalPool:
    """``workers`` processes on this machine."""

    def __init__(self, workers: int):
        if workers < 1:
            raise ArchiveError(f"--workers {workers}: at least one worker is needed")
        self.description = f"{workers} local worker{'s' if workers > 1 else ''}"
        self._executor = concurrent.futures.ProcessPoolExecutor(
            max_workers=workers,
            mp_context=multiprocessing.get_context("spawn"),
            initializer=prepare_pool_worker,
        )
        self._running: dict[concurrent.futures.Future, BagJob] = {}

    def __enter__(self) -> LocalPool:
        return self

    def __exit__(self, *exc_info) -> None:
        self._executor.shutdown(wait=True, cancel_futures=True)

    def run(self, work: Callable[[BagJob], BagOutcome], jobs: list[BagJob]) -> Iterator[BagOutcome]:
        # The workers start here, with Ctrl-C blocked until they are ready to take it.
        signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT})
        try:
            self._running = {self._executor.submit(work, job): job for job in jobs}
        finally:
            signal.pthread_sigmask(signal.SIG_UNBLOCK, {signal.SIGINT})
        for future in concurrent.futures.as_completed(list(self._running)):
            yield self._outcome(future)

    def _outcome(self, future: concurrent.futures.Future) -> BagOutcome:
        job = self._running.pop(future)
        try:
            return future.result()
        except concurrent.futures.process.BrokenProcessPool as error:
            return _died(job, error)

    def abandon(self) -> list[BagOutcome]:
        """After Ctrl-C: cancel the bags not started, wait for those in progress (which were
        interrupted too) and return their outcomes."""
        for future in self._running:
            future.cancel()
        self._executor.shutdown(wait=True, cancel_futures=True)
        return [self._outcome(future) for future in list(self._running) if not future.cancelled()]


class DaskPool:
    """The workers of the Dask distributed scheduler at ``address`` (``tcp://host:8786``)."""

    def __init__(self, address: str):
        import distributed

        self._distributed = distributed
        try:
            self._client = distributed.Client(address, timeout=SCHEDULER_TIMEOUT_S)
        except (OSError, TimeoutError) as error:
            raise ArchiveError(f"Dask scheduler {address}: {error}") from None
        workers = self._client.scheduler_info(n_workers=-1)["workers"]
        if not workers:
            self._client.close()
            raise ArchiveError(f"Dask scheduler {address} has no workers")
        threads = sum(worker["nthreads"] for worker in workers.values())
        self.description = f"Dask scheduler {address}: {len(workers)} workers, {threads} threads"
        self._running: dict = {}

    def __enter__(self) -> DaskPool:
        return self

    def __exit__(self, *exc_info) -> None:
        self._client.close()

    def run(self, work: Callable[[BagJob], BagOutcome], jobs: list[BagJob]) -> Iterator[BagOutcome]:
        # pure=False: the same bag submitted again (--redo, a new run) is new work.
        self._running = {self._client.submit(work, job, pure=False): job for job in jobs}
        for future in self._distributed.as_completed(list(self._running)):
            job = self._running.pop(future)
            try:
                yield future.result()
            except Exception as error:  # KilledWorker, a worker lost with its task
                yield _died(job, error)

    def abandon(self) -> list[BagOutcome]:
        """After Ctrl-C: cancel the bags not started; those running finish on their workers
        (they are reported as not done: the next run finds them marked and skips them)."""
        self._client.cancel(list(self._running))
        return []
