"""Conversions between the compensation's contract messages and values (no DDS)."""

import math

import numpy as np
import pytest
from geometry_msgs.msg import TwistWithCovarianceStamped, Vector3Stamped
from nav_msgs.msg import Odometry
from rclpy.serialization import deserialize_message, serialize_message
from scipy.spatial.transform import Rotation
from sensor_msgs.msg import NavSatFix, NavSatStatus, Temperature
from std_msgs.msg import Float64MultiArray, MultiArrayDimension

from buoy_common.contract import (
    seconds_to_iso8601,
    seconds_to_stamp,
    stamp_to_seconds,
    window_label,
)
from buoy_nav.rotations import rotate_by_quaternion_components
from wind_comp.compensation_messages import (
    BULK_ENCODING_FROM_SAMPLES,
    STATS_FIELDS,
    MalformedMessageError,
    anemometer_record,
    anemometer_sample,
    anemometer_sample_cdr,
    dvl_record,
    fix_fields,
    fix_fields_cdr,
    fix_record,
    flow_cdr,
    flows_cdr,
    flows_with_covariance_cdr,
    odometry_fields,
    odometry_fields_cdr,
    odometry_record,
    product_messages,
    stats_values,
    temperature_sample,
    temperature_sample_fields,
)
from wind_comp.config import CompensatorConfig
from wind_comp.pipeline import StampOrder, wind_pipeline
from wind_comp.products import WindAverager
from wind_comp.wind_echo_node import wind_line

RNG = np.random.default_rng(11)
CONFIG = CompensatorConfig(anemometer_position_body_m=(0, 0, 3), anemometer_rpy_deg=(0, 0, 0))


def odometry(quat_xyzw, rate_body, velocity_body, sec=100, nanosec=0):
    message = Odometry()
    message.header.stamp.sec, message.header.stamp.nanosec = sec, nanosec
    message.header.frame_id = "map"
    message.child_frame_id = "base_link"
    o = message.pose.pose.orientation
    o.x, o.y, o.z, o.w = (float(v) for v in quat_xyzw)
    t = message.twist.twist
    t.angular.x, t.angular.y, t.angular.z = (float(v) for v in rate_body)
    t.linear.x, t.linear.y, t.linear.z = (float(v) for v in velocity_body)
    return message


def wind(vector, frame="anemometer_link", sec=100, nanosec=0):
    message = Vector3Stamped()
    message.header.stamp.sec, message.header.stamp.nanosec = sec, nanosec
    message.header.frame_id = frame
    message.vector.x, message.vector.y, message.vector.z = (float(v) for v in vector)
    return message


def test_stamps_round_trip_within_float_resolution():
    # Float seconds near 2026 resolve 2.4e-7 s: outputs therefore copy the input stamps.
    for sec, nanosec in [(1_767_225_600, 50_000_000), (0, 1), (1_767_225_600, 999_999_999)]:
        message = wind([1, 2, 3], sec=sec, nanosec=nanosec)
        back_sec, back_nanosec = seconds_to_stamp(stamp_to_seconds(message.header.stamp))
        assert abs((back_sec - sec) * 1_000_000_000 + back_nanosec - nanosec) <= 250
    assert seconds_to_stamp(1_767_225_660.0) == (1_767_225_660, 0)


def test_odometry_velocity_is_rotated_into_enu_like_scipy():
    attitude = Rotation.from_euler("ZYX", [0.7, -0.2, 0.3])
    velocity_body = np.array([1.5, -0.4, 0.2])
    scale = 3.0  # unnormalised quaternions are normalised, not used as given
    t_s, quat, rate, velocity, *_ = odometry_fields(
        odometry(scale * attitude.as_quat(), [0.01, 0.02, 0.03], velocity_body, 5, 250_000_000)
    )
    assert t_s == 5.25
    np.testing.assert_allclose(
        rotate_by_quaternion_components(quat, velocity), attitude.apply(velocity_body), atol=1e-14
    )
    np.testing.assert_array_equal(rate, [0.01, 0.02, 0.03])


