"""The current from a DVL (paper 003) on analytic cases: current = v_nav + R_nb (ω × l) −
R_nb R_bd v_dvl, each term with its sign, and every DVL sample answered once, bad ones with NaN.

Readings are written from first principles here (the DVL's velocity through the water in its
own axes), never with the estimator's routines."""

import math

import numpy as np
import pytest
from geometry_msgs.msg import TwistWithCovarianceStamped
from scipy.spatial.transform import Rotation

from buoy_common.contract import Reason
from wind_comp.compensation_messages import dvl_sample
from wind_comp.compensator import SampleStatus
from wind_comp.config import ConfigError, CurrentConfig
from wind_comp.pipeline import current_pipeline, mostly_invalid_warning

NAV_RATE_HZ = 50.0
DVL_RATE_HZ = 1.0


def elementary(axis: str, angle_deg: float) -> np.ndarray:
    c, s = math.cos(math.radians(angle_deg)), math.sin(math.radians(angle_deg))
    if axis == "x":
        return np.array([[1, 0, 0], [0, c, -s], [0, s, c]])
    if axis == "y":
        return np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]])
    return np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])


def zyx(roll_deg, pitch_deg, yaw_deg) -> np.ndarray:
    return elementary("z", yaw_deg) @ elementary("y", pitch_deg) @ elementary("x", roll_deg)


def dvl_message(t_s: float, velocity_dvl_mps, frame: str = "dvl_link"):
    message = TwistWithCovarianceStamped()
    message.header.stamp.sec, nanosec = divmod(round(t_s * 1e9), 1_000_000_000)
    message.header.stamp.nanosec = nanosec
    message.header.frame_id = frame
    linear = message.twist.twist.linear
    linear.x, linear.y, linear.z = (float(v) for v in velocity_dvl_mps)
    return message


class Platform:
    """A platform turning at a constant body rate ω (relative to the local level, rad/s) from
    attitude R0 and moving at a constant ENU velocity: its navigation is exact to interpolate."""

    def __init__(self, attitude_0: Rotation, rate_body_rad_s, velocity_enu_mps):
        self.attitude_0 = attitude_0
        self.rate = np.asarray(rate_body_rad_s, dtype=float)
        self.velocity = np.asarray(velocity_enu_mps, dtype=float)

    def attitude(self, t_s: float) -> np.ndarray:
        return (self.attitude_0 * Rotation.from_rotvec(self.rate * t_s)).as_matrix()

    def odometry(self, t_s: float):
        """nav/odometry values: stamp, quaternion, body rate (the Earth's rate left out: no
        fix is given, so the pipeline takes the rate as it is), body velocity."""
        attitude = Rotation.from_matrix(self.attitude(t_s))
        return t_s, attitude.as_quat(), self.rate, attitude.inv().apply(self.velocity)

    def dvl_reading(self, t_s, current_enu_mps, position_body_m, mounting_rpy_deg):
        """The DVL's velocity through the water in its own axes:
        R_bdᵀ R_nbᵀ (v + R_nb (ω × l) − current)."""
        attitude = self.attitude(t_s)
        over_ground = self.velocity + attitude @ np.cross(self.rate, position_body_m)
        through_water_enu = over_ground - np.asarray(current_enu_mps, dtype=float)
        return zyx(*mounting_rpy_deg).T @ attitude.T @ through_water_enu


def estimate(platform: Platform, readings, config: CurrentConfig, duration_s: float = 20.0):
    """Feed navigation and DVL messages in stamp order; return the pipeline, the corrected
    samples and the rejections of the DVL messages."""
    pipeline = current_pipeline(config)
    nav_t = np.arange(0.0, duration_s, 1.0 / NAV_RATE_HZ)
    arrivals = [(t, 0, platform.odometry(t)) for t in nav_t]
    arrivals += [
        (message.header.stamp.sec + message.header.stamp.nanosec * 1e-9, 1, message)
        for message in readings
    ]
    arrivals.sort(key=lambda item: item[:2])
    rejections = []
    outputs = []
    for _, kind, item in arrivals:
        if kind == 0:
            assert pipeline.add_odometry(*item) is None
        else:
            rejections.append(pipeline.add_sample(dvl_sample(item, config.dvl_frame_id)))
        outputs.append(pipeline.ready().samples)
    outputs.append(pipeline.flush().samples)
    status = np.concatenate([o.status for o in outputs])
    current = np.concatenate([o.flow_enu_mps for o in outputs])
    return pipeline, status, current, rejections


