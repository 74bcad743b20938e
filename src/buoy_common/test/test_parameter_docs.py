"""Parameter files and reference written from declarations: values that read back as they were
declared, nesting by the dotted names, and defaults that cannot be written left as comments."""

import dataclasses
import math

import pytest
import yaml

from buoy_common.parameter_declarations import (
    NON_NEGATIVE,
    FileSection,
    NodeParameters,
    ParameterFile,
    ParameterSets,
    broken_rules,
    declared_parameters,
    open_interval,
    parameter,
)
from buoy_common.parameter_docs import outdated_files, parameter_file_text, reference_text
from buoy_common.parameters import load_parameter_files


@dataclasses.dataclass(frozen=True)
class _Example:
    noise_mps: float = parameter(0.05, unit="m/s", meaning="white noise", rule=NON_NEGATIVE)
    probability: float = parameter(0.9999, meaning="gate", rule=open_interval(0.0, 1.0))
    floor_m2: float = parameter(1e-6, unit="m²", meaning="smallest variance")
    large: float = parameter(2.5e20, meaning="a large number")
    count: int = parameter(3, meaning="a count")
    enabled: bool = parameter(True, meaning="a switch", heading="Switches")
    frame: str = parameter("anemometer_link", meaning="a frame")
    empty: str = parameter("", meaning="no node")
    vector: tuple[float, float, float] = parameter((0.0, -1.5, 3.0), unit="m", meaning="a lever")
    unset: float = parameter(math.nan, meaning="NaN: unset")
    intervals: tuple[tuple[float, float], ...] = parameter((), unit="s", meaning="outages")


def _example_sets() -> ParameterSets:
    declared = tuple(declared_parameters(_Example, "example."))
    section = FileSection("/**", declared, "a wildcard section")
    files = (ParameterFile("config/example.yaml", ("Example.",), (section,)),)
    return ParameterSets("example", (NodeParameters("example_node", "example", declared),), files)


def test_a_generated_file_reads_back_every_writable_default_as_declared(tmp_path):
    sets = _example_sets()
    path = tmp_path / "example.yaml"
    path.write_text(parameter_file_text(sets.files[0]))
    values = load_parameter_files([path], "example_node")
    expected = {
        f"example.{field.name}": field.default
        for field in dataclasses.fields(_Example)
        if field.name not in ("unset", "intervals")
    }
    expected["example.vector"] = [0.0, -1.5, 3.0]
    assert values == expected
    assert all(type(values[name]) is type(expected[name]) for name in expected)


def test_unwritable_defaults_and_headings_are_comments():
    text = parameter_file_text(_example_sets().files[0])
    assert "      # unset: .nan" in text
    assert "      # intervals: []" in text
    assert "      # Switches\n      enabled: true" in text
    assert "noise_mps: 0.05" in text and "# white noise, m/s" in text
    assert yaml.safe_load(text)["/**"]["ros__parameters"]["example"]["floor_m2"] == 1e-6


def test_a_commented_section_sets_nothing():
    declared = tuple(declared_parameters(_Example, "example."))
    text = parameter_file_text(
        ParameterFile("x.yaml", ("X.",), (FileSection("/**/node", declared, commented=True),))
    )
    assert yaml.safe_load(text) is None
    assert "# /**/node:\n#   ros__parameters:\n#     example:\n" in text


def test_the_reference_has_a_row_per_parameter_with_type_default_unit_and_rule():
    text = reference_text([_example_sets()])
    assert "| `example.noise_mps` | double | `0.05` | m/s | ≥ 0 | white noise |" in text
    assert "| `example.vector` | double[3] | `[0.0, -1.5, 3.0]` | m |  | a lever |" in text
    assert "| `example.unset` | double | `NaN` |" in text
    assert "| `example.count` | integer | `3` |" in text


def test_a_file_changed_by_hand_is_outdated(tmp_path):
    sets = _example_sets()
    for path, text in {"config/example.yaml": parameter_file_text(sets.files[0])}.items():
        (tmp_path / path).parent.mkdir(parents=True)
        (tmp_path / path).write_text(text)
    (tmp_path / "docs").mkdir()
    (tmp_path / "docs" / "parameters.md").write_text(reference_text([sets]))
    assert outdated_files(tmp_path, [sets]) == []
    changed = (tmp_path / "config/example.yaml").read_text().replace("0.05", "0.06")
    (tmp_path / "config/example.yaml").write_text(changed)
    assert outdated_files(tmp_path, [sets]) == ["config/example.yaml"]


@pytest.mark.parametrize(
    ("values", "broken"),
    [({}, []), ({"noise_mps": -0.1}, ["noise_mps"]), ({"probability": 1.0}, ["probability"])],
)
def test_broken_rules_names_the_fields_whose_value_breaks_its_declared_rule(values, broken):
    config = _Example(**values)
    assert [name for name, _ in broken_rules(config)] == broken
