"""Every aiding source that reads its messages as records (the fields the bulk decoder gives
for a chunk of a bag) makes of each record the measurement, or the rejection, it makes of the
same message decoded alone: offline tools decode by chunks, the live node one message at a
time."""

import math

import numpy as np
import pytest

from buoy_common import cdr_bulk
from buoy_common.bag_io import jazzy_typestore
from buoy_common.contract import Reason
from buoy_nav.aiding import AIDING_SOURCES
from buoy_nav.aiding.ahrs_attitude import AT_ONCE_FROM
from buoy_nav.config import FusionConfig
from buoy_nav.error_state_filter import ERROR_STATES
from buoy_nav.fusion_messages import measurements_from_records

RECORD_SOURCES = [source for source in AIDING_SOURCES if source.record_fields]
MESSAGES = 400
RNG = np.random.default_rng(11)


def columns_of(source) -> dict[str, np.ndarray]:
    """Plausible values of the source's fields, some of them what a source must reject (NaN,
    a zero or scaled quaternion, a negative variance, no fix), on stamps that repeat or go back
    now and then."""
    layout = {item.name: item for item in cdr_bulk.LAYOUTS[source.msgtype()]}
    stamps_ns = 1_700_000_000 * 10**9 + np.cumsum(RNG.integers(-20, 100, MESSAGES)) * 10**6
    columns = {"stamp_ns": stamps_ns, "frame_id": "sensor"}
    for item in layout.values():
        if item.name not in ("sec", "nanosec", "frame_id") and item.constant is None:
            columns[item.name] = np.ones((MESSAGES, *item.shape), dtype=item.kind)
    for name in source.record_fields:
        item = layout[name]
        if item.kind.startswith("<i") or item.kind.startswith("<u"):
            columns[name] = RNG.choice([-1, 0, 2], MESSAGES)
            continue
        values = RNG.normal(0.0, 1.0, (MESSAGES, *item.shape))
        if name == "magnetic_field":
            values *= 3e-5  # T: the Earth's field
        if name.endswith("covariance"):
            values = np.abs(values) * 1e-4
            values[RNG.random(MESSAGES) < 0.05, ..., 0] = -1e-4
        if item.parts == "xyzw":
            values /= np.linalg.norm(values, axis=1, keepdims=True)
            values[RNG.random(MESSAGES) < 0.05] = 0.0
            values[RNG.random(MESSAGES) < 0.05] *= 1.1
        first_component = values.reshape(MESSAGES, -1)[:, 0]
        first_component[RNG.random(MESSAGES) < 0.03] = math.nan
        columns[name] = values
    return columns


def same(a, b) -> bool:
    """Equal to the bit: numbers, arrays, tuples and named tuples of them, reasons."""
    if isinstance(a, tuple) and isinstance(b, tuple):
        return len(a) == len(b) and all(same(x, y) for x, y in zip(a, b, strict=True))
    if isinstance(a, (np.ndarray, float, np.floating)) or isinstance(b, np.ndarray):
        x, y = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
        return x.shape == y.shape and x.tobytes() == y.tobytes()
    return a == b


@pytest.mark.parametrize("source_class", RECORD_SOURCES, ids=lambda s: s.kind)
def test_a_record_makes_what_its_message_makes(source_class):
    columns = columns_of(source_class)
    raws = cdr_bulk.encode(source_class.msgtype(), columns)
    decoded = cdr_bulk.decode(source_class.msgtype(), raws)
    assert decoded.valid.all()
    store = jazzy_typestore()
    from_messages = source_class(FusionConfig(), ERROR_STATES)
    from_records = source_class(FusionConfig(), ERROR_STATES)
    outcomes = set()
    for index, raw in enumerate(raws):
        message = store.deserialize_cdr(raw, source_class.msgtype())
        stamp = message.header.stamp
        t_s = stamp.sec + stamp.nanosec * 1e-9
        fields = [decoded[name][index].tolist() for name in source_class.record_fields]
        expected = from_messages.measurement_from_message(message)
        made = from_records.measurement_from_record(t_s, *fields)
        assert same(made, expected), (index, made, expected)
        outcome = expected if isinstance(expected, str) else from_messages.validated(expected)
        outcomes.add(outcome if isinstance(outcome, str) else "usable")
    # The values reached the sources' checks: they take some and refuse others.
    assert len(outcomes) > 1, outcomes


