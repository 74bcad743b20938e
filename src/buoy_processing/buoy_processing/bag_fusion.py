"""The fusion alone over a recorded bag: ``nav/*`` and ``tf`` (and the truth topics, copied)
written to another. ``fuse_bag`` is the command line of :func:`fuse_bag`; the run itself is
:func:`buoy_processing.offline_runner.run_fusion`, as for ``process_bag``.
"""

from __future__ import annotations

import time
from typing import NamedTuple

from buoy_common.bag_io import BagReader, Recovery
from buoy_common.namespaces import TopicView
from buoy_common.safe_output import check_outputs_apart_from_inputs
from buoy_common.sensor_frames import sensor_transforms, shared_values
from buoy_nav.config import FusionConfig
from buoy_processing.offline_fusion import OfflineFusion, sensor_topics_of, truth_topics_of
from buoy_processing.offline_runner import OfflineRun, run_fusion


class FusedBag(NamedTuple):
    """What :func:`fuse_bag` did."""

    fusion: OfflineFusion
    """The fusion that ran (its :meth:`OfflineFusion.summary` reports it)."""
    topic_counts: dict[str, int]
    """Messages written, per topic."""
    wall_s: float
    """Wall-clock time of the run, s."""
    duration_s: float
    """Span of the input bag's log times, s."""
    recovery: Recovery | None
    """What was wrong with the input bag and how much of it was read; None for a sound bag."""


def fuse_bag(
    in_bag,
    out_bag,
    config: FusionConfig,
    overwrite: bool = False,
    view: TopicView | None = None,
    smooth: bool = False,
    nav_rate_hz: float = 0.0,
) -> FusedBag:
    """Run the fusion over ``in_bag`` into ``out_bag`` (a new bag; replaced with ``overwrite``),
    over the topics of ``view``'s namespace (the root when None), writing into the same namespace;
    with ``smooth`` the fixed-interval smoother's solution (:mod:`buoy_processing.offline_runner`);
    with ``nav_rate_hz`` (Hz) above 0 the solutions at that rate only
    (:mod:`buoy_processing.nav_output_rate`). Raises BagError for a missing or unreadable bag or one
    without the fusion's required topics, and OutputError, before anything is read or written, if
    ``out_bag`` is, contains or lies inside ``in_bag``."""
    started = time.monotonic()
    check_outputs_apart_from_inputs([in_bag], [out_bag])
    view = view or TopicView()
    with BagReader(in_bag, view) as reader:
        run = OfflineRun(
            reader,
            out_bag,
            config,
            sensor_topics_of(reader, config),
            f"fuse_bag {in_bag}",
            view,
            copied_topics=truth_topics_of(reader),
            smooth=smooth,
            overwrite=overwrite,
            nav_rate_hz=nav_rate_hz,
            static_transforms=sensor_transforms(shared_values(config), imu_link=True),
        )
        fusion, counts, _, _ = run_fusion(run)
    return FusedBag(fusion, counts, time.monotonic() - started, reader.duration_s, reader.recovery)
