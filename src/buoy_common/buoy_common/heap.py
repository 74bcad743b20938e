"""Python's cyclic garbage collector kept off the objects a long pass over records starts with.

A pass over an hour of records allocates millions of short-lived objects; after every few
hundred the collector walks the young ones that survived, and now and then every tracked object
alive. Most of those were made before the pass (the modules, numpy's and numba's objects, the
compiled kernels' dispatchers, the engine: some 300 000 objects once an engine is built) and
live as long as the pass anyway. Frozen (``gc.freeze``), they are left out of every walk; a
simulated motion-pack hour through ``process_bag`` takes some 4 % less CPU
(``docs/benchmarks.md``). A live node's start-up builds as many (some 130 000 objects); a full
collection walking them takes some 27 ms, in the middle of whatever callback allocated last, so
a node freezes them once it is built.
"""

import contextlib
import gc
from collections.abc import Iterator


def freeze_existing_objects() -> None:
    """Leave every object alive now out of the collector's walks for the rest of the process:
    at a command's start, what its imports built; once a node is built, what its start-up
    built."""
    gc.freeze()


@contextlib.contextmanager
def existing_objects_frozen() -> Iterator[None]:
    """Leave every object alive at entry out of the collector's walks while the block runs, and
    hand them back to it after: a pass may run in a long-lived process (a worker of an archive's
    cluster), where cyclic garbage among them must still be collected one day."""
    gc.freeze()
    try:
        yield
    finally:
        gc.unfreeze()
