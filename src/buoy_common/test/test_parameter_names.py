"""Unknown parameter names: refused with the closest known name, other nodes' keys tolerated."""

import pytest

from buoy_common.parameters import (
    ParameterError,
    check_parameter_files,
    check_parameter_names,
    command_line_parameters,
)

KNOWN = ["anemometer.position", "anemometer.rpy_deg", "compensation.max_nav_gap_s"]


def test_a_misspelt_shared_key_of_an_own_group_is_refused_with_the_closest_name():
    with pytest.raises(ParameterError) as error:
        check_parameter_names(KNOWN, shared=["anemometer.postion"])
    assert "'anemometer.postion'" in str(error.value)
    assert "did you mean 'anemometer.position'?" in str(error.value)


def test_shared_keys_of_other_nodes_groups_are_ignored():
    check_parameter_names(KNOWN, shared=["gnss.secondary_antena", "fusion.anything", "scenario"])


def test_own_and_command_line_keys_must_all_be_known():
    with pytest.raises(ParameterError, match=r"'gnss\.primary_antenna'"):
        check_parameter_names(KNOWN, own=["gnss.primary_antenna"])
    check_parameter_names(KNOWN, own=["use_sim_time", "compensation.max_nav_gap_s"])


def test_every_unknown_name_is_listed():
    with pytest.raises(ParameterError) as error:
        check_parameter_names(KNOWN, shared=["anemometer.postion"], own=["compensation.xyz"])
    message = str(error.value)
    assert "'anemometer.postion'" in message and "'compensation.xyz'" in message


def test_files_sections_are_told_apart(tmp_path):
    shared = tmp_path / "shared.yaml"
    shared.write_text(
        "/**:\n  ros__parameters:\n    gnss: {secondary_antena: [1.0, 0.0, 1.0]}\n"
        "compensation_node:\n  ros__parameters:\n    compensation: {max_nav_gap_s: 0.2}\n"
        "other_node:\n  ros__parameters:\n    anemometer: {postion: [0.0, 0.0, 1.0]}\n"
    )
    check_parameter_files([shared], "compensation_node", KNOWN)
    with pytest.raises(ParameterError, match=r"did you mean 'anemometer\.position'"):
        check_parameter_files([shared], "other_node", KNOWN)


def test_command_line_parameters_reads_every_ros_arguments_block():
    files, names = command_line_parameters(
        [
            "node",
            "-p",
            "not_ros",
            "--ros-args",
            "--params-file",
            "a.yaml",
            "-p",
            "x.y:=1",
            "--",
            "--ros-args",
            "--param",
            "z:=true",
        ]
    )
    assert files == ["a.yaml"]
    assert names == ["x.y", "z"]


def test_a_group_no_node_of_the_suite_reads_is_refused_naming_the_closest_group():
    # A misspelt group in a shared file would otherwise be ignored by every node.
    with pytest.raises(ParameterError) as error:
        check_parameter_names(KNOWN, shared=["compenstion.max_nav_gap_s"])
    message = str(error.value)
    assert "unknown parameter group 'compenstion'" in message
    assert "did you mean 'compensation'?" in message


def test_a_group_unknown_to_the_suite_is_refused_in_a_nodes_own_section():
    with pytest.raises(ParameterError, match=r"group 'anemometr'.*did you mean 'anemometer'"):
        check_parameter_names(KNOWN, own=["anemometr.position"])


def test_groups_of_other_nodes_of_the_suite_and_of_ros_are_accepted_in_shared_sections():
    check_parameter_names(
        KNOWN,
        shared=["fusion.moored", "imu.gyro_noise_deg_sqrt_h", "seed", "qos_overrides./a.depth"],
    )


def test_the_suite_groups_are_a_parameter():
    check_parameter_names(KNOWN, shared=["other.x"], suite_groups={"other"})
    with pytest.raises(ParameterError, match="group 'other'"):
        check_parameter_names(KNOWN, shared=["other.x"], suite_groups=set())


def test_an_undotted_name_no_node_reads_is_refused_naming_the_closest():
    with pytest.raises(ParameterError, match=r"unknown parameter 'sead': .*did you mean 'seed'"):
        check_parameter_names(KNOWN, shared=["sead"])
