"""Why outputs do not reproduce: the fields a comparison finds different, and the diagnosis built from them.

The comparison of a module's output field by field keeps the fields that
differ (array elements as one ``[*]`` field); ``diagnose`` reads one such
comparison per output and says per field how often and how it differs —
on one side only, a constant offset, the same two values, varying amounts,
rounding, now and then — with the ``ignore:`` line to add and how many
outputs the frames kept would then match. ``ignore:`` takes a leaf, a whole
struct, an array, or ``[*]`` for every element.
"""

from __future__ import annotations

import math

import pytest

from astaa_deft.analysis.deft.diagnosis import (
    ALWAYS, CONSTANT, OFFSET, RECORDED_ONLY, REPLAYED_ONLY, ROUNDED, SOMETIMES, diagnose, unmatched_ignores,
)
from astaa_deft.analysis.deft.validator import (
    MAX_FIELD_DIFFERENCES, Comparison, compare_messages, flatten,
)


def message(i: int, **header: object) -> dict:
    return {"header": {"seq": i, "stamp": 0.05 * i, **header}, "x": [0.1 * i, 1.0], "count": i, "debug": {"a": i}}


# -- ignore: what it takes ---------------------------------------------------------------------------------


def test_ignore_takes_a_leaf_a_whole_struct_an_array_or_every_element():
    value = {"header": {"seq": 1, "stamp": 2.0}, "headers": 3, "points": [{"t": 0.0, "x": 1.0}, {"t": 1.0, "x": 2.0}]}
    assert set(flatten(value, ["header.stamp"])) == {"header.seq", "headers", "points[0].t", "points[0].x",
                                                     "points[1].t", "points[1].x"}
    # a whole struct: every field in it, and nothing that merely starts with its name
    assert set(flatten(value, ["header"])) == {"headers", "points[0].t", "points[0].x", "points[1].t", "points[1].x"}
    assert set(flatten(value, ["points"])) == {"header.seq", "header.stamp", "headers"}
    assert set(flatten(value, ["points[*].t"])) == {"header.seq", "header.stamp", "headers", "points[0].x",
                                                    "points[1].x"}
    assert set(flatten(value, ["points[1]"])) == {"header.seq", "header.stamp", "headers", "points[0].t",
                                                  "points[0].x"}
    # and the comparison follows: a struct ignored whole makes outputs that differ only there match
    a, b = {"header": {"seq": 1, "frame_id": "map"}, "x": 1.0}, {"header": {"seq": 2}, "x": 1.0}
    assert compare_messages(a, b, ["header"]).distance == 0.0
    assert compare_messages(a, b, ["header.seq"]).distance == math.inf


# -- the fields a comparison finds different ---------------------------------------------------------------


def test_a_comparison_names_the_fields_that_differ_and_how():
    replayed = {"header": {"seq": 3, "stamp": 1.0}, "x": [1.0, 2.0, 3.0], "label": "car", "extra": 1}
    recorded = {"header": {"seq": 3, "stamp": 1.5, "frame_id": "map"}, "x": [1.5, 2.5, 3.5], "label": "bus"}
    cmp = compare_messages(replayed, recorded)
    assert cmp.distance == math.inf and cmp.how == "fields differ"
    by_path = {f.path: f for f in cmp.fields}
    assert list(by_path) == ["extra", "header.frame_id", "header.stamp", "label", "x[*]"]  # replayed-only first
    assert (by_path["extra"].side, by_path["extra"].replayed, by_path["extra"].recorded) == ("replayed", "1", "")
    assert (by_path["header.frame_id"].side, by_path["header.frame_id"].recorded) == ("recorded", "'map'")
    stamp = by_path["header.stamp"]
    assert (stamp.side, stamp.delta, stamp.uniform, stamp.squared) == ("both", -0.5, True, 0.25)
    x = by_path["x[*]"]  # an array's elements are one field
    assert (x.leaves, x.delta, x.uniform, x.squared) == (3, -0.5, True, 0.75)
    label = by_path["label"]
    assert (label.delta, label.squared, label.recorded, label.replayed) == (None, math.inf, "'bus'", "'car'")
    assert "header.seq" not in by_path and cmp.fields_left_out == 0


