"""Codecs: round trips, the only-that-field property, non-finite floats, hostile payloads."""

from __future__ import annotations

import math

import cbor2
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from astaa_deft.io.codecs import (
    Codec, DecodeError, EncodeError, UnknownCodecError, available_codecs, get_codec,
    register_codec, same_value,
)
from astaa_deft.io.codecs.json_codec import JsonCodec
from astaa_deft.model.fields import FieldPath, get, set_field

JSON = get_codec("json")
CBOR = get_codec("cbor")
CODECS = [JSON, CBOR]
FAST = settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow])

# ---------------------------------------------------------------- strategies

IDENTIFIERS = st.text(alphabet="abxyz_0", min_size=1, max_size=3)  # valid in field paths
JSON_SCALARS = st.none() | st.booleans() | st.integers() | st.floats() | st.text(max_size=12)
CBOR_SCALARS = JSON_SCALARS | st.binary(max_size=12)


def plain_values(scalars, keys=IDENTIFIERS):
    return st.recursive(
        scalars,
        lambda inner: st.lists(inner, max_size=4) | st.dictionaries(keys, inner, max_size=4),
        max_leaves=10,
    )


def messages(scalars, keys=IDENTIFIERS):
    return st.dictionaries(keys, plain_values(scalars, keys), min_size=1, max_size=5)


def scalars_for(codec: Codec):
    return CBOR_SCALARS if codec is CBOR else JSON_SCALARS


def every_path(value, prefix=()):
    """Every concrete path in a message (each key and index, at every depth)."""
    children = value.items() if type(value) is dict else enumerate(value) if type(value) is list else ()
    for slot, child in children:
        here = prefix + (slot,)
        yield FieldPath(here)
        yield from every_path(child, here)


# ---------------------------------------------------------------- registry

def test_registry_knows_json_and_cbor():
    assert set(available_codecs()) >= {"json", "cbor"}
    assert get_codec("json").name == "json" and get_codec("cbor").name == "cbor"


def test_unknown_codec_names_the_known_ones():
    with pytest.raises(KeyError) as caught:
        get_codec("protobuf")
    assert isinstance(caught.value, UnknownCodecError)
    assert "'protobuf'" in str(caught.value) and "cbor, json" in str(caught.value)


def test_register_refuses_to_shadow_unless_asked():
    with pytest.raises(ValueError, match="already registered"):
        register_codec(JsonCodec())
    register_codec(JSON, replace=True)
    assert get_codec("json") is JSON


# ---------------------------------------------------------------- round trips

@pytest.mark.parametrize("codec", CODECS, ids=lambda c: c.name)
@FAST
@given(data=st.data())
def test_carried_messages_round_trip_exactly(codec, data):
    message = data.draw(messages(scalars_for(codec), keys=st.text(max_size=6)))
    assert codec.carries(message) is None
    assert same_value(codec.decode(codec.encode(message)), message)


@pytest.mark.parametrize("codec", CODECS, ids=lambda c: c.name)
@FAST
@given(data=st.data())
def test_rewriting_one_field_changes_only_that_field(codec, data):
    original = data.draw(messages(scalars_for(codec)))
    payload = codec.encode(original)
    path = data.draw(st.sampled_from(list(every_path(original))))
    new = data.draw(plain_values(scalars_for(codec)))

    message = codec.decode(payload)
    [(_, old)] = set_field(message, path, new)
    rewritten = codec.decode(codec.encode(message))

    [(_, delivered)] = get(rewritten, path)
    assert same_value(delivered, new)
    set_field(rewritten, path, old)  # undoing the rewrite must give the original back
    assert same_value(rewritten, codec.decode(payload))


# ---------------------------------------------------------------- JSON specifics

def test_json_reads_and_writes_non_finite_tokens():
    message = JSON.decode(b'{"a": NaN, "b": Infinity, "c": -Infinity}')
    assert math.isnan(message["a"]) and message["b"] == math.inf and message["c"] == -math.inf
    assert JSON.encode({"a": math.nan, "b": math.inf, "c": -math.inf}) == b'{"a":NaN,"b":Infinity,"c":-Infinity}'
    assert JSON.carries(math.nan) is None


