"""Test case generation: deterministic, valid against the spec, weighted like
ASTAA's findings, never touching brittle fields unless asked."""

from __future__ import annotations

from collections import Counter
from pathlib import Path

import pytest

from astaa_deft.io.codecs import get_codec
from astaa_deft.cli.commands import generate as generate_command
from astaa_deft.model.errors import InputError
from astaa_deft.model.fields import FieldPath
from astaa_deft.engine.intercept import load_dictionary, load_testcase
from astaa_deft.engine.intercept.dictionary import wire_value
from astaa_deft.engine.intercept import generate as gen
from astaa_deft.engine.intercept.generate import (
    GenerateOptions, generate, generate_to_directory, is_generation_brittle, iter_testcases, mutation_targets,
    write_testcases,
)
from astaa_deft.engine.intercept.testcase import Selection
from astaa_deft.engine.spec.loader import load_spec, load_spec_text

ROOT = Path(__file__).resolve().parent.parent
SPEC_PATH = ROOT / "tests" / "data" / "intercept_sut.yaml"
SPEC = load_spec(SPEC_PATH)
DICTIONARY = load_dictionary()

# Every field generation must leave alone by default in intercept_sut.yaml:
# header bookkeeping found by name (Trajectory.header, Scan.meta: a Header)
# and the spec's own brittle list (Trajectory.debug_note).
BRITTLE = {
    ("trajectory", "header.seq"), ("trajectory", "header.stamp"), ("trajectory", "header.frame_id"),
    ("trajectory", "debug_note"),
    ("scan", "meta.seq"), ("scan", "meta.stamp"), ("scan", "meta.frame_id"),
}
# The stamp family's fields: stamps and sequence numbers by name, brittle or not (odometry's top-level stamp).
STAMPS = {("trajectory", "header.seq"), ("trajectory", "header.stamp"), ("scan", "meta.seq"),
          ("scan", "meta.stamp"), ("odometry", "stamp")}


def assignments(testcases):
    """(channel, assignment) of every ``set`` policy (the semantic families' remove and swap set none)."""
    for testcase in testcases:
        for policy in testcase.policies:
            for assignment in getattr(policy.action, "fields", ()):
                yield policy.channels[0], assignment


def touched_fields(testcases):
    """(channel, field path) of every field any policy acts on, whatever its action."""
    return {(policy.channels[0], path) for testcase in testcases for policy in testcase.policies
            for path in policy.action.field_paths()}


def test_same_seed_same_bytes_other_seed_other_cases():
    first = [t.to_xml() for t in generate(SPEC, DICTIONARY, 30, seed=42)]
    assert first == [t.to_xml() for t in generate(SPEC, DICTIONARY, 30, seed=42)]
    assert first != [t.to_xml() for t in generate(SPEC, DICTIONARY, 30, seed=43)]
    # A case does not depend on how many were asked for.
    assert first[:10] == [t.to_xml() for t in generate(SPEC, DICTIONARY, 10, seed=42)]


def test_brittle_fields_are_recognised():
    def brittle(channel: str, path: str) -> bool:
        return is_generation_brittle(SPEC, SPEC.channel(channel).type, FieldPath.parse(path))

    assert all(brittle(channel, path) for channel, path in BRITTLE)
    assert not brittle("odometry", "stamp")  # a top-level stamp outside any header is a real input
    assert not brittle("trajectory", "points[*].v")
    assert not brittle("scan", "ranges")


def test_never_brittle_by_default_and_only_when_asked():
    testcases = generate(SPEC, DICTIONARY, 400, seed=1)
    bulk = [t for t in testcases if not t.description.startswith("stamp:")]
    touched = touched_fields(bulk)
    assert not touched & BRITTLE
    assert "status" not in {channel for channel, _ in touched}  # no consumers: nobody to test
    with_brittle = {(channel, a.path)
                    for channel, a in assignments(generate(SPEC, DICTIONARY, 400, seed=1, include_brittle=True))
                    if (channel, a.path) not in STAMPS}
    assert with_brittle & BRITTLE