def readings_of(platform, current, position, rpy, times):
    return [dvl_message(t, platform.dvl_reading(t, current, position, rpy)) for t in times]


DVL_TIMES = np.arange(1.0, 19.0, 1.0 / DVL_RATE_HZ) + 0.013
POSITION = (0.4, -0.3, -2.5)
RPY = (178.0, -3.0, 30.0)


def test_still_platform_in_a_uniform_current():
    platform = Platform(
        Rotation.from_euler("ZYX", [50.0, 2.0, -3.0], degrees=True), [0] * 3, [0] * 3
    )
    current = np.array([0.7, -0.4, 0.0])
    config = CurrentConfig(dvl_position_body_m=POSITION, dvl_rpy_deg=RPY)
    _, status, estimated, _ = estimate(
        platform, readings_of(platform, current, POSITION, RPY, DVL_TIMES), config
    )
    assert np.all(status == SampleStatus.VALID)
    np.testing.assert_allclose(estimated, np.tile(current, (DVL_TIMES.size, 1)), atol=1e-12)


def test_pure_rotation_in_still_water_gives_no_current():
    """The platform turns about all three axes at up to 0.4 rad/s: the DVL, 2.5 m below and
    off the axis, sweeps through still water at about 1 m/s, all of it the lever arm's."""
    platform = Platform(Rotation.identity(), [0.3, -0.4, 0.25], [0.0, 0.0, 0.0])
    config = CurrentConfig(dvl_position_body_m=POSITION, dvl_rpy_deg=RPY)
    readings = readings_of(platform, [0.0, 0.0, 0.0], POSITION, RPY, DVL_TIMES)
    assert (
        min(
            np.linalg.norm([r.twist.twist.linear.x, r.twist.twist.linear.y, r.twist.twist.linear.z])
            for r in readings
        )
        > 0.5
    )
    _, status, estimated, _ = estimate(platform, readings, config)
    assert np.all(status == SampleStatus.VALID)
    # Interpolating a constant-rate rotation by slerp is exact: only round-off remains.
    np.testing.assert_allclose(estimated, 0.0, atol=1e-9)


@pytest.mark.parametrize("yaw_deg", [90.0, -90.0])
def test_mounting_rotation_with_its_sign(yaw_deg):
    """A DVL yawed +90° has its x axis along body +y (left): a platform heading North through
    still water at 2 m/s reads (0, -2, 0) in it (yawed −90°: (0, +2, 0)). Only the mounting the
    reading was taken with gives zero current; the opposite one turns the reading by 180°."""
    heading_north = Rotation.from_euler("ZYX", [90.0, 0.0, 0.0], degrees=True)
    platform = Platform(heading_north, [0.0] * 3, [0.0, 2.0, 0.0])
    rpy = (0.0, 0.0, yaw_deg)
    readings = readings_of(platform, [0.0] * 3, (0.0, 0.0, -2.0), rpy, DVL_TIMES)
    first = readings[0].twist.twist.linear
    np.testing.assert_allclose(
        [first.x, first.y, first.z], [0.0, -math.copysign(2.0, yaw_deg), 0.0], atol=1e-12
    )
    right = CurrentConfig(dvl_position_body_m=(0.0, 0.0, -2.0), dvl_rpy_deg=rpy)
    _, _, estimated, _ = estimate(platform, readings, right)
    np.testing.assert_allclose(estimated, 0.0, atol=1e-12)
    wrong = CurrentConfig(dvl_position_body_m=(0.0, 0.0, -2.0), dvl_rpy_deg=(0.0, 0.0, -yaw_deg))
    _, _, estimated, _ = estimate(platform, readings, wrong)
    np.testing.assert_allclose(estimated, np.tile([0.0, 4.0, 0.0], (DVL_TIMES.size, 1)), atol=1e-12)


