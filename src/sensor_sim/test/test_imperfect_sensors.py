"""The imperfections of the sensors real flux buoys carry, measured from the simulator's own
messages against its truth: the motion pack's lag and the σ it claims, the uncalibrated
magnetometer's ellipsoid, a single GNSS antenna at 1 Hz off the IMU grid on a mast, GNSS
outages silent on every GNSS topic, and a moored buoy without GNSS."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from sensor_sim.geodesy import geodetic_to_enu_m
from sensor_sim.motion_pack import igrf_declination_deg
from sensor_sim.scenario import load_scenario
from sensor_sim.streams import STREAMS, merged_messages
from sensor_sim.truth import TruthModel

NO_GNSS = "measured_moored_no_gnss"
SINGLE_GNSS = "measured_moored_single_gnss"
OUTAGES = "set_e_imperfect"
TESLA_PER_MICROTESLA = 1e-6
GNSS_TOPICS = ("gnss/fix", "gnss/vel", "gnss/heading", "gnss/baseline", "gnss/baseline_tertiary")


def scenario_messages(scenario, kinds=None):
    """Every message (topic, stamp_ns, message) of the scenario's carried streams, in stamp
    order, as simulate_bag writes them."""
    truth = TruthModel(scenario)
    streams = [
        spec.build(scenario, truth, {})
        for kind, spec in STREAMS.items()
        if spec.carried(scenario) and (kinds is None or kind in kinds)
    ]
    return merged_messages(streams, scenario.duration_s), truth


def on_topic(messages, topic):
    return [(stamp, message) for name, stamp, message in messages if name == topic]


def scenario_time_s(scenario, stamps_ns) -> np.ndarray:
    return (np.asarray(stamps_ns, dtype=np.int64) - scenario.start_time_ns) * 1e-9


def pack_attitude(messages, scenario):
    """(scenario times s, the motion pack's attitude with its yaw reference taken out)."""
    pack = on_topic(messages, "imu/data")
    t = scenario_time_s(scenario, [stamp for stamp, _ in pack])
    quaternions = [
        [m.orientation.x, m.orientation.y, m.orientation.z, m.orientation.w] for _, m in pack
    ]
    return t, Rotation.from_quat(quaternions), [m for _, m in pack]


def declination_turn(scenario) -> Rotation:
    """The pack's yaw reference: magnetic north, the true yaw plus the declination (the
    simulator's IGRF; the pack's yaw is ENU, counter-clockwise)."""
    return Rotation.from_rotvec([0.0, 0.0, np.radians(igrf_declination_deg(scenario))])


def phasor(t_s: np.ndarray, values: np.ndarray, angular_frequency_rad_s: float) -> complex:
    """Complex amplitude of values at one frequency, from a least-squares sine fit."""
    design = np.column_stack(
        [
            np.cos(angular_frequency_rad_s * t_s),
            np.sin(angular_frequency_rad_s * t_s),
            np.ones_like(t_s),
        ]
    )
    cosine, sine, _ = np.linalg.lstsq(design, values, rcond=None)[0]
    return complex(cosine, -sine)


def test_motion_pack_lags_as_a_first_order_filter_at_the_roll_frequency():
    # Roll alone, about one fixed axis, and no other pack error: what is left is the lag.
    scenario = load_scenario(
        NO_GNSS,
        [
            "duration_s=140",
            "motion.pitch_amplitude_deg=0",
            "motion.yaw_amplitude_deg=0",
            "motion.mooring_yaw_amplitude_deg=0",
            "sensors.ahrs.error_deg=0",
            "sensors.ahrs.noise_deg=0",
        ],
    )
    messages, truth = scenario_messages(scenario, {"imu"})
    t, attitude, _ = pack_attitude(messages, scenario)
    settled = t > 10.0 * scenario.sensors.ahrs.lag_time_constant_s
    roll_out = attitude.as_euler("ZYX")[settled, 2]
    roll_true = truth.evaluate(t[settled]).euler_rad[:, 0]
    omega = 2.0 * np.pi / scenario.motion.roll_period_s
    response = phasor(t[settled], roll_out, omega) / phasor(t[settled], roll_true, omega)
    tau = scenario.sensors.ahrs.lag_time_constant_s
    first_order = 1.0 / (1.0 + 1j * omega * tau)
    assert abs(response) == pytest.approx(abs(first_order), rel=0.002)
    # The pack works in samples (50 Hz): its phase may differ from the continuous lag's by
    # half a sample at this frequency (0.55 deg); a lag 0.02 s off would be 1.3 deg off.
    sample_s = 1.0 / scenario.sensors.rates.imu_hz
    assert abs(np.angle(response) - np.angle(first_order)) < omega * sample_s
    assert np.degrees(np.angle(response)) == pytest.approx(-16.2, abs=1.0)


def test_motion_pack_lag_shows_in_the_cross_correlation_of_the_full_motion():
    scenario = load_scenario(NO_GNSS, ["duration_s=200"])
    messages, truth = scenario_messages(scenario, {"imu"})
    t, attitude, _ = pack_attitude(messages, scenario)
    roll_out = attitude.as_euler("ZYX")[:, 2]
    roll_true = truth.evaluate(t).euler_rad[:, 0]
    sample_s = t[1] - t[0]
    shifts = np.arange(0, 40)
    correlation = [
        np.dot(roll_out[shift:] - roll_out.mean(), roll_true[: t.size - shift] - roll_true.mean())
        for shift in shifts
    ]
    delay_s = shifts[int(np.argmax(correlation))] * sample_s
    omega = 2.0 * np.pi / scenario.motion.roll_period_s
    tau = scenario.sensors.ahrs.lag_time_constant_s
    # A first-order lag delays a sine by atan(ωτ)/ω (0.29 s for 0.3 s at 6.5 s).
    assert delay_s == pytest.approx(np.arctan(omega * tau) / omega, abs=1.5 * sample_s)


def test_motion_pack_claims_the_data_sheet_sigma_while_its_lag_error_is_far_larger():
    scenario = load_scenario(NO_GNSS, ["duration_s=300"])
    messages, truth = scenario_messages(scenario, {"imu"})
    t, attitude, pack = pack_attitude(messages, scenario)
    claimed_deg = np.degrees(np.sqrt([pack[0].orientation_covariance[i] for i in (0, 4, 8)]))
    assert claimed_deg == pytest.approx([0.1, 0.1, 0.5], rel=1e-9)
    assert all(
        np.array_equal(m.orientation_covariance, pack[0].orientation_covariance) for m in pack
    )
    error = (declination_turn(scenario).inv() * attitude).as_euler("ZYX") - truth.evaluate(
        t
    ).attitude.as_euler("ZYX")
    error = (error + np.pi) % (2.0 * np.pi) - np.pi
    settled = t > 2.0
    roll_rms_deg = np.degrees(np.sqrt(np.mean(error[settled, 2] ** 2)))
    pitch_rms_deg = np.degrees(np.sqrt(np.mean(error[settled, 1] ** 2)))
    # Physics: a first-order lag τ leaves A ωτ / sqrt(1 + (ωτ)²) of a sine of amplitude A, RMS
    # that over sqrt(2); the pack's slow error and noise add in quadrature.
    motion = scenario.motion
    ahrs = scenario.sensors.ahrs
    omega = 2.0 * np.pi / motion.roll_period_s
    lag_share = omega * ahrs.lag_time_constant_s / np.hypot(1.0, omega * ahrs.lag_time_constant_s)
    other_deg = np.hypot(ahrs.error_deg, ahrs.noise_deg)
    expected_roll = np.hypot(motion.roll_amplitude_deg * lag_share / np.sqrt(2.0), other_deg)
    expected_pitch = np.hypot(motion.pitch_amplitude_deg * lag_share / np.sqrt(2.0), other_deg)
    assert roll_rms_deg == pytest.approx(expected_roll, rel=0.1)
    assert pitch_rms_deg == pytest.approx(expected_pitch, rel=0.1)
    # The covariance under-claims by the configured amount: 0.1 deg against about 1.8 deg.
    assert roll_rms_deg / claimed_deg[0] > 15.0
    assert pitch_rms_deg / claimed_deg[1] > 12.0


def fit_ellipsoid(points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(centre, shape matrix A with (x − c)ᵀ A (x − c) = 1) of the quadric through points,
    by linear least squares on xᵀ A x + bᵀ x + d = 1."""
    x, y, z = points.T
    design = np.column_stack(
        [x * x, y * y, z * z, 2 * x * y, 2 * x * z, 2 * y * z, x, y, z, np.ones_like(x)]
    )
    # Scale-free: the smallest right singular vector of the homogeneous system.
    coefficients = np.linalg.svd(design, full_matrices=False)[2][-1]
    a, b, c, d, e, f = coefficients[:6]
    quadric = np.array([[a, d, e], [d, b, f], [e, f, c]])
    linear = coefficients[6:9]
    centre = -0.5 * np.linalg.solve(quadric, linear)
    scale = centre @ quadric @ centre - coefficients[9]
    return centre, quadric / scale


def measured_field_ut(scenario) -> np.ndarray:
    messages, _ = scenario_messages(scenario, {"imu"})
    field_t = [
        [m.magnetic_field.x, m.magnetic_field.y, m.magnetic_field.z]
        for _, m in on_topic(messages, "imu/mag")
    ]
    return np.array(field_t) / TESLA_PER_MICROTESLA


@pytest.mark.parametrize("noise_ut", [0.0, None])
def test_magnetometer_ellipsoid_is_centred_on_the_hard_iron_and_shaped_by_the_soft_iron(noise_ut):
    # The measured buoy's magnetometer, turned over as for a calibration (the turning run).
    magnetometer = load_scenario(NO_GNSS).sensors.magnetometer
    overrides = [
        f"sensors.magnetometer.hard_iron_ut={list(magnetometer.hard_iron_ut)}",
        f"sensors.magnetometer.soft_iron={list(magnetometer.soft_iron)}",
    ]
    if noise_ut is not None:
        overrides.append(f"sensors.magnetometer.noise_ut={noise_ut}")
    scenario = load_scenario("turning", overrides)
    centre, shape = fit_ellipsoid(measured_field_ut(scenario))
    # Without noise the field lies exactly on the ellipsoid; with the sensor's 0.1 µT noise
    # an algebraic fit of 2000 samples lands within a few noise σ.
    noise = scenario.sensors.magnetometer.noise_ut
    tolerance_ut = 1e-6 if noise == 0.0 else 3.0 * noise
    assert centre == pytest.approx(magnetometer.hard_iron_ut, abs=tolerance_ut)
    # measured − hard iron = S B with |B| constant: (S⁻ᵀ S⁻¹) up to the field's magnitude.
    soft_iron = np.reshape(magnetometer.soft_iron, (3, 3))
    expected = np.linalg.inv(soft_iron @ soft_iron.T)
    assert shape / np.trace(shape) == pytest.approx(
        expected / np.trace(expected), abs=1e-9 if noise == 0.0 else 2e-3
    )


def test_single_gnss_antenna_at_1_hz_off_the_imu_grid_on_its_mast():
    scenario = load_scenario(SINGLE_GNSS, ["duration_s=60"])
    messages, truth = scenario_messages(scenario, {"imu", "gnss"})
    topics = {topic for topic, _, _ in messages if topic.startswith("gnss/")}
    assert topics == {"gnss/fix", "gnss/vel"}
    fixes = on_topic(messages, "gnss/fix")
    stamps = np.array([stamp for stamp, _ in fixes], dtype=np.int64)
    assert set(np.diff(stamps)) == {1_000_000_000}
    assert set((stamps - scenario.start_time_ns) % 1_000_000_000) == {310_000_000}
    assert [stamp for stamp, _ in on_topic(messages, "gnss/vel")] == list(stamps)
    imu_stamps = np.array([stamp for stamp, _ in on_topic(messages, "imu/data_raw")])
    nearest_ns = np.min(np.abs(stamps[:, None] - imu_stamps[None, :]), axis=1)
    # Halfway between two 50 Hz samples: no GNSS sample shares a stamp with the IMU.
    assert set(nearest_ns) == {10_000_000}
    # The antenna's place: the fix minus the truth's base_link is R·lever, to the fix noise.
    t = scenario_time_s(scenario, stamps)
    state = truth.evaluate(t)
    origin_rad = np.radians([scenario.origin_latitude_deg, scenario.origin_longitude_deg])
    fix_enu = geodetic_to_enu_m(
        np.radians([m.latitude for _, m in fixes]),
        np.radians([m.longitude for _, m in fixes]),
        np.array([m.altitude for _, m in fixes]),
        *origin_rad,
        scenario.origin_altitude_m,
    )
    base_enu = geodetic_to_enu_m(
        np.radians(state.latitude_deg),
        np.radians(state.longitude_deg),
        state.altitude_m,
        *origin_rad,
        scenario.origin_altitude_m,
    )
    lever_m = np.asarray(scenario.sensors.extrinsics.primary_antenna_body_m)
    assert tuple(lever_m) == (0.1, 0.2, 1.9)
    residual = fix_enu - base_enu - state.attitude.apply(lever_m)
    gnss = scenario.sensors.gnss
    assert np.abs(residual[:, :2]).max() < 5 * gnss.position_noise_horizontal_m
    assert np.abs(residual[:, 2]).max() < 5 * gnss.position_noise_vertical_m
    # The mast is seen: without it the fix would be metres off.
    assert np.abs(fix_enu - base_enu).max(axis=0)[2] > 1.5


def test_gnss_outages_silence_every_gnss_topic_and_nothing_else():
    scenario = load_scenario(OUTAGES, ["duration_s=200"])
    without = load_scenario(OUTAGES, ["duration_s=200", "sensors.gnss.silent_outages_s=[]"])
    messages, _ = scenario_messages(scenario)
    reference, _ = scenario_messages(without)
    (start, end), *_ = scenario.sensors.gnss.silent_outages_s
    assert (start, end) == (120.0, 180.0)

    def silenced(topic, stamp):
        return topic.startswith("gnss/") and start <= scenario_time_s(scenario, stamp) < end

    kept = [(topic, stamp) for topic, stamp, _ in reference if not silenced(topic, stamp)]
    assert [(topic, stamp) for topic, stamp, _ in messages] == kept
    assert len(kept) < len(reference)
    silent_gnss = [(topic, stamp) for topic, stamp, _ in reference if silenced(topic, stamp)]
    assert {topic for topic, _ in silent_gnss} == {"gnss/fix", "gnss/vel"}
    assert len(silent_gnss) == 2 * 60
    # The samples either side are the same measurements as without the outage.
    fixes = [m.latitude for topic, _, m in messages if topic == "gnss/fix"]
    reference_fixes = [
        m.latitude
        for topic, stamp, m in reference
        if topic == "gnss/fix" and not silenced(topic, stamp)
    ]
    assert fixes == reference_fixes


def test_moored_buoy_without_gnss_carries_no_gnss_topic_and_stays_on_its_mooring():
    scenario = load_scenario(NO_GNSS, ["duration_s=120"])
    messages, truth = scenario_messages(scenario)
    topics = {topic for topic, _, _ in messages}
    assert not topics & set(GNSS_TOPICS)
    assert {"imu/data_raw", "imu/data", "imu/mag", "anemometer/wind"} <= topics
    rates_hz = {
        topic: (len(on_topic(messages, topic)) - 1) / scenario.duration_s
        for topic in ("imu/data_raw", "imu/data", "imu/mag", "anemometer/wind")
    }
    assert rates_hz == {
        "imu/data_raw": 50.0,
        "imu/data": 50.0,
        "imu/mag": 10.0,
        "anemometer/wind": 10.0,
    }
    assert scenario.current is None
    state = truth.evaluate(np.arange(0.0, scenario.duration_s, 0.02))
    # Wave orbital motion only: no drift away from the mooring.
    assert np.linalg.norm(state.velocity_enu_mps[:, :2].mean(axis=0)) < 0.01


@pytest.mark.parametrize(
    "name",
    [
        "measured_moored_no_gnss",
        "measured_moored_single_gnss",
        "set_a_imperfect",
        "set_b_imperfect",
        "set_c_imperfect",
        "set_d_imperfect",
        "set_e_imperfect",
    ],
)
def test_imperfect_scenarios_carry_the_imperfections_of_their_set(name):
    scenario = load_scenario(name)
    sensors = scenario.sensors
    assert sensors.rates.imu_hz == 50.0
    if sensors.gnss.receiver != "none":
        assert (sensors.rates.gnss_hz, sensors.rates.gnss_offset_s) == (1.0, 0.31)
        assert sensors.extrinsics.primary_antenna_body_m == (0.1, 0.2, 1.9)
    else:
        assert scenario.current is None
    if sensors.magnetometer.fitted:
        assert sensors.magnetometer.hard_iron_ut == (18.0, -27.5, 12.0)
        soft_iron = np.reshape(sensors.magnetometer.soft_iron, (3, 3))
        assert np.diag(soft_iron) == pytest.approx([1.08, 0.93, 1.02])
        assert np.abs(soft_iron - np.diag(np.diag(soft_iron))).max() <= 0.07
    if sensors.ahrs.fitted:
        assert sensors.ahrs.lag_time_constant_s == 0.3
        assert sensors.ahrs.claimed_sigma_deg == (0.1, 0.1, 0.5)
        assert sensors.ahrs.sample_every == 1
