"""The parameter files and docs/parameters.md are what the declarations give: a default changed
by hand, a parameter missing or unknown in a file is a failure naming it; and the groups a node
accepts from other nodes are exactly the groups the suite's packages declare."""

from __future__ import annotations

from pathlib import Path

import pytest

from buoy_common.extrinsics import SHARED_PARAMETERS
from buoy_common.parameter_declarations import is_writable_default
from buoy_common.parameter_docs import generated_files, suite_parameter_sets
from buoy_common.parameters import (
    SUITE_PARAMETER_GROUPS,
    ParameterError,
    coerce_parameter,
    config_parameters,
    load_parameter_files,
    load_parameter_sections,
    parameter_group,
)
from buoy_nav.config import (
    FUSION_FIELDS_NOT_PARAMETERS,
    FUSION_PARAMETER_PREFIX,
    FusionConfig,
    fusion_config_from_files,
)
from wind_comp.config import compensator_config_from_files

REPO = Path(__file__).resolve().parents[2]
SUITE = suite_parameter_sets()
FILES = [parameter_file for sets in SUITE for parameter_file in sets.files]
# Parameters of nodes whose parameters are declared in their node modules.
UNDECLARED_NODE_GROUPS = {
    "wait_for_subscribers_timeout_s",
    "drain_timeout_s",
    "port",
    "address",
    "topics",
}


def test_every_package_of_the_suite_declares_its_parameters():
    assert [sets.package for sets in SUITE] == ["buoy_nav", "sensor_sim", "wind_comp"]


@pytest.mark.parametrize("path", sorted(generated_files(SUITE)))
def test_the_generated_file_is_current(path):
    expected = generated_files(SUITE)[path]
    assert (REPO / path).read_text() == expected, (
        f"{path} differs from the declarations: change the declaration, then run "
        "`python -m buoy_common.parameter_docs --write`"
    )


def _section_values(path: Path, target: str) -> dict:
    node = target.removeprefix("/**/") if target != "/**" else "any_node"
    wildcard, own = load_parameter_sections([path], node)
    return wildcard if target == "/**" else own


def _drift(parameter_file) -> list[str]:
    """What a parameter file says that its declarations do not: each problem in words."""
    problems = []
    for section in parameter_file.sections:
        if section.commented:
            continue
        found = _section_values(REPO / parameter_file.path, section.target)
        declared = {p.name: p.default for p in section.parameters if is_writable_default(p.default)}
        problems += [f"{name} is missing" for name in declared.keys() - found.keys()]
        problems += [
            f"{name} is not a declared parameter" for name in found.keys() - declared.keys()
        ]
        for name in declared.keys() & found.keys():
            value = coerce_parameter(name, found[name], declared[name])
            if value != declared[name]:
                problems.append(f"{name} is {value!r}, declared {declared[name]!r}")
    return sorted(problems)


@pytest.mark.parametrize("parameter_file", FILES, ids=[f.path for f in FILES])
def test_a_parameter_file_holds_each_declared_parameter_with_its_default(parameter_file):
    problems = _drift(parameter_file)
    assert not problems, f"{parameter_file.path}: " + "; ".join(problems)


def test_every_fusion_parameter_is_in_fusion_yaml():
    (fusion,) = [f for f in FILES if f.path.endswith("fusion.yaml")]
    values = _section_values(REPO / fusion.path, "/**")
    (node,) = [n for sets in SUITE for n in sets.nodes if n.node == "fusion_node"]
    own = {p.name for p in node.parameters if p.name not in SHARED_PARAMETERS}
    fields = {
        name
        for _, name, _ in config_parameters(
            FusionConfig, FUSION_PARAMETER_PREFIX, skip=FUSION_FIELDS_NOT_PARAMETERS
        )
        if name not in SHARED_PARAMETERS
    }
    # The node declares a parameter for every configuration field, and the file lists them all.
    assert own == fields
    assert set(values) == own


def test_the_groups_every_node_accepts_are_those_the_suite_declares():
    declared = {
        parameter_group(p.name) for sets in SUITE for node in sets.nodes for p in node.parameters
    }
    declared |= {parameter_group(name) for name in SHARED_PARAMETERS}
    assert declared | UNDECLARED_NODE_GROUPS == SUITE_PARAMETER_GROUPS


@pytest.mark.parametrize(
    "from_files", [fusion_config_from_files, compensator_config_from_files], ids=["fusion", "wind"]
)
def test_offline_tools_refuse_a_misspelt_group_of_a_shared_file(from_files, tmp_path):
    path = tmp_path / "misspelt.yaml"
    path.write_text("/**:\n  ros__parameters:\n    compenstion:\n      max_nav_gap_s: 0.2\n")
    with pytest.raises(ParameterError, match=r"group 'compenstion'.*did you mean 'compensation'"):
        from_files([path])


SIGMA_LIMITS = {
    "compensation_node": (
        "compensation.max_attitude_sigma_deg",
        "compensation.max_wind_sigma_horizontal_mps",
        "compensation.max_wind_sigma_vertical_mps",
    ),
    "current_node": (
        "current.max_attitude_sigma_deg",
        "current.max_current_sigma_horizontal_mps",
        "current.max_current_sigma_vertical_mps",
    ),
}
SHIPPED_PARAMETER_FILES = sorted(
    path.relative_to(REPO)
    for pattern in ("src/*/config/**/*.yaml", "bags/*.yaml", "tools/*.yaml")
    for path in REPO.glob(pattern)
    if "ros__parameters" in path.read_text()
)


def test_the_shipped_parameter_files_are_found():
    assert Path("src/buoy_common/config/records/ooi_fdchp_params.yaml") in SHIPPED_PARAMETER_FILES
    assert len(SHIPPED_PARAMETER_FILES) >= 8


@pytest.mark.parametrize("path", SHIPPED_PARAMETER_FILES, ids=str)
def test_no_shipped_parameter_file_widens_a_sigma_limit(path):
    """A sample is valid only while its uncertainty is within the limits: a shipped file may
    tighten them, never widen them past their defaults."""
    defaults = {
        declared.name: declared.default
        for sets in SUITE
        for node in sets.nodes
        for declared in node.parameters
    }
    for node, names in SIGMA_LIMITS.items():
        values = load_parameter_files([REPO / path], node)
        for name in names:
            assert float(values.get(name, defaults[name])) <= defaults[name], (
                f"{path} sets {name} to {values[name]}, above its default {defaults[name]}"
            )
