"""The interception engine on real codecs and real test cases: what each action
delivers to whom and when, the events it reports, and determinism."""

from __future__ import annotations

import json
import math
from pathlib import Path

import cbor2
import pytest

from astaa_deft.io.codecs import get_codec, same_value
from astaa_deft.model.errors import InputError
from astaa_deft.engine.intercept import Delivery, Interceptor, TestCase, load_dictionary, parse_testcase
from astaa_deft.model.tagged import from_tagged, to_tagged
from astaa_deft.engine.intercept.actions.set import Assignment, Set
from astaa_deft.engine.intercept.testcase import Policy
from astaa_deft.engine.spec.loader import load_spec

ROOT = Path(__file__).resolve().parent.parent
SPEC = load_spec(ROOT / "tests" / "data" / "intercept_sut.yaml")
DICTIONARY = load_dictionary()
JSON = get_codec("json")
TRAJ_CONSUMERS = ("control", "monitor")


def engine(policies: str, seed: int = 1) -> Interceptor:
    xml = f'<testcase id="tc" seed="{seed}"><description/>{policies}</testcase>'
    return Interceptor(parse_testcase(xml.encode(), "tc.xml", SPEC), SPEC, DICTIONARY)


def trajectory(seq: int, stamp: float | None = None, points: int = 3) -> bytes:
    return JSON.encode({
        "header": {"seq": seq, "stamp": float(seq) / 10 if stamp is None else stamp, "frame_id": "map"},
        "points": [{"x": float(i), "y": 0.5, "v": 10.0 + i} for i in range(points)],
        "gear": "drive", "tags": ["a"], "debug_note": ""})


def scan(seq: int) -> bytes:
    return cbor2.dumps({"meta": {"seq": seq, "stamp": seq / 10, "frame_id": "lidar"},
                        "ranges": [1.0, 2.0], "intensities": [5.0, 6.0], "count": 2, "valid": True,
                        "blob": b"\x00\x01", "label": "x"})


def feed(interceptor: Interceptor, count: int, *, period: float = 0.1, start: float = 0.0,
         make=trajectory, channel: str = "trajectory", consumers=TRAJ_CONSUMERS, tick: bool = True
         ) -> list[tuple[float, list[Delivery]]]:
    """Messages 1..count at start + i*period (and a tick after each); what came back at each time."""
    out = []
    for i in range(count):
        now = start + i * period
        delivered = interceptor.on_message(channel, consumers, make(i + 1), now)
        if tick:
            delivered += interceptor.on_tick(now)
        out.append((now, delivered))
    return out


def decoded(delivery: Delivery) -> dict:
    return JSON.decode(delivery.payload)


def mutated(results) -> list[Delivery]:
    return [d for _, ds in results for d in ds if d.event is not None]


# ---------------------------------------------------------------- the untouched path

def test_untouched_messages_come_back_as_the_same_object():
    interceptor = engine('<policy id="p"><channel>trajectory</channel><window from="100"/><drop/></policy>')
    payload = trajectory(1)
    [delivery] = interceptor.on_message("trajectory", TRAJ_CONSUMERS, payload, 0.5)
    assert delivery.payload is payload
    assert (delivery.consumers, delivery.original, delivery.event, delivery.at) == (TRAJ_CONSUMERS, None, None, 0.5)


def test_unselected_messages_are_never_decoded():
    interceptor = engine('<policy id="p"><channel>trajectory</channel><window from="5"/>'
                         '<set><field path="gear" value="park"/></set></policy>')
    garbage = b"\xff not json"
    [delivery] = interceptor.on_message("trajectory", TRAJ_CONSUMERS, garbage, 1.0)
    assert delivery.payload is garbage and delivery.event is None


def test_channels_lists_targets_and_window_anchors():
    interceptor = engine('<policy id="p"><channel>trajectory</channel><window from="0" to="1">'
                         '<after channel="odometry" message="5"/></window><drop/></policy>'
                         '<policy id="q"><type>Scan</type><drop/></policy>')
    assert interceptor.channels() == {"trajectory", "odometry", "scan"}
    payload = b"{}"
    [delivery] = interceptor.on_message("status", (), payload, 0.0)  # not affected at all
    assert delivery.payload is payload


# ---------------------------------------------------------------- set

