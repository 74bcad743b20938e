"""Typed parameters, the same for live nodes and offline tools.

Every configurable core has a frozen dataclass of simple fields (float, int, bool, str, tuples
of floats) with unit-suffixed names. A node declares one ROS parameter per field; an offline tool
reads the same names from the same ROS parameter YAML files. Both go through ``build_config``,
so a value is accepted or refused identically, with a message that names the parameter.
"""

from __future__ import annotations

import dataclasses
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
    return {**wildcard, **own}
