"""Typed parameters, the same for live nodes and offline tools.

Every configurable core has a frozen dataclass of simple fields (float, int, bool, str, tuples
of floats) with unit-suffixed names, each declared once with its default, unit, rule and meaning
(:mod:`buoy_common.parameter_declarations`). A node declares one ROS parameter per field; an
offline tool reads the same names from the same ROS parameter YAML files. Both go through
``build_config``, so a value is accepted or refused identically, with a message that names the
parameter.
"""

from __future__ import annotations

import dataclasses
import difflib
import math
import re
from collections.abc import Iterable, Mapping
from pathlib import Path
from typing import Any

import yaml

from buoy_common.extrinsics import field_parameter


class ParameterError(ValueError):
    """A parameter value or parameter file is unusable; the message names it."""


def coerce_parameter(name: str, value: Any, default: Any) -> Any:
    """Check ``value`` against the type of ``default`` and return it in that type.

    Integers are accepted where a number is expected (YAML ``100`` for ``100.0``). A tuple of
    pairs (intervals) is given as a flat list. Raises ParameterError naming the parameter.
    """

    def fail(expected: str):
        raise ParameterError(f"parameter '{name}' must be {expected}, got {value!r}")

    if isinstance(default, bool):
        if not isinstance(value, bool):
            fail("true or false")
        return value
    if isinstance(default, int):
        if isinstance(value, bool) or not isinstance(value, int):
            fail("an integer")
        return value
    if isinstance(default, float):
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            fail("a number")
        return float(value)
    if isinstance(default, str):
        if not isinstance(value, str):
            fail("a string")
        return value
    if isinstance(default, tuple):
        if isinstance(value, (str, bytes)) or not isinstance(value, Iterable):
            fail("a list of numbers")
        try:
            numbers = [float(x) for x in value]
        except (TypeError, ValueError):
            fail("a list of numbers")
        if any(math.isinf(x) for x in numbers):
            fail("a list of finite numbers")
        if is_interval_list(default):
            if len(numbers) % 2:
                fail("a flat list of [start, end] pairs")
            return tuple((numbers[i], numbers[i + 1]) for i in range(0, len(numbers), 2))
        if default and len(numbers) != len(default):
            fail(f"a list of {len(default)} numbers")
        return tuple(numbers)
    return value


def is_interval_list(default: Any) -> bool:
    """Fields holding (start, end) intervals are typed tuple[tuple[float, float], ...]."""
    return isinstance(default, tuple) and (not default or isinstance(default[0], tuple))


def to_ros_value(default: Any) -> Any:
    """A field default as a ROS parameter value (tuples become flat lists of doubles)."""
    if is_interval_list(default):
        return [float(x) for pair in default for x in pair]
    if isinstance(default, tuple):
        return [float(x) for x in default]
    return default


def field_default(field: dataclasses.Field) -> Any:
    if field.default is not dataclasses.MISSING:
        return field.default
    if field.default_factory is not dataclasses.MISSING:
        return field.default_factory()
    raise TypeError(f"configuration field '{field.name}' has no default")


def config_parameters(
    config_type: type,
    prefix: str = "",
    renamed: Mapping[str, str] | None = None,
    skip: Iterable[str] = (),
    base: Any = None,
) -> list[tuple[str, str, Any]]:
    """(field name, parameter name, default) for each parameter-backed field of config_type.

    A field's parameter is, in this order: its name in ``renamed``, the shared parameter it is
    declared with (:func:`buoy_common.extrinsics.shared_field`), or ``prefix`` + its name.
    Defaults come from ``base`` (an instance of config_type) when given.
    """
    renamed = renamed or {}
    skip = set(skip)
    return [
        (
            field.name,
            renamed.get(field.name) or field_parameter(field) or prefix + field.name,
            field_default(field) if base is None else getattr(base, field.name),
        )
        for field in dataclasses.fields(config_type)
        if field.name not in skip
    ]


