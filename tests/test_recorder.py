"""The recorder process's own logic: which bus messages it flags as undecodable."""

from __future__ import annotations

import pytest

from astaa_deft.io.codecs import DecodeError, get_codec
from astaa_deft.engine.session.recorder import FAST_JSON_LIMIT, undecodable

JSON = get_codec("json")

# Payloads at the edges of JSON: orjson's quick answer must never accept one the codec rejects.
EDGES = [
    b'{"a": 1}', b' {"a":1} ', b'\t{"a":\r\n1}', b'{"a":1,"a":2}', b'{"a":18446744073709551616}', b'{"a":1E5}',
    b'{"a":-0}', b'{"a":"\\u0000"}', b'{"a":"\x7f"}', b'{"\xc3\xa9":1}', b'{"a":true,"b":null,"c":false}',
    b'{"a":NaN}', b'{"a":Infinity}', b'{"a":"\\ud800"}', b'{"a":1e400}',  # the stdlib accepts, orjson not
    b'[1]', b'"text"', b'1', b'null',  # valid JSON, not an object
    b'\xef\xbb\xbf{}', b'{"a":"\x01"}', b'{"a":1}x', b'', b'{"a":"\xed\xa0\x80"}', b'{"a":1.}', b'{"a":01}',
    b'{"a":.5}', b'{"a":-}', b'\x00{}', b'{}\x00', b'{"a":"\\x"}', b'{"a":[1,2,]}', b'{"a":1,}',
    b'{"a":"\xf4\x90\x80\x80"}', b'\x0c{}', b'{}\xa0', b'\xff',
    b'{"a":' + b'[' * 900 + b']' * 900 + b'}',  # deep, but short enough for the quick answer
]


def _codec_reason(codec, data: bytes) -> str | None:
    try:
        codec.decode(data)
    except DecodeError as exc:
        return str(exc)
    return None


@pytest.mark.parametrize("data", EDGES)
def test_json_verdict_is_the_codecs(data: bytes) -> None:
    assert undecodable(JSON, data) == _codec_reason(JSON, data)


def test_a_long_json_payload_is_judged_by_the_codec_alone() -> None:
    deep = b'{"a":' + b'[' * 2000 + b']' * 2000 + b'}'  # orjson's depth limit aside, beyond the stdlib's
    assert len(deep) > FAST_JSON_LIMIT
    assert undecodable(JSON, deep) == _codec_reason(JSON, deep)


def test_cbor_verdict_is_the_codecs() -> None:
    cbor = get_codec("cbor")
    for data in (cbor.encode({"a": 1}), b"\xff\xff", b""):
        assert undecodable(cbor, data) == _codec_reason(cbor, data)


@pytest.mark.parametrize("data", EDGES)
def test_simdjsons_quick_answer_never_accepts_what_the_codec_rejects(data: bytes) -> None:
    from astaa_deft.engine.session.recorder import _JsonObjectCheck

    check = _JsonObjectCheck()
    accepted = check(data)
    assert not accepted or _codec_reason(JSON, data) is None
    assert check(data) == accepted  # the parser is reusable: a second look gives the same answer
    if data in (b'{"a": 1}', b'{"a":1,"a":2}', b'{"a":"\x7f"}', b'{"\xc3\xa9":1}'):
        assert accepted  # plain objects take the quick way


def test_simdjsons_quick_answer_agrees_with_the_codec_on_damaged_json() -> None:
    """Random byte edits of JSON objects (seeded): whatever simdjson accepts, the codec decodes."""
    import random

    from astaa_deft.engine.session.recorder import _JsonObjectCheck

    check, rnd = _JsonObjectCheck(), random.Random(1)
    bases = [b'{"a": 1, "b": [1.5, -2e3, "x\\u00e9"], "c": {"d": null, "e": true}}', b'{"header": {"seq": 1}}']
    accepted = 0
    for _ in range(20_000):
        data = bytearray(rnd.choice(bases))
        for _ in range(rnd.randint(1, 3)):
            at = rnd.randrange(len(data))
            edit = rnd.random()
            if edit < 0.4:
                data[at] = rnd.randrange(256)
            elif edit < 0.7:
                data[at:at] = bytes([rnd.randrange(256)])
            else:
                del data[at]
        if check(bytes(data)):
            accepted += 1
            assert _codec_reason(JSON, bytes(data)) is None, bytes(data)
    assert accepted  # some edits leave valid JSON (a digit for a digit, a space)