def test_set_literal_and_dictionary_values_with_events():
    interceptor = engine('<policy id="p"><channel>trajectory</channel>'
                         '<set><field path="points[*].v" value="dict:float.nan"/>'
                         '<field path="gear" value="reverse"/></set></policy>')
    payload = trajectory(7)
    [delivery] = interceptor.on_message("trajectory", TRAJ_CONSUMERS, payload, 2.0)
    message = decoded(delivery)
    assert all(math.isnan(p["v"]) for p in message["points"]) and message["gear"] == "reverse"
    assert delivery.original is payload and delivery.consumers == TRAJ_CONSUMERS
    event = delivery.event
    assert (event.testcase, event.policy, event.action, event.channel, event.message_index, event.time) == \
        ("tc", "p", "set", "trajectory", 1, 2.0)
    assert [c.path for c in event.fields] == ["points[0].v", "points[1].v", "points[2].v", "gear"]
    assert event.fields[0].old == 10.0 and math.isnan(event.fields[0].new)
    assert event.fields[3].old == "drive" and event.fields[3].new == "reverse"


def test_set_only_changes_the_named_fields():
    interceptor = engine('<policy id="p"><channel>trajectory</channel>'
                         '<set><field path="points[1].x" value="-1"/></set></policy>')
    payload = trajectory(1)
    [delivery] = interceptor.on_message("trajectory", TRAJ_CONSUMERS, payload, 0.0)
    expected = JSON.decode(payload)
    expected["points"][1]["x"] = -1.0
    assert same_value(decoded(delivery), expected)


def test_undecodable_payload_under_set_is_delivered_untouched_with_a_reason():
    interceptor = engine('<policy id="p"><channel>trajectory</channel>'
                         '<set><field path="gear" value="park"/></set></policy>')
    garbage = b'{"header": '
    [delivery] = interceptor.on_message("trajectory", TRAJ_CONSUMERS, garbage, 0.0)
    assert delivery.payload is garbage and delivery.original is None
    assert delivery.event.detail["skipped"].startswith("undecodable: malformed JSON")


def test_missing_field_is_reported_and_payload_kept():
    interceptor = engine('<policy id="p"><channel>trajectory</channel>'
                         '<set><field path="points[5].v" value="1"/></set></policy>')
    payload = trajectory(1)
    [delivery] = interceptor.on_message("trajectory", TRAJ_CONSUMERS, payload, 0.0)
    assert delivery.payload is payload and delivery.original is None
    assert delivery.event.detail["skipped_fields"] == [
        {"path": "points[5].v", "reason": "no such field in this message"}]


def test_value_the_codec_cannot_carry_is_skipped_with_the_codec_reason():
    interceptor = engine('<policy id="p"><channel>scan</channel><set>'
                         '<field path="label" value="dict:string.lone_surrogate"/>'
                         '<field path="count" value="dict:int.width_overflow"/></set></policy>')
    [delivery] = interceptor.on_message("scan", ("planner",), scan(1), 0.0)
    message = cbor2.loads(delivery.payload)
    assert message["label"] == "x" and message["count"] == 128
    [skipped] = delivery.event.detail["skipped_fields"]
    assert skipped["path"] == "label" and "lone surrogate" in skipped["reason"]


def test_bytes_fields_travel_as_bytes_in_cbor():
    interceptor = engine('<policy id="p"><channel>scan</channel><set>'
                         '<field path="blob" value="dict:bytes.all_ff"/></set></policy>')
    [delivery] = interceptor.on_message("scan", ("planner",), scan(1), 0.0)
    assert cbor2.loads(delivery.payload)["blob"] == b"\xff" * 64


def test_time_rules_use_the_previous_real_message():
    interceptor = engine('<policy id="back"><channel>trajectory</channel><window from="0.15"/><select limit="1"/>'
                         '<set><field path="header.stamp" value="dict:time.jump_back"/></set></policy>'
                         '<policy id="same"><channel>trajectory</channel><window from="0.25"/><select limit="1"/>'
                         '<set><field path="header.stamp" value="dict:time.repeat_previous"/></set></policy>')
    results = feed(interceptor, 4, make=lambda i: trajectory(i, stamp=100.0 + i))
    stamps = [decoded(ds[0])["header"]["stamp"] for _, ds in results]
    assert stamps == [101.0, 102.0, 101.0, 103.0]  # message 3: previous (102) - 1 s; message 4: previous again