AT_ONCE_SOURCES = [
    source for source in RECORD_SOURCES if hasattr(source, "measurements_from_records")
]


@pytest.mark.parametrize("source_class", AT_ONCE_SOURCES, ids=lambda s: s.kind)
def test_records_made_at_once_are_what_each_makes_alone(source_class):
    """A run of records made at once (``measurements_from_records``) gives each one the
    measurement or the rejection it gets alone, to the bit, over runs of any length with what
    the source keeps carried between them: a stamp that repeats or goes back is refused after
    one that was refused for its values too, and a stamp that is not a number is refused."""
    columns = columns_of(source_class)
    raws = cdr_bulk.encode(source_class.msgtype(), columns)
    decoded = cdr_bulk.decode(source_class.msgtype(), raws)
    stamps_s = (decoded["sec"] + decoded["nanosec"] * 1e-9).tolist()
    for place in RNG.choice(MESSAGES, 6, replace=False).tolist():
        stamps_s[place] = float(RNG.choice([math.nan, math.inf, -math.inf]))
    fields = [decoded[name].tolist() for name in source_class.record_fields]
    alone = source_class(FusionConfig(), ERROR_STATES)
    expected = [
        alone.measurement_from_record(t_s, *(field[index] for field in fields))
        for index, t_s in enumerate(stamps_s)
    ]
    at_once = source_class(FusionConfig(), ERROR_STATES)
    made, start = [], 0
    while start < MESSAGES:
        end = start + int(RNG.integers(1, 80))
        made += measurements_from_records(
            at_once,
            stamps_s[start:end],
            list(zip(*(field[start:end] for field in fields), strict=True)),
        )
        start = end
    assert len(made) == MESSAGES
    for index, (one, other) in enumerate(zip(made, expected, strict=True)):
        assert same(one, other), (index, one, other)
    # The stamp each kept last: a later usable record makes the same interval after both.
    usable = next(i for i, outcome in enumerate(expected) if not isinstance(outcome, str))
    later = [field[usable] for field in fields]
    assert same(
        at_once.measurement_from_record(2e9, *later), alone.measurement_from_record(2e9, *later)
    )
    refused = {outcome for outcome in expected if isinstance(outcome, str)}
    assert len(refused) >= 4, refused


def test_a_pack_run_with_a_malformed_covariance_is_made_one_by_one():
    """A run of the pack's records whose covariances are not all nine numbers is made record by
    record: the short one refused as malformed, the others as each alone."""
    source_class = next(source for source in AT_ONCE_SOURCES if source.kind == "ahrs")
    count = 2 * AT_ONCE_FROM
    quaternions = [[0.0, 0.0, math.sin(0.1 * k), math.cos(0.1 * k)] for k in range(count)]
    covariances = [[1e-4, 0, 0, 0, 1e-4, 0, 0, 0, 1e-4] for _ in range(count)]
    covariances[2] = covariances[2][:8]
    stamps_s = [100.0 + 0.1 * k for k in range(count)]
    alone = source_class(FusionConfig(), ERROR_STATES)
    expected = [
        alone.measurement_from_record(*record)
        for record in zip(stamps_s, quaternions, covariances, strict=True)
    ]
    at_once = source_class(FusionConfig(), ERROR_STATES)
    assert at_once.measurements_from_records(stamps_s, quaternions, covariances) is None
    made = measurements_from_records(
        at_once, stamps_s, list(zip(quaternions, covariances, strict=True))
    )
    assert expected[2] == Reason.MALFORMED
    assert all(same(one, other) for one, other in zip(made, expected, strict=True))
