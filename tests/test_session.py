"""The session layer: typed log records and run_session (real processes, real Zenoh on loopback)."""

from __future__ import annotations

import threading
from pathlib import Path

import pytest

from astaa_deft.model.errors import InputError
from astaa_deft.io.log import records as rec
from astaa_deft.io.log.reader import read_log
from astaa_deft.engine.session import RunOptions, RunResult, run_session
from astaa_deft.engine.spec.loader import load_spec
from astaa_deft.model.records import Verdict

from proxy_helpers import ECHO_SPEC

ALL_KINDS = [
    rec.RunStarted(time_ns=1, mode="star", spec="echo", command_line=("astaa-deft", "proxy")),
    rec.RunStopping(2),
    rec.RunStopped(3),
    rec.RunEnd(4, "time limit"),
    rec.ProcessExit(module="talker", pid=42, returncode=3, signal=None, time_ns=5, during_shutdown=False,
                    stderr_tail="Traceback ..."),
    rec.Violation(invariant="speed", invariant_kind="bound", severity="high", time_ns=6, channel="status", seq=7,
                  message={"v": 1}, detail="too fast", crash="Hindering", module=None),
    rec.RunVerdict(klass=Verdict.HINDERING,
                   first=rec.Violation(invariant="speed", invariant_kind="bound", severity="high",
                           time_ns=6, channel=None, seq=None, message=None,
                           detail="too fast",
                           crash="Hindering"), summary="1 violation", reasons=("a reason",), time_ns=7),
    rec.UndeclaredKey(8, "talker", "test/extra", "declare it"),
    rec.MutationRecord(time_ns=9, policy="p1", action="set", channel="data", message_index=12,
                       fields=(rec.TaggedFieldChange("value", 1.0, {"float": "nan"}),), testcase="tc",
                       consumers=("listener",), time=1.5, detail={"steps": []}, original_sequence=4,
                       delivered_sequence=5),
    rec.ModuleLogLine(10, "talker", "stderr", "ERROR: boom"),
    rec.FlagRecord(time_ns=12, channel="data", sequence=4, reason="not JSON", size=11),
    rec.OtherEvent("bus_lost", 11, (("detail", "router gone"),)),
]


@pytest.mark.parametrize("record", ALL_KINDS, ids=lambda r: r.kind)
def test_every_record_has_one_encoding_both_ways(record):
    assert rec.decode(rec.encode(record)) == record


def test_existing_log_events_decode_to_records():
    # The shapes older tools wrote (no format field, lists not tuples).
    old = {"kind": "process_exit", "time_ns": 5, "module": "m", "pid": 1, "returncode": -9, "signal": "SIGKILL",
           "during_shutdown": False, "abnormal": True, "stderr_tail": ""}
    exit_ = rec.decode(old)
    assert isinstance(exit_, rec.ProcessExit) and exit_.signal == "SIGKILL" and exit_.abnormal
    started = rec.decode({"kind": "run_started", "time_ns": 1, "mode": "star", "spec": "s", "command_line": ["a"]})
    assert started == rec.RunStarted(time_ns=1, mode="star", spec="s", command_line=("a",))


def test_a_newer_record_format_is_refused_with_a_clear_message():
    with pytest.raises(InputError, match="newer astaa-deft"):
        rec.decode({"kind": "run_started", "time_ns": 1, "format": rec.FORMAT + 1}, where="x.mcap")


def test_a_record_missing_required_fields_is_kept_not_guessed():
    assert isinstance(rec.decode({"kind": "process_exit", "time_ns": 3}), rec.OtherEvent)


def _all_delivered(run) -> str | None:
    out = run.run_dir / "listener.out"
    return "all delivered" if out.exists() and out.read_text().count("\n") >= 100 else None


def test_concurrent_sessions_in_one_process_are_isolated(tmp_path):
    spec = load_spec(ECHO_SPEC)
    results: dict[str, RunResult] = {}
    events: dict[str, list] = {"a": [], "b": []}

    def one(name: str) -> None:
        options = RunOptions(mode="star", record=tmp_path / f"{name}.mcap", run_dir=tmp_path / f"run-{name}",
                             params={"count": "100", "rate": "200"}, time_limit=60.0)
        results[name] = run_session(spec, options, stop_when=_all_delivered, on_event=events[name].append)

    threads = [threading.Thread(target=one, args=(n,)) for n in ("a", "b")]
    for t in threads:
        t.start()
    for t in threads:
        t.join(120)
    for name in ("a", "b"):
        result = results[name]
        assert result.end_reason == "all delivered"
        assert result.sent["data"] == 100 and result.recorded["data"] == 100
        assert result.complete and result.observed and result.log == tmp_path / f"{name}.mcap"
        assert (tmp_path / f"run-{name}" / "listener.out").read_text().count("\n") == 100
        kinds = [type(r) for r in events[name]]
        assert rec.RunStarted in kinds and rec.RunVerdict in kinds
        logged = [rec.decode(e) for e in read_log(result.log).events()]
        assert any(isinstance(r, rec.RunEnd) and r.reason == "all delivered" for r in logged)
        assert sum(isinstance(r, rec.RunStarted) for r in logged) == 1, (name, [r for r in logged if not isinstance(r, rec.ProcessExit)])  # the other session's events are not here


def test_a_relative_run_dir_still_hands_modules_a_config_they_can_open(tmp_path, monkeypatch):
    """A relative --run-dir with a module 'cwd' gave the module a relative
    ZENOH_CONFIG path that did not exist from its own directory, and it crashed."""
    import sys
    import textwrap

    from astaa_deft.engine.spec.loader import load_spec_text

    elsewhere = tmp_path / "module_home"
    elsewhere.mkdir()
    probe = textwrap.dedent("""\
        import os, time
        open(os.environ["ZENOH_CONFIG"]).read()
        print("config readable", flush=True)
        time.sleep(30)
        """)
    (elsewhere / "probe.py").write_text(probe)
    spec = load_spec_text(textwrap.dedent(f"""\
        name: reldir
        modules:
          - {{name: probe, command: ["{sys.executable}", "probe.py"], cwd: "{elsewhere}",
             ready: {{log: "config readable", timeout: 15}}}}
        channels:
          - {{name: data, key: t/data, producer: probe, type: Sample}}
        types:
          Sample: {{seq: uint64}}
        """), name="reldir.yaml")
    monkeypatch.chdir(tmp_path)
    result = run_session(spec, RunOptions(mode="star", run_dir=Path("runs/one"), time_limit=1.0))
    assert result.end_reason == "time limit"
    assert not result.crashes and result.verdict.klass == "Pass"