def test_json_keeps_number_kinds_zero_sign_and_key_order():
    message = JSON.decode(b'{"z": 1.0, "a": 1, "m": -0.0, "big": 18446744073709551616}')
    assert list(message) == ["z", "a", "m", "big"]
    assert type(message["z"]) is float and type(message["a"]) is int
    assert math.copysign(1.0, message["m"]) == -1.0
    assert message["big"] == 2**64
    assert same_value(JSON.decode(JSON.encode(message)), message)


def test_json_carries_lone_surrogates_as_escapes():
    message = {"s": "a\ud800b", "t": "caf\u00e9"}
    assert JSON.carries(message) is None
    payload = JSON.encode(message)
    assert payload == b'{"s":"a\\ud800b","t":"caf\\u00e9"}'
    assert same_value(JSON.decode(payload), message)


@pytest.mark.parametrize("value, reason", [
    (b"\xff", "base64"),
    ({"blob": [b"x"]}, "at blob[0]"),
    ("\ud83d\ude00", "surrogate"),  # would come back as the single character U+1F600
    pytest.param(10**5000, "digit", id="10**5000"),
    ({1: 2}, "key 1 is not a string"),
    ({"x": {1, 2}}, "a set"),
    ((1, 2), "a tuple"),
    (object(), "JSON cannot carry"),
])
def test_json_says_why_it_cannot_carry(value, reason):
    problem = JSON.carries(value)
    assert problem is not None and reason in problem


def test_carries_refuses_cycles_without_crashing():
    looped: list = []
    looped.append(looped)
    for codec in CODECS:
        assert "cycle" in codec.carries({"a": looped})
    shared = [1.0]
    assert JSON.carries({"a": shared, "b": shared}) is None  # sharing is fine, only cycles are not


def test_numpy_scalars_are_not_plain_data():
    import numpy as np
    assert "float64" in JSON.carries(np.float64(1.5))


# ---------------------------------------------------------------- CBOR specifics

def test_cbor_carries_bytes_nan_and_big_integers():
    message = {"blob": b"\x00\xff", "nan": math.nan, "inf": -math.inf, "huge": 2**200, "neg": -(2**70)}
    assert CBOR.carries(message) is None
    assert same_value(CBOR.decode(CBOR.encode(message)), message)


def test_cbor_cannot_carry_lone_surrogates():
    assert "UTF-8" in CBOR.carries({"s": "\udc80"})
    with pytest.raises(EncodeError):
        CBOR.encode({"s": "\udc80"})


def test_cbor_accepts_the_self_describe_tag():
    assert CBOR.decode(b"\xd9\xd9\xf7" + cbor2.dumps({"a": 1})) == {"a": 1}


# ---------------------------------------------------------------- hostile payloads

@pytest.mark.parametrize("payload, reason", [
    (b"", "malformed"),
    (b"\xff\xfe{}", "invalid UTF-8 at byte 0"),
    (b'{"a": "\xed\xa0\x80"}', "invalid UTF-8"),  # an encoded surrogate is not UTF-8
    (b"\xef\xbb\xbf{}", "malformed"),  # BOM
    (b"[1, 2]", "top level is an array"),
    (b"null", "top level is null"),
    (b'{"a": 1} x', "Extra data"),
    (b'{"a": nan}', "malformed"),  # only the NaN spelling is accepted
    (b"[" * 100_000, "JSON"),
    (b'{"a": ' + b"7" * 5000 + b"}", "unreadable JSON"),
])
def test_json_rejects_malformed_payloads_with_a_reason(payload, reason):
    with pytest.raises(DecodeError, match=reason):
        JSON.decode(payload)