def test_rules_needing_a_previous_message_skip_the_first_one():
    interceptor = engine('<policy id="p"><channel>trajectory</channel><select limit="1"/>'
                         '<set><field path="header.stamp" value="dict:time.repeat_previous"/></set></policy>')
    [delivery] = interceptor.on_message("trajectory", TRAJ_CONSUMERS, trajectory(1), 0.0)
    assert delivery.event.detail["skipped_fields"][0]["reason"] == "no previous message on this channel"


def test_array_rules():
    interceptor = engine('<policy id="p"><channel>scan</channel><set>'
                         '<field path="ranges" value="dict:array.sibling_mismatch"/>'
                         '<field path="intensities" value="dict:array.ten_times_longer"/></set></policy>')
    [delivery] = interceptor.on_message("scan", ("planner",), scan(1), 0.0)
    message = cbor2.loads(delivery.payload)
    assert len(message["ranges"]) == 3 and len(message["intensities"]) == 20


def test_ten_times_longer_elements_are_independent_copies():
    interceptor = engine('<policy id="a"><channel>trajectory</channel><set>'
                         '<field path="points" value="dict:array.ten_times_longer"/></set></policy>'
                         '<policy id="b"><channel>trajectory</channel><set>'
                         '<field path="points[0].v" value="-1"/></set></policy>')
    [delivery] = interceptor.on_message("trajectory", TRAJ_CONSUMERS, trajectory(1), 0.0)
    v = [p["v"] for p in decoded(delivery)["points"]]
    assert len(v) == 30 and v[0] == -1.0 and v.count(-1.0) == 1


# ---------------------------------------------------------------- windows, selection, consumers

def test_time_window_is_half_open():
    interceptor = engine('<policy id="p"><channel>trajectory</channel><window from="0.2" to="0.5"/><drop/></policy>')
    dropped = [now for now, ds in feed(interceptor, 8) if ds[0].consumers == ()]
    assert dropped == pytest.approx([0.2, 0.3, 0.4])


def test_window_counted_from_the_nth_message_on_another_channel():
    interceptor = engine('<policy id="p"><channel>trajectory</channel>'
                         '<window from="0" to="0.25"><after channel="odometry" message="2"/></window><drop/></policy>')
    odometry = JSON.encode({"stamp": 0.0, "speed": 1.0, "mode": 0})
    assert interceptor.on_message("odometry", ("planner",), odometry, 0.0)[0].payload is odometry
    assert interceptor.on_message("trajectory", TRAJ_CONSUMERS, trajectory(1), 0.5)[0].event is None
    interceptor.on_message("odometry", ("planner",), odometry, 1.0)  # the anchor: window [1.0, 1.25)
    dropped = [now for now, ds in feed(interceptor, 5, start=1.0) if ds[0].consumers == ()]
    assert dropped == pytest.approx([1.0, 1.1, 1.2])


def test_every_kth_and_limit():
    interceptor = engine('<policy id="p"><channel>trajectory</channel><select every="3" limit="2"/><drop/></policy>')
    dropped = [i for i, (_, ds) in enumerate(feed(interceptor, 12), 1) if ds[0].consumers == ()]
    assert dropped == [1, 4]


def test_probability_is_seeded():
    policy = '<policy id="p"><channel>trajectory</channel><select probability="0.3"/><drop/></policy>'

    def dropped(seed: int) -> list[int]:
        return [i for i, (_, ds) in enumerate(feed(engine(policy, seed), 200), 1) if ds[0].consumers == ()]

    assert dropped(5) == dropped(5)
    assert dropped(5) != dropped(6)
    assert 30 < len(dropped(5)) < 90


def test_consumer_subset_gets_the_mutation_others_the_original_object():
    interceptor = engine('<policy id="p"><channel>trajectory</channel><consumer>monitor</consumer>'
                         '<set><field path="gear" value="park"/></set></policy>')
    payload = trajectory(1)
    deliveries = interceptor.on_message("trajectory", TRAJ_CONSUMERS, payload, 0.0)
    by_consumer = {d.consumers: d for d in deliveries}
    assert set(by_consumer) == {("control",), ("monitor",)}
    assert by_consumer[("control",)].payload is payload and by_consumer[("control",)].event is None
    assert decoded(by_consumer[("monitor",)])["gear"] == "park"
    assert by_consumer[("monitor",)].event.consumers == ("monitor",)