def test_matching_outputs_carry_no_fields_and_many_differences_are_counted_not_all_described():
    same = {"a": 1.0, "b": [1, 2]}
    assert compare_messages(same, dict(same)) == Comparison(distance=0.0, max_error=0.0, points=3, how="fields")
    wide_replayed = {f"f{i}": float(i) for i in range(MAX_FIELD_DIFFERENCES + 5)}
    wide_recorded = {key: value + 1.0 for key, value in wide_replayed.items()}
    cmp = compare_messages(wide_replayed, wide_recorded)
    assert len(cmp.fields) == MAX_FIELD_DIFFERENCES and cmp.fields_left_out == 5
    assert cmp.distance == pytest.approx(math.sqrt(MAX_FIELD_DIFFERENCES + 5))
    uneven = compare_messages({"x": [1.0, 2.0]}, {"x": [1.5, 2.0 + 0.25]})
    assert (uneven.fields[0].delta, uneven.fields[0].uniform) == (-0.5, False)


# -- the diagnosis ------------------------------------------------------------------------------------------


def comparisons(replayed: list[dict], recorded: list[dict], ignore: tuple[str, ...] = ("debug",)) -> list[Comparison]:
    return [compare_messages(a, b, ignore) for a, b in zip(replayed, recorded, strict=True)]


def test_no_diagnosis_when_every_output_reproduces():
    outputs = [message(i) for i in range(5)]
    assert diagnose(comparisons(outputs, outputs), threshold=0.0) is None
    near = [{**m, "x": [m["x"][0] + 0.01, 1.0]} for m in outputs]
    assert diagnose(comparisons(near, outputs), threshold=0.1) is None  # within θ


def test_a_field_the_node_adds_is_named_with_the_line_that_makes_the_kept_frames_match():
    recorded = [message(i, frame_id="base_link") for i in range(10)]
    replayed = [message(i) for i in range(10)]
    replayed[4]["x"][0] += 0.5  # one frame wrong as well
    found = diagnose(comparisons(replayed, recorded), threshold=0.0, ignore=("debug",), where="replay.modules[0]")
    assert found is not None and (found.judged, found.not_reproduced, found.compared) == (10, 10, 10)
    frame_id = found.fields[0]
    assert (frame_id.path, frame_id.how, frame_id.differs, frame_id.blocking, frame_id.in_line) == (
        "header.frame_id", RECORDED_ONLY, 10, 10, True)
    assert "'base_link'" in frame_id.detail
    x = next(f for f in found.fields if f.path == "x[*]")
    assert (x.how, x.differs, x.in_line) == (SOMETIMES, 1, False)
    assert found.ignore == ("debug", "header.frame_id") and found.ignore_line == "ignore: [debug, header.frame_id]"
    assert found.reproduced_with_line == 9  # all but the wrong frame
    text = "\n".join(found.lines("sut.yaml"))
    assert "header.frame_id" in text and "ignore: [debug, header.frame_id]" in text
    assert "replay.modules[0] of sut.yaml" in text and "9 of the 10" in text
    stored = found.as_json()
    assert stored["ignore_line"] == "ignore: [debug, header.frame_id]" and stored["fields"][0]["how"] == RECORDED_ONLY


def test_a_field_only_the_module_returns_a_constant_offset_and_constant_values_go_into_the_line():
    recorded = [message(i) for i in range(6)]
    replayed = [{**message(i), "count": i + 1, "unit": "m",
                 "header": {**message(i)["header"], "stamp": "now"}} for i in range(6)]
    recorded = [{**m, "header": {**m["header"], "stamp": "then"}} for m in recorded]
    found = diagnose(comparisons(replayed, recorded), threshold=0.0)
    assert found is not None
    hows = {f.path: (f.how, f.in_line) for f in found.fields}
    assert hows == {"unit": (REPLAYED_ONLY, True), "count": (OFFSET, True), "header.stamp": (CONSTANT, True)}
    assert "+1" in next(f.detail for f in found.fields if f.path == "count")
    assert set(found.ignore) == {"unit", "count", "header.stamp"} and found.reproduced_with_line == 6


