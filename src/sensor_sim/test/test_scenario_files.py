"""Scenario loading: shipped files, overrides, and the errors a user can make."""

from __future__ import annotations

import numpy as np
import pytest

from sensor_sim.scenario import (
    DEFAULT_START_TIME_NS,
    Scenario,
    ScenarioError,
    available_scenarios,
    load_scenario,
)

SHIPPED = [
    "measured_moored_no_gnss",
    "measured_moored_single_gnss",
    "moored_motion_pack",
    "open_ocean",
    "sea_state",
    "set_a_imperfect",
    "set_b_imperfect",
    "set_c_imperfect",
    "set_d_imperfect",
    "set_e_imperfect",
    "ship_current",
    "six_position",
    "static",
    "tilt_table",
    "turning",
    "vertical_wind",
    "wind_tunnel",
]


def test_all_shipped_scenarios_are_listed_and_load():
    assert available_scenarios() == SHIPPED
    for name in SHIPPED:
        scenario = load_scenario(name)
        assert isinstance(scenario, Scenario)
        assert scenario.name == name
        assert scenario.description
        assert scenario.duration_s > 0
        assert scenario.start_time_ns == DEFAULT_START_TIME_NS


def test_default_epoch_is_2026_new_year_utc():
    from datetime import UTC, datetime

    epoch = datetime(2026, 1, 1, tzinfo=UTC).timestamp()
    assert int(epoch) * 1_000_000_000 == DEFAULT_START_TIME_NS


def test_overrides_reach_typed_fields():
    scenario = load_scenario(
        "wind_tunnel",
        overrides=["wind.speed_mps=15", "duration_s=120", "motion.roll_amplitude_deg=12"],
    )
    assert scenario.wind.speed_mps == 15.0
    assert isinstance(scenario.wind.speed_mps, float)
    assert scenario.duration_s == 120.0
    assert scenario.motion.roll_amplitude_deg == 12.0
    # Untouched keys keep the file's values.
    assert scenario.motion.sway_amplitude_deg == 15.0


def test_seed_argument_replaces_file_seed_and_override_order_applies():
    assert load_scenario("static").seed == 1
    assert load_scenario("static", seed=42).seed == 42
    assert load_scenario("static", overrides=["seed=7", "seed=8"]).seed == 8
    assert load_scenario("static", overrides=["seed=7"], seed=9).seed == 9


def test_sections_can_be_created_and_removed_by_override():
    static = load_scenario("static")
    assert static.current is None
    drifting = load_scenario("static", overrides=["current.speed_mps=0.3"])
    assert drifting.current is not None
    assert drifting.current.speed_mps == 0.3
    moored = load_scenario("sea_state", overrides=["current=null"])
    assert moored.current is None


def test_outage_lists_become_tuples_of_intervals():
    scenario = load_scenario(
        "static", overrides=["sensors.gnss.fix_outages_s=[[10, 20.5], [30, 40]]"]
    )
    assert scenario.sensors.gnss.fix_outages_s == ((10.0, 20.5), (30.0, 40.0))


def test_scenario_file_by_path(tmp_path):
    path = tmp_path / "harbour.yaml"
    path.write_text("description: test\nduration_s: 12\nwind:\n  speed_mps: 3\n")
    scenario = load_scenario(str(path))
    assert scenario.name == "harbour"
    assert scenario.duration_s == 12.0
    assert scenario.wind.speed_mps == 3.0


def test_stamps_are_epoch_plus_scenario_time():
    scenario = load_scenario("static")
    stamps = scenario.stamps_ns([0.0, 0.1, 2000.0])
    assert stamps.dtype == np.int64
    assert list(stamps - scenario.start_time_ns) == [0, 100_000_000, 2_000_000_000_000]


def test_unknown_scenario_names_the_shipped_ones():
    with pytest.raises(ScenarioError, match=r"unknown scenario 'storm'.*sea_state"):
        load_scenario("storm")


def test_unreadable_file(tmp_path):
    with pytest.raises(ScenarioError, match="cannot read"):
        load_scenario(str(tmp_path / "missing.yaml"))


def test_malformed_yaml_names_the_file(tmp_path):
    path = tmp_path / "broken.yaml"
    path.write_text("wind: {speed_mps: 5\nmotion: [\n")
    with pytest.raises(ScenarioError, match=r"broken\.yaml.*malformed YAML"):
        load_scenario(str(path))


def test_top_level_must_be_a_mapping(tmp_path):
    path = tmp_path / "list.yaml"
    path.write_text("- 1\n- 2\n")
    with pytest.raises(ScenarioError, match="top level must be a mapping"):
        load_scenario(str(path))


