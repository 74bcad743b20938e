"""The ``nav/*`` and ``tf`` messages of an offline run, encoded a stretch of solutions at a time.

An offline run writes five messages a solution (``nav/odometry``, ``nav/imu``,
``nav/velocity``, ``nav/fix`` and ``tf``). Packed one by one from each solution's values
(:func:`buoy_nav.fusion_messages.solution_cdr`, what the live node publishes), they cost the
interpreter more than the filter's step that made the solution. The engine of an offline run
writes its solutions as rows instead (:mod:`buoy_nav.solution_rows`); here a stretch of rows
becomes the messages' columns, which the bag's writer encodes, each type's messages together
(:func:`buoy_common.cdr_bulk.encode`; the offline tools' writing process does it on the second
core: :mod:`buoy_common.bag_io.stretch`): the same bytes, which a test holds equal to the
messages packed one by one.

Until a stretch is handed over, :class:`OrderedOutput` keeps a place in the output for each of
its solutions' messages and holds back whatever the run writes after the first of them, so the
bag holds every message in the order, and with the log time, it would have had written one by
one.
"""

from __future__ import annotations

import bisect
from typing import NamedTuple

import numpy as np

from buoy_common.bag_io.stretch import ColumnMessages, Stretch
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


def nav_columns(
    rows: np.ndarray,
    secs: np.ndarray,
    nanosecs: np.ndarray,
    body_numbers: np.ndarray | None = None,
) -> list[dict[str, object]]:
    """The columns (:func:`buoy_common.cdr_bulk.encode`'s) of the five messages of each
    solution written as ``rows`` (:mod:`buoy_nav.solution_rows`) with header stamps ``secs``,
    ``nanosecs``, by topic in :data:`NAV_TOPIC_ORDER`, a message per row; ``body_numbers``:
    the rows' :func:`~buoy_nav.nav_numbers.body_numbers` when the hand-over made them already
    (None: made here)."""
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
    body = (
        body_numbers_of_solutions(attitude, velocity_enu, velocity_cov, gyro_bias_cov)
        if body_numbers is None
        else body_numbers
    )
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
        {
            **stamp,
            "frame_id": MAP_FRAME,
            "linear": velocity_enu,
            "angular": np.zeros((count, 3)),
            "covariance": covariance(ENU_TWIST_COVARIANCE, 36),
        },
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
        {
            **stamp,
            "frame_id": MAP_FRAME,
            "child_frame_id": BODY_FRAME,
            "translation": position_map,
            "rotation": attitude,
        },
    ]


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
        self._nav_topics = tuple(
            (writer.output_name(stored), msgtype) for stored, msgtype in _STORED_IN_ORDER
        )
        self._held: list[tuple] = []
        """The writes held behind the places, in order: a raw write as its record (output
        topic, msgtype, log time ns, CDR bytes), a message object's as a :class:`_Message`."""
        self._objects_held: list[int] = []
        """Where the message objects are in :attr:`_held`."""
        # Each place kept: its solution's index among those given since the last rows were
        # taken, its messages' log time (ns), and how many writes were held before it.
        self._place_solutions: list[int] = []
        self._place_log_times_ns: list[int] = []
        self._place_held_before: list[int] = []
        self._solutions = 0
        """Solutions given since the last rows were taken, with a place or without."""

    @property
    def counts(self) -> dict[str, int]:
        """Messages written, per topic (what is held back not yet)."""
        return self._writer.counts

    def write_raw(self, topic: str, msgtype: str, log_time_ns: int, raw: bytes) -> None:
        if self._place_solutions:
            self._held.append((self._writer.output_name(topic), msgtype, log_time_ns, raw))
        else:
            self._writer.write_raw(topic, msgtype, log_time_ns, raw)

    def write(self, topic: str, msgtype: str, log_time_ns: int, message) -> None:
        """A message object (a product's, made afresh): written in its turn."""
        if self._place_solutions:
            self._objects_held.append(len(self._held))
            self._held.append(_Message(topic, msgtype, log_time_ns, message))
        else:
            self._writer.write(topic, msgtype, log_time_ns, message)

    def add_solution(self, log_time_ns: int, written: bool) -> None:
        """The next solution's place, its messages to be written with log time
        ``log_time_ns`` (ns), or, when not ``written`` (the navigation output's rate leaves
        it out), no place."""
        if written:
            self._place_solutions.append(self._solutions)
            self._place_log_times_ns.append(log_time_ns)
            self._place_held_before.append(len(self._held))
        self._solutions += 1

    def finish(self) -> None:
        """End of the run: every place must have been written (RuntimeError saying how many
        solutions' messages were not: their rows were never handed over)."""
        if self._place_solutions:
            raise RuntimeError(
                f"the nav/* and tf of {len(self._place_solutions)} solutions were never "
                "written: their rows were not handed over"
            )

    def take_columns(self, columns: SolutionColumns) -> None:
        """The solutions given since the last call, as columns
        (:class:`~buoy_processing.solution_columns.HeldBackSolutions` hands them over): their
        messages written in their places, and every write held back behind them."""
        self.take_rows(columns.rows, columns.secs, columns.nanosecs, columns.body_numbers)

    def take_rows(
        self,
        rows: np.ndarray,
        secs: np.ndarray,
        nanosecs: np.ndarray,
        body_numbers: np.ndarray | None = None,
    ) -> None:
        """:meth:`take_columns` of the rows of the oldest solutions given and their header
        stamps (and their body-frame numbers, None: made here): those written in their places
        and the writes held between them; the places of solutions given since, and what waits
        behind them, kept."""
        count = rows.shape[0]
        if count > self._solutions:
            raise ValueError(f"{count} rows for {self._solutions} solutions given")
        places = bisect.bisect_left(self._place_solutions, count)
        held_due = (
            self._place_held_before[places]
            if places < len(self._place_solutions)
            else len(self._held)
        )
        solutions = np.asarray(self._place_solutions[:places], dtype=int)
        columns = nav_columns(
            rows[solutions],
            secs[solutions],
            nanosecs[solutions],
            None if body_numbers is None else body_numbers[solutions],
        )
        stretch = Stretch(
            tuple(
                ColumnMessages(topic, msgtype, topic_columns)
                for (topic, msgtype), topic_columns in zip(self._nav_topics, columns, strict=True)
            ),
            self._place_log_times_ns[:places],
            self._held[:held_due],
            self._place_held_before[:places],
        )
        self._write_in_order(stretch, [at for at in self._objects_held if at < held_due])
        self._keep_after(count, places, held_due)

    def _write_in_order(self, stretch: Stretch, objects_at: list[int]) -> None:
        """``stretch`` to the writer, split at the message objects among its records (at
        ``objects_at``), each written in its turn."""
        written = 0
        for at in objects_at:
            before, stretch = stretch.split(at - written)
            self._writer.write_named_stretch(before)
            self._writer.write(*self._held[at])
            written = at + 1
        self._writer.write_named_stretch(stretch)

    def _keep_after(self, count: int, places: int, held_due: int) -> None:
        """Drop the first ``places`` places, of the oldest ``count`` solutions, and the
        first ``held_due`` writes held; what remains renumbered."""
        self._place_solutions = [solution - count for solution in self._place_solutions[places:]]
        del self._place_log_times_ns[:places]
        self._place_held_before = [before - held_due for before in self._place_held_before[places:]]
        del self._held[:held_due]
        self._objects_held = [at - held_due for at in self._objects_held if at >= held_due]
        self._solutions -= count
