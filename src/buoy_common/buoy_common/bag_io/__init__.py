"""Reading and writing rosbag2 bags (metadata.yaml version 9, one MCAP file).

A bag is a directory holding ``metadata.yaml`` and one ``.mcap`` file with the ``ros2`` profile
and ``ros2msg`` schemas, as ``ros2 bag record`` writes and ``ros2 bag play`` reads. Messages are
kept as CDR bytes; log times are integer nanoseconds. Bags are read through rosbags
(:mod:`~buoy_common.bag_io.reading`, damaged ones through the ``mcap`` stream reader,
:mod:`~buoy_common.bag_io.recovery`) and written through the ``mcap`` writer
(:mod:`~buoy_common.bag_io.writing`), in a process of its own for the offline tools
(:mod:`~buoy_common.bag_io.background`). No module here imports rclpy: bags are used offline as
well as by the recorder and player nodes.
"""

from buoy_common.bag_io.background import BackgroundBagWriter
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

__all__ = [
    "RECOVERED_BAG_EXIT_CODE",
    "BackgroundBagWriter",
    "BagError",
    "BagMessage",
    "BagProgress",
    "BagReader",
    "BagWriter",
    "Recovery",
    "TopicInfo",
    "jazzy_typestore",
]
