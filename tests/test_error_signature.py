"""Findings that say which error: an error's type and innermost frame, read from a module's output,
and a campaign that tells a mutated case's error from its unmutated twin's.

The reports are the runtimes' own formats; the campaign runs a real SUT
(tests/sut/errors.yaml) whose worker logs a KeyError raised in ``step``
early on chosen launches and a ValueError late on others.
"""

from __future__ import annotations

from pathlib import Path

import pytest

from astaa_deft.engine.monitor import check_log
from astaa_deft.engine.monitor.error_signature import ErrorSignature, signature_of_output
from astaa_deft.orchestration.campaign.campaign import shows_failure
from astaa_deft.orchestration.journal.model import CaseOutcome, Finding
from astaa_deft.orchestration.campaign.signature import failure_key, same_failure

from monitor_helpers import HandMadeLog, load

PYTHON = [
    "Traceback (most recent call last):",
    '  File "/opt/stack/planning/node.py", line 88, in on_routing',
    "    self.plan(msg)",
    '  File "/opt/stack/planning/planner.py", line 42, in step',
    "    return world['lane']",
    "           ~~~~~^^^^^^^^",
    "KeyError: 'lane'",
]
CHAINED = [
    "Traceback (most recent call last):",
    '  File "/opt/stack/lib/frenet.py", line 10, in project',
    "    raise ProjectionDomainLongitudinalError(s)",
    "frenet.ProjectionDomainLongitudinalError: s=212.3 beyond the reference path",
    "",
    "During handling of the above exception, another exception occurred:",
    "",
    "Traceback (most recent call last):",
    '  File "/opt/stack/planning/planner.py", line 77, in finish_route',
    "    raise ValueError('route already finished')",
    "ValueError: route already finished",
]
GO = [
    "panic: runtime error: index out of range [3] with length 3",
    "",
    "goroutine 1 [running]:",
    "main.step(...)",
    "\t/home/u/planner/main.go:12 +0x1d",
    "main.main()",
    "\t/home/u/planner/main.go:20 +0x25",
    "exit status 2",
]
JAVA = ['Exception in thread "main" java.lang.IllegalStateException: no route',
        "\tat com.stack.Planner.step(Planner.java:42)", "\tat com.stack.Main.main(Main.java:9)"]
FAULT = ["Fatal Python error: Segmentation fault", "", "Current thread 0x00007f (most recent call first):",
         '  File "/opt/stack/ext.py", line 3 in solve', '  File "/opt/stack/node.py", line 9 in <module>']
ONE_LINERS = {
    "terminate called after throwing an instance of 'std::runtime_error'": "std::runtime_error in C++ terminate",
    "terminate called without an active exception": "terminate without an active exception in C++ terminate",
    "thread 'main' panicked at src/planner.rs:4:5:": "Rust panic in planner.rs",
    "Segmentation fault (core dumped)": "SIGSEGV",
    "2026-11-27 10:00:01,002 ERROR planner: no path after 12 iterations":
        "N-N-N N:N:N,N ERROR planner: no path after N iterations",
}


def _findings(tmp_path, lines: list[str]):
    spec = load("- {name: planner_errors, kind: exceptions, modules: [planning]}\n")
    log = HandMadeLog(tmp_path / "run.mcap", spec)
    for k, line in enumerate(lines):
        log.event("module_log", 0.1 + 0.001 * k, module="planning", stream="output", line=line)
    log.event("run_stopping", 5.0)
    return check_log(log.close(), spec).violations


@pytest.mark.parametrize("lines, signature", [
    (PYTHON, "KeyError in planner.py:step"),
    (CHAINED, "frenet.ProjectionDomainLongitudinalError in frenet.py:project"),  # the chain's first: its cause
    (GO, "Go panic: runtime error: index out of range [N] with length N in main.go:main.step"),
    (JAVA, "java.lang.IllegalStateException in Planner.java:com.stack.Planner.step"),
    (FAULT, "Fatal Python error: Segmentation fault in ext.py:solve"),
])
def test_a_multi_line_report_is_one_finding_naming_its_error_and_innermost_frame(tmp_path, lines, signature):
    [found] = _findings(tmp_path, [*lines, "planning cycle 9: ok"])
    assert found.message["signature"] == signature, found.message
    assert found.message["line"] == lines[0] and signature in found.detail, found.detail
    assert found.time_ns == min(f.time_ns for f in _findings(tmp_path, lines))  # dated by its first line


def test_a_report_cut_by_the_run_s_end_still_names_what_it_read(tmp_path):
    [found] = _findings(tmp_path, PYTHON[:4])
    assert found.message["signature"] == "Python exception in planner.py:step"


@pytest.mark.parametrize("line, signature", ONE_LINERS.items())
def test_a_one_line_error_names_itself(tmp_path, line, signature):
    [found] = _findings(tmp_path, [line])
    assert found.message["signature"] == signature