def test_policies_stack_in_document_order_into_one_event():
    interceptor = engine('<policy id="a"><channel>trajectory</channel>'
                         '<set><field path="gear" value="park"/></set></policy>'
                         '<policy id="b"><channel>trajectory</channel>'
                         '<set><field path="gear" value="reverse"/></set></policy>'
                         '<policy id="c"><channel>trajectory</channel><delay ms="100"/></policy>')
    assert interceptor.on_message("trajectory", TRAJ_CONSUMERS, trajectory(1), 0.0) == []
    [delivery] = interceptor.on_tick(0.1)
    assert decoded(delivery)["gear"] == "reverse" and delivery.at == pytest.approx(0.1)
    event = delivery.event
    assert (event.policy, event.action) == ("a+b+c", "set+set+delay")
    assert [(c.old, c.new) for c in event.fields] == [("drive", "park"), ("park", "reverse")]
    assert [step["policy"] for step in event.detail["steps"]] == ["a", "b", "c"]


# ---------------------------------------------------------------- the other actions

def test_drop_returns_an_event_only_delivery():
    interceptor = engine('<policy id="p"><channel>trajectory</channel><drop/></policy>')
    payload = trajectory(1)
    [delivery] = interceptor.on_message("trajectory", TRAJ_CONSUMERS, payload, 0.0)
    assert delivery.consumers == () and delivery.original is payload
    assert delivery.event.action == "drop" and delivery.event.consumers == TRAJ_CONSUMERS


def test_delay_holds_until_due_and_later_messages_overtake():
    interceptor = engine('<policy id="p"><channel>trajectory</channel><select limit="1"/><delay ms="250"/></policy>')
    order = [decoded(d)["header"]["seq"] for _, ds in feed(interceptor, 6) for d in ds]
    assert order == [2, 3, 1, 4, 5, 6]  # due at 0.25 s: goes out before message 4 (0.3 s)
    assert interceptor.flush(1.0) == []


def test_flush_releases_delayed_messages_now():
    interceptor = engine('<policy id="p"><channel>trajectory</channel><delay ms="5000"/></policy>')
    feed(interceptor, 2)
    released = interceptor.flush(1.0)
    assert [decoded(d)["header"]["seq"] for d in released] == [1, 2]
    assert all(d.at == 1.0 for d in released)


def test_duplicate_adds_marked_copies():
    interceptor = engine('<policy id="p"><channel>trajectory</channel><duplicate copies="2"/></policy>')
    payload = trajectory(1)
    real, first, second = interceptor.on_message("trajectory", TRAJ_CONSUMERS, payload, 0.0)
    assert real.payload is payload and real.event is None
    for number, copy in enumerate((first, second), 1):
        assert copy.payload == payload and copy.original is payload
        assert copy.event.detail == {"copy": number, "copies": 2}


def test_reorder_swaps_pairs():
    interceptor = engine('<policy id="p"><channel>trajectory</channel><reorder/></policy>')
    order = [decoded(d)["header"]["seq"] for _, ds in feed(interceptor, 6) for d in ds]
    assert order == [2, 1, 4, 3, 6, 5]


def test_reorder_releases_after_max_hold_and_at_flush():
    interceptor = engine('<policy id="p"><channel>trajectory</channel><select every="2"/>'
                         '<reorder max-hold-ms="150"/></policy>')
    assert interceptor.on_message("trajectory", TRAJ_CONSUMERS, trajectory(1), 0.0) == []
    assert interceptor.on_tick(0.1) == []
    [released] = interceptor.on_tick(0.2)
    assert released.event.detail["released"] == "no next message within max-hold-ms"
    interceptor.on_message("trajectory", TRAJ_CONSUMERS, trajectory(2), 0.3)
    assert interceptor.on_message("trajectory", TRAJ_CONSUMERS, trajectory(3), 0.4) == []
    [held] = interceptor.flush(0.45)
    assert decoded(held)["header"]["seq"] == 3 and held.event.detail["released"] == "end of run"