def test_the_stamp_family_touches_only_stamps_and_sequence_numbers_even_brittle_ones():
    stamp_cases = [t for t in generate(SPEC, DICTIONARY, 400, seed=1) if t.description.startswith("stamp:")]
    touched = {(channel, a.path, a.value) for channel, a in assignments(stamp_cases)}
    fields = {(channel, path) for channel, path, _value in touched}
    assert fields <= STAMPS and fields & BRITTLE  # header stamps are brittle, and still reached
    assert {value for _, _, value in touched} <= {f"dict:{key}" for key in gen.STAMP_FAULTS}
    # a sequence number only ever repeats the previous one; stamps get every fault
    assert {value for _, path, value in touched if path.endswith("seq")} == {"dict:time.repeat_previous"}
    assert {value for _, path, value in touched if path.endswith("stamp")} == {f"dict:{key}"
                                                                              for key in gen.STAMP_FAULTS}


def test_shapes_follow_astaa_findings_next_to_sustained_and_stamp_families():
    """Weights 42 : 22 : 8 (ASTAA's bugs) : 20 sustained : 7 stamp -> of 1000 cases ~424 one field of one
    message, ~222 several fields, ~81 repeated, ~202 sustained, ~71 stamp faults (these families alone:
    the semantic ones come on top, tests/test_semantic_faults.py)."""
    shapes = Counter()
    for testcase in generate(SPEC, DICTIONARY, 1000, seed=7, families=gen.EXCEPTIONAL):
        [policy] = testcase.policies
        family = testcase.description.split(":")[0]
        if family == "stamp":
            shapes["stamp"] += 1
        elif family == "sustained":  # one field held: every message of a 1-5 s window, or 5-50 messages
            assert len(policy.action.fields) == 1
            if policy.selection.limit is None:
                assert policy.selection == Selection() and policy.window.end - policy.window.start <= 5.0 + 1e-9
            else:
                assert 5 <= policy.selection.limit <= 50
            shapes["sustained"] += 1
        elif policy.selection.limit is None:
            assert family == "repeated"
            shapes["repeated"] += 1
        else:
            assert policy.selection.limit == 1
            shapes["single" if len(policy.action.fields) == 1 else "multi"] += 1
    # multi_field draws on a channel with one usable field degrade to single, hence the ranges.
    assert 360 <= shapes["single"] <= 500
    assert 170 <= shapes["multi"] <= 290
    assert 55 <= shapes["repeated"] <= 115
    assert 160 <= shapes["sustained"] <= 250
    assert 45 <= shapes["stamp"] <= 100


def test_windows_fit_the_duration_and_cases_validate(tmp_path):
    testcases = generate(SPEC, DICTIONARY, 60, seed=5, duration=12.0)
    for testcase in testcases:
        [policy] = testcase.policies
        assert 0.0 <= policy.window.start < policy.window.end <= 12.0
    paths = write_testcases(testcases, tmp_path / "out")
    assert [p.name for p in paths[:2]] == ["tc-0001.xml", "tc-0002.xml"]
    for path, testcase in zip(paths, testcases, strict=True):
        assert load_testcase(path, SPEC, DICTIONARY) == testcase


def test_multi_field_cases_never_overlap():
    for testcase in generate(SPEC, DICTIONARY, 300, seed=11):
        paths = [FieldPath.parse(path).segments for path in testcase.policies[0].action.field_paths()]
        for i, a in enumerate(paths):
            for b in paths[i + 1:]:
                shorter, longer = sorted((a, b), key=len)
                assert longer[:len(shorter)] != shorter


