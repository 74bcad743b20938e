"""CDR codecs over numpy arrays: a run of messages of one type decoded into columns, and
columns encoded back into messages, a whole chunk at a time.

:mod:`buoy_common.cdr` reads and writes one message per ``struct`` call; at sensor rates the
interpreter's cost per message then dominates. Messages of one topic that share their frame
ids have one layout (CDR, XCDR1, little endian: :mod:`buoy_common.cdr` describes it), so their
bytes, joined, are a numpy structured array with explicit offsets: one ``np.frombuffer`` decodes
them all, one ``tobytes`` encodes them all. The layouts handled are those of the fixed-size types
the suite reads and writes at sensor rates (:data:`LAYOUTS`).

Decoding walks every message's layout at once (the string lengths, read vectorised, decide the
offsets), groups the messages by layout and decodes each group in one call. A message the walk
does not accept (big-endian, a length that disagrees with its strings, a string without its
terminating NUL or not UTF-8, a ``TFMessage`` of other than one transform) is decoded alone by
rosbags' typestore, as :meth:`~buoy_common.bag_io.BagReader.decode` decodes it; one that rosbags
cannot decode either is marked invalid with the reason (:attr:`MessageColumns.rejected`), its
values NaN or zero. Nothing is guessed: a column holds what rosbags decodes, or nothing.

Encoding writes the bytes rosbags' ``serialize_cdr`` writes (padding zeroed; rclpy's
``serialize_message`` differs only in what its padding holds). Values it cannot hold (a stamp
out of range, an integer field out of its type's range, an id that is not text) raise
ValueError naming the field.

Values are in the units of the message definitions (SI, REP 103), in the frame the message's
``frame_id`` names; quaternions x, y, z, w; covariances row-major.
"""

from __future__ import annotations

import functools
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import NamedTuple

import numpy as np

from buoy_common.bag_io.common import jazzy_typestore, one_line

_DATA_START = 4
_LITTLE_ENDIAN_HEADER = (0, 1, 0, 0)
_STRING = "string"
NS_PER_S = 1_000_000_000


class _Field(NamedTuple):
    """One field of a layout: its column name, numpy type (little-endian) or ``_STRING``, the
    shape of one message's value, where rosbags' message object holds it (attribute path,
    digits index a sequence) and, for a vector or quaternion, the attributes of its parts."""

    name: str
    kind: str
    shape: tuple[int, ...] = ()
    path: str = ""
    parts: str = ""
    constant: int | None = None

    @property
    def count(self) -> int:
        return int(np.prod(self.shape, dtype=np.int64))

    @property
    def item_size(self) -> int:
        return 4 if self.kind == _STRING else np.dtype(self.kind).itemsize


def _header(prefix: str = "header") -> tuple[_Field, ...]:
    return (
        _Field("sec", "<i4", path=f"{prefix}.stamp.sec"),
        _Field("nanosec", "<u4", path=f"{prefix}.stamp.nanosec"),
        _Field("frame_id", _STRING, path=f"{prefix}.frame_id"),
    )


def _vector(name: str, path: str) -> _Field:
    return _Field(name, "<f8", (3,), path, "xyz")


def _quaternion(name: str, path: str) -> _Field:
    return _Field(name, "<f8", (4,), path, "xyzw")


def _matrix(name: str, size: int, path: str) -> _Field:
    return _Field(name, "<f8", (size * size,), path)


def _scalar(name: str, path: str, kind: str = "<f8") -> _Field:
    return _Field(name, kind, (), path)


