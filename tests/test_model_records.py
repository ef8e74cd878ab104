"""The record types of a run (astaa_deft/model/records.py): their text and JSON forms, and damaged input."""

from __future__ import annotations

import json

import pytest

from astaa_deft.io.log import records as rec
from astaa_deft.model.json_fields import JsonFields
from astaa_deft.model.records import (
    CRASH_CLASSES, CRASH_SCALE, FieldChange, Mutation, ProcessExit, RecordError, RunEnd, Verdict, Violation,
    mutation_row, mutation_row_json,
)


def test_a_verdict_reads_and_writes_as_its_class_name():
    assert [v.value for v in CRASH_SCALE] == ["Catastrophic", "Restart", "Abort", "Silent", "Hindering", "Pass"]
    assert Verdict.PASS not in CRASH_CLASSES and len(CRASH_CLASSES) == 5
    for verdict in Verdict:
        assert str(verdict) == f"{verdict}" == verdict.value == verdict
        assert json.dumps({"class": verdict}) == json.dumps({"class": verdict.value})
        assert Verdict.named(verdict.value.upper()) is verdict
    assert Verdict.named("fine") is None
    assert Verdict.CATASTROPHIC.rank < Verdict.SILENT.rank < Verdict.PASS.rank


def test_a_process_exit_keeps_its_three_texts():
    killed = ProcessExit("planning", 41, -9, "SIGKILL", 5, False)
    assert killed.describe() == "module 'planning' (pid 41) killed by SIGKILL"
    assert killed.describe(with_pid=False) == "module 'planning' killed by SIGKILL"
    assert killed.as_finding() == "module 'planning' was killed by SIGKILL"
    assert ProcessExit("control", 7, 3, None, 5, False).as_finding() == "module 'control' exited with code 3"
    assert killed.abnormal and not ProcessExit("control", 7, 3, None, 5, True).abnormal
    assert not ProcessExit("control", 7, 0, None, 5, False).abnormal


def test_a_process_exit_reads_back_from_its_log_form():
    exit_ = ProcessExit("talker", 42, 3, None, 5, False, "Traceback ...")
    body = rec.encode(exit_)
    assert list(body) == ["kind", "time_ns", "module", "pid", "returncode", "signal", "during_shutdown", "abnormal",
                          "stderr_tail"]  # the order logs have always had
    assert rec.decode(json.loads(json.dumps(body))) == exit_


@pytest.mark.parametrize("body", [{"pid": 1, "returncode": 0}, {"module": "m", "returncode": 0},
                                  {"module": "m", "pid": 1, "returncode": "0"}, ["not", "an", "object"]])
def test_a_damaged_process_exit_is_refused_with_the_place(body):
    with pytest.raises(RecordError, match="run.mcap"):
        ProcessExit.from_json(body, where="run.mcap")


def test_a_damaged_process_exit_in_a_log_is_kept_as_an_unknown_event_not_dropped():
    record = rec.decode({"kind": "process_exit", "time_ns": 9, "pid": 1, "returncode": 1})
    assert isinstance(record, rec.OtherEvent) and record.kind == "process_exit" and record.time_ns == 9


def test_a_violation_has_one_type_and_two_key_orders():
    v = Violation("speed", "bound", "high", 6, "status", 7, {"v": 1}, "too fast", Verdict.HINDERING, "talker")
    assert Violation.from_json(v.to_json()) == v
    assert list(v.to_json())[:4] == ["invariant", "invariant_kind", "severity", "time_ns"]
    assert list(rec.encode(v)) == ["kind", "time_ns", "invariant", "invariant_kind", "severity", "crash", "detail",
                                   "module", "channel", "seq", "message"]  # the log's order, as before
    assert rec.decode(json.loads(rec.to_json_text(v))) == v


def test_a_violation_from_an_odd_log_keeps_the_finding():
    v = Violation.from_json({"invariant": "x", "time_ns": "soon", "crash": "Weird", "seq": True, "message": [1]})
    assert (v.invariant, v.time_ns, v.crash, v.seq, v.message) == ("x", 0, Verdict.SILENT, None, None)


def test_a_mutation_row_is_the_mutation():
    m = Mutation("tc", "p1", "set", "data", ("sink",), 7, 1.25,
                 (FieldChange("a.b[2]", 0.5, float("nan")),), {"skipped": [b"\x00"]})
    row = m.to_row()
    assert type(row) is tuple and Mutation.from_row(row) == m  # (the same NaN object: equal by identity)
    assert json.dumps(mutation_row_json(row)) == json.dumps(m.to_json())
    assert mutation_row(("tc", "p1", "set", "data", ("sink",)), 7, 1.25, ())[8] == {}
    assert m.to_json()["fields"] == [{"path": "a.b[2]", "old": 0.5, "new": {"float": "nan"}}]


def test_a_live_mutation_is_logged_in_its_tagged_form():
    m = Mutation("tc", "p1", "set", "data", ("sink",), 7, 1.25, (FieldChange("v", 1.0, float("inf")),))
    record = rec.MutationRecord.of(m, 99)
    assert record.fields == (FieldChange("v", 1.0, {"float": "inf"}),) and record.detail == {}
    assert rec.decode_mutation(m.to_json(), 99) == record


def test_a_run_end_needs_its_reason():
    assert RunEnd.from_json({"time_ns": 4, "reason": "time limit"}) == RunEnd(4, "time limit")
    with pytest.raises(RecordError):
        RunEnd.from_json({"time_ns": 4})


def test_json_fields_never_give_a_value_of_the_wrong_type():
    read = JsonFields({"n": True, "i": 3, "s": "x", "f": 2, "l": ["a", 1], "o": {"k": 1}, "objs": [{}, 1]})
    assert read.integer("n") == 0 and read.optional_integer("n") is None and read.integer("i") == 3
    assert read.optional_text("i") is None and read.text("i") == "3" and read.text("absent", "?") == "?"
    assert read.number("f") == 2.0 and read.number("s") == 0.0
    assert read.texts("l") == ("a", "1") and read.texts("absent") == ()
    assert read.object("o") == {"k": 1} and read.object("l") is None and read.objects("objs") == ({},)
