"""JSON through orjson where it gives exactly what ``JsonCodec`` gives, and None where it might not.

A mutated message is decoded and encoded once each, and the stdlib's JSON
is most of a ``set`` on a small message (docs/performance.md, "JSON").
orjson is not the stdlib, though, so this module only answers when the
answer is provably the codec's own:

* ``loads``: orjson's value when it reads the payload as an object. Where
  the two readers differ orjson refuses (``NaN``/``Infinity`` tokens, lone
  surrogates, numbers beyond a double, a BOM), except for integers beyond
  64 bits, which orjson reads as floats: those show as a float of magnitude
  2**63 or more, which ``dumps`` refuses (written with an exponent) and the
  caller checks for in the values it replaces (``is_exact_scalar``).
* ``dumps``: orjson's bytes when they are the stdlib encoder's (ASCII,
  compact): both write the shortest round-trip digits of a float, but
  orjson writes non-ASCII text as UTF-8, DEL unescaped, and small floats
  as ``0.00001`` / ``1e-7`` where Python writes ``1e-05`` / ``1e-07``. Any
  output with a non-ASCII byte, DEL, an exponent or ``0.0000`` is refused,
  whatever caused it (a string that merely contains ``e-`` costs the
  general path, never a wrong byte).

``tests/test_json_fast.py`` compares both against the codec on generated
documents.
"""

from __future__ import annotations

import math
from collections.abc import Callable

import orjson

_loads, _dumps = orjson.loads, orjson.dumps
_DecodeError, _EncodeError = orjson.JSONDecodeError, orjson.JSONEncodeError
# Doubles this large may be integers orjson read beyond its 64-bit range.
_BIG = float(2**63)
_SCALARS = (str, int, bool, type(None))


def loads(payload: bytes) -> dict | None:
    """``JsonCodec.decode(payload)`` when orjson reads an object (see the module doc); else None."""
    try:
        value = _loads(payload)
    except _DecodeError:
        return None
    return value if type(value) is dict else None


def dumps(message: dict) -> bytes | None:
    """``JsonCodec.encode(message)`` when orjson's bytes are provably the same; else None."""
    try:
        out = _dumps(message)
    except _EncodeError:  # nested deeper than orjson writes, a type it does not know
        return None
    if not out.isascii() or 127 in out:  # an int: one memchr (a bytes needle costs ten times more)
        return None
    # Searched as text: a str search runs at a third of a bytes search's cost (measured, 200 B: the five
    # checks as bytes took 1.4 µs, six times orjson's own writing); "-" and "+" first, each one memchr.
    text = out.decode("ascii")
    if ("-" in text and "e-" in text) or ("+" in text and "e+" in text) or "0.0000" in text:
        return None
    return out


def is_exact_scalar(value: object) -> bool:
    """A value ``loads`` gave that the stdlib reader gives too: a scalar, and no float that may have been an integer.

    (Containers are not checked value by value: the fast path leaves a
    field holding one to the codec.)
    """
    if type(value) is float:
        return math.isfinite(value) and abs(value) < _BIG
    return type(value) in _SCALARS


def writes_alike(value: object, encode: Callable[[object], bytes]) -> bool:
    """True if orjson writes this value exactly as ``encode`` (the codec's encoder) does."""
    try:
        return _dumps(value) == encode(value)
    except Exception:  # noqa: BLE001 - any failure means: not alike, use the codec
        return False