LAYOUTS: dict[str, tuple[_Field, ...]] = {
    "sensor_msgs/msg/Imu": (
        *_header(),
        _quaternion("orientation", "orientation"),
        _matrix("orientation_covariance", 3, "orientation_covariance"),
        _vector("angular_velocity", "angular_velocity"),
        _matrix("angular_velocity_covariance", 3, "angular_velocity_covariance"),
        _vector("linear_acceleration", "linear_acceleration"),
        _matrix("linear_acceleration_covariance", 3, "linear_acceleration_covariance"),
    ),
    "geometry_msgs/msg/Vector3Stamped": (*_header(), _vector("vector", "vector")),
    "sensor_msgs/msg/NavSatFix": (
        *_header(),
        _scalar("status", "status.status", "<i1"),
        _scalar("service", "status.service", "<u2"),
        _scalar("latitude", "latitude"),
        _scalar("longitude", "longitude"),
        _scalar("altitude", "altitude"),
        _matrix("position_covariance", 3, "position_covariance"),
        _scalar("position_covariance_type", "position_covariance_type", "<u1"),
    ),
    "geometry_msgs/msg/TwistWithCovarianceStamped": (
        *_header(),
        _vector("linear", "twist.twist.linear"),
        _vector("angular", "twist.twist.angular"),
        _matrix("covariance", 6, "twist.covariance"),
    ),
    "sensor_msgs/msg/MagneticField": (
        *_header(),
        _vector("magnetic_field", "magnetic_field"),
        _matrix("magnetic_field_covariance", 3, "magnetic_field_covariance"),
    ),
    "sensor_msgs/msg/Temperature": (
        *_header(),
        _scalar("temperature", "temperature"),
        _scalar("variance", "variance"),
    ),
    "nav_msgs/msg/Odometry": (
        *_header(),
        _Field("child_frame_id", _STRING, path="child_frame_id"),
        _vector("position", "pose.pose.position"),
        _quaternion("orientation", "pose.pose.orientation"),
        _matrix("pose_covariance", 6, "pose.covariance"),
        _vector("linear", "twist.twist.linear"),
        _vector("angular", "twist.twist.angular"),
        _matrix("twist_covariance", 6, "twist.covariance"),
    ),
    # One transform: the sequence's length is part of the layout, and must be 1.
    "tf2_msgs/msg/TFMessage": (
        _Field("transforms", "<u4", constant=1),
        *_header("transforms.0.header"),
        _Field("child_frame_id", _STRING, path="transforms.0.child_frame_id"),
        _vector("translation", "transforms.0.transform.translation"),
        _quaternion("rotation", "transforms.0.transform.rotation"),
    ),
}
"""The message types handled, each as its fields in CDR order; the column of a field is named
after it (the string fields' columns hold ``str``)."""


@dataclass
class MessageColumns:
    """Messages of one type as columns: ``columns[name]`` holds field ``name`` of every message,
    shape (n, *field shape) (strings: an object array of ``str``). ``valid`` is False for the
    messages nothing could decode, whose reasons are in ``rejected`` (index → reason)."""

    msgtype: str
    columns: dict[str, np.ndarray]
    valid: np.ndarray
    rejected: dict[int, str] = field(default_factory=dict)

    def __len__(self) -> int:
        return len(self.valid)

    def __getitem__(self, name: str) -> np.ndarray:
        return self.columns[name]

    @property
    def stamp_ns(self) -> np.ndarray:
        """Header stamps, int64 ns since the epoch (negative before it)."""
        return self.columns["sec"].astype(np.int64) * NS_PER_S + self.columns["nanosec"]


def stamp_parts(stamp_ns) -> tuple[np.ndarray, np.ndarray]:
    """(sec, nanosec) of int64 stamps ``stamp_ns`` (ns since the epoch), nanosec in
    [0, 10⁹), as a header holds them."""
    sec, nanosec = np.divmod(np.asarray(stamp_ns, dtype=np.int64), NS_PER_S)
    return sec, nanosec


def handles(msgtype: str) -> bool:
    """Whether ``msgtype`` ('pkg/msg/Type') has a layout here."""
    return msgtype in LAYOUTS


def _layout(msgtype: str) -> tuple[_Field, ...]:
    layout = LAYOUTS.get(msgtype)
    if layout is None:
        raise ValueError(f"no bulk CDR layout for {msgtype!r}; handled: {', '.join(LAYOUTS)}")
    return layout


def _aligned(position, size: int):
    """``position`` (bytes from the message's start) moved up to a multiple of ``size``
    counted from the end of the encapsulation header."""
    return position + (-(position - _DATA_START) % size)