def test_interleave_injects_copies_of_the_last_real_message():
    interceptor = engine('<policy id="p"><channel>trajectory</channel><window from="0.3" to="0.6"/>'
                         '<interleave rate="40"><field path="header.stamp" value="dict:time.jump_back"/>'
                         '</interleave></policy>')
    results = feed(interceptor, 8, period=0.1)
    injected = [d for _, ds in results for d in ds if d.event is not None]
    real = [d for _, ds in results for d in ds if d.event is None]
    assert len(real) == 8 and all(d.original is None for d in real)
    # 40 Hz from 0.325 s (one period after the first real message in the window) until 0.6 s
    assert len(injected) == 11
    assert all(0.3 < d.at < 0.6 for d in injected)
    first = injected[0]
    assert first.event.action == "interleave" and first.event.message_index == 4
    assert decoded(first)["header"]["seq"] == 4 and decoded(first)["header"]["stamp"] == pytest.approx(-0.6)
    assert first.original == trajectory(4)


def test_corrupt_flip_and_truncate_are_deterministic():
    policies = ('<policy id="f"><channel>trajectory</channel><corrupt mode="flip" bytes="3"/></policy>'
                '<policy id="t"><channel>scan</channel><corrupt mode="truncate"/></policy>')

    def corrupted(seed: int) -> tuple[Delivery, Delivery]:
        interceptor = engine(policies, seed)
        [flipped] = interceptor.on_message("trajectory", TRAJ_CONSUMERS, trajectory(1), 0.0)
        [truncated] = interceptor.on_message("scan", ("planner",), scan(1), 0.0)
        return flipped, truncated

    flipped, truncated = corrupted(9)
    original = trajectory(1)
    positions = flipped.event.detail["flipped_bytes"]
    assert len(positions) == 3
    assert [i for i in range(len(original)) if original[i] != flipped.payload[i]] == positions
    assert truncated.payload == scan(1)[:truncated.event.detail["truncated_to"]]
    assert [d.payload for d in corrupted(9)] == [flipped.payload, truncated.payload]


# ---------------------------------------------------------------- determinism and events as JSON

MIXED = ('<policy id="nan"><channel>trajectory</channel><select probability="0.4"/>'
         '<set><field path="points[*].v" value="dict:float.nan"/></set></policy>'
         '<policy id="late"><channel>trajectory</channel><select probability="0.2"/><delay ms="120"/></policy>'
         '<policy id="swap"><channel>trajectory</channel><select probability="0.1"/><reorder/></policy>'
         '<policy id="dup"><channel>trajectory</channel><select probability="0.1"/><duplicate/></policy>'
         '<policy id="flip"><channel>trajectory</channel><select probability="0.1"/><corrupt mode="flip"/></policy>'
         '<policy id="inject"><channel>trajectory</channel><window from="2" to="3"/><interleave rate="30"/></policy>')


def _transcript(seed: int) -> list:
    interceptor = engine(MIXED, seed)
    log = []
    for _now, deliveries in feed(interceptor, 60, period=0.05):
        log.extend((d.consumers, d.payload, d.at, d.original, json.dumps(d.event.to_json()) if d.event else None)
                   for d in deliveries)
    log.extend((d.consumers, d.payload, d.at) for d in interceptor.flush(10.0))
    return log


def test_same_seed_and_stream_give_identical_deliveries_and_events():
    assert _transcript(3) == _transcript(3)
    assert _transcript(3) != _transcript(4)


def test_events_serialise_to_strict_json_and_back():
    interceptor = engine('<policy id="p"><channel>scan</channel><set>'
                         '<field path="ranges[0]" value="dict:float.inf"/><field path="blob" value="dict:bytes.empty"/>'
                         '<field path="label" value="json:{&quot;float&quot;: &quot;nan&quot;}"/>'
                         '</set></policy>')
    [delivery] = interceptor.on_message("scan", ("planner",), scan(1), 0.0)
    event_json = delivery.event.to_json()
    text = json.dumps(event_json, allow_nan=False)  # no NaN/Infinity tokens, no bytes
    fields = json.loads(text)["fields"]
    assert fields[0]["new"] == {"float": "inf"}
    assert fields[1] == {"path": "blob", "old": {"base64": "AAE="}, "new": {"base64": ""}}
    assert fields[2]["new"] == {"object": {"float": "nan"}}  # a real object that looks like a tag is wrapped
    for field, change in zip(fields, delivery.event.fields, strict=True):
        assert same_value(from_tagged(field["new"]), change.new)