def test_lever_arm_with_its_sign():
    """Yawing at 0.5 rad/s, a DVL 2 m ahead of base_link moves left at 1 m/s: the reading holds
    it; the estimate removes it with the lever arm's sign, and the mirrored arm doubles it."""
    platform = Platform(Rotation.identity(), [0.0, 0.0, 0.5], [0.0, 0.0, 0.0])
    ahead = (2.0, 0.0, 0.0)
    readings = readings_of(platform, [0.0] * 3, ahead, (0, 0, 0), DVL_TIMES)
    first = readings[0].twist.twist.linear
    # ω × l = (0, 0, 0.5) × (2, 0, 0) = (0, 1, 0): to the left, body axes.
    np.testing.assert_allclose([first.x, first.y, first.z], [0.0, 1.0, 0.0], atol=1e-12)
    right = CurrentConfig(dvl_position_body_m=ahead, dvl_rpy_deg=(0, 0, 0))
    _, _, estimated, _ = estimate(platform, readings, right)
    np.testing.assert_allclose(estimated, 0.0, atol=1e-9)
    mirrored = CurrentConfig(dvl_position_body_m=(-2.0, 0.0, 0.0), dvl_rpy_deg=(0, 0, 0))
    _, _, estimated, _ = estimate(platform, readings, mirrored)
    speeds = np.linalg.norm(estimated, axis=1)
    np.testing.assert_allclose(speeds, 2.0, atol=1e-9)


def test_moving_turning_platform_in_a_current_recovers_it():
    """Everything at once: a platform cruising, turning about three axes, a turned and offset
    DVL, a current with a vertical part (the waves' orbital motion at one instant)."""
    platform = Platform(
        Rotation.from_euler("ZYX", [20.0, 5.0, -8.0], degrees=True),
        [0.05, -0.08, 0.1],
        [1.2, -3.0, 0.1],
    )
    current = np.array([1.5, 0.9, -0.2])
    config = CurrentConfig(dvl_position_body_m=POSITION, dvl_rpy_deg=RPY)
    _, status, estimated, _ = estimate(
        platform, readings_of(platform, current, POSITION, RPY, DVL_TIMES), config
    )
    assert np.all(status == SampleStatus.VALID)
    np.testing.assert_allclose(estimated, np.tile(current, (DVL_TIMES.size, 1)), atol=1e-9)


def test_bad_dvl_samples_are_rejected_counted_and_answered_with_nan():
    platform = Platform(Rotation.identity(), [0.0] * 3, [0.5, 0.0, 0.0])
    config = CurrentConfig(dvl_position_body_m=POSITION, dvl_rpy_deg=RPY, max_dvl_speed_mps=10.0)
    readings = readings_of(platform, [0.1, 0.2, 0.0], POSITION, RPY, DVL_TIMES)
    readings[3] = dvl_message(DVL_TIMES[3], [math.nan, 0.2, 0.0])  # a ping flagged invalid
    readings[5] = dvl_message(DVL_TIMES[5], [12.0, 0.0, 0.0])  # beyond any DVL's range
    readings[7] = dvl_message(DVL_TIMES[7], [0.5, 0.0, 0.0], frame="base_link")
    readings[9] = dvl_message(DVL_TIMES[8], [0.5, 0.0, 0.0])  # repeats the previous stamp
    pipeline, status, estimated, rejections = estimate(platform, readings, config)
    assert status.size == len(readings)  # one output per input, in order
    expected = {
        3: SampleStatus.INVALID_MEASUREMENT,
        5: SampleStatus.SPEED_OUT_OF_RANGE,
        7: SampleStatus.INVALID_MEASUREMENT,
        9: SampleStatus.INVALID_STAMP,
    }
    for index, code in enumerate(status):
        assert code == expected.get(index, SampleStatus.VALID), index
        assert np.isnan(estimated[index]).all() == (index in expected)
    assert rejections[3] == Reason.NON_FINITE
    assert rejections[7] == Reason.WRONG_FRAME
    assert rejections[9] == Reason.STAMP_NOT_INCREASING
    assert {reason: n for reason, n in pipeline.status_counts().items() if n} == {
        "valid": len(readings) - 4,
        Reason.INVALID_DVL: 2,
        Reason.DVL_SPEED_OUT_OF_RANGE: 1,
        Reason.INVALID_STAMP: 1,
    }
    assert mostly_invalid_warning(pipeline.status_counts(), "DVL") is None