def test_a_field_differing_by_varying_amounts_in_every_output_is_offered_not_added_unless_declared_brittle():
    recorded = [message(i) for i in range(8)]
    replayed = [{**m, "header": {**m["header"], "stamp": m["header"]["stamp"] + 0.01 * (i % 3 + 1)}}
                for i, m in enumerate(recorded)]
    found = diagnose(comparisons(replayed, recorded), threshold=0.0, ignore=("debug",))
    assert found is not None and found.fields[0].how == ALWAYS and not found.fields[0].in_line
    assert found.ignore == () and found.ignore_line is None and found.maybe == ("header.stamp",)
    assert any("clock, a counter or noise" in line and "ignore: [debug, header.stamp]" in line
               for line in found.lines())
    declared = diagnose(comparisons(replayed, recorded), threshold=0.0, ignore=("debug",),
                        brittle=lambda path: path == "header.stamp")
    assert declared is not None and declared.ignore == ("debug", "header.stamp") and declared.maybe == ()
    assert declared.reproduced_with_line == 8 and "brittle" in declared.fields[0].detail


def test_rounding_is_a_matter_for_theta_not_for_ignore():
    recorded = [message(i) for i in range(4)]
    replayed = [{**m, "x": [math.nextafter(m["x"][0], 9.0), 1.0]} for m in recorded]
    found = diagnose(comparisons(replayed, recorded), threshold=0.0)
    assert found is not None and found.fields[0].how == ROUNDED and found.ignore == ()
    assert "set θ" in found.fields[0].detail


def test_a_step_that_raised_and_outputs_with_nothing_on_one_side_are_counted_apart():
    recorded = [message(i) for i in range(4)]
    raised = compare_messages({"__replay_error__": "ValueError: bad input"}, recorded[0])
    found = diagnose(
        [raised, Comparison(distance=math.inf, max_error=math.inf, points=0,
                            how="one empty"), Comparison(distance=0.0, max_error=0.0, points=0, how="both empty"),
         Comparison(distance=0.0, max_error=0.0, points=0, how="silent"), compare_messages(recorded[3], recorded[3])],
        threshold=0.0)
    assert found is not None and (found.judged, found.not_reproduced, found.compared) == (4, 2, 1)
    assert (found.raised, found.raised_example, found.unanswered) == (1, "ValueError: bad input", 1)
    assert found.fields == () and found.ignore == ()
    text = "\n".join(found.lines())
    assert "raised on 1" in text and "nothing on one side" in text


def test_trajectories_report_their_distances():
    found = diagnose(
        [Comparison(distance=0.4, max_error=0.3, points=20,
                    how="interpolated"), Comparison(distance=0.0, max_error=0.0, points=20, how="interpolated")],
        threshold=0.1)
    assert found is not None and found.trajectory_distances == (0.4,) and found.compared == 0
    assert any("compared as trajectories" in line for line in found.lines())


def test_an_ignore_entry_that_names_no_field_is_said_with_a_close_one():
    recorded = [message(0, frame_id="map"), {"objects": [{"id": 1, "stamp": 2.0}]}]
    assert unmatched_ignores(recorded, ("debug", "header.stamps", "objects[*].stamp", "objects")) == (
        ("header.stamps", "did you mean 'header.stamp'?"),)
    assert unmatched_ignores([], ("anything",)) == ()
    found = diagnose(comparisons([message(1)], [message(1, frame_id="map")], ("header.stamps",)), threshold=0.0,
                     ignore=("header.stamps",), recorded=[message(1, frame_id="map")])
    assert found is not None and found.unknown_ignores == (("header.stamps", "did you mean 'header.stamp'?"),)
    assert any("'ignore: header.stamps' names no field" in line for line in found.lines())
