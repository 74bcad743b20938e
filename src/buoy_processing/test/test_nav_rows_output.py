"""The ``nav/*`` and ``tf`` of solutions written as rows, encoded a stretch at a time: the bytes
the live node packs one solution at a time, and a bag in the order written one by one."""

import numpy as np
import pytest
from geometry_msgs.msg import Vector3Stamped
from mcap.reader import make_reader

from buoy_common import cdr_bulk
from buoy_common.bag_io import BagWriter
from buoy_common.contract import NAV_MSGTYPES, TF_MSGTYPE, TF_TOPIC
from buoy_common.namespaces import NamespacedWriter, TopicView
from buoy_nav import earth
from buoy_nav.error_state_filter import ERROR_STATES, ErrorStateFilter
from buoy_nav.fusion_messages import nav_values, solution_cdr, transform_cdr
from buoy_nav.mechanization import StrapdownIntegrator
from buoy_nav.solution import SolutionBuilder
from buoy_nav.solution_rows import SolutionRows
from buoy_processing.nav_rows_output import NAV_TOPIC_ORDER, OrderedOutput, nav_columns
from buoy_processing.solution_columns import solution_columns

PLANE = earth.LocalTangentPlane(0.7, -1.2, 0.0)


def solutions_and_rows(count: int, distrust, seed: int = 21):
    """``count`` random solutions built as objects and the same written as rows, with their
    header stamps (sec, nanosec)."""
    rng = np.random.default_rng(seed)
    built, written = SolutionBuilder(PLANE), SolutionBuilder(PLANE, SolutionRows())
    solutions, stamps = [], []
    for index in range(count):
        factor = rng.normal(size=(ERROR_STATES.dim, ERROR_STATES.dim))
        kalman = ErrorStateFilter(factor @ factor.T, 0.99)
        attitude = rng.normal(size=4)
        integrator = StrapdownIntegrator(
            tuple(attitude / np.linalg.norm(attitude)),
            tuple(rng.normal(scale=3.0, size=3)),
            0.7 + rng.normal(scale=1e-3),
            -1.2 + rng.normal(scale=1e-3),
            rng.normal(scale=20.0),
            tuple(rng.normal(scale=1e-3, size=3)),
            tuple(rng.normal(scale=1e-2, size=3)),
        )
        for builder in (built, written):
            builder.distrust(distrust)
            builder.covariance_changed()
            builder.biases_changed()
        gyro = tuple(rng.normal(scale=0.3, size=3).tolist())
        force = tuple(rng.normal(loc=(0.0, 0.0, 9.8), scale=2.0).tolist())
        arguments = (integrator, kalman, 100.0 + index, gyro, force, (False,) * 3)
        solutions.append(built.emit(*arguments))
        written.emit(*arguments)
        stamps.append((1_700_000_000 + index, int(rng.integers(0, 1_000_000_000))))
    return solutions, written.rows.take(count), np.array(stamps, dtype=np.int64)


def packed_one_by_one(solution, sec: int, nanosec: int) -> list[bytes]:
    """The five messages of ``solution`` as the live node packs them, in topic order."""
    values = nav_values(solution)._replace(sec=sec, nanosec=nanosec)
    return [*solution_cdr(values).values(), transform_cdr(values)]


@pytest.mark.parametrize("distrust", [None, (1e-4, 2e-3)])
def test_messages_of_rows_are_the_bytes_packed_one_by_one(distrust):
    solutions, rows, stamps = solutions_and_rows(64, distrust)
    columns = nav_columns(rows, stamps[:, 0].copy(), stamps[:, 1].copy())
    msgtypes = {**NAV_MSGTYPES, TF_TOPIC: TF_MSGTYPE}
    encoded = [
        cdr_bulk.encode(msgtypes[topic], topic_columns)
        for topic, topic_columns in zip(NAV_TOPIC_ORDER, columns, strict=True)
    ]
    # The body-frame numbers the hand-over made for the corrections give the same bytes.
    handed_over = solution_columns(rows, stamps)
    assert encoded == [
        cdr_bulk.encode(msgtypes[topic], topic_columns)
        for topic, topic_columns in zip(
            NAV_TOPIC_ORDER,
            nav_columns(rows, handed_over.secs, handed_over.nanosecs, handed_over.body_numbers),
            strict=True,
        )
    ]
    for index, solution in enumerate(solutions):
        expected = packed_one_by_one(solution, *stamps[index].tolist())
        assert [messages[index] for messages in encoded] == expected, index


def bag_messages(path):
    """(topic, log time, bytes) of every message of the bag at ``path``, in file order."""
    with open(next(path.glob("*.mcap")), "rb") as stream:
        return [
            (channel.topic, message.log_time, bytes(message.data))
            for _, channel, message in make_reader(stream).iter_messages(log_time_order=False)
        ]


def mean_bytes(tmp_path, mean, message) -> bytes:
    """What a bag holds of ``message`` written alone on topic and type ``mean``."""
    with BagWriter(tmp_path / "alone") as bag:
        bag.write(*mean, 0, message)
    return bag_messages(tmp_path / "alone")[0][2]


@pytest.mark.parametrize("namespace", ["", "/buoy2"])
def test_a_stretch_is_written_where_its_solutions_were_given(tmp_path, namespace):
    """Writes between and after solutions (a copied sonic message, a product's message object,
    a solution left out by the navigation rate) come out in the order given, each solution's
    five messages in its place with its log time, every topic in the buoy's namespace; rows
    taken for the oldest solutions write what came before the next place, and nothing after
    it."""
    solutions, rows, stamps = solutions_and_rows(3, None)
    sonic = ("/anemometer/wind", "geometry_msgs/msg/Vector3Stamped")
    raw = bytes(range(40))
    mean = ("/wind/mean_1min", "geometry_msgs/msg/Vector3Stamped")
    mean_message = Vector3Stamped()
    mean_message.vector.x = 7.5
    with BagWriter(tmp_path / "out") as bag:
        output = OrderedOutput(NamespacedWriter(bag, TopicView(namespace)))
        output.write_raw(*sonic, 5, raw)
        output.add_solution(10, True)
        output.write_raw(*sonic, 11, raw)
        output.add_solution(20, False)
        output.add_solution(30, True)
        output.write(mean[0], mean[1], 30, mean_message)
        output.write_raw(*sonic, 31, raw)
        assert output.counts == {namespace + sonic[0]: 1}
        output.take_rows(rows[:2], stamps[:2, 0].copy(), stamps[:2, 1].copy())
        assert output.counts[namespace + sonic[0]] == 2
        assert sum(output.counts.values()) == 2 + len(NAV_TOPIC_ORDER)
        with pytest.raises(ValueError, match="2 rows for 1 solutions given"):
            output.take_rows(rows[1:], stamps[1:, 0].copy(), stamps[1:, 1].copy())
        with pytest.raises(RuntimeError, match="of 1 solutions were never written"):
            output.finish()
        output.take_rows(rows[2:], stamps[2:, 0].copy(), stamps[2:, 1].copy())
        output.finish()
    expected = [(namespace + sonic[0], 5, raw)]
    for index, log_time in ((0, 10), (2, 30)):
        packed = packed_one_by_one(solutions[index], *stamps[index].tolist())
        expected += [
            (f"{namespace}/{topic}", log_time, message)
            for topic, message in zip(NAV_TOPIC_ORDER, packed, strict=True)
        ]
        if log_time == 30:
            expected.append((namespace + mean[0], 30, mean_bytes(tmp_path, mean, mean_message)))
        expected.append((namespace + sonic[0], log_time + 1, raw))
    assert bag_messages(tmp_path / "out") == expected