def build_config(
    config_type: type,
    values_by_parameter: Mapping[str, Any],
    prefix: str = "",
    renamed: Mapping[str, str] | None = None,
    skip: Iterable[str] = (),
    base: Any = None,
    **fixed: Any,
):
    """Build ``config_type`` from parameter values; absent parameters keep their defaults.

    The defaults are the dataclass's own, or the field values of ``base`` when given.

    ``fixed`` supplies fields that are not parameters (and removes them from the parameter set).
    Validation errors of the dataclass are re-raised as ParameterError naming the parameter.
    """
    values = dict(fixed)
    if base is not None:
        values = {f.name: getattr(base, f.name) for f in dataclasses.fields(base)} | values
    parameter_of_field = {}
    for field_name, parameter, default in config_parameters(
        config_type, prefix, renamed, set(skip) | set(fixed), base
    ):
        parameter_of_field[field_name] = parameter
        if parameter in values_by_parameter:
            values[field_name] = coerce_parameter(
                parameter, values_by_parameter[parameter], default
            )
    try:
        return config_type(**values)
    except (ValueError, TypeError) as error:
        # Speak of parameters, not fields, everywhere in the message: a check relating two
        # fields (the antennas, the origin) then names both parameters.
        message = str(error)
        named = []
        for field_name, parameter in parameter_of_field.items():
            message, count = re.subn(rf"(?<![\w.]){field_name}(?!\w)", parameter, message)
            if count:
                named.append((message.index(parameter), parameter))
        if named:
            raise ParameterError(f"parameter '{min(named)[1]}': {message}") from error
        raise ParameterError(message) from error


def _flatten(tree: Mapping[str, Any], prefix: str = "") -> dict[str, Any]:
    flat = {}
    for key, value in tree.items():
        name = f"{prefix}{key}"
        if isinstance(value, Mapping):
            flat.update(_flatten(value, name + "."))
        else:
            flat[name] = value
    return flat


def load_parameter_files(paths: Iterable[str | Path], node_name: str) -> dict[str, Any]:
    """Parameters that ROS would give node ``node_name`` from these ``--params-file`` files.

    Sections ``/**`` and the node's own name (``node``, ``/node``, ``/**/node``) apply, later
    files and node sections overriding earlier ones. Nested keys become dotted names.
    """
    wildcard, own = load_parameter_sections(paths, node_name)
    return {**wildcard, **own}


def load_parameter_sections(
    paths: Iterable[str | Path], node_name: str
) -> tuple[dict[str, Any], dict[str, Any]]:
    """The parameters of the ``/**`` sections and those of node ``node_name``'s own sections
    (``node``, ``/node``, ``/**/node``) in these files, each with later files winning."""
    wildcard: dict[str, Any] = {}
    own: dict[str, Any] = {}
    for path in paths:
        path = Path(path)
        try:
            document = yaml.safe_load(path.read_text())
        except OSError as error:
            raise ParameterError(f"cannot read parameter file {path}: {error.strerror}") from error
        except yaml.YAMLError as error:
            # One line: the parser's message spans several.
            detail = " ".join(str(error).split())
            raise ParameterError(f"parameter file {path} is not valid YAML: {detail}") from error
        if document is None:
            continue
        if not isinstance(document, Mapping):
            raise ParameterError(f"parameter file {path}: expected a mapping of node names")
        for section, body in document.items():
            if not isinstance(body, Mapping) or "ros__parameters" not in body:
                raise ParameterError(
                    f"parameter file {path}: section '{section}' has no 'ros__parameters'"
                )
            parameters = body["ros__parameters"] or {}
            if not isinstance(parameters, Mapping):
                raise ParameterError(
                    f"parameter file {path}: '{section}.ros__parameters' must be a mapping"
                )
            target = str(section).lstrip("/")
            if target == "**":
                wildcard.update(_flatten(parameters))
            elif target in (node_name, f"**/{node_name}"):
                own.update(_flatten(parameters))
    return wildcard, own


ROS_BUILTIN_PARAMETERS = frozenset({"use_sim_time", "start_type_description_service"})
"""Parameters every ROS node declares by itself."""
ROS_PARAMETER_GROUPS = frozenset({*ROS_BUILTIN_PARAMETERS, "qos_overrides"})
"""Groups ROS itself reads (``qos_overrides./topic.publisher.depth``)."""