def test_messages_read_from_cdr_equal_decoded_messages_and_convert_as_columns_bitwise():
    quats = Rotation.random(20, random_state=3).as_quat()
    messages = [
        odometry(q, RNG.normal(0, 0.1, 3), RNG.normal(0, 2, 3), nanosec=i)
        for i, q in enumerate(quats)
    ]
    # One message at a time as compensation_node takes them, from message objects and from CDR.
    singles = [odometry_fields(m) for m in messages]
    assert [odometry_fields_cdr(serialize_message(m)) for m in messages] == singles
    # Whole columns, as process_bag converts them: the same numbers, bit for bit.
    quat_columns = np.array([q for _, q, _, _, *_ in singles])
    velocity_columns = np.array([v for _, _, _, v, *_ in singles])
    np.testing.assert_array_equal(
        np.stack(rotate_by_quaternion_components(quat_columns.T, velocity_columns.T), axis=-1),
        [rotate_by_quaternion_components(q, v) for _, q, _, v, *_ in singles],
    )
    np.testing.assert_array_equal(quat_columns, quats)
    np.testing.assert_array_equal([t for t, *_ in singles], [i * 1e-9 + 100 for i in range(20)])


@pytest.mark.parametrize(
    ("change", "reason"),
    [
        (lambda m: setattr(m.pose.pose.orientation, "w", math.nan), "non_finite"),
        (lambda m: setattr(m.twist.twist.angular, "y", math.inf), "non_finite"),
        (lambda m: setattr(m.twist.twist.linear, "x", math.nan), "non_finite"),
        (
            lambda m: setattr(m.pose.pose, "orientation", type(m.pose.pose.orientation)(w=0.0)),
            "zero_quaternion",
        ),
        (lambda m: setattr(m.header, "frame_id", "odom"), "wrong_frame"),
        (lambda m: setattr(m, "child_frame_id", "imu_link"), "wrong_frame"),
    ],
)
def test_malformed_odometry_is_rejected_with_its_reason(change, reason):
    message = odometry([0, 0, 0, 1], [0, 0, 0], [0, 0, 0])
    change(message)
    with pytest.raises(MalformedMessageError) as raised:
        odometry_fields(message)
    assert raised.value.reason == reason
    good = odometry([0, 0, 0, 1], [0, 0, 0], [1, 0, 0])
    later = odometry([0, 0, 0, 1], [0, 0, 0], [1, 0, 0], nanosec=1)
    pipeline, rejected = wind_pipeline(CONFIG), {}
    for candidate in (good, message, later):
        try:
            assert pipeline.add_odometry(*odometry_fields(candidate)) is None
        except MalformedMessageError as error:
            rejected[error.reason] = rejected.get(error.reason, 0) + 1
    assert rejected == {reason: 1}
    pipeline.ready()
    assert pipeline.n_nav_accepted == 2


def test_anemometer_sample_round_trip_and_rejections():
    sample = anemometer_sample(wind([3.0, -4.0, 0.5], sec=7, nanosec=500_000_000))
    assert sample.rejection is None
    assert sample.t_s == 7.5
    np.testing.assert_array_equal(sample.flow_sensor_mps, [3.0, -4.0, 0.5])
    for message, reason in [
        (wind([math.nan, 1.0, 0.0]), "non_finite"),
        (wind([1.0, math.inf, 0.0]), "non_finite"),
        (wind([1.0, 1.0, 0.0], frame="imu_link"), "wrong_frame"),
    ]:
        rejected = anemometer_sample(message)
        assert rejected.rejection == reason
        assert rejected.t_s == 100.0  # the stamp survives: the output keeps its place
        assert np.all(np.isnan(rejected.flow_sensor_mps))


@pytest.mark.parametrize(
    ("vector", "frame"),
    [
        ([3.0, -4.0, 0.5], "anemometer_link"),
        ([math.nan, 1.0, 0.0], "anemometer_link"),
        ([1.0, 1.0, 0.0], "imu_link"),
        ([1.0, 1.0, 0.0], ""),
        ([1.0, 1.0, 0.0], "anemometer_link_with_a_longer_name"),
    ],
)
def test_anemometer_sample_from_cdr_equals_the_decoded_message(vector, frame):
    message = wind(vector, frame=frame, sec=1_767_225_600, nanosec=123_456_789)
    expected = anemometer_sample(message)
    sample, sec, nanosec = anemometer_sample_cdr(serialize_message(message))
    assert (sec, nanosec) == (1_767_225_600, 123_456_789)
    assert sample.t_s == expected.t_s
    assert sample.rejection == expected.rejection
    np.testing.assert_array_equal(sample.flow_sensor_mps, expected.flow_sensor_mps)