def test_values_fit_the_field_and_the_channel_encoding():
    targets = mutation_targets(SPEC, DICTIONARY)
    assert targets
    for target in targets:
        codec = get_codec(target.channel.encoding)
        for entry in target.values:
            assert entry.problem(target.site) is None
            if not entry.is_dynamic:
                assert codec.carries(wire_value(entry.static_value(target.site), target.site.field_type, codec)) is None
    # The lone surrogate is generated for JSON strings, never for the CBOR scan.
    lone = {channel for channel, a in assignments(generate(SPEC, DICTIONARY, 500, seed=3))
            if a.value == "dict:string.lone_surrogate"}
    assert lone == {"trajectory"}


def test_a_spec_with_nothing_to_mutate_is_an_input_error():
    spec = load_spec_text(
        "name: n\nmodules: [{name: a, command: x}, {name: b, command: x}]\n"
        "channels: [{name: c, key: k, producer: a, consumers: [b], type: H}]\n"
        "types: {Header: {seq: uint64, stamp: time}, H: {header: Header}}\n")
    with pytest.raises(InputError, match="no field to mutate") as caught:
        generate(spec, DICTIONARY, 3, seed=1)
    assert "--include-brittle" in caught.value.problems[0].fix
    assert len(generate(spec, DICTIONARY, 3, seed=1, include_brittle=True)) == 3


def test_generate_command_writes_files_and_refuses_to_mix(tmp_path, capsys):
    out = tmp_path / "cases"
    assert generate_command.generate(SPEC_PATH, out, GenerateOptions(count=25, seed=9, duration=20.0)) == 0
    files = sorted(out.glob("tc-*.xml"))
    assert len(files) == 25
    assert "wrote 25 test cases" in capsys.readouterr().out
    assert [f.read_bytes() for f in files] == [t.to_xml() for t in generate(SPEC, DICTIONARY, 25, 9, duration=20.0)]
    with pytest.raises(InputError, match="already holds 25 test case"):
        generate_command.generate(SPEC_PATH, out, GenerateOptions(count=5, seed=9))
    with pytest.raises(InputError, match="at least 1"):
        generate_command.generate(SPEC_PATH, tmp_path / "other", GenerateOptions(count=0, seed=9))


def test_generation_is_a_library_call_that_prints_nothing(tmp_path, capsys):
    from astaa_deft.engine.intercept.generate import generate_to_directory

    report = generate_to_directory(load_spec(SPEC_PATH), tmp_path / "cases",
                                   GenerateOptions(count=6, seed=4, duration=10.0))
    assert capsys.readouterr().out == ""
    assert [p.name for p in report.paths] == [f"tc-{n:04d}.xml" for n in range(1, 7)]
    assert sum(report.shapes.values()) == 6
    drawn = generate(SPEC, DICTIONARY, 6, 4, duration=10.0)
    assert [p.read_bytes() for p in report.paths] == [t.to_xml() for t in drawn]


def test_cases_are_drawn_one_at_a_time_not_as_a_whole_list():
    """A trillion asked for is no longer a list built before anything is written: each case is
    drawn when reached, the same case as a short run draws at that number."""
    cases = iter_testcases(SPEC, DICTIONARY, 10**12, seed=42)
    first = [next(cases) for _ in range(3)]
    assert [t.id for t in first] == ["tc-0000000000001", "tc-0000000000002", "tc-0000000000003"]
    short = generate(SPEC, DICTIONARY, 3, seed=42)
    assert [t.policies for t in first] == [t.policies for t in short]


def test_generate_to_directory_writes_what_generate_draws(tmp_path):
    report = generate_to_directory(SPEC, tmp_path / "out", GenerateOptions(count=25, seed=7))
    drawn = generate(SPEC, DICTIONARY, 25, seed=7)
    assert report.count == 25 and sum(report.shapes.values()) == 25
    assert [p.read_bytes() for p in report.paths] == [t.to_xml() for t in drawn]
    assert sorted(p.name for p in (tmp_path / "out").iterdir()) == [p.name for p in report.paths]
