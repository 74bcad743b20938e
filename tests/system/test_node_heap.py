"""A running node keeps the garbage collector off what its start-up built.

A node's process holds some 130 000 objects once its engine or pipeline is built (modules,
numpy's and numba's objects, the compiled kernels); a full collection walks them all, about
27 ms on this machine, in the middle of whatever callback allocated last: five times the
latency budget of a sample. :func:`buoy_common.base_node.run_node` freezes them
(:mod:`buoy_common.heap`) once the node is built, before it spins.
"""

from __future__ import annotations

import subprocess
import sys

import pytest

pytestmark = pytest.mark.ros

NOT_FROZEN_EXIT_CODE = 3
PROBE = f"""
import gc
import sys

from buoy_common.base_node import SuiteNode, run_node
from buoy_nav.config import FusionConfig
from buoy_nav.engine import FusionEngine


class HeapProbe(SuiteNode):
    def __init__(self):
        super().__init__("heap_probe")
        self.engine = FusionEngine(FusionConfig())
        self.built_objects = len(gc.get_objects())
        self.create_timer(0.01, self.check)

    def check(self):
        frozen = gc.get_freeze_count()
        print(f"built {{self.built_objects}} frozen {{frozen}}", flush=True)
        self.finish(0 if frozen >= 0.9 * self.built_objects else {NOT_FROZEN_EXIT_CODE})


sys.exit(run_node(HeapProbe))
"""


def test_what_a_node_built_is_frozen_while_it_spins(ros_env):
    completed = subprocess.run(
        [sys.executable, "-c", PROBE], env=ros_env, capture_output=True, text=True, timeout=120
    )
    assert completed.returncode == 0, completed.stdout + completed.stderr