@functools.cache
def _dtype(msgtype: str, string_sizes: tuple[int, ...], message_size: int = 0) -> np.dtype:
    """The structured dtype of a ``msgtype`` message whose strings take ``string_sizes`` bytes
    each (their NULs included), ``message_size`` bytes long with the padding after its last
    field (0: none): string ``s`` is the fields ``s.length``, ``s`` (its text, absent when
    empty) and ``s.nul``."""
    names, formats, offsets = ["encapsulation"], [("u1", (4,))], [0]
    position, sizes = _DATA_START, iter(string_sizes)

    def add(name, kind, at):
        names.append(name)
        formats.append(kind)
        offsets.append(at)

    for item in _layout(msgtype):
        position = _aligned(position, item.item_size)
        if item.kind == _STRING:
            size = next(sizes)
            add(f"{item.name}.length", "<u4", position)
            if size > 1:
                add(item.name, np.dtype((np.void, size - 1)), position + 4)
            add(f"{item.name}.nul", "u1", position + 3 + size)
            position += 4 + size
        else:
            add(item.name, (item.kind, item.shape) if item.shape else item.kind, position)
            position += item.item_size * item.count
    return np.dtype(
        {
            "names": names,
            "formats": formats,
            "offsets": offsets,
            "itemsize": max(position, message_size),
        }
    )


# -- decoding --------------------------------------------------------------------------------------


def _empty_columns(layout: tuple[_Field, ...], count: int) -> dict[str, np.ndarray]:
    columns = {}
    for item in layout:
        if item.constant is not None:
            continue
        if item.kind == _STRING:
            columns[item.name] = np.full(count, "", dtype=object)
        elif np.dtype(item.kind).kind == "f":
            columns[item.name] = np.full((count, *item.shape), np.nan)
        else:
            columns[item.name] = np.zeros(
                (count, *item.shape), dtype=np.dtype(item.kind).newbyteorder("=")
            )
    return columns


def _gather_u32(buffer: np.ndarray, at: np.ndarray) -> np.ndarray:
    """The little-endian uint32 at each byte index ``at`` of ``buffer``, as int64."""
    value = np.zeros(len(at), dtype=np.int64)
    for byte in range(4):
        value |= buffer[at + byte].astype(np.int64) << (8 * byte)
    return value


class _Walk(NamedTuple):
    """Each message's layout, as far as its bytes say it: whether it fits one, and its string
    sizes (one column per string field)."""

    fits: np.ndarray
    string_sizes: np.ndarray


def _walk(layout: tuple[_Field, ...], buffer: np.ndarray, starts, lengths) -> _Walk:
    """Follows ``layout`` through every message at once (``starts``/``lengths`` into the
    joined ``buffer``)."""
    count = len(starts)
    fits = lengths >= _DATA_START
    safe_starts = np.where(fits, starts, 0)
    fits &= (buffer[safe_starts] == 0) & (buffer[safe_starts + 1] == 1)
    position = np.full(count, _DATA_START, dtype=np.int64)
    sizes = []
    for item in layout:
        position = _aligned(position, item.item_size)
        if item.kind == _STRING or item.constant is not None:
            fits &= position + 4 <= lengths
            value = _gather_u32(buffer, np.where(fits, safe_starts + position, 0))
            if item.constant is not None:
                fits &= value == item.constant
                position = position + 4
                continue
            fits &= (value >= 1) & (position + 4 + value <= lengths)
            value = np.where(fits, value, 1)
            sizes.append(value)
            position = position + 4 + value
        else:
            position = position + item.item_size * item.count
    # Some writers pad a message's end to 4 bytes (the padding is no field: rosbags and
    # rclpy ignore it).
    fits &= (position <= lengths) & (lengths < position + 4)
    string_sizes = np.stack(sizes, axis=1) if sizes else np.zeros((count, 0), dtype=np.int64)
    return _Walk(fits, string_sizes)


