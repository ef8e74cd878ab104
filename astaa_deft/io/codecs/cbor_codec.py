"""CBOR messages (RFC 8949), via cbor2: one map per payload.

CBOR natively carries what JSON cannot: byte strings, NaN and infinities, and
integers of any size (beyond 64 bits as bignum tags 2/3).

Decode accepts only plain data (see ``base``): a top-level map with text keys,
and no other tagged items (dates, decimals, sets, shared references...) nor
``undefined``/simple values. Those would not survive a field rewrite and
re-encode unchanged, so such a payload is reported undecodable and forwarded
untouched. Trailing bytes after the map are an error for the same reason.
"""

from __future__ import annotations

import io
from typing import Any

import cbor2

from astaa_deft.model.json import DecodedMessage
from astaa_deft.io.codecs.base import CODECS, Codec, DecodeError, EncodeError, first_uncarried, kind_of

# RFC 8949 §3.4.6: an optional "this is CBOR" tag 55799 in front of the item.
_SELF_DESCRIBE_PREFIX = b"\xd9\xd9\xf7"
# Exact types: cbor2 wraps simple values, undefined etc. in look-alike classes.
_PLAIN_SCALARS = frozenset({str, int, float, bool, bytes, type(None)})


class CborCodec(Codec):
    name = "cbor"

    def decode(self, payload: bytes) -> DecodedMessage:
        try:
            data = bytes(payload)
            if data.startswith(_SELF_DESCRIBE_PREFIX):
                data = data[len(_SELF_DESCRIBE_PREFIX):]
            stream = io.BytesIO(data)
            value = cbor2.CBORDecoder(stream).decode()
            consumed = stream.tell()
        except RecursionError:
            raise DecodeError("CBOR nested too deeply") from None
        except Exception as exc:  # CBORDecodeError and whatever a tag decoder raises
            raise DecodeError(f"malformed CBOR: {exc}") from None
        if type(value) is not dict:
            raise DecodeError(f"top level is {kind_of(value)}, expected a map")
        if consumed != len(data):
            raise DecodeError(f"{len(data) - consumed} trailing bytes after the message")
        problem = _not_plain_data(value)
        if problem:
            raise DecodeError(problem)
        return value

    def encode(self, value: object) -> bytes:
        try:
            return cbor2.dumps(value)
        except Exception as exc:  # CBOREncodeError, UnicodeEncodeError (surrogates), RecursionError
            raise EncodeError(f"cannot encode as CBOR: {exc}") from None

    def carries(self, value: object) -> str | None:
        return first_uncarried(value, _cbor_scalar_problem)


def _not_plain_data(message: dict) -> str | None:
    """Why a decoded message is not plain data, or None. Runs per message: kept lean.

    A container met twice means cbor2 resolved a shared reference (tags
    28/29): rewriting one place would silently rewrite the other, and a cycle
    would never finish encoding.
    """
    seen: set[int] = set()
    pending: list[Any] = [message]
    while pending:
        node = pending.pop()
        if id(node) in seen:
            return "shared or cyclic references (CBOR tags 28/29) are not supported"
        seen.add(id(node))
        if type(node) is dict:
            for key, item in node.items():
                if type(key) is not str:
                    return f"map key {key!r} is not a text string"
                kind = type(item)
                if kind is dict or kind is list:
                    pending.append(item)
                elif kind not in _PLAIN_SCALARS:
                    return f"unsupported CBOR item: {kind_of(item)}"
        # Arrays of scalars (point clouds, ranges) are checked at C speed.
        elif not _PLAIN_SCALARS.issuperset(map(type, node)):
            for item in node:
                kind = type(item)
                if kind is dict or kind is list:
                    pending.append(item)
                elif kind not in _PLAIN_SCALARS:
                    return f"unsupported CBOR item: {kind_of(item)}"
    return None


def _cbor_scalar_problem(value: Any) -> str | None:
    kind = type(value)
    if kind is str:
        try:
            value.encode("utf-8")
        except UnicodeEncodeError:
            return "CBOR text must be valid UTF-8 (it contains a lone surrogate)"
        return None
    if kind in _PLAIN_SCALARS:
        return None
    return f"CBOR (as plain data) cannot carry {kind_of(value)}"


CODECS.register(CborCodec.name, CborCodec())