@pytest.mark.parametrize("payload, reason", [
    (b"", "malformed"),
    (cbor2.dumps([1, 2]), "top level is an array"),
    (cbor2.dumps({"a": 1}) + b"\x00", "1 trailing bytes"),
    (cbor2.dumps({1: "a"}), "map key 1"),
    (b"\xa1\x61a\xc1\x1a\x00\x00\x00\x01", "datetime"),  # tag 1: epoch date
    (b"\xa1\x61a\xf7", "Undefined"),
    (b"\xa1\x61a\xe0", "SimpleValue"),
    (b"\xa1\x61a\xd9\x01\x02\x81\x01", "set"),  # tag 258: a set
    (b"\xa1\x61a\x62\xff\xfe", "malformed"),  # text that is not UTF-8
])
def test_cbor_rejects_what_would_not_survive_a_rewrite(payload, reason):
    with pytest.raises(DecodeError, match=reason):
        CBOR.decode(payload)


def test_cbor_rejects_shared_and_cyclic_references():
    shared = [1, 2]
    with pytest.raises(DecodeError, match="shared or cyclic"):
        CBOR.decode(cbor2.dumps({"a": shared, "b": shared}, value_sharing=True))
    looped: dict = {}
    looped["self"] = looped
    with pytest.raises(DecodeError, match="shared or cyclic"):
        CBOR.decode(cbor2.dumps(looped, value_sharing=True))


@pytest.mark.parametrize("codec", CODECS, ids=lambda c: c.name)
def test_every_truncation_is_a_decode_error(codec):
    payload = codec.encode({"header": {"seq": 1, "stamp": 0.5}, "points": [{"x": 1.5}], "tag": "é"})
    for end in range(len(payload)):
        with pytest.raises(DecodeError):
            codec.decode(payload[:end])


@pytest.mark.parametrize("codec", CODECS, ids=lambda c: c.name)
def test_any_bytes_like_payload_is_accepted_and_anything_else_is_a_decode_error(codec):
    payload = codec.encode({"a": 1})
    assert codec.decode(bytearray(payload)) == {"a": 1}
    assert codec.decode(memoryview(payload)) == {"a": 1}
    with pytest.raises(DecodeError):
        codec.decode(None)  # type: ignore[arg-type]


JSONISH = st.text(alphabet='{}[]":,.0123456789eE+-NaInfitylsrun \\u', max_size=40).map(str.encode)


@pytest.mark.parametrize("codec", CODECS, ids=lambda c: c.name)
@settings(max_examples=300, deadline=None)
@given(payload=st.binary(max_size=64) | JSONISH)
def test_arbitrary_bytes_decode_to_a_message_or_a_decode_error(codec, payload):
    try:
        message = codec.decode(payload)
    except DecodeError as exc:
        assert str(exc)
        return
    assert type(message) is dict
    assert same_value(codec.decode(codec.encode(message)), message)


@pytest.mark.parametrize("codec", CODECS, ids=lambda c: c.name)
@FAST
@given(data=st.data())
def test_corrupted_messages_decode_to_a_message_or_a_decode_error(codec, data):
    payload = bytearray(codec.encode(data.draw(messages(scalars_for(codec)))))
    for _ in range(data.draw(st.integers(1, 3))):
        payload[data.draw(st.integers(0, len(payload) - 1))] = data.draw(st.integers(0, 255))
    try:
        message = codec.decode(bytes(payload))
    except DecodeError:
        return
    assert codec.carries(message) is None


# ---------------------------------------------------------------- encode errors

@pytest.mark.parametrize("codec", CODECS, ids=lambda c: c.name)
def test_encode_raises_only_encode_error(codec):
    looped: list = []
    looped.append(looped)
    for value in ({"a": object()}, {"a": looped}):
        with pytest.raises(EncodeError):
            codec.encode(value)


def test_same_value_is_strict_where_round_trips_must_be():
    assert same_value({"a": [math.nan]}, {"a": [math.nan]})
    assert not same_value(0.0, -0.0)
    assert not same_value(1, 1.0) and not same_value(1, True)
    assert not same_value({"a": 1, "b": 2}, {"b": 2, "a": 1})
