"""The orjson shortcut for ``set`` on JSON gives byte for byte what the general path (stdlib codec) gives.

``json_fast`` answers only when its answer is the codec's; the engine's fast
path for a lone ``set`` policy must deliver the same payload and the same
event (values of the same types) as ``SetRuntime.apply`` through ``Pending``.
Generated documents cover what the two JSON libraries write differently
(non-ASCII text, DEL, small and large floats, integers beyond 64 bits).
"""

from __future__ import annotations

import json
from pathlib import Path

from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from astaa_deft.io.codecs import DecodeError, get_codec, json_fast, same_value
from astaa_deft.engine.intercept import Delivery, Interceptor, load_dictionary, parse_testcase
from astaa_deft.engine.spec.loader import load_spec
from astaa_deft.model.records import Rewritten

ROOT = Path(__file__).resolve().parent.parent
SPEC = load_spec(ROOT / "tests" / "data" / "intercept_sut.yaml")
DICTIONARY = load_dictionary()
JSON = get_codec("json")
CONSUMERS = ("control", "monitor")

floats = st.one_of(
    st.floats(allow_nan=False, allow_infinity=False),
    st.sampled_from([1e-05, 1.5e-05, 9.99e-05, 1e-07, 1e-4, 1e15, 1e16, 1e22, 5e-324, -0.0, 0.0, 0.1, 1e300]),
)
ints = st.one_of(st.integers(-2**70, 2**70), st.sampled_from([2**63 - 1, 2**63, 2**64 - 1, 2**64, -2**63, -2**63 - 1]))
texts = st.one_of(st.text(max_size=12), st.sampled_from(["é", "\x7f", "a\x00b", "\u2028", "e-1", "1e+5", "0.00001",
                                                          "\ud800", "😀", "\\/"]))
scalars = st.one_of(st.none(), st.booleans(), ints, floats, texts)
documents = st.dictionaries(texts, st.recursive(scalars, lambda inner: st.one_of(
    st.lists(inner, max_size=4), st.dictionaries(texts, inner, max_size=4)), max_leaves=12), max_size=6)


def written(document: dict, style: int) -> bytes:
    """The document as some producer might write it (spacing, escaping)."""
    if style == 0:
        return JSON.encode(document)
    if style == 1:
        return json.dumps(document).encode("utf-8", "surrogatepass")
    return json.dumps(document, ensure_ascii=False, indent=1).encode("utf-8", "surrogatepass")


