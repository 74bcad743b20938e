"""The ``nav/*`` and ``tf`` messages of an offline run, encoded a stretch of solutions at a time.

An offline run writes five messages a solution (``nav/odometry``, ``nav/imu``,
``nav/velocity``, ``nav/fix`` and ``tf``). Packed one by one from each solution's values
(:func:`buoy_nav.fusion_messages.solution_cdr`, what the live node publishes), they cost the
interpreter more than the filter's step that made the solution. The engine of an offline run
writes its solutions as rows instead (:mod:`buoy_nav.solution_rows`); here a stretch of rows
becomes the messages' columns and each type's messages are encoded together
(:func:`buoy_common.cdr_bulk.encode`): the same bytes, which a test holds equal to the
messages packed one by one.

Until a stretch is encoded, :class:`OrderedOutput` keeps a place in the output for each of its
solutions' messages and holds back whatever the run writes after the first of them, so the
bag holds every message in the order, and with the log time, it would have had written one by
one.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from buoy_common import cdr_bulk
from buoy_common.contract import (
    BODY_FRAME,
    MAP_FRAME,
    NAV_FIX_TOPIC,
    NAV_IMU_TOPIC,
    NAV_MSGTYPES,
    NAV_ODOMETRY_TOPIC,
    NAV_VELOCITY_TOPIC,
    TF_MSGTYPE,
    TF_TOPIC,
    bag_topic,
)
from buoy_common.namespaces import NamespacedWriter
from buoy_nav import solution_rows as row
from buoy_nav.aiding.gnss_fix import STATUS_FIX
from buoy_nav.fusion_messages import COVARIANCE_TYPE_KNOWN, SERVICE_GPS
from buoy_nav.nav_numbers import (
    ATTITUDE_COVARIANCE,
    BODY_TWIST_COVARIANCE,
    ENU_TWIST_COVARIANCE,
    GYRO_BIAS_COVARIANCE,
    POSE_COVARIANCE,
    POSITION_COVARIANCE,
    VELOCITY_BODY,
    body_numbers_of_solutions,
    covariance_numbers_of_solutions,
)
from buoy_processing.solution_columns import SolutionColumns

NAV_TOPIC_ORDER = (NAV_ODOMETRY_TOPIC, NAV_IMU_TOPIC, NAV_VELOCITY_TOPIC, NAV_FIX_TOPIC, TF_TOPIC)
"""The messages of one solution, in the order they are written."""
_STORED_IN_ORDER = tuple(
    (bag_topic(topic), {**NAV_MSGTYPES, TF_TOPIC: TF_MSGTYPE}[topic]) for topic in NAV_TOPIC_ORDER
)


def nav_messages(rows: np.ndarray, secs: np.ndarray, nanosecs: np.ndarray) -> list[list[bytes]]:
    """The CDR bytes of the five messages of each solution written as ``rows``
    (:mod:`buoy_nav.solution_rows`) with header stamps ``secs``, ``nanosecs``, by topic in
    :data:`NAV_TOPIC_ORDER`, each list a message per row."""
    count = rows.shape[0]
    attitude = np.ascontiguousarray(rows[:, row.ATTITUDE_XYZW])
    velocity_enu = np.ascontiguousarray(rows[:, row.VELOCITY_ENU])
    attitude_cov, velocity_cov, position_cov, gyro_bias_cov = (
        np.ascontiguousarray(rows[:, columns]).reshape(-1, 3, 3)
        for columns in (
            row.ATTITUDE_COVARIANCE,
            row.VELOCITY_COVARIANCE,
            row.POSITION_COVARIANCE,
            row.GYRO_BIAS_COVARIANCE,
        )
    )
    body = body_numbers_of_solutions(attitude, velocity_enu, velocity_cov, gyro_bias_cov)
    numbers = covariance_numbers_of_solutions(
        attitude_cov, velocity_cov, position_cov, gyro_bias_cov
    )

    def covariance(start: int, size: int) -> np.ndarray:
        return numbers[:, start : start + size]

    stamp = {"sec": secs, "nanosec": nanosecs}
    position_map = rows[:, row.POSITION_MAP]
    rate = rows[:, row.ANGULAR_RATE]
    geodetic = rows[:, row.GEODETIC]
    return [
        cdr_bulk.encode(
            NAV_MSGTYPES[NAV_ODOMETRY_TOPIC],
            {
                **stamp,
                "frame_id": MAP_FRAME,
                "child_frame_id": BODY_FRAME,
                "position": position_map,
                "orientation": attitude,
                "pose_covariance": covariance(POSE_COVARIANCE, 36),
                "linear": body[:, VELOCITY_BODY : VELOCITY_BODY + 3],
                "angular": rate,
                "twist_covariance": body[:, BODY_TWIST_COVARIANCE : BODY_TWIST_COVARIANCE + 36],
            },
        ),
        cdr_bulk.encode(
            NAV_MSGTYPES[NAV_IMU_TOPIC],
            {
                **stamp,
                "frame_id": BODY_FRAME,
                "orientation": attitude,
                "orientation_covariance": covariance(ATTITUDE_COVARIANCE, 9),
                "angular_velocity": rate,
                "angular_velocity_covariance": covariance(GYRO_BIAS_COVARIANCE, 9),
                "linear_acceleration": rows[:, row.SPECIFIC_FORCE],
                "linear_acceleration_covariance": np.zeros((count, 9)),
            },
        ),
        cdr_bulk.encode(
            NAV_MSGTYPES[NAV_VELOCITY_TOPIC],
            {
                **stamp,
                "frame_id": MAP_FRAME,
                "linear": velocity_enu,
                "angular": np.zeros((count, 3)),
                "covariance": covariance(ENU_TWIST_COVARIANCE, 36),
            },
        ),
        cdr_bulk.encode(
            NAV_MSGTYPES[NAV_FIX_TOPIC],
            {
                **stamp,
                "frame_id": BODY_FRAME,
                "status": np.full(count, STATUS_FIX),
                "service": np.full(count, SERVICE_GPS),
                "latitude": geodetic[:, 0],
                "longitude": geodetic[:, 1],
                "altitude": geodetic[:, 2],
                "position_covariance": covariance(POSITION_COVARIANCE, 9),
                "position_covariance_type": np.full(count, COVARIANCE_TYPE_KNOWN),
            },
        ),
        cdr_bulk.encode(
            TF_MSGTYPE,
            {
                **stamp,
                "frame_id": MAP_FRAME,
                "child_frame_id": BODY_FRAME,
                "translation": position_map,
                "rotation": attitude,
            },
        ),
    ]


class _Place(NamedTuple):
    """The place of one solution's messages: the solution's index among those given since the
    last rows were taken, and the messages' log time (ns)."""

    solution: int
    log_time_ns: int