def test_anemometer_cdr_reader_declines_what_it_does_not_handle():
    raw = serialize_message(wind([1.0, 2.0, 3.0]))
    assert anemometer_sample_cdr(b"\x01\x00" + raw[2:]) is None  # big-endian
    assert anemometer_sample_cdr(raw[:20]) is None


def test_stamp_order_accepts_only_increasing_stamps():
    order = StampOrder()
    assert [order.advance(t) for t in (1.0, 2.0, 2.0, 1.5, 3.0, math.nan)] == [
        True,
        True,
        False,
        False,
        True,
        False,
    ]


def test_fix_latitude_and_its_rejections():
    fix = NavSatFix()
    fix.status.status = NavSatStatus.STATUS_FIX
    fix.latitude = -33.5
    pipeline = wind_pipeline(CONFIG)
    assert pipeline.add_fix(*fix_fields(fix)) is None
    assert pipeline.latitude_deg == -33.5
    fix.status.status = NavSatStatus.STATUS_NO_FIX
    fix.latitude = math.nan
    assert pipeline.add_fix(*fix_fields(fix)) is None  # no fix: the latitude is kept
    assert pipeline.latitude_deg == -33.5
    fix.status.status = NavSatStatus.STATUS_FIX
    assert pipeline.add_fix(*fix_fields(fix)) == "non_finite"
    fix.latitude = 91.0
    assert pipeline.add_fix(*fix_fields(fix)) == "latitude_out_of_range"
    assert pipeline.latitude_deg == -33.5


def test_flow_cdr_is_the_stamped_map_vector_ros_serialises():
    for vector in ([1.0, -2.5, 0.25], [math.nan, math.nan, math.nan]):
        raw = flow_cdr(1_767_225_600, 50_000_000, vector)
        message = deserialize_message(raw, Vector3Stamped)
        assert (message.header.stamp.sec, message.header.stamp.nanosec) == (
            1_767_225_600,
            50_000_000,
        )
        assert message.header.frame_id == "map"
        np.testing.assert_array_equal(
            [message.vector.x, message.vector.y, message.vector.z], vector
        )
        assert serialize_message(message) == raw
    vectors = np.array([[1.0, -2.5, 0.25], [math.nan] * 3, [3.0, 4.0, 5.0]])
    secs, nanosecs = np.array([1_767_225_600, 1, 2]), np.array([50_000_000, 0, 999_999_999])
    assert flows_cdr(secs, nanosecs, vectors) == [
        flow_cdr(int(sec), int(nanosec), vector)
        for sec, nanosec, vector in zip(secs, nanosecs, vectors.tolist(), strict=True)
    ]


@pytest.mark.parametrize("copies", [1, BULK_ENCODING_FROM_SAMPLES])
def test_flows_with_covariance_cdr_is_the_message_ros_serialises_for_each_sample(copies):
    """A few samples (encoded one by one) and a batch (encoded at once)."""
    vectors = np.tile([[1.0, -2.5, 0.25], [math.nan] * 3, [-0.0, 4.0, 5.0]], (copies, 1))
    covariances = RNG.normal(size=(3 * copies, 3, 3))
    covariances[1::3] = math.nan
    secs, nanosecs = [1_767_225_600, 1, 2] * copies, [50_000_000, 0, 999_999_999] * copies
    raws = flows_with_covariance_cdr(secs, nanosecs, vectors, covariances)
    assert len(raws) == 3 * copies
    for raw, sec, nanosec, vector, covariance in zip(
        raws, secs, nanosecs, vectors, covariances, strict=True
    ):
        message = TwistWithCovarianceStamped()
        message.header.stamp.sec, message.header.stamp.nanosec = sec, nanosec
        message.header.frame_id = "map"
        linear = message.twist.twist.linear
        linear.x, linear.y, linear.z = vector.tolist()
        covariance_6x6 = np.zeros((6, 6))
        covariance_6x6[:3, :3] = covariance
        covariance_6x6[3:, 3:] = np.diag([-1.0, -1.0, -1.0])
        message.twist.covariance = covariance_6x6.ravel().tolist()
        assert raw == serialize_message(message)
    # One sample, as the live node asks, and none.
    assert flows_with_covariance_cdr([1], [0], vectors[1:2], covariances[1:2]) == raws[1:2]
    assert flows_with_covariance_cdr([], [], np.empty((0, 3)), np.empty((0, 3, 3))) == []


