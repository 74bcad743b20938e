"""Each parameter declared once: name, type, default, unit, rule and meaning.

A configuration dataclass declares a field of its own with :func:`parameter`, a field backed by a
parameter every node shares with :func:`buoy_common.extrinsics.shared_field`. The dataclass stays
the typed configuration the code uses; :func:`buoy_common.parameters.config_parameters` reads its
defaults, :func:`broken_rules` applies its rules, and :func:`declared_parameters` lists it with
units and meanings for the parameter files and the reference that
:mod:`buoy_common.parameter_docs` generates.

A package makes its nodes' parameters known to that generator with :class:`ParameterSets`,
registered under the entry point group :data:`ENTRY_POINT_GROUP`.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable, Iterable, Mapping
from dataclasses import dataclass
from typing import Any

from buoy_common.extrinsics import SHARED_PARAMETERS, field_parameter
from buoy_common.parameters import config_parameters, is_interval_list

DECLARATION_METADATA_KEY = "declaration"
ENTRY_POINT_GROUP = "buoy_common.parameter_sets"
"""Entry points of this group are functions returning a package's :class:`ParameterSets`."""
WILDCARD_SECTION_COMMENT = (
    "a wildcard section, so that `-p name:=value` on the command line still wins"
)


@dataclass(frozen=True)
class Rule:
    """What a valid value is: ``text`` completes "must be ..." ("> 0", "in (0, 1)"),
    ``holds(value)`` tells whether a value is one."""

    text: str
    holds: Callable[[Any], bool]

    def __str__(self) -> str:
        return self.text


NON_NEGATIVE = Rule("≥ 0", lambda value: value >= 0.0)
POSITIVE = Rule("> 0", lambda value: value > 0.0)


def at_least(bound: float) -> Rule:
    return Rule(f"≥ {bound:g}", lambda value: value >= bound)


def open_interval(low: float, high: float) -> Rule:
    return Rule(f"in ({low:g}, {high:g})", lambda value: low < value < high)


def half_open_interval(low: float, high: float) -> Rule:
    return Rule(f"in [{low:g}, {high:g})", lambda value: low <= value < high)


def closed_interval(low: float, high: float) -> Rule:
    return Rule(f"in [{low:g}, {high:g}]", lambda value: low <= value <= high)


def one_of(*choices: str) -> Rule:
    return Rule(f"one of {', '.join(choices)}", lambda value: value in choices)


def custom_rule(text: str, holds: Callable[[Any], bool]) -> Rule:
    """A rule of its own (a matrix, a set of values)."""
    return Rule(text, holds)


@dataclass(frozen=True)
class Declaration:
    """What a field's metadata says of its parameter besides its name and default.

    ``heading`` starts a group of related parameters in the generated files."""

    meaning: str
    unit: str = ""
    rule: Rule | None = None
    heading: str | None = None


def parameter(
    default: Any,
    *,
    meaning: str,
    unit: str = "",
    rule: Rule | None = None,
    heading: str | None = None,
) -> Any:
    """A dataclass field backed by a parameter of the node's own: its default, one line of
    meaning, its unit ("" for a dimensionless value, a name or a switch) and its rule."""
    declaration = Declaration(meaning, unit, rule, heading)
    return dataclasses.field(default=default, metadata={DECLARATION_METADATA_KEY: declaration})


def field_declaration(field: dataclasses.Field) -> Declaration:
    """The declaration of a field's parameter, shared or its own."""
    shared = field_parameter(field)
    if shared is not None:
        declared = SHARED_PARAMETERS[shared]
        holds = Rule(declared.rule, lambda value: declared.check(value) is None)
        return Declaration(declared.meaning, declared.unit, holds)
    declaration = field.metadata.get(DECLARATION_METADATA_KEY)
    if declaration is None:
        raise TypeError(f"configuration field '{field.name}' is declared without parameter()")
    return declaration