def test_a_driver_s_dvl_frame_is_rejected_unless_configured():
    platform = Platform(Rotation.from_euler("ZYX", [20.0, 0, 0], degrees=True), [0] * 3, [0] * 3)
    current = np.array([0.3, 0.5, 0.0])
    readings = readings_of(platform, current, POSITION, RPY, DVL_TIMES)
    for message in readings:
        message.header.frame_id = "adcp"
    config = CurrentConfig(dvl_position_body_m=POSITION, dvl_rpy_deg=RPY)
    assert dvl_sample(readings[0], config.dvl_frame_id).frame_id == "adcp"
    pipeline, status, estimated, rejections = estimate(platform, readings, config)
    assert set(rejections) == {Reason.WRONG_FRAME}
    assert np.isnan(estimated).all()
    warning = mostly_invalid_warning(pipeline.status_counts(), "DVL")
    assert warning == f"most DVL samples are invalid: {len(readings)} of {len(readings)} " + (
        f"(mostly invalid_dvl: {len(readings)})"
    )

    config = CurrentConfig(dvl_position_body_m=POSITION, dvl_rpy_deg=RPY, dvl_frame_id="adcp")
    _, status, estimated, rejections = estimate(platform, readings, config)
    assert set(rejections) == {None}
    assert np.all(status == SampleStatus.VALID)
    np.testing.assert_allclose(estimated, np.tile(current, (DVL_TIMES.size, 1)), atol=1e-12)


def test_products_are_vector_means_with_the_direction_the_water_goes():
    platform = Platform(Rotation.from_euler("ZYX", [10.0, 0, 0], degrees=True), [0] * 3, [0] * 3)
    current = np.array([math.sqrt(3.0), 1.0, 0.0])  # paper 003: 2 m/s toward 60°
    config = CurrentConfig(
        dvl_position_body_m=POSITION, dvl_rpy_deg=RPY, product_windows_s=(5.0, 10.0)
    )
    pipeline = current_pipeline(config)
    products = []
    for t in np.arange(0.0, 21.0, 1.0 / NAV_RATE_HZ):
        pipeline.add_odometry(*platform.odometry(t))
        if abs(t - round(t)) < 1e-9 and 0.0 < t < 20.0:
            reading = platform.dvl_reading(t + 0.5, current, POSITION, RPY)
        else:
            continue
        pipeline.add_sample(dvl_sample(dvl_message(t + 0.5, reading)))
        products += pipeline.ready().products
    products += pipeline.flush().products
    full = [p for p in products if p.window_s == 10.0 and p.n_valid == 10]
    assert full
    for product in full:
        assert product.speed_mps == pytest.approx(2.0, abs=1e-12)
        assert product.direction_deg == pytest.approx(60.0, abs=1e-9)
        assert product.std_u_mps == pytest.approx(0.0, abs=1e-12)


def test_bad_settings_name_the_setting():
    with pytest.raises(ConfigError, match="max_dvl_speed_mps"):
        CurrentConfig(max_dvl_speed_mps=0.0)
    with pytest.raises(ConfigError, match=r"dvl\.position"):
        CurrentConfig(dvl_position_body_m=(0.0, 0.0, -500.0))
    with pytest.raises(ConfigError, match=r"dvl\.rpy_deg"):
        CurrentConfig(dvl_rpy_deg=(0.0, 95.0, 0.0))
    with pytest.raises(ConfigError, match="nav_history_s"):
        CurrentConfig(max_nav_gap_s=5.0, nav_history_s=2.0)
    with pytest.raises(ConfigError, match="dvl_frame_id"):
        CurrentConfig(dvl_frame_id=" ")