@pytest.mark.parametrize(
    ("frame", "value", "expected"),
    [
        ("anemometer_link", 21.5, (42.25, 21.5)),
        ("anemometer_link", math.nan, "non_finite"),
        ("anemometer_link", -math.inf, "non_finite"),
        ("sonic_link", 21.5, "wrong_frame"),
    ],
)
def test_temperature_sample_of_fields_equals_that_of_the_message(frame, value, expected):
    message = Temperature()
    message.header.stamp.sec, message.header.stamp.nanosec = 42, 250_000_000
    message.header.frame_id = frame
    message.temperature = value
    assert temperature_sample(message) == expected
    assert temperature_sample_fields(42, 250_000_000, frame, value) == expected


def test_product_messages_carry_the_window_statistics():
    averager = WindAverager(60.0, 3.0)
    stamps = 1_767_225_600.0 + np.arange(0.0, 61.0, 0.5)
    winds = np.column_stack(
        [np.full(stamps.shape, 4.0), RNG.normal(0, 1, stamps.shape), np.zeros(stamps.shape)]
    )
    winds[3] = np.nan
    (product,) = averager.add_batch(stamps, winds)
    mean, stats = product_messages(Vector3Stamped, Float64MultiArray, MultiArrayDimension, product)
    assert seconds_to_stamp(product.window_end_s) == (
        mean.header.stamp.sec,
        mean.header.stamp.nanosec,
    )
    assert mean.header.frame_id == "map"
    np.testing.assert_allclose(
        [mean.vector.x, mean.vector.y, mean.vector.z],
        np.nanmean(winds[stamps < product.window_end_s], axis=0),
    )
    values = stats_values(stats)
    assert tuple(values) == STATS_FIELDS
    assert values["n_invalid"] == 1 and values["n_valid"] == 119
    assert values["vector_mean_direction_deg"] == pytest.approx(product.vector_mean_direction_deg)


def test_window_labels():
    assert [window_label(w) for w in (60.0, 600.0, 30.0, 2.5)] == ["1min", "10min", "30s", "2p5s"]


def test_echo_lines():
    assert seconds_to_iso8601(1_767_225_600.05) == "2026-01-01T00:00:00.050Z"
    line = wind_line(0.0, 1.0, 0.0, 0.0)  # blowing toward East: from the West
    assert "speed   1.00 m/s" in line and "from 270.0 deg" in line
    assert wind_line(0.0, math.nan, 0.0, 0.0).endswith("invalid")


@pytest.mark.parametrize(
    ("frame", "child", "quat", "rate"),
    [
        ("map", "base_link", [0.1, -0.2, 0.3, 0.9], [0.01, -0.02, 0.03]),
        ("odom", "base_link", [0.1, -0.2, 0.3, 0.9], [0.01, -0.02, 0.03]),
        ("map", "base_link_long_name", [0.1, -0.2, 0.3, 0.9], [0.01, -0.02, 0.03]),
        ("map", "base_link", [0.0, 0.0, 0.0, 0.0], [0.01, -0.02, 0.03]),
        ("map", "base_link", [0.1, -0.2, 0.3, 0.9], [math.inf, -0.02, 0.03]),
    ],
)
def test_odometry_fields_from_cdr_equal_the_decoded_message(frame, child, quat, rate):
    message = odometry(quat, rate, [1.5, -0.4, 0.2], sec=1_767_225_600, nanosec=987_654_321)
    message.header.frame_id, message.child_frame_id = frame, child
    message.pose.covariance = RNG.normal(size=36).tolist()
    raw = serialize_message(message)
    try:
        expected = odometry_fields(message)
    except MalformedMessageError as error:
        with pytest.raises(MalformedMessageError) as raised:
            odometry_fields_cdr(raw)
        assert raised.value.reason == error.reason
        return
    fields = odometry_fields_cdr(raw)
    assert fields[0] == expected[0]
    for got, want in zip(fields[1:], expected[1:], strict=True):
        np.testing.assert_array_equal(got, want)


