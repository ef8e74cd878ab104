"""The interface every message codec implements, and its errors.

A codec turns a message payload into plain data and back. Plain data is what
field paths (``astaa_deft.model.fields``) address and what mutations rewrite:

* a ``dict`` with ``str`` keys at the top level (a message is an object);
* nested ``dict`` (``str`` keys, order preserved), ``list``;
* scalars ``str``, ``int`` (any size the codec carries), ``float`` (NaN and
  infinities included), ``bool``, ``None``, and ``bytes`` where the encoding
  has byte strings.

Codecs sit on the proxy's per-message path, so ``decode`` and ``encode`` stay
thin wrappers over C-accelerated libraries; the thorough checks live in
``carries``, which runs once per candidate value, not once per message.
"""

from __future__ import annotations

import math
from abc import ABC, abstractmethod
from typing import Any
from collections.abc import Callable

from astaa_deft.model.json import DecodedMessage
from astaa_deft.model.errors import AstaaDeftError
from astaa_deft.model.registry import Registry


class CodecError(AstaaDeftError):
    """Base of the errors a codec raises; the message is a short reason."""


class DecodeError(CodecError):
    """The payload is not a message this codec can read (the proxy forwards it untouched)."""


class EncodeError(CodecError):
    """The value cannot be written in this encoding."""


class Codec(ABC):
    """A message encoding. ``name`` is also its MCAP ``message_encoding``."""

    name: str

    @abstractmethod
    def decode(self, payload: bytes) -> DecodedMessage:
        """Plain data of one message; raises only ``DecodeError``, whatever the bytes."""

    @abstractmethod
    def encode(self, value: object) -> bytes:
        """The payload for ``value``; raises only ``EncodeError``."""

    @abstractmethod
    def carries(self, value: object) -> str | None:
        """``None`` if ``decode(encode(value))`` gives ``value`` back, else why not.

        Used to skip exceptional values an encoding cannot deliver (with the
        reason in the report) instead of failing mid-run.
        """

    def __repr__(self) -> str:
        return f"<{type(self).__name__} {self.name!r}>"


# Modules of this package that are not codecs (helpers, and ``cdr``, which loads rosbags and is
# reached through its family's module, ``cdr_family``).
_NOT_CODECS = ("base", "cdr", "json_fast", "jsonschema", "rmw_attachment")

# Codecs by name: each codec's module registers one instance (codecs are stateless and shared).
CODECS: Registry[Codec] = Registry("codec", "astaa_deft.io.codecs", skip=_NOT_CODECS)
# Families of codecs named ``family:argument`` (``cdr:geometry_msgs/msg/Twist``): each family's
# module registers how to build the codec of one argument (first use, then kept).
CODEC_FAMILIES: Registry[Callable[[str], Codec]] = Registry("codec family", "astaa_deft.io.codecs", skip=_NOT_CODECS)


def same_value(a: object, b: object) -> bool:
    """Structural equality of plain data, stricter than ``==`` where it matters here.

    NaN equals NaN, ``0.0`` differs from ``-0.0``, ``1`` differs from ``1.0``
    and ``True``, and dict key order counts: exactly the distinctions a
    mutation or a codec round trip must preserve.
    """
    if type(a) is not type(b):
        return False
    # Both of one type from here; each check names both so that the checker knows it too.
    if isinstance(a, float) and isinstance(b, float):
        if math.isnan(a):
            return math.isnan(b)
        return a == b and math.copysign(1.0, a) == math.copysign(1.0, b)
    if isinstance(a, dict) and isinstance(b, dict):
        return list(a) == list(b) and all(same_value(a[k], b[k]) for k in a)
    if isinstance(a, list) and isinstance(b, list):
        return len(a) == len(b) and all(same_value(x, y) for x, y in zip(a, b, strict=False))
    return a == b


def kind_of(value: object) -> str:
    """A short name for a value's type in error messages ("an array", "a string"...)."""
    names = {
        dict: "an object", list: "an array", str: "a string", bytes: "a byte string",
        bool: "a boolean", int: "an integer", float: "a number", type(None): "null",
    }
    return names.get(type(value)) or f"a {type(value).__name__}"


def first_uncarried(value: object, scalar_problem: Callable[[object], str | None]) -> str | None:
    """Why a codec cannot carry ``value`` (first problem found, with its place), or None.

    Walks objects and arrays (object keys must be strings, cycles are
    refused) and asks ``scalar_problem`` about every key and every leaf.
    """
    try:
        return _walk(value, "", set(), scalar_problem)
    except RecursionError:
        return "nested too deeply to encode"


def _walk(node: Any, where: str, ancestors: set[int],
          scalar_problem: Callable[[Any], str | None]) -> str | None:
    if type(node) is dict or type(node) is list:
        if id(node) in ancestors:
            return "contains itself (a cycle)" + _at(where)
        ancestors.add(id(node))
        if type(node) is dict:
            children = []
            for key in node:
                if type(key) is not str:
                    return f"object key {key!r} is not a string" + _at(where)
                problem = scalar_problem(key)
                if problem:
                    return f"object key {key!r}: {problem}" + _at(where)
                children.append((node[key], f"{where}.{key}" if where else key))
        else:
            children = [(item, f"{where}[{i}]") for i, item in enumerate(node)]
        for child, child_where in children:
            problem = _walk(child, child_where, ancestors, scalar_problem)
            if problem:
                return problem
        ancestors.discard(id(node))
        return None
    problem = scalar_problem(node)
    return problem + _at(where) if problem else None


def _at(where: str) -> str:
    return f" (at {where})" if where else ""
