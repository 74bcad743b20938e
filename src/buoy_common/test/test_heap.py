"""A long pass over records keeps the collector off the objects it starts with, and only while
it runs: a worker that runs pass after pass gets them collectable again, even when a pass
fails."""

import gc
import weakref

import pytest

from buoy_common.heap import existing_objects_frozen


class _Node:
    """An object that can sit in a reference cycle and be watched by a weak reference."""

    def __init__(self):
        self.partner = None


def _cycle() -> weakref.ref:
    """A reference cycle nothing else refers to: garbage only the collector can reclaim."""
    first, second = _Node(), _Node()
    first.partner, second.partner = second, first
    return weakref.ref(first)


def test_a_pass_leaves_what_it_started_with_alone_and_hands_it_back():
    before_the_pass = _cycle()
    with existing_objects_frozen():
        gc.collect()
        # Frozen at entry, the garbage of before the pass outlives a full collection.
        assert before_the_pass() is not None
        during_the_pass = _cycle()
        gc.collect()
        assert during_the_pass() is None
    gc.collect()
    assert before_the_pass() is None


def test_a_failed_pass_hands_back_what_it_started_with():
    before_the_pass = _cycle()
    with pytest.raises(RuntimeError), existing_objects_frozen():
        raise RuntimeError("the pass failed")
    gc.collect()
    assert before_the_pass() is None