class _Message(NamedTuple):
    """A message object's write, held back (a raw write is held as its record)."""

    topic: str
    msgtype: str
    log_time_ns: int
    message: object


class OrderedOutput:
    """The run's output (``writer``) with a place kept for each solution's messages until
    they are encoded (:meth:`take_rows`): a write after the first place waits behind it."""

    def __init__(self, writer: NamespacedWriter):
        self._writer = writer
        self._queue: list[_Place | _Message | tuple] = []
        """The places kept and the writes held: a message object's, or a raw one as its
        (topic, msgtype, log time ns, CDR bytes)."""
        self._solutions = 0
        """Solutions given since the last rows were taken, with a place or without."""
        self._places: list[int] = []

    @property
    def counts(self) -> dict[str, int]:
        """Messages written, per topic (what is held back not yet)."""
        return self._writer.counts

    def write_raw(self, topic: str, msgtype: str, log_time_ns: int, raw: bytes) -> None:
        if self._places:
            self._queue.append((topic, msgtype, log_time_ns, raw))
        else:
            self._writer.write_raw(topic, msgtype, log_time_ns, raw)

    def write(self, topic: str, msgtype: str, log_time_ns: int, message) -> None:
        """A message object (a product's, made afresh): written in its turn."""
        if self._places:
            self._queue.append(_Message(topic, msgtype, log_time_ns, message))
        else:
            self._writer.write(topic, msgtype, log_time_ns, message)

    def add_solution(self, log_time_ns: int, written: bool) -> None:
        """The next solution's place, its messages to be written with log time
        ``log_time_ns`` (ns), or, when not ``written`` (the navigation output's rate leaves
        it out), no place."""
        if written:
            self._queue.append(_Place(self._solutions, log_time_ns))
            self._places.append(self._solutions)
        self._solutions += 1

    def finish(self) -> None:
        """End of the run: every place must have been written (RuntimeError saying how many
        solutions' messages were not: their rows were never handed over)."""
        if self._places:
            raise RuntimeError(
                f"the nav/* and tf of {len(self._places)} solutions were never written: "
                "their rows were not handed over"
            )

    def take_columns(self, columns: SolutionColumns) -> None:
        """The solutions given since the last call, as columns
        (:class:`~buoy_processing.solution_columns.HeldBackSolutions` hands them over): their
        messages written in their places, and every write held back behind them."""
        self.take_rows(columns.rows, columns.secs, columns.nanosecs)

    def take_rows(self, rows: np.ndarray, secs: np.ndarray, nanosecs: np.ndarray) -> None:
        """:meth:`take_columns` of the rows of the oldest solutions given and their header
        stamps: those written in their places and the writes held between them; the places
        of solutions given since, and what waits behind them, kept."""
        count = rows.shape[0]
        if count > self._solutions:
            raise ValueError(f"{count} rows for {self._solutions} solutions given")
        due = self._due(count)
        places = np.array([item.solution for item in due if isinstance(item, _Place)], dtype=int)
        messages = []
        if len(places):
            encoded = nav_messages(rows[places], secs[places], nanosecs[places])
            messages = list(zip(*encoded, strict=True))
        # Raw messages go to the writer a stretch at a time; a message object in its turn.
        records = []
        written = 0
        for item in due:
            if isinstance(item, _Place):
                for (stored, msgtype), raw in zip(_STORED_IN_ORDER, messages[written], strict=True):
                    records.append((stored, msgtype, item.log_time_ns, raw))
                written += 1
            elif isinstance(item, _Message):
                self._writer.write_raw_many(records)
                records = []
                self._writer.write(*item)
            else:
                records.append(item)
        self._writer.write_raw_many(records)

    def _due(self, count: int) -> list:
        """What is written once the oldest ``count`` solutions' rows are taken: the queue up
        to the place of the first solution after them; the rest is kept, renumbered."""
        queue = self._queue
        cut = len(queue)
        for at, item in enumerate(queue):
            if isinstance(item, _Place) and item.solution >= count:
                cut = at
                break
        self._queue = [
            _Place(item.solution - count, item.log_time_ns) if isinstance(item, _Place) else item
            for item in queue[cut:]
        ]
        self._places = [solution - count for solution in self._places if solution >= count]
        self._solutions -= count
        return queue[:cut]