@settings(max_examples=300, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(documents, st.integers(0, 2))
def test_loads_and_dumps_answer_only_with_the_codecs_own_result(document, style):
    payload = written(document, style)
    fast = json_fast.loads(payload)
    try:
        general = JSON.decode(payload)
    except DecodeError:  # e.g. a lone surrogate written as UTF-8: the stdlib refuses it, orjson too
        assert fast is None
        return
    if fast is not None:
        assert same_value(fast, general) or _holds_big_float(fast)
    message = general if fast is None else fast
    out = json_fast.dumps(message)
    if out is not None:
        assert out == JSON.encode(message)


def _holds_big_float(value) -> bool:
    """orjson reads integers beyond 64 bits as floats of magnitude >= 2**63 (dumps and is_exact_scalar refuse them)."""
    if type(value) is float:
        return not json_fast.is_exact_scalar(value)
    if type(value) is list:
        return any(_holds_big_float(v) for v in value)
    if type(value) is dict:
        return any(_holds_big_float(v) for v in value.values())
    return False


def test_dumps_refuses_what_orjson_writes_otherwise():
    for value in (1e-05, 1.5e-05, 1e-07, 2.0**70, "é", "\x7f", "\u2028"):
        assert json_fast.dumps({"v": value}) is None, value
    assert json_fast.dumps({"v": 0.5, "s": "plain"}) == JSON.encode({"v": 0.5, "s": "plain"})


def test_loads_refuses_what_only_the_stdlib_reads():
    for payload in (b'{"v": NaN}', b'{"v": -Infinity}', b'{"v": 1e400}', b'{"v": "\\ud800"}', b"[1]",
                    b'\xef\xbb\xbf{"v": 1}', b'{"v": "\xff"}'):
        assert json_fast.loads(payload) is None, payload
    assert not json_fast.is_exact_scalar(json_fast.loads(b'{"v": 18446744073709551616}')["v"])


def engines(assignments: str) -> tuple[Interceptor, Interceptor]:
    """The same test case twice: with the engine's shortcut, and forced through the general path."""
    xml = (f'<testcase id="tc" seed="1"><description/><policy id="p"><channel>trajectory</channel>'
           f'<set>{assignments}</set></policy></testcase>').encode()
    fast = Interceptor(parse_testcase(xml, "tc.xml", SPEC), SPEC, DICTIONARY)
    general = Interceptor(parse_testcase(xml, "tc.xml", SPEC), SPEC, DICTIONARY)
    general._channels["trajectory"].fast = None
    return fast, general


def through_lane(engine: Interceptor, payload: bytes, now: float) -> list:
    """What ``engine.lane`` (the proxy's way) gives for one message, as the deliveries ``on_message`` returns."""
    lane = engine.lane("trajectory", CONSUMERS)
    assert lane is not None
    done = lane(payload, now)
    if done is None:
        return [Delivery(CONSUMERS, payload, now)]
    if isinstance(done, Rewritten):
        return [Delivery(CONSUMERS, done.payload, now, original=payload, event=engine.event(done.event))]
    return done


def test_a_lone_set_policy_on_json_takes_the_shortcut():
    fast, general = engines('<field path="header.seq" value="0"/>')
    assert fast._channels["trajectory"].fast is not None
    assert general._channels["trajectory"].fast is None
    # Not for a value orjson writes otherwise (NaN), a wildcard path, or a derived value.
    for assignments in ('<field path="points[0].v" value="dict:float.nan"/>',
                        '<field path="points[*].v" value="1.0"/>',
                        '<field path="header.stamp" value="dict:time.jump_back"/>'):
        assert engines(assignments)[0]._channels["trajectory"].fast is None, assignments


trajectories = st.fixed_dictionaries({
    "header": st.fixed_dictionaries({"seq": ints, "stamp": floats, "frame_id": texts}),
    "points": st.lists(st.fixed_dictionaries({"x": floats, "y": floats, "v": st.one_of(floats, ints)}), max_size=3),
    "gear": st.sampled_from(["drive", "park"]), "tags": st.lists(texts, max_size=2), "debug_note": texts,
})
ASSIGNMENTS = ('<field path="header.seq" value="0"/><field path="points[1].v" value="2.5"/>'
               '<field path="header.frame_id" value="str:odom"/>')


@settings(max_examples=200, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(st.lists(st.tuples(trajectories, st.integers(0, 2)), min_size=1, max_size=4))
def test_shortcut_deliveries_and_events_are_the_general_paths(messages):
    fast, general = engines(ASSIGNMENTS)
    laned, _ = engines(ASSIGNMENTS)
    for i, (document, style) in enumerate(messages):
        if i == 1:  # a payload only the stdlib reads goes the general way in both
            payload = written(document, style).replace(b'"gear"', b'"nan": NaN, "gear"', 1)
        else:
            payload = written(document, style)
        now = i * 0.1
        expected = general.on_message("trajectory", CONSUMERS, payload, now)
        for got in (fast.on_message("trajectory", CONSUMERS, payload, now), through_lane(laned, payload, now)):
            assert len(got) == len(expected) == 1
            g, e = got[0], expected[0]
            assert (g.consumers, g.payload, g.at, g.original) == (e.consumers, e.payload, e.at, e.original)
            assert g.event == e.event
            assert same_value(json.loads(json.dumps(g.event.to_json())), json.loads(json.dumps(e.event.to_json())))
            for gc, ec in zip(g.event.fields, e.event.fields, strict=True):
                assert same_value(gc.old, ec.old) and same_value(gc.new, ec.new)
    # What each policy did, as the run's record says it, is the same whichever way the messages went.
    assert laned.applications(1.0) == fast.applications(1.0) == general.applications(1.0)


def test_shortcut_falls_back_where_it_might_differ():
    fast, general = engines('<field path="header.seq" value="0"/>')
    cases = [
        {"header": {"seq": 2**70, "stamp": 0.5, "frame_id": "m"}},  # the old value: beyond 64 bits
        {"header": {"seq": 1, "stamp": 1e-05, "frame_id": "m"}},  # a float orjson writes positionally
        {"header": {"seq": 1, "stamp": 0.5, "frame_id": "é"}},  # non-ASCII
        {"header": {"stamp": 0.5, "frame_id": "m"}},  # the field is missing: reported by the general path
    ]
    laned, _ = engines('<field path="header.seq" value="0"/>')
    for i, document in enumerate(cases):
        payload = json.dumps(document, ensure_ascii=False).encode()
        e, g, lg = (general.on_message("trajectory", CONSUMERS, payload, i)[0],
                    fast.on_message("trajectory", CONSUMERS, payload, i)[0], through_lane(laned, payload, i)[0])
        assert (g.payload, g.original, g.event) == (lg.payload, lg.original, lg.event) == \
            (e.payload, e.original, e.event)