def decode(msgtype: str, raws: Sequence[bytes]) -> MessageColumns:
    """The messages ``raws`` (CDR bytes, each a ``msgtype``) as columns, in their order."""
    layout = _layout(msgtype)
    count = len(raws)
    result = MessageColumns(msgtype, _empty_columns(layout, count), np.ones(count, dtype=bool))
    if count == 0:
        return result
    lengths = np.fromiter(map(len, raws), dtype=np.int64, count=count)
    joined = b"".join(raws)
    buffer = np.frombuffer(joined, dtype=np.uint8)
    starts = np.concatenate(([0], np.cumsum(lengths[:-1])))
    walk = _walk(layout, np.concatenate((buffer, np.zeros(8, np.uint8))), starts, lengths)
    leftovers = [np.flatnonzero(~walk.fits)]
    keys = np.column_stack((lengths, walk.string_sizes))[walk.fits]
    indices = np.flatnonzero(walk.fits)
    for key, members in _groups_by_layout(keys, indices):
        data = joined if len(members) == count else b"".join([raws[i] for i in members])
        dtype = _dtype(msgtype, tuple(int(size) for size in key[1:]), int(key[0]))
        leftovers.append(_fill(result, layout, members, np.frombuffer(data, dtype=dtype)))
    for index in np.sort(np.concatenate(leftovers)):
        _decode_alone(result, layout, int(index), raws[index])
    return result


def _groups_by_layout(keys: np.ndarray, indices: np.ndarray):
    """(key, message indices) of each distinct row of ``keys`` (the messages ``indices``)."""
    if not len(indices):
        return
    if (keys == keys[0]).all():
        yield keys[0], indices  # the usual case, without np.unique's sort
        return
    groups, group_of = np.unique(keys, axis=0, return_inverse=True)
    group_of = group_of.reshape(-1)
    for number, key in enumerate(groups):
        yield key, indices[group_of == number]


def _fill(result: MessageColumns, layout, members: np.ndarray, records: np.ndarray) -> np.ndarray:
    """Columns of ``members`` from their ``records``; returns the members whose strings were
    not NUL-terminated UTF-8, left to :func:`_decode_alone`."""
    unreadable = np.zeros(len(members), dtype=bool)
    for item in layout:
        if item.constant is not None:
            continue
        if item.kind == _STRING:
            unreadable |= records[f"{item.name}.nul"] != 0
            texts, bad = _texts(records, item.name)
            unreadable |= bad
            result.columns[item.name][members] = texts
        else:
            result.columns[item.name][members] = records[item.name]
    return members[unreadable]


def _texts(records: np.ndarray, name: str) -> tuple[np.ndarray, np.ndarray]:
    """The text of string field ``name`` of ``records`` (an object array), and where it is not
    UTF-8."""
    if name not in records.dtype.names:
        return np.full(len(records), "", dtype=object), np.zeros(len(records), dtype=bool)
    values = records[name]
    if (values == values[0]).all():
        distinct, which = values[:1], np.zeros(len(values), dtype=np.intp)
    else:
        distinct, which = np.unique(values, return_inverse=True)
    texts = np.empty(len(distinct), dtype=object)
    bad = np.zeros(len(distinct), dtype=bool)
    for number, value in enumerate(distinct):
        try:
            texts[number] = bytes(value).decode()
        except UnicodeDecodeError:
            texts[number], bad[number] = "", True
    which = which.reshape(-1)
    return texts[which], bad[which]


def _decode_alone(result: MessageColumns, layout, index: int, raw: bytes) -> None:
    """Message ``index`` decoded by rosbags, or marked invalid with the reason."""
    try:
        message = jazzy_typestore().deserialize_cdr(raw, result.msgtype)
        values = {item.name: _value_of(message, item) for item in layout if item.constant is None}
    except _NotOneTransformError as error:
        _reject(result, layout, index, str(error))
        return
    except Exception as error:  # rosbags raises what its decoder met; the reason is kept
        _reject(result, layout, index, f"undecodable {result.msgtype}: {one_line(error)}")
        return
    for name, value in values.items():
        result.columns[name][index] = value


class _NotOneTransformError(ValueError):
    pass


def _value_of(message, item: _Field):
    value = message
    for step in item.path.split("."):
        if step.isdigit():
            if len(value) != 1:
                raise _NotOneTransformError(f"holds {len(value)} transforms, not one")
            value = value[int(step)]
        else:
            value = getattr(value, step)
    if item.parts:
        return [getattr(value, part) for part in item.parts]
    return value


def _reject(result: MessageColumns, layout, index: int, reason: str) -> None:
    result.valid[index] = False
    result.rejected[index] = reason
    for name, empty in _empty_columns(layout, 1).items():
        result.columns[name][index] = empty[0]


# -- encoding --------------------------------------------------------------------------------------


