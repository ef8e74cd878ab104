"""A case's recorder started ahead (warm): the same log as a cold one, and no process left behind."""

from __future__ import annotations

import json
import subprocess
import time
from pathlib import Path

import pytest

from astaa_deft.orchestration.campaign.runner import CaseLimits, run_case
from astaa_deft.io.log import layout
from astaa_deft.io.log.reader import read_log
from astaa_deft.engine.session.bus_run import warm_recorder
from astaa_deft.engine.spec.loader import load_spec

ECHO = Path(__file__).parent / "sut" / "echo.yaml"
PARAMS = {"count": "40", "rate": "100"}


def test_a_warm_recorder_records_the_case_as_a_cold_one_does(tmp_path: Path):
    spec = load_spec(ECHO)
    cold = run_case(spec, None, PARAMS, tmp_path / "cold", limits=CaseLimits(horizon=3.0))
    recorder = warm_recorder([ECHO])
    warm = run_case(spec, None, PARAMS, tmp_path / "warm", limits=CaseLimits(horizon=3.0), warm_recorder=recorder)
    assert cold.status == warm.status == "done", (cold, warm)
    assert recorder.wait(timeout=10) == 0  # the warm process was the case's recorder, and it finished cleanly
    logs = {name: read_log(tmp_path / name / "run.mcap") for name in ("cold", "warm")}
    # The talker's messages, less their wall-clock stamps: the same sequence in both logs.
    data = {name: [(d["header"]["seq"], d["value"]) for d in (json.loads(m.data) for m in log.on("test/data"))]
            for name, log in logs.items()}
    assert len(data["warm"]) == len(data["cold"]) == 40
    assert data["warm"] == data["cold"]
    assert logs["warm"].attachments[layout.SPEC_ATTACHMENT] == logs["cold"].attachments[layout.SPEC_ATTACHMENT]
    assert (tmp_path / "warm" / "modules" / "recorder.log").is_file()  # its stderr went to the run's folder


def test_a_dead_warm_recorder_is_replaced_by_a_fresh_one(tmp_path: Path):
    recorder = warm_recorder([ECHO])
    recorder.kill()
    recorder.wait(timeout=10)
    outcome = run_case(load_spec(ECHO), None, PARAMS, tmp_path / "case", limits=CaseLimits(horizon=3.0),
                       warm_recorder=recorder)
    assert outcome.status == "done", outcome
    assert len(read_log(tmp_path / "case" / "run.mcap").on("test/data")) == 40


def test_an_unused_warm_recorder_exits_at_end_of_input():
    recorder = warm_recorder([ECHO])
    assert recorder.stdin is not None
    recorder.stdin.close()
    try:
        assert recorder.wait(timeout=20) == 0
    except subprocess.TimeoutExpired:
        recorder.kill()
        raise


def test_a_case_whose_recorder_is_forked_from_its_warm_worker_is_recorded_in_full(tmp_path: Path):
    # The worker (--warm) forks the case's recorder before its payload comes (campaign/forked.py).
    from astaa_deft.engine.bus.processes import python_module
    from astaa_deft.io import pipe_messages
    from astaa_deft.io.pipe_messages import bytes_reader
    from astaa_deft.orchestration.journal.model import BASELINE, PlannedCase
    from astaa_deft.orchestration.campaign.payload import CaseMessage, CasePayload, OutcomeMessage, case_json

    case = PlannedCase(case_id="a", kind=BASELINE, number=1, seed=0, params=PARAMS, testcase=None)
    payload = {"spec": str(ECHO), "case": case_json(case), "run_dir": str(tmp_path / "a"), "horizon": 3.0}
    done = subprocess.run([*python_module("astaa_deft.orchestration.campaign.worker"), "--warm", str(ECHO)],
                          input=pipe_messages.encode(CaseMessage(CasePayload.from_json(payload))),
                          capture_output=True, timeout=60)
    message = pipe_messages.receive(bytes_reader(done.stdout), (OutcomeMessage,), source="the worker's stdout")
    assert message is not None, done.stderr[-2000:]
    outcome = message.outcome
    assert outcome.status == "done", (outcome, done.stderr[-2000:])
    assert len(read_log(tmp_path / "a" / "run.mcap").on("test/data")) == 40
    assert (tmp_path / "a" / "modules" / "recorder.log").is_file()


