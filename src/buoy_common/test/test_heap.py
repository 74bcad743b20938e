"""The collector's settings for a long pass over records are the pass's alone: a worker that
runs pass after pass gets its collector back as it was, even when a pass fails."""

import gc
import weakref

import pytest

from buoy_common.heap import PASS_COLLECTION_ALLOCATIONS, existing_objects_frozen


class _Node:
    """An object that can sit in a reference cycle and be watched by a weak reference."""

    def __init__(self):
        self.partner = None


def _cycle() -> weakref.ref:
    """A reference cycle nothing else refers to: garbage only the collector can reclaim."""
    first, second = _Node(), _Node()
    first.partner, second.partner = second, first
    return weakref.ref(first)


def test_a_pass_collects_rarely_and_hands_the_collector_back():
    thresholds = gc.get_threshold()
    frozen = gc.get_freeze_count()
    before_the_pass = _cycle()
    with existing_objects_frozen():
        assert gc.get_threshold() == (PASS_COLLECTION_ALLOCATIONS, *thresholds[1:])
        assert gc.get_freeze_count() > frozen
        gc.collect()
        # Frozen at entry, the garbage of before the pass outlives a full collection.
        assert before_the_pass() is not None
    assert gc.get_threshold() == thresholds
    gc.collect()
    assert before_the_pass() is None


def test_a_failed_pass_hands_the_collector_back():
    thresholds = gc.get_threshold()
    before_the_pass = _cycle()
    with pytest.raises(RuntimeError), existing_objects_frozen():
        raise RuntimeError("the pass failed")
    assert gc.get_threshold() == thresholds
    gc.collect()
    assert before_the_pass() is None