def encode(msgtype: str, columns: dict[str, object]) -> list[bytes]:
    """CDR bytes of the messages whose fields ``columns`` holds (as :func:`decode` returns them:
    one row per message; ``sec`` and ``nanosec``, or ``stamp_ns``; a string field may be one
    ``str`` for every message), in order."""
    layout = _layout(msgtype)
    columns = _with_stamp_parts(columns)
    count = _row_count(layout, columns)
    messages: list[bytes] = [b""] * count
    for key, members in _groups_by_text(layout, columns, count).items():
        dtype = _dtype(msgtype, tuple(len(text) + 1 for text in key))
        records = np.zeros(len(members), dtype=dtype)
        records["encapsulation"] = _LITTLE_ENDIAN_HEADER
        for item, text in zip((i for i in layout if i.kind == _STRING), key, strict=True):
            records[f"{item.name}.length"] = len(text) + 1
            if text:
                records[item.name] = text
        for item in layout:
            if item.kind != _STRING:
                records[item.name] = _column_values(item, columns, members)
        data = records.tobytes()
        size = dtype.itemsize
        if len(members) == count:
            return [data[start : start + size] for start in range(0, len(data), size)]
        for number, index in enumerate(members):
            messages[index] = data[number * size : (number + 1) * size]
    return messages


def _with_stamp_parts(columns: dict[str, object]) -> dict[str, object]:
    if "stamp_ns" not in columns:
        return columns
    sec, nanosec = stamp_parts(columns["stamp_ns"])
    return {**columns, "sec": sec, "nanosec": nanosec}


def _row_count(layout, columns: dict[str, object]) -> int:
    missing = [i.name for i in layout if i.constant is None and i.name not in columns]
    if missing:
        raise ValueError(f"columns lack {', '.join(missing)}")
    return len(np.atleast_1d(np.asarray(columns["sec"])))


def _groups_by_text(layout, columns: dict[str, object], count: int) -> dict[tuple, np.ndarray]:
    """Message indices by the UTF-8 bytes of their string fields (in field order)."""
    names = [item.name for item in layout if item.kind == _STRING]
    given = [columns[name] for name in names]
    if all(isinstance(value, str) for value in given):
        return {_encoded(names, tuple(given)): np.arange(count)}
    per_message = [[value] * count if isinstance(value, str) else list(value) for value in given]
    for name, values in zip(names, per_message, strict=True):
        if len(values) != count:
            raise ValueError(f"column {name} holds {len(values)} values for {count} messages")
    keys = list(zip(*per_message, strict=True))
    distinct = dict.fromkeys(keys)
    if len(distinct) == 1:
        return {_encoded(names, keys[0]): np.arange(count)}
    members: dict[tuple, list[int]] = {key: [] for key in distinct}
    for index, key in enumerate(keys):
        members[key].append(index)
    return {_encoded(names, key): np.asarray(indices) for key, indices in members.items()}


def _encoded(names: list[str], texts: tuple) -> tuple[bytes, ...]:
    """``texts`` (the values of string fields ``names``) as UTF-8; ValueError naming the field
    of one that is not text."""
    encoded = []
    for name, text in zip(names, texts, strict=True):
        if not isinstance(text, str):
            raise ValueError(f"column {name}: {text!r} is not text")
        try:
            encoded.append(text.encode())
        except UnicodeEncodeError as error:
            raise ValueError(f"column {name}: not UTF-8 text: {error}") from error
    return tuple(encoded)


def _column_values(item: _Field, columns: dict[str, object], members: np.ndarray):
    if item.constant is not None:
        return item.constant
    values = np.asarray(columns[item.name])
    if values.shape[1:] != item.shape and values.ndim > 0:
        raise ValueError(
            f"column {item.name} has rows of shape {values.shape[1:]}, not {item.shape}"
        )
    selected = values[members] if values.ndim > 0 else values
    kind = np.dtype(item.kind)
    if kind.kind in "iu":
        limits = np.iinfo(kind)
        if not np.issubdtype(selected.dtype, np.integer):
            raise ValueError(f"column {item.name} must hold integers, not {selected.dtype}")
        if selected.size and (selected.min() < limits.min or selected.max() > limits.max):
            raise ValueError(
                f"column {item.name} holds values outside [{limits.min}, {limits.max}]"
            )
    return selected
