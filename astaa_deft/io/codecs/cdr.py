"""ROS 2 CDR messages (as rmw_zenoh sends them), via rosbags, one codec per message type.

CDR carries no field names or types: a payload is read against its type's
definition. So, unlike JSON and CBOR, a CDR codec is named after its type,
``cdr:geometry_msgs/msg/Twist``; the spec loader gives a ``encoding: cdr``
channel that codec name, and ``get_codec`` builds the codec on first use from
the process's typestore (``astaa_deft.io.ros2.types``).

Plain data (see ``base``): a message is a dict of its fields in definition
order; nested messages are dicts; arrays are lists, except arrays of bytes
(``uint8``/``byte``/``char``), which are one ``bytes`` value (an image or a
point cloud stays one object instead of 100 000 ints). Integers stay ints,
floats stay floats.

Encoding a decoded message gives the same bytes back for payloads written
with zero padding (every ROS 2 serializer does); the proxy forwards an
untouched message as the original bytes anyway. Encoding refuses what CDR
cannot carry in that field (an int32 out of range, a float in an int field,
a fixed-size array of another length, a missing field): the engine then
delivers the real message and reports why.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np
from rosbags.typesys.base import Nodetype

from astaa_deft.model.json import DecodedMessage
from astaa_deft.io.ros2.types import BYTE_PRIMITIVES, Ros2Types, shared_types
from astaa_deft.io.codecs.base import Codec, DecodeError, EncodeError, first_uncarried, kind_of

PREFIX = "cdr:"
MESSAGE_ENCODING = "cdr"  # MCAP's well-known name, as `ros2 bag record -s mcap` writes it

_DTYPES = {
    "bool": np.bool_, "byte": np.uint8, "char": np.uint8, "octet": np.uint8,
    "int8": np.int8, "uint8": np.uint8, "int16": np.int16, "uint16": np.uint16,
    "int32": np.int32, "uint32": np.uint32, "int64": np.int64, "uint64": np.uint64,
    "float32": np.float32, "float64": np.float64,
}
_PLAIN_SCALARS = frozenset({int, float, bool, str, bytes})


class CdrCodec(Codec):
    """Messages of one ROS 2 type. ``name`` is ``cdr:<type>``; ``message_encoding`` is ``cdr``."""

    message_encoding = MESSAGE_ENCODING

    def __init__(self, type_name: str, types: Ros2Types | None = None):
        self.types = types or shared_types()
        self.types.check_name(type_name)  # Ros2TypeError with close names
        self.type_name = type_name
        self.name = PREFIX + type_name
        self._converters = _Converters(self.types)
        self._to_plain = self._converters.to_plain(type_name)
        self._from_plain = self._converters.from_plain(type_name)

    def decode(self, payload: bytes) -> DecodedMessage:
        try:
            data = bytes(payload)
            if len(data) < 4 or data[0] != 0 or data[1] not in (0, 1):
                raise DecodeError("not a CDR payload (no CDR encapsulation header)")
            message = self.types.store.deserialize_cdr(data, self.type_name)
            return self._to_plain(message)
        except DecodeError:
            raise
        except Exception as exc:  # struct.error, IndexError, UnicodeDecodeError, SerdeError…
            raise DecodeError(f"malformed CDR for {self.type_name}: {type(exc).__name__}: {exc}") from None

    def encode(self, value: object) -> bytes:
        if type(value) is not dict:
            raise EncodeError(f"a {self.type_name} message must be an object, not {kind_of(value)}")
        try:
            message = self._from_plain(value, "")
            return bytes(self.types.store.serialize_cdr(message, self.type_name))
        except EncodeError:
            raise
        except Exception as exc:  # OverflowError, struct.error, ValueError, TypeError…
            raise EncodeError(f"cannot encode as {self.type_name} CDR: {type(exc).__name__}: {exc}") from None

    def carries(self, value: object) -> str | None:
        return first_uncarried(value, _cdr_scalar_problem)


def codec_for_type(type_name: str) -> CdrCodec:
    return CdrCodec(type_name)


def _cdr_scalar_problem(value: Any) -> str | None:
    kind = type(value)
    if kind is str:
        try:
            value.encode("utf-8")
        except UnicodeEncodeError:
            return "CDR strings are UTF-8 (it contains a lone surrogate)"
        return None
    if kind in _PLAIN_SCALARS:
        return None
    if value is None:
        return "CDR has no null: every field holds a value of its type"
    return f"CDR cannot carry {kind_of(value)}"


class _Converters:
    """Per-type functions between rosbags' message objects and plain data, built once."""

    def __init__(self, types: Ros2Types):
        self.types = types
        self._to: dict[str, Callable[[Any], dict]] = {}
        self._from: dict[str, Callable[[dict, str], Any]] = {}

    # -- rosbags object -> plain data ------------------------------------------
    def to_plain(self, type_name: str) -> Callable[[Any], dict]:
        if type_name in self._to:
            return self._to[type_name]
        fields: list[tuple[str, Callable[[Any], Any] | None]] = []

        def convert(message: Any) -> dict:
            return {name: (conv(getattr(message, name)) if conv else getattr(message, name))
                    for name, conv in fields}

        self._to[type_name] = convert  # before the fields: recursive types resolve to it
        for name, desc in self.types.store.fielddefs[type_name][1]:
            fields.append((name, self._to_value(desc)))
        return convert

    def _to_value(self, desc: tuple) -> Callable[[Any], Any] | None:
        node, arg = desc
        if node == Nodetype.BASE:
            return None  # Python scalars already
        if node == Nodetype.NAME:
            return self._lazy_to(arg)
        (item_node, item_arg), _size = arg
        if item_node == Nodetype.BASE:
            if item_arg[0] in BYTE_PRIMITIVES:
                return lambda array: array.tobytes()
            if item_arg[0] in ("string", "wstring"):
                return list
            return lambda array: array.tolist()
        item = self._to_value((item_node, item_arg))
        assert item is not None
        return lambda items: [item(x) for x in items]

    def _lazy_to(self, type_name: str) -> Callable[[Any], dict]:
        if type_name in self._to:
            return self._to[type_name]
        cell: list[Callable[[Any], dict]] = []

        def convert(message: Any) -> dict:
            if not cell:
                cell.append(self.to_plain(type_name))
            return cell[0](message)

        return convert

    # -- plain data -> rosbags object ---------------------------------------------
    def from_plain(self, type_name: str) -> Callable[[dict, str], Any]:
        if type_name in self._from:
            return self._from[type_name]
        cls = self.types.store.types[type_name]
        fields: list[tuple[str, Callable[[Any, str], Any] | None]] = []
        names: set[str] = set()

        def build(value: dict, where: str) -> Any:
            if type(value) is not dict:
                raise EncodeError(f"{where or 'the message'} must be an object ({type_name}), not {kind_of(value)}")
            if len(value) != len(names) or not names.issuperset(value):
                missing = [n for n, _ in fields if n not in value]
                extra = [k for k in value if k not in names]
                what = f"missing field {missing[0]!r}" if missing else f"unknown field {extra[0]!r}"
                raise EncodeError(f"{what} in {where or 'the message'} ({type_name})")
            kwargs = {}
            for name, conv in fields:
                item = value[name]
                kwargs[name] = conv(item, f"{where}.{name}" if where else name) if conv else item
            return cls(**kwargs)

        self._from[type_name] = build
        for name, desc in self.types.store.fielddefs[type_name][1]:
            fields.append((name, self._from_value(desc)))
            names.add(name)
        return build

    def _from_value(self, desc: tuple) -> Callable[[Any, str], Any] | None:
        node, arg = desc
        if node == Nodetype.BASE:
            return None  # the serializer refuses what does not fit (struct.error)
        if node == Nodetype.NAME:
            return self._lazy_from(arg)
        (item_node, item_arg), size = arg
        fixed = node == Nodetype.ARRAY

        def check_length(items: Any, where: str) -> None:
            if fixed and len(items) != size:
                raise EncodeError(f"{where} has {len(items)} elements; the type fixes it at {size}")
            if not fixed and size and len(items) > size:
                raise EncodeError(f"{where} has {len(items)} elements; the type bounds it at {size}")

        if item_node == Nodetype.BASE and item_arg[0] not in ("string", "wstring"):
            dtype = _DTYPES[item_arg[0]]
            as_bytes = item_arg[0] in BYTE_PRIMITIVES

            def array(items: Any, where: str) -> Any:
                if as_bytes and type(items) is bytes:
                    check_length(items, where)
                    return np.frombuffer(items, dtype=np.uint8)
                if type(items) is not list:
                    raise EncodeError(f"{where} must be an array, not {kind_of(items)}")
                check_length(items, where)
                return np.asarray(items, dtype=dtype)

            return array
        item = self._from_value((item_node, item_arg))

        def sequence(items: Any, where: str) -> Any:
            if type(items) is not list:
                raise EncodeError(f"{where} must be an array, not {kind_of(items)}")
            check_length(items, where)
            if item is None:
                return list(items)
            return [item(x, f"{where}[{i}]") for i, x in enumerate(items)]

        return sequence

    def _lazy_from(self, type_name: str) -> Callable[[Any, str], Any]:
        if type_name in self._from:
            return self._from[type_name]
        cell: list[Callable[[dict, str], Any]] = []

        def build(value: Any, where: str) -> Any:
            if not cell:
                cell.append(self.from_plain(type_name))
            return cell[0](value, where)

        return build