def test_two_tracebacks_in_a_row_are_two_findings_with_their_own_errors(tmp_path):
    found = _findings(tmp_path, [*PYTHON, *CHAINED[:4]])
    assert [f.message["signature"] for f in found] == [
        "KeyError in planner.py:step", "frenet.ProjectionDomainLongitudinalError in frenet.py:project"]


def test_a_log_finding_names_its_pattern(tmp_path):
    spec = load('- {name: solver, kind: log, modules: [planning], pattern: "solver gave up"}\n')
    log = HandMadeLog(tmp_path / "run.mcap", spec)
    log.event("module_log", 0.1, module="planning", stream="output", line="solver gave up at 3")
    log.event("run_stopping", 5.0)
    [found] = check_log(log.close(), spec).violations
    assert found.message["signature"] == "/solver gave up/"


def test_a_crashed_module_s_last_words_name_its_error_even_with_the_traceback_s_start_cut_off():
    assert signature_of_output(PYTHON[2:]) == ErrorSignature("KeyError", "planner.py:step")
    assert signature_of_output(["loading map", "bye"], "SIGABRT") == ErrorSignature("SIGABRT")
    assert signature_of_output(["loading map"]) is None


# -- the campaign: buckets, twins ------------------------------------------------------------------
def _error(signature: str, at: float) -> Finding:
    return Finding(invariant="planner_errors", crash="Silent", module="planning", channel=None, detail="logged",
                   severity="high", at=at, signature=signature)


def test_a_twin_failing_another_way_or_at_another_phase_is_not_the_same_failure():
    early = _error("KeyError in planner.py:step", 5.0)
    assert same_failure(_error("KeyError in planner.py:step", 5.6), early)
    assert not same_failure(_error("ValueError in planner.py:finish_route", 5.0), early)  # another error
    assert not same_failure(_error("KeyError in planner.py:step", 21.4), early)  # the same, at another phase
    mutated = CaseOutcome(status="done", verdict="Silent", summary="", findings=[early])
    twin = CaseOutcome(status="done", verdict="Silent", summary="",
                       findings=[_error("ValueError in planner.py:finish_route", 21.4)])
    assert not shows_failure(twin, mutated)
    assert failure_key(mutated).text() == "Silent|planner_errors|planning|KeyError in planner.py:step"
    unsigned = Finding(invariant="speed_limit", crash="Silent", module="planning", channel="status",
                       detail="x")  # no error named: as before
    assert same_failure(unsigned,
        Finding(invariant="speed_limit", crash="Silent", module="planning", channel="status", detail="y", at=3.0))
    assert failure_key(CaseOutcome(status="done", verdict="Silent", summary="",
                                   findings=[unsigned])).text() == "Silent|speed_limit|planning"


@pytest.mark.slow  # a live campaign: four runs of a real SUT (~40 s)
def test_a_case_raising_keyerror_early_whose_twin_raises_valueerror_late_is_a_bug_not_flaky(tmp_path: Path):
    from test_campaign_control import SET_AUX, campaign

    counter = tmp_path / "launches"
    counter.mkdir()
    # One run at a time. Launches: 1 baseline (clean); 2 the case and 3 its re-run (KeyError in step, 0.8 s
    # in); 4 its unmutated twin (ValueError in finish_route, 2.5 s in).
    params = {"counter_dir": [str(counter)], "raise_launches": ["2,3"], "late_launches": ["4"]}
    journal = campaign(tmp_path / "c", Path(__file__).parent / "sut" / "errors.yaml", [SET_AUX], params=params,
                       baseline_runs=1, reruns=1)
    try:
        [bucket] = [b for b in journal.buckets() if b.kind != "baseline"]
        assert (bucket.kind, bucket.rerun_failures, bucket.reruns, bucket.control_failures, bucket.controls) == \
            ("bug", 1, 1, 0, 1), bucket
        assert bucket.invariant == "worker_errors" and "KeyError in steady_worker.py:step" in bucket.signature
        twin = journal.outcome(journal.case("t-B001-1"))
        assert twin is not None and twin.failed
        assert [f.signature for f in twin.findings] == ["ValueError in steady_worker.py:finish_route"], twin
    finally:
        journal.close()


def test_a_traceback_is_reported_at_its_exception_line_without_waiting_for_the_next_line():
    from astaa_deft.engine.monitor.monitorset import MonitorSet

    monitors = MonitorSet(load("- {name: planner_errors, kind: exceptions, modules: [planning]}\n"), 0)
    found = [monitors.on_log_line("planning", line, 10 + k) for k, line in enumerate(PYTHON)]
    assert [len(f) for f in found] == [0] * (len(PYTHON) - 1) + [1]  # a quiet module after it: no wait
    assert found[-1][0].time_ns == 10 and found[-1][0].message["signature"] == "KeyError in planner.py:step"
    assert monitors.on_log_line("planning", "", 20) == [] and monitors.finish(30) == []  # once