def test_a_forked_recorder_is_its_own_process_group_and_exits_at_end_of_input():
    from astaa_deft.engine.bus.processes import python_module

    code = ("import sys, os; from astaa_deft.orchestration.campaign.forked import fork_recorder; from pathlib import Path; "
            f"r = fork_recorder(Path({str(ECHO)!r}).read_text(), 'echo.yaml'); "
            "print(os.getpgid(r.pid) == r.pid, r.pid != os.getpid()); r.stdin.close(); print(r.wait(timeout=20))")
    done = subprocess.run([*python_module("astaa_deft")[:-2], "-c", code], capture_output=True, text=True, timeout=60)
    assert done.stdout.split() == ["True", "True", "0"], done.stderr[-2000:]


def test_no_recorder_is_forked_from_a_process_with_other_threads():
    import threading

    from astaa_deft.engine.bus.process_launch import UnsafeFork
    from astaa_deft.orchestration.campaign.forked import fork_recorder

    stop = threading.Event()
    other = threading.Thread(target=stop.wait)
    other.start()
    try:
        with pytest.raises(UnsafeFork, match="a case's recorder: forked only from a single-threaded process"):
            fork_recorder(ECHO.read_text(), ECHO.name)
    finally:
        stop.set()
        other.join()


def _echo_payload(tmp_path: Path, name: str) -> dict:
    from astaa_deft.orchestration.journal.model import BASELINE, PlannedCase
    from astaa_deft.orchestration.campaign.payload import case_json

    case = PlannedCase(case_id=name, kind=BASELINE, number=1, seed=0, params=PARAMS, testcase=None)
    return {"spec": str(ECHO), "case": case_json(case), "run_dir": str(tmp_path / name), "horizon": 3.0,
            "dictionaries": []}


def test_pool_cases_run_in_processes_forked_from_one_template(tmp_path: Path):
    from astaa_deft.orchestration.campaign.executors import LocalPool
    from astaa_deft.orchestration.campaign.zygote import Zygote

    pool = LocalPool(2)
    try:
        for name in ("a", "b", "c"):
            pool.submit(name, _echo_payload(tmp_path, name))
        outcomes = {}
        while pool.pending():
            outcomes.update(dict(pool.done(timeout=1.0)))
        templates = list(pool._zygotes.values())
    finally:
        pool.close()
    assert len(templates) == 1 and isinstance(templates[0], Zygote)  # one template for the spec, all three forked
    assert templates[0].process.returncode == 0  # it reaped its cases and exited when the pool closed
    for name, outcome in outcomes.items():
        assert outcome.status == "done", outcome
        assert len(read_log(tmp_path / name / "run.mcap").on("test/data")) == 40
        assert (tmp_path / name / "case.log").is_file()


def test_a_forked_case_past_its_time_is_stopped_with_its_process_group(tmp_path: Path, monkeypatch):
    from astaa_deft.orchestration.campaign import executors
    from astaa_deft.orchestration.campaign.executors import LocalPool

    monkeypatch.setattr(executors, "CASE_TIMEOUT_MARGIN", -2.0)  # 1 s for a case that runs 3 s
    pool = LocalPool(1)
    try:
        pool.submit("slow", _echo_payload(tmp_path, "slow"))
        outcomes = {}
        while pool.pending():
            outcomes.update(dict(pool.done(timeout=1.0)))
    finally:
        pool.close()
    assert outcomes["slow"].status == "error" and outcomes["slow"].error == "timeout"
    pids = list(json.loads((tmp_path / "slow" / "modules" / "processes.json").read_text()).values())
    deadline = time.monotonic() + 20.0  # its modules die with it (each module's own shutdown takes a moment)
    while time.monotonic() < deadline and any(_running(pid) for pid in pids):
        time.sleep(0.1)
    assert pids and not any(_running(pid) for pid in pids)


def _running(pid: int) -> bool:
    try:
        return Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[-1].split()[0] not in ("Z", "X")
    except OSError:
        return False