SUITE_PARAMETER_GROUPS = frozenset(
    {
        # The shared parameters (buoy_common.extrinsics) and the processing nodes' own.
        "gnss",
        "anemometer",
        "dvl",
        "origin",
        "site",
        "magnetic",
        "ahrs",
        "fusion",
        "compensation",
        "current",
        # The simulator nodes (sensor_sim.parameters).
        "scenario",
        "scenario_overrides",
        "seed",
        "rate_hz",
        "time_offset_s",
        "wait_for_subscriber_node",
        "wait_for_subscriptions",
        "imu",
        "magnetometer",
        "motion_pack",
        "rate_factor",
        "publish_rate_hz",
        "wait_for_subscribers",
        "wait_for_nodes",
        "start_delay_s",
        # bag_player and foxglove_bridge.
        "wait_for_subscribers_timeout_s",
        "drain_timeout_s",
        "port",
        "address",
        "topics",
    }
)
"""The parameter groups some node of the suite declares: a group outside them, in any section a
node reads, is a mistake (a misspelt ``compenstion:``). A node cannot import the other packages'
declarations (the simulator shares no code with the estimator), so the groups are listed here;
a test holds this list to the declarations of every package."""


def parameter_group(name: str) -> str:
    """The first component of a dotted parameter name (``anemometer`` of
    ``anemometer.position``); a name without a dot is its own group."""
    return name.split(".", 1)[0]


def check_parameter_names(
    known: Iterable[str],
    shared: Iterable[str] = (),
    own: Iterable[str] = (),
    suite_groups: Iterable[str] = SUITE_PARAMETER_GROUPS,
) -> None:
    """Refuse parameters given to a node that it does not know, naming the closest known one.

    ``own`` are the names given to this node alone (its own section of a parameter file, or
    ``-p`` on its command line): each must be known. ``shared`` are the names of ``/**``
    sections, which every node of a system reads: such a file legitimately holds the
    parameters of other nodes, so a name is refused only when its group (``anemometer`` of
    ``anemometer.position``) is one of this node's groups. A misspelt ``anemometer.postion``
    is thus refused by every node that uses the anemometer's parameters and ignored by the
    others. A name in either whose group no node of the suite knows (``suite_groups``) is
    refused as well, naming the closest known group. Raises ParameterError.
    """
    known = set(known) | ROS_BUILTIN_PARAMETERS
    groups = {parameter_group(name) for name in known}
    all_groups = groups | set(suite_groups) | ROS_PARAMETER_GROUPS
    given = set(own) | set(shared)
    stray = {name for name in given if parameter_group(name) not in all_groups}
    unknown = {name for name in own if name not in known} - stray
    unknown |= {name for name in shared if name not in known and parameter_group(name) in groups}
    descriptions = [_unknown_group(name, all_groups) for name in sorted(stray)]
    descriptions += [_unknown_name(name, known) for name in sorted(unknown)]
    if descriptions:
        raise ParameterError("; ".join(descriptions))


def _unknown_name(name: str, known: set[str]) -> str:
    closest = difflib.get_close_matches(name, sorted(known), n=1, cutoff=0.6)
    hint = f"did you mean '{closest[0]}'?" if closest else "no similar parameter is known"
    return f"unknown parameter '{name}' ({hint})"


def _unknown_group(name: str, groups: set[str]) -> str:
    group = parameter_group(name)
    closest = difflib.get_close_matches(group, sorted(groups), n=1, cutoff=0.6)
    hint = f"did you mean '{closest[0]}'?" if closest else "no similar one is known"
    what = f"parameter '{name}'" if group == name else f"parameter group '{group}' of '{name}'"
    return f"unknown {what}: no node of the suite reads it ({hint})"


def check_parameter_files(
    paths: Iterable[str | Path], node_name: str, known: Iterable[str]
) -> None:
    """:func:`check_parameter_names` for the parameters these files give node ``node_name``."""
    wildcard, own = load_parameter_sections(paths, node_name)
    check_parameter_names(known, shared=wildcard, own=own)


def command_line_parameters(ros_arguments: Iterable[str]) -> tuple[list[str], list[str]]:
    """(``--params-file`` paths, names set with ``-p``/``--param``) of a ROS command line,
    from every ``--ros-args`` block."""
    params_files, names = [], []
    in_ros_arguments = False
    arguments = list(ros_arguments)
    for index, argument in enumerate(arguments):
        if argument == "--ros-args":
            in_ros_arguments = True
        elif argument == "--":
            in_ros_arguments = False
        elif in_ros_arguments and index + 1 < len(arguments):
            value = arguments[index + 1]
            if argument == "--params-file":
                params_files.append(value)
            elif argument in ("-p", "--param"):
                names.append(value.split(":=", 1)[0])
    return params_files, names
