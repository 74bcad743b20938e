"""Messages into CDR bytes: rosbags messages as they are, rclpy messages copied into rosbags'
classes first (without importing rclpy), so that the offline tools and the recorder write the
same bytes."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
from rosbags.interfaces import Nodetype
from rosbags.typesys.base import normalize_fieldname

from buoy_common.bag_io.common import BagError, one_line, require_known_type

# numpy dtypes rosbags uses for arrays of each primitive type.
_ARRAY_DTYPES = {
    "bool": np.bool_,
    "byte": np.int8,
    "char": np.uint8,
    "int8": np.int8,
    "int16": np.int16,
    "int32": np.int32,
    "int64": np.int64,
    "uint8": np.uint8,
    "uint16": np.uint16,
    "uint32": np.uint32,
    "uint64": np.uint64,
    "float32": np.float32,
    "float64": np.float64,
}
_STRING_TYPES = {"string", "wstring"}
_RCLPY_MESSAGE_MODULE = re.compile(r"^(?P<package>\w+)\.msg\._\w+$")


def serialize(typestore, path: Path, topic: str, msgtype: str, message) -> bytes:
    """CDR bytes of a rosbags or rclpy ``message`` of ``msgtype``; BagError naming the bag and
    topic when it does not fit the type.

    rclpy messages are copied field by field into rosbags' classes, which also converts what
    rclpy holds differently: ``byte`` as ``bytes``, ``char`` as ``str``, sequences as
    ``array.array`` or lists.
    """
    require_known_type(typestore, path, topic, msgtype)
    try:
        typed = _as_typestore_message(typestore, msgtype, message)
        return bytes(typestore.serialize_cdr(typed, msgtype))
    except BagError as error:
        raise BagError(f"bag {path}: topic {topic}: {error}") from error
    except Exception as error:
        raise BagError(
            f"bag {path}: topic {topic}: cannot serialise "
            f"{type(message).__name__} as {msgtype}: {one_line(error)}"
        ) from error


def _as_typestore_message(typestore, msgtype: str, source):
    """``source`` as an instance of the typestore's class for ``msgtype``."""
    if getattr(source, "__msgtype__", None) == msgtype:
        return source
    module_match = _RCLPY_MESSAGE_MODULE.match(type(source).__module__)
    if module_match:
        source_type = f"{module_match['package']}/msg/{type(source).__name__}"
        if source_type != msgtype:
            raise BagError(f"message is a {source_type}, not a {msgtype}")
    _, fields = typestore.fielddefs[msgtype]
    values = {}
    for name, description in fields:
        python_name = normalize_fieldname(name)
        value = getattr(source, name) if hasattr(source, name) else getattr(source, python_name)
        values[python_name] = _as_typestore_value(typestore, description, value)
    return typestore.types[msgtype](**values)


def _as_typestore_value(typestore, description, value):
    kind, detail = description
    if kind == Nodetype.NAME:
        return _as_typestore_message(typestore, detail, value)
    if kind == Nodetype.BASE:
        return _as_typestore_scalar(detail[0], value)
    element, _ = detail
    element_kind, element_detail = element
    if element_kind == Nodetype.NAME:
        return [_as_typestore_message(typestore, element_detail, item) for item in value]
    basename = element_detail[0]
    if basename in _STRING_TYPES:
        return [str(item) for item in value]
    dtype = _ARRAY_DTYPES[basename]
    if isinstance(value, (bytes, bytearray, memoryview)):
        return np.frombuffer(bytes(value), dtype=dtype).copy()
    items = list(value)
    if items and isinstance(items[0], (bytes, bytearray)):
        return np.frombuffer(b"".join(items), dtype=dtype).copy()
    if items and isinstance(items[0], str):
        items = [ord(item) for item in items]
    return np.asarray(items, dtype=dtype)


def _as_typestore_scalar(basename: str, value):
    if isinstance(value, (bytes, bytearray)):
        # rosbags holds `byte` as a signed octet.
        return int.from_bytes(value[:1], "little", signed=True)
    if basename == "char" and isinstance(value, str):
        return ord(value)
    return value
