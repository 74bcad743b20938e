"""Reading and writing rosbag2 bags (metadata.yaml version 9, one MCAP file).

A bag is a directory holding ``metadata.yaml`` and one ``.mcap`` file with the ``ros2`` profile
and ``ros2msg`` schemas, as ``ros2 bag record`` writes and ``ros2 bag play`` reads. Messages are
kept as CDR bytes; log times are integer nanoseconds. Bags are read through rosbags
(:mod:`~buoy_common.bag_io.reading`, finished ones through their chunk index,
:mod:`~buoy_common.bag_io.indexed`, damaged ones through the ``mcap`` stream reader,
:mod:`~buoy_common.bag_io.recovery`) and written through the ``mcap`` writer
(:mod:`~buoy_common.bag_io.writing`), in a process of its own for the offline tools
(:mod:`~buoy_common.bag_io.background`), which also encodes the messages handed to it as
columns (:mod:`~buoy_common.bag_io.stretch`). A chunk of messages at a time can be decoded by
topic into numpy columns (:mod:`~buoy_common.bag_io.columns`). No module here imports rclpy:
bags are used offline as well as by the recorder and player nodes.

The names below are imported from their modules when first used (PEP 562), so that a process
that needs one module, such as the offline tools' writing process, imports only that one and
not rosbags' reader and type system.
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from buoy_common.bag_io.background import BackgroundBagWriter
    from buoy_common.bag_io.columns import TopicColumns, batch_columns
    from buoy_common.bag_io.common import (
        RECOVERED_BAG_EXIT_CODE,
        BagError,
        BagMessage,
        Recovery,
        TopicInfo,
        jazzy_typestore,
    )
    from buoy_common.bag_io.progress import BagProgress
    from buoy_common.bag_io.reading import BagReader
    from buoy_common.bag_io.writing import BagWriter

_MODULE_OF = {
    "RECOVERED_BAG_EXIT_CODE": "common",
    "BackgroundBagWriter": "background",
    "BagError": "common",
    "BagMessage": "common",
    "BagProgress": "progress",
    "BagReader": "reading",
    "BagWriter": "writing",
    "TopicColumns": "columns",
    "batch_columns": "columns",
    "Recovery": "common",
    "TopicInfo": "common",
    "jazzy_typestore": "common",
}

__all__ = [
    "RECOVERED_BAG_EXIT_CODE",
    "BackgroundBagWriter",
    "BagError",
    "BagMessage",
    "BagProgress",
    "BagReader",
    "BagWriter",
    "Recovery",
    "TopicColumns",
    "TopicInfo",
    "batch_columns",
    "jazzy_typestore",
]


def __getattr__(name: str):
    module = _MODULE_OF.get(name)
    if module is None:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    value = getattr(importlib.import_module(f"{__name__}.{module}"), name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted({*globals(), *__all__})