def test_unknown_key_in_file_is_named(tmp_path):
    path = tmp_path / "typo.yaml"
    path.write_text("wind:\n  sped_mps: 5\n")
    with pytest.raises(ScenarioError, match=r"typo\.yaml.*unknown key 'wind\.sped_mps'"):
        load_scenario(str(path))


@pytest.mark.parametrize(
    ("override", "pattern"),
    [
        ("wind.sped_mps=5", r"override 'wind\.sped_mps=5': unknown key"),
        ("nonsense=1", r"override 'nonsense=1': unknown key"),
        ("wind.speed_mps.x=1", r"wind\.speed_mps is a value, not a section"),
        ("wind.speed_mps", "expected the form dotted.key=value"),
        ("wind.speed_mps=[1, 2", "not valid YAML"),
    ],
)
def test_bad_override_syntax_or_key(override, pattern):
    with pytest.raises(ScenarioError, match=pattern):
        load_scenario("static", overrides=[override])


@pytest.mark.parametrize(
    ("override", "pattern"),
    [
        ("wind.speed_mps=fast", r"wind\.speed_mps = 'fast': expected a number"),
        ("wind.speed_mps=true", r"wind\.speed_mps = True: expected a number"),
        ("seed=1.5", r"seed = 1\.5: expected an integer"),
        ("motion.sway_axis=yaw", r"motion\.sway_axis = 'yaw': expected one of 'roll', 'pitch'"),
        ("wind=5", r"wind must be a mapping"),
        ("sensors.gnss.fix_outages_s=[[1, 2, 3]]", r"fix_outages_s\[0\].*list of 2 items"),
        ("duration_s=.nan", r"duration_s = nan: expected a finite number"),
    ],
)
def test_wrong_types_name_key_value_and_override(override, pattern):
    with pytest.raises(ScenarioError, match=pattern) as error:
        load_scenario("static", overrides=[override])
    assert f"override {override!r}" in str(error.value)


@pytest.mark.parametrize(
    ("override", "pattern"),
    [
        ("wind.speed_mps=-3", r"wind\.speed_mps = -3\.0: must be >= 0"),
        ("duration_s=0", r"duration_s = 0\.0: must be > 0"),
        ("motion.roll_period_s=0", r"motion\.roll_period_s = 0\.0: must be > 0"),
        ("origin_latitude_deg=89.9", r"origin_latitude_deg = 89\.9: must be within"),
        ("sensors.imu.gyro_bias_correlation_time_s=0", r"sensors\.imu\.gyro_bias_corr"),
        ("sensors.gnss.fix_outages_s=[[20, 10]]", r"start < end"),
        ("motion.sway_period_s=8", r"motion\.sway_period_s = 8\.0: must be >= 11\.000 s"),
        ("motion.pitch_amplitude_deg=70", r"pitch could reach 85\.0 deg"),
    ],
)
def test_non_physical_values_are_refused(override, pattern):
    name = "wind_tunnel" if "sway" in override or "pitch" in override else "static"
    overrides = [override, "motion.pitch_deg=15"] if "pitch_amp" in override else [override]
    with pytest.raises(ScenarioError, match=pattern):
        load_scenario(name, overrides=overrides)


def test_negative_seed_argument_is_refused():
    with pytest.raises(ScenarioError, match=r"seed argument -1.*seed = -1: must be >= 0"):
        load_scenario("static", seed=-1)


def test_name_key_is_refused(tmp_path):
    path = tmp_path / "named.yaml"
    path.write_text("name: other\n")
    with pytest.raises(ScenarioError, match="'name' is not allowed"):
        load_scenario(str(path))


@pytest.mark.parametrize(
    ("override", "named"),
    [
        ("sensors.rates.gnss_offset_s=0.1", "sensors.rates.gnss_offset_s"),
        ("sensors.ahrs.claimed_sigma_deg=[0.1, -0.1, 0.5]", "sensors.ahrs.claimed_sigma_deg"),
        ("sensors.extrinsics.primary_antenna_body_m=[0.7, 0, 1]", "gnss.secondary_antenna"),
    ],
)
def test_imperfection_options_refuse_impossible_values(override, named):
    # gnss_offset_s must stay within one period of the receiver (10 Hz: 0.1 s).
    with pytest.raises(ScenarioError, match=named.replace(".", r"\.")):
        load_scenario("sea_state", overrides=[override])


def test_imperfection_options_default_to_the_perfect_sensors():
    sensors = load_scenario("sea_state").sensors
    assert sensors.rates.gnss_offset_s == 0.0
    assert sensors.extrinsics is None
    assert sensors.gnss.silent_outages_s == ()
    assert np.isnan(sensors.ahrs.claimed_sigma_deg).all()
