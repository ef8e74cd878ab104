"""JSON messages (UTF-8 text, one object per payload).

Non-finite floats: decode accepts the ``NaN``, ``Infinity`` and ``-Infinity``
tokens and encode writes them. Python, rosbridge-style and many robot JSON
stacks emit them, and a NaN mutation must reach the consumer as NaN, not as
``null`` or an error. Strict RFC 8259 parsers reject such messages; that
rejection is itself a robustness finding about the consumer.

Encode escapes every non-ASCII character (``\\u00e9``), which is equally valid
JSON, lets lone surrogates (an exceptional string value) travel as escapes,
and uses the stdlib's fastest string path.
"""

from __future__ import annotations

import json
import re
import sys
from typing import Any

from astaa_deft.model.json import DecodedMessage
from astaa_deft.io.codecs.base import CODECS, Codec, DecodeError, EncodeError, first_uncarried, kind_of

# Built once: json.loads/dumps with options construct a new object per call.
_DECODER = json.JSONDecoder()  # parse_constant accepts NaN/Infinity/-Infinity
# check_circular off: decoded messages have no cycles (set_field copies the
# values it inserts), and a cycle still fails, as a RecursionError, which
# encode reports. Saves ~15% per message.
_ENCODER = json.JSONEncoder(ensure_ascii=True, allow_nan=True, check_circular=False, separators=(",", ":"))

# A high surrogate right before a low one is written as two escapes that any
# JSON parser (Python's included) reads back as ONE astral character.
_SURROGATE_PAIR = re.compile("[\ud800-\udbff][\udc00-\udfff]")


class JsonCodec(Codec):
    name = "json"

    def decode(self, payload: bytes) -> DecodedMessage:
        try:
            text = str(payload, "utf-8")  # any bytes-like; strict: no BOM skipping, no surrogates
            value = _DECODER.decode(text)
        except UnicodeDecodeError as exc:
            raise DecodeError(f"invalid UTF-8 at byte {exc.start}") from None
        except json.JSONDecodeError as exc:
            raise DecodeError(f"malformed JSON: {exc.msg} at line {exc.lineno} column {exc.colno}") from None
        except RecursionError:
            raise DecodeError("JSON nested too deeply") from None
        except ValueError as exc:  # e.g. an integer beyond Python's digit limit
            raise DecodeError(f"unreadable JSON: {exc}") from None
        except Exception as exc:  # e.g. TypeError for a payload that is not bytes
            raise DecodeError(f"cannot decode {type(payload).__name__} payload: {exc}") from None
        if type(value) is not dict:
            raise DecodeError(f"top level is {kind_of(value)}, expected an object")
        return value

    def encode(self, value: object) -> bytes:
        try:
            return _ENCODER.encode(value).encode("ascii")
        except Exception as exc:  # TypeError, ValueError (cycle, digit limit), RecursionError
            raise EncodeError(f"cannot encode as JSON: {exc}") from None

    def carries(self, value: object) -> str | None:
        return first_uncarried(value, _json_scalar_problem)


def _json_scalar_problem(value: Any) -> str | None:
    kind = type(value)
    if kind is float or kind is bool or value is None:
        return None
    if kind is str:
        return _string_problem(value)
    if kind is int:
        return _int_problem(value)
    if kind is bytes:
        return "JSON has no byte strings (a bytes field travels as base64 text)"
    return f"JSON cannot carry {kind_of(value)}"


def _string_problem(text: str) -> str | None:
    try:
        text.encode("utf-8")
        return None  # the common case: no surrogates at all
    except UnicodeEncodeError:
        pass
    if _SURROGATE_PAIR.search(text):
        return "a high surrogate followed by a low surrogate would be read back as one character"
    return None  # lone surrogates travel as \\uXXXX escapes


def _int_problem(number: int) -> str | None:
    # JSON numbers have no size limit, so 2**64 and beyond are carried exactly
    # (a consumer choking on them is a finding). Python only refuses to print
    # integers longer than its int-to-str digit limit (4300 digits by default).
    try:
        str(number)
        return None
    except ValueError:
        limit = getattr(sys, "get_int_max_str_digits", lambda: 0)()
        return f"integer longer than Python's {limit}-digit limit for JSON text"


CODECS.register(JsonCodec.name, JsonCodec())