def broken_rules(config: Any) -> list[tuple[str, Rule]]:
    """(field name, rule) of every field of its own whose value breaks its declared rule, in
    field order."""
    broken = []
    for field in dataclasses.fields(config):
        declaration = field.metadata.get(DECLARATION_METADATA_KEY)
        if declaration is None or declaration.rule is None:
            continue
        if not declaration.rule.holds(getattr(config, field.name)):
            broken.append((field.name, declaration.rule))
    return broken


@dataclass(frozen=True)
class DeclaredParameter:
    """One parameter as a node declares it, for the parameter files and the reference."""

    name: str
    default: Any
    meaning: str
    unit: str = ""
    rule: str = ""
    heading: str | None = None
    ros_type: str = ""
    """The ROS type when the default does not tell it (``string[]``)."""

    @property
    def type_name(self) -> str:
        """The ROS parameter type: bool, integer, double, string, double[3], double[], and
        double[] of [start, end] pairs for intervals."""
        default = self.default
        if self.ros_type:
            return self.ros_type
        if isinstance(default, bool):
            return "bool"
        if isinstance(default, int):
            return "integer"
        if isinstance(default, float):
            return "double"
        if isinstance(default, str):
            return "string"
        if is_interval_list(default):
            return "double[] ([start, end] pairs)"
        if isinstance(default, tuple) and default:
            return f"double[{len(default)}]"
        if isinstance(default, tuple):
            return "double[]"
        raise TypeError(f"parameter '{self.name}': no ROS type for {default!r}")

    @property
    def description(self) -> str:
        """The ROS parameter description: meaning and unit."""
        return f"{self.meaning} ({self.unit})" if self.unit else self.meaning

    @property
    def shared(self) -> bool:
        return self.name in SHARED_PARAMETERS


def declared_parameters(
    config_type: type,
    prefix: str = "",
    renamed: Mapping[str, str] | None = None,
    skip: Iterable[str] = (),
) -> list[DeclaredParameter]:
    """Every parameter behind the fields of ``config_type``, in field order (see
    :func:`buoy_common.parameters.config_parameters` for the names)."""
    fields = {field.name: field for field in dataclasses.fields(config_type)}
    declared = []
    for field_name, name, default in config_parameters(config_type, prefix, renamed, skip):
        declaration = field_declaration(fields[field_name])
        declared.append(
            DeclaredParameter(
                name,
                default,
                declaration.meaning,
                declaration.unit,
                str(declaration.rule or ""),
                declaration.heading,
            )
        )
    return declared


def shared_parameter(name: str) -> DeclaredParameter:
    """A shared parameter (interface contract) as a node declares it."""
    declared = SHARED_PARAMETERS[name]
    return DeclaredParameter(name, declared.default, declared.meaning, declared.unit, declared.rule)


@dataclass(frozen=True)
class NodeParameters:
    """Every parameter one node (and the offline tools reading its sections) declares."""

    node: str
    summary: str
    parameters: tuple[DeclaredParameter, ...]


@dataclass(frozen=True)
class FileSection:
    """One section of a parameter file: ``/**`` or a node's own (``/**/imu_sim_node``).

    ``commented``: the whole section is written as comments, a listing of the defaults that
    sets nothing (the simulator's sensors take their defaults from the scenario)."""

    target: str
    parameters: tuple[DeclaredParameter, ...]
    comment: str = ""
    commented: bool = False


@dataclass(frozen=True)
class ParameterFile:
    """A parameter file generated from the declarations: its path from the repository root,
    the comment lines at its top, and its sections."""

    path: str
    header: tuple[str, ...]
    sections: tuple[FileSection, ...]


@dataclass(frozen=True)
class ParameterSets:
    """What a package declares: its nodes' parameters and the files listing them."""

    package: str
    nodes: tuple[NodeParameters, ...]
    files: tuple[ParameterFile, ...] = ()


def is_writable_default(default: Any) -> bool:
    """Whether a default can be written as a value in a parameter file: NaN (unset) and empty
    lists (no type for ROS) are written as comments instead."""
    if isinstance(default, float):
        return not math.isnan(default)
    if isinstance(default, tuple):
        flat = [x for item in default for x in (item if isinstance(item, tuple) else (item,))]
        return bool(flat) and not any(math.isnan(x) for x in flat)
    return True