@pytest.mark.parametrize(("status", "latitude"), [(0, 35.25), (-1, 35.25), (2, -89.5)])
def test_fix_fields_from_cdr_equal_the_decoded_message(status, latitude):
    message = NavSatFix()
    message.header.frame_id = "base_link"
    message.status.status, message.status.service = status, NavSatStatus.SERVICE_GPS
    message.latitude, message.longitude, message.altitude = latitude, 120.5, 3.25
    raw = serialize_message(message)
    assert fix_fields_cdr(raw) == (status, latitude)
    assert fix_fields_cdr(raw) == fix_fields(message)


def test_nav_cdr_readers_decline_what_they_do_not_handle():
    odometry_raw = serialize_message(odometry([0, 0, 0, 1], [0, 0, 0], [0, 0, 0]))
    fix_raw = serialize_message(NavSatFix())
    for reader, raw in ((odometry_fields_cdr, odometry_raw), (fix_fields_cdr, fix_raw)):
        assert reader(b"\x01\x00" + raw[2:]) is None  # big-endian
        assert reader(raw[:14]) is None


def decoded_as(message_type, calls: list):
    """A decoder of ``message_type`` that notes each use in ``calls``."""

    def decode(raw):
        calls.append(raw)
        return deserialize_message(raw, message_type)

    return decode


def test_records_read_the_bytes_where_they_can_and_decode_the_rest_alike():
    """Live and offline read a message through the same record readers: from its CDR bytes,
    or from the message decoded when the CDR reader declines them."""
    calls = []
    message = wind([3.0, -4.0, 0.5], sec=1_767_225_600, nanosec=123_456_789)
    raw = serialize_message(message)
    big_endian = b"\x01\x00" + raw[2:]  # what the CDR reader declines, decoded from `raw`
    from_cdr = anemometer_record(raw, decoded_as(Vector3Stamped, calls))
    assert calls == []
    from_decoded = anemometer_record(big_endian, lambda _: message)
    assert from_cdr == from_decoded == (anemometer_sample(message), 1_767_225_600, 123_456_789)

    odometry_message = odometry([0.1, -0.2, 0.3, 0.9], [0.01, -0.02, 0.03], [1.5, -0.4, 0.2])
    odometry_message.pose.covariance[28] = math.nan  # unknown: an infinite variance
    odometry_raw = serialize_message(odometry_message)
    read = odometry_record(odometry_raw, decoded_as(Odometry, calls))
    assert calls == []
    decoded = odometry_record(b"\x01\x00" + odometry_raw[2:], lambda _: odometry_message)
    # The covariances hold the NaN: compared as arrays, NaN equal to NaN.
    assert read[:5] == decoded[:5]
    for from_bytes, from_message in zip(read[5:], decoded[5:], strict=True):
        np.testing.assert_array_equal(from_bytes, from_message)
    assert read[4] == math.inf
    assert math.isnan(read[5][4])

    fix = NavSatFix()
    fix.status.status, fix.latitude = NavSatStatus.STATUS_FIX, -33.5
    fix_raw = serialize_message(fix)
    assert fix_record(fix_raw, decoded_as(NavSatFix, calls)) == (0, -33.5)
    assert calls == []
    assert fix_record(b"\x01\x00" + fix_raw[2:], lambda _: fix) == (0, -33.5)


@pytest.mark.parametrize(
    ("velocity", "frame", "reason"),
    [
        ([0.5, -0.25, 0.125], "dvl_link", None),
        ([math.nan, 0.0, 0.0], "dvl_link", "non_finite"),
        ([0.5, -0.25, 0.125], "adcp_link", "wrong_frame"),
    ],
)
def test_dvl_record_is_the_water_past_the_dvl_with_the_header_stamp(velocity, frame, reason):
    message = TwistWithCovarianceStamped()
    message.header.stamp.sec, message.header.stamp.nanosec = 42, 250_000_000
    message.header.frame_id = frame
    linear = message.twist.twist.linear
    linear.x, linear.y, linear.z = velocity
    calls = []
    sample, sec, nanosec = dvl_record(
        serialize_message(message), decoded_as(TwistWithCovarianceStamped, calls)
    )
    assert len(calls) == 1
    assert (sample.t_s, sec, nanosec, sample.rejection) == (42.25, 42, 250_000_000, reason)
    expected = [-v for v in velocity] if reason is None else [math.nan] * 3
    np.testing.assert_array_equal(sample.flow_sensor_mps, expected)
    assert sample.frame_id == (frame if reason == "wrong_frame" else "")
