"""The record types of a run (astaa_deft/model/records.py): their text and JSON forms, and damaged input."""

from __future__ import annotations

import json
from dataclasses import replace

import pytest

from astaa_deft.io.log import records as rec
from astaa_deft.model.json_fields import JsonFields
from astaa_deft.model.records import (
    CRASH_CLASSES, CRASH_SCALE, FieldChange, Mutation, ProcessExit, RecordError, RunEnd, TaggedFieldChange, Verdict,
    Violation, mutation_row,
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
    killed = ProcessExit(module="planning", pid=41, returncode=-9, signal="SIGKILL", time_ns=5, during_shutdown=False)
    assert killed.describe() == "module 'planning' (pid 41) killed by SIGKILL"
    assert killed.describe(with_pid=False) == "module 'planning' killed by SIGKILL"
    assert killed.as_finding() == "module 'planning' was killed by SIGKILL"
    assert ProcessExit(module="control", pid=7, returncode=3, signal=None, time_ns=5,
                       during_shutdown=False).as_finding() == "module 'control' exited with code 3"
    assert killed.abnormal and not ProcessExit(module="control", pid=7, returncode=3, signal=None, time_ns=5,
                                               during_shutdown=True).abnormal
    assert not ProcessExit(module="control", pid=7, returncode=0, signal=None, time_ns=5,
                           during_shutdown=False).abnormal


def test_a_process_exit_reads_back_from_its_log_form():
    exit_ = ProcessExit(module="talker", pid=42, returncode=3, signal=None, time_ns=5, during_shutdown=False,
                        stderr_tail="Traceback ...")
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


def test_a_violation_has_one_type_and_one_form():
    v = Violation(invariant="speed", invariant_kind="bound", severity="high", time_ns=6, channel="status", seq=7,
                  message={"v": 1}, detail="too fast", crash=Verdict.HINDERING, module="talker")
    assert Violation.from_json(v.to_json()) == v
    assert list(rec.encode(v)) == ["kind", "time_ns", "invariant", "invariant_kind", "severity", "crash", "detail",
                                   "module", "channel", "seq", "message"]  # the log's order, as before
    assert rec.encode(v) == {"kind": "violation", **v.to_json()}  # the log's form is its one form
    assert rec.decode(json.loads(rec.to_json_text(v))) == v


def test_a_violation_from_an_odd_log_keeps_the_finding():
    v = Violation.from_json({"invariant": "x", "time_ns": "soon", "crash": "Weird", "seq": True, "message": [1]})
    assert (v.invariant, v.time_ns, v.crash, v.seq, v.message) == ("x", 0, Verdict.SILENT, None, None)


def test_a_mutation_row_is_the_mutation():
    m = Mutation(testcase="tc", policy="p1", action="set", channel="data", consumers=("sink",), message_index=7,
                 time=1.25, fields=(FieldChange("a.b[2]", 0.5, float("nan")),), detail={"skipped": [b"\x00"]})
    row = m.to_row()
    assert type(row) is tuple and Mutation.from_row(row) == m  # (the same NaN object: equal by identity)
    assert json.dumps(Mutation.row_json(row)) == json.dumps(m.to_json())
    assert mutation_row(("tc", "p1", "set", "data", ("sink",)), 7, 1.25, ())[8] == {}
    assert m.to_json()["fields"] == [{"path": "a.b[2]", "old": 0.5, "new": {"float": "nan"}}]


def test_a_live_mutation_is_logged_in_its_tagged_form():
    m = Mutation(testcase="tc", policy="p1", action="set", channel="data", consumers=("sink",), message_index=7,
                 time=1.25, fields=(FieldChange("v", 1.0, float("inf")),))
    record = rec.MutationRecord.of(m, 99)
    assert record.fields == (TaggedFieldChange("v", 1.0, {"float": "inf"}),) and record.detail == {}
    assert rec.MutationRecord.from_json(m.to_json(), time_ns=99) == record
    assert record.fields[0].untagged() == FieldChange("v", 1.0, float("inf")) == m.fields[0]
    assert m.fields[0].tagged() == record.fields[0]


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


# ---------------------------------------------------------------- the wire forms, byte for byte

# What the tool wrote before each record type owned its form (captured from the previous encoder): a log written
# now is byte-identical, so logs written before read as they always did.
WRITTEN_BEFORE = [
    (rec.RunStarted(time_ns=1, mode="star", spec="echo", command_line=("astaa-deft", "proxy"), interceptor_epoch_ns=77),
     '{"kind": "run_started", "time_ns": 1, "mode": "star", "spec": "echo", "command_line": ["astaa-deft", "proxy"], '
     '"interceptor_epoch_ns": 77}'),
    (rec.RunStopping(2), '{"kind": "run_stopping", "time_ns": 2}'),
    (rec.RunStopped(3), '{"kind": "run_stopped", "time_ns": 3}'),
    (RunEnd(4, "time limit"), '{"kind": "run_end", "time_ns": 4, "reason": "time limit"}'),
    (ProcessExit(module="talker", pid=42, returncode=3, signal=None, time_ns=5, during_shutdown=False,
                 stderr_tail="Traceback ..."),
     '{"kind": "process_exit", "time_ns": 5, "module": "talker", "pid": 42, "returncode": 3, "signal": null, '
     '"during_shutdown": false, "abnormal": true, "stderr_tail": "Traceback ..."}'),
    (Violation(invariant="speed", invariant_kind="bound", severity="high", time_ns=6, channel="status", seq=7,
               message={"v": 1}, detail="too fast", crash=Verdict.HINDERING, module=None),
     '{"kind": "violation", "time_ns": 6, "invariant": "speed", "invariant_kind": "bound", "severity": "high", '
     '"crash": "Hindering", "detail": "too fast", "module": null, "channel": "status", "seq": 7, "message": {"v": 1}}'),
    (rec.RunVerdict(klass=Verdict.HINDERING,
                    first=Violation(invariant="speed", invariant_kind="bound", severity="high", time_ns=6,
                        channel=None, seq=None, message=None, detail="too fast",
                        crash=Verdict.HINDERING), summary="1 violation", reasons=("a reason",), time_ns=7),
     '{"kind": "verdict", "time_ns": 7, "class": "Hindering", "first": {"time_ns": 6, "invariant": "speed", '
     '"invariant_kind": "bound", "severity": "high", "crash": "Hindering", "detail": "too fast", "module": null, '
     '"channel": null, "seq": null, "message": null}, "summary": "1 violation", "reasons": ["a reason"]}'),
    (rec.UndeclaredKey(8, "talker", "test/extra", "declare it"),
     '{"kind": "undeclared_key", "time_ns": 8, "module": "talker", "key": "test/extra", "note": "declare it"}'),
    (rec.MutationRecord(time_ns=9, policy="p1", action="set", channel="data", message_index=12,
                        fields=(TaggedFieldChange("value", 1.0, {"float": "nan"}),), testcase="tc",
                        consumers=("listener",), time=1.5, detail={"steps": []}, original_sequence=4,
                        delivered_sequence=5),
     '{"kind": "mutation", "time_ns": 9, "testcase": "tc", "policy": "p1", "action": "set", "channel": "data", '
     '"consumers": ["listener"], "message_index": 12, "time": 1.5, "fields": [{"path": "value", "old": 1.0, '
     '"new": {"float": "nan"}}], "detail": {"steps": []}, "original_sequence": 4, "delivered_sequence": 5}'),
    (rec.PolicyApplicationsRecord(time_ns=13, testcase="tc", policy="p1", action="set", window_start_s=0.5,
                                  window_end_s=None, anchor="data#3", in_window=4, touched=2, run_end_s=9.5,
                                  traffic=({"channel": "data", "count": 3, "first_s": 0.1, "last_s": 0.9},),
                                  untouched_reason=None),
     '{"kind": "policy_applications", "time_ns": 13, "testcase": "tc", "policy": "p1", "action": "set", '
     '"window_start_s": 0.5, "window_end_s": null, "anchor": "data#3", "in_window": 4, "touched": 2, '
     '"run_end_s": 9.5, "traffic": [{"channel": "data", "count": 3, "first_s": 0.1, "last_s": 0.9}], '
     '"untouched_reason": null}'),
    (rec.ModuleLogLine(10, "talker", "stderr", "ERROR: boom"),
     '{"kind": "module_log", "time_ns": 10, "module": "talker", "stream": "stderr", "line": "ERROR: boom"}'),
    (rec.FlagRecord(time_ns=12, channel="data", sequence=4, reason="not JSON", size=11),
     '{"kind": "undecodable", "time_ns": 12, "channel": "data", "sequence": 4, "reason": "not JSON", "size": 11}'),
    (rec.OtherEvent("bus_lost", 11, (("detail", "router gone"),)),
     '{"kind": "bus_lost", "time_ns": 11, "detail": "router gone"}'),
]


@pytest.mark.parametrize("record, text", WRITTEN_BEFORE, ids=lambda x: getattr(x, "kind", ""))
def test_every_event_is_written_as_before_and_reads_back(record, text):
    assert rec.to_json_text(record) == text
    assert rec.decode(json.loads(text)) == record


def test_a_mutation_has_one_json_form_live_on_the_pipe_and_in_the_log():
    m = Mutation(testcase="tc", policy="p1", action="set", channel="data", consumers=("sink",), message_index=7,
                 time=1.25, fields=(FieldChange("a.b[2]", 0.5, float("nan")), FieldChange("s", "x\ud800", b"\x00\x01")),
                 detail={"skipped": [b"\x00"], "float": 1})
    written_before = (
        '{"testcase": "tc", "policy": "p1", "action": "set", "channel": "data", "consumers": ["sink"], '
        '"message_index": 7, "time": 1.25, "fields": [{"path": "a.b[2]", "old": 0.5, "new": {"float": "nan"}}, '
        '{"path": "s", "old": {"str_escaped": "x\\\\ud800"}, "new": {"base64": "AAE="}}], '
        '"detail": {"skipped": [{"base64": "AA=="}], "float": 1}}')
    assert json.dumps(m.to_json()) == json.dumps(Mutation.row_json(m.to_row())) == written_before
    logged = rec.MutationRecord.logged(m.to_json(), 3, None)  # what the recorder writes on the mutations topic
    record = rec.MutationRecord.from_json(logged, time_ns=5)
    assert record == replace(rec.MutationRecord.of(m, 5), original_sequence=3)
    assert json.dumps(record.to_json()) == json.dumps(logged)  # the record writes back what it was read from
    assert tuple(c.untagged() for c in record.fields)[0].path == "a.b[2]"