@pytest.mark.parametrize("value", [float("nan"), -math.inf, b"\x00\xff", "\udc80 lone", {"base64": 1},
                                   [1.5, {"x": float("inf")}], {"a": {"str_escaped": "x"}}, "plain", 2**70])
def test_tagging_round_trips(value):
    tagged = to_tagged(value)
    json.dumps(tagged, allow_nan=False).encode("utf-8")
    assert same_value(from_tagged(tagged), value)


def test_a_testcase_built_in_code_with_a_bad_field_is_an_input_error():
    testcase = TestCase(id="x", seed=1, description="",
                        policies=(Policy(id="p", action=Set((Assignment("nope", "1"),)), channels=("trajectory",)),))
    with pytest.raises(InputError, match="Trajectory has no field 'nope'"):
        Interceptor(testcase, SPEC, DICTIONARY)
    unknown = TestCase(id="x", seed=1, description="",
                       policies=(Policy(id="p", action=Set((Assignment("gear", "park"),)), channels=("nowhere",)),))
    with pytest.raises(InputError, match="unknown channel"):
        Interceptor(unknown, SPEC, DICTIONARY)


def test_held_back_messages_name_their_payload_and_come_back_on_their_own_channel():
    """What on_message returns goes out as that channel's current message unless it names
    its original: a delayed or reordered message must never be mistaken for it."""
    interceptor = engine('<policy id="late"><channel>trajectory</channel><select limit="1"/><delay ms="50"/></policy>'
                         '<policy id="swap"><channel>scan</channel><select limit="1"/><reorder/></policy>')
    first = trajectory(1)
    assert interceptor.on_message("trajectory", TRAJ_CONSUMERS, first, 0.0) == []
    # The trajectory is due at 0.05 s, but a scan message (itself held by reorder) does
    # not carry it out: the caller would route it as a scan.
    assert interceptor.on_message("scan", ("planner",), scan(1), 0.1) == []
    second = trajectory(2)
    released, current = interceptor.on_message("trajectory", TRAJ_CONSUMERS, second, 0.2)
    assert released.payload is first and released.original is first and released.event.action == "delay"
    assert current.payload is second and current.original is None
    next_scan, swapped = interceptor.on_message("scan", ("planner",), scan(2), 0.3)
    assert next_scan.original is None and swapped.original == scan(1) and swapped.event.action == "reorder"


def test_load_interceptor_reads_checks_and_merges_dictionaries(tmp_path):
    from astaa_deft.engine.intercept import load_interceptor

    mine = tmp_path / "mine.yaml"
    mine.write_text("enum:\n  sport: sport\n")
    case = tmp_path / "case.xml"
    case.write_text('<testcase id="c" seed="1"><description/><policy id="p"><channel>trajectory</channel>'
                    '<set><field path="gear" value="dict:enum.sport"/></set></policy></testcase>')
    interceptor = load_interceptor(case, SPEC, [mine])
    [delivery] = interceptor.on_message("trajectory", TRAJ_CONSUMERS, trajectory(1), 0.0)
    assert decoded(delivery)["gear"] == "sport"
    with pytest.raises(InputError, match="unknown dictionary entry 'dict:enum.sport'"):
        load_interceptor(case, SPEC)


def test_interleave_reports_an_undecodable_template_once_and_resumes_with_the_next():
    interceptor = engine('<policy id="p"><channel>trajectory</channel><interleave rate="100"/></policy>')
    interceptor.on_message("trajectory", TRAJ_CONSUMERS, b"not json", 0.0)
    reported = interceptor.on_tick(0.05)
    assert len(reported) == 1 and reported[0].consumers == ()
    assert reported[0].event.detail["skipped"].startswith("undecodable")
    assert interceptor.on_tick(0.1) == []
    interceptor.on_message("trajectory", TRAJ_CONSUMERS, trajectory(2), 0.1)
    copies = interceptor.on_tick(0.125)  # slots at 0.11 and 0.12 s
    assert len(copies) == 2 and all(decoded(d)["header"]["seq"] == 2 for d in copies)
    assert [d.event.detail["injection"] for d in copies] == [1, 2]
