"""Ctrl-C (SIGINT) and SIGTERM while a real `fuzz` subprocess searches at module level: the command ends with
130 / 143, leaves no process of its own behind, its journal and DIR/module_level/state.json agree, and
`fuzz --resume` goes on to the end."""

from __future__ import annotations

import json
import signal
import sqlite3
import subprocess
import sys
import time
from pathlib import Path

import psutil
import pytest

SPEC = Path(__file__).parent / "sut" / "modlevel.yaml"
WAIT = 240.0  # s: a bound against a hang, not a speed figure


def _fuzz(out: Path, *extra: str, params: tuple[str, ...] = ()) -> list[str]:
    return [sys.executable, "-m", "astaa_deft.cli", "fuzz", "--spec", str(SPEC), "-o", str(out), "--cases", "1",
            "--seed", "0", "--baseline", "1", "--reruns", "1", "--no-minimise", "--params",
            "seconds=3", *params, "--workers", "1", *extra]


def _descendants(proc: psutil.Process) -> list[psutil.Process]:
    try:
        return proc.children(recursive=True)
    except psutil.NoSuchProcess:
        return []


def _until(what, seen: list[psutil.Process], cmd: subprocess.Popen) -> None:
    """Wait until ``what()`` holds while the command runs, remembering every process it started meanwhile."""
    proc = psutil.Process(cmd.pid)
    deadline = time.monotonic() + WAIT
    while not what():
        assert cmd.poll() is None, cmd.communicate()[1]
        assert time.monotonic() < deadline, "the campaign never got there"
        seen += [p for p in _descendants(proc) if p not in seen]
        time.sleep(0.02)
    seen += [p for p in _descendants(proc) if p not in seen]


def _cmdline(p: psutil.Process) -> str:
    try:
        return " ".join(p.cmdline())
    except psutil.Error:
        return ""


def _workers(seen: list[psutil.Process]) -> list[psutil.Process]:
    return [p for p in seen if "module_level_worker" in _cmdline(p)]


def _module_level_cases(out: Path) -> dict[str, str]:
    db = sqlite3.connect(out / "journal.sqlite")
    try:
        return dict(db.execute("SELECT case_id, status FROM cases "
                               "WHERE strategy='module-level' AND kind='mutated'").fetchall())
    finally:
        db.close()


def _alive(p: psutil.Process) -> bool:
    try:
        return p.is_running() and p.status() != psutil.STATUS_ZOMBIE
    except psutil.Error:
        return False


def _interrupted(out: Path, sig: signal.Signals, ready, *params: str) -> tuple[int, str, list[psutil.Process], int]:
    """The command's exit code and output once ``ready`` held and ``sig`` was sent; every process it started,
    and how many module-level workers ran when it was sent."""
    cmd = subprocess.Popen(_fuzz(out, "--module-level-seconds", "60", params=params), stdout=subprocess.PIPE,
                           stderr=subprocess.PIPE, text=True)
    seen: list[psutil.Process] = []
    try:
        _until(lambda: ready(seen), seen, cmd)
        workers = len([p for p in _workers(seen) if _alive(p)])
        cmd.send_signal(sig)
        printed, err = cmd.communicate(timeout=WAIT)
    finally:
        if cmd.poll() is None:
            cmd.kill()
            cmd.wait()
    return cmd.returncode, printed + err, seen, workers


# Each replayed step sleeps 2 ms (modlevel.yaml's step_ms): the search lasts ~10 s instead of ~2 s, long enough
# to be interrupted while its workers replay, on a loaded machine too (a sleep does not slow down with the load).
STEP_MS = "step_ms=2"


def _interrupted_search(out: Path, sig: signal.Signals, code: int) -> None:
    """Interrupted while the workers replay (each one has written a result line): ``code``, no traceback, no
    process left, nothing of the search decided, and the way on (``--resume``) said."""
    code_seen, err, seen, workers = _interrupted(out, sig, lambda seen: len(_workers(seen)) >= 2 and all(
        p.stat().st_size > 0 for p in (out / "module_level").glob("m*-0.jsonl")) and
        len(list((out / "module_level").glob("m*-0.jsonl"))) == 2, STEP_MS)
    assert code_seen == code, err
    assert "Traceback" not in err, err
    assert workers >= 2, "the module-level workers did not run when it was interrupted"
    assert not [_cmdline(p) for p in seen if _alive(p)], "a process was left"
    assert not (out / "module_level" / "state.json").exists()  # the search did not finish: nothing decided
    assert _module_level_cases(out) == {}  # and nothing of it in the journal
    assert "--resume" in err


def test_an_interrupted_search_stops_its_workers_and_decides_nothing(tmp_path: Path):
    """Ctrl-C in the default run; the resume to the end (a whole campaign more) is the SIGTERM form below."""
    _interrupted_search(tmp_path / "campaign", signal.SIGINT, 130)


@pytest.mark.slow
@pytest.mark.promise
def test_a_terminated_search_stops_its_workers_and_a_resume_searches_again(tmp_path: Path):
    out = tmp_path / "campaign"
    _interrupted_search(out, signal.SIGTERM, 143)
    # The resumed search's time box as the first one's: its plan ends it on a quiet machine, a loaded one needs
    # the time to find the seeded defects again.
    done = subprocess.run(_fuzz(out, "--resume", "--module-level-seconds", "60", params=(STEP_MS,)),
                          capture_output=True, text=True, timeout=WAIT * 2)
    assert done.returncode in (0, 1), done.stderr
    state = json.loads((out / "module_level" / "state.json").read_text())
    assert state["complete"] is True and state["findings"]
    cases = _module_level_cases(out)
    assert set(cases) == {f["case_id"] for f in state["findings"]} and set(cases.values()) == {"done"}


@pytest.mark.slow
@pytest.mark.promise
def test_an_interrupt_after_the_search_keeps_what_it_decided_and_a_resume_finishes_it(tmp_path: Path):
    out = tmp_path / "campaign"
    state_file = out / "module_level" / "state.json"
    # the search ended (its state is written first); its live cases and module tests are being written
    code_seen, err, seen, _workers_then = _interrupted(out, signal.SIGINT, lambda seen: state_file.exists())
    assert code_seen == 130, err
    assert "Traceback" not in err, err
    assert not [_cmdline(p) for p in seen if _alive(p)], "a process was left"
    state = json.loads(state_file.read_text())
    assert state["findings"]
    planned = _module_level_cases(out)
    ids = {f["case_id"] for f in state["findings"] if f["case_id"]}
    assert set(planned) <= {f"m-{k + 1:04d}" for k in range(len(state["findings"]))}  # only its findings' cases
    assert ids <= set(planned)  # a case the state names is in the journal
    done = subprocess.run(_fuzz(out, "--resume"), capture_output=True, text=True, timeout=WAIT * 2)
    assert done.returncode in (0, 1), done.stderr
    after = json.loads(state_file.read_text())
    assert after["complete"] is True
    assert [f["verdict"] for f in after["findings"]] == [f["verdict"] for f in state["findings"]]  # not searched
    # again: the same findings
    cases = _module_level_cases(out)
    assert set(cases) == {f["case_id"] for f in after["findings"]} and set(cases.values()) == {"done"}
    assert all(f["tests"] for f in after["findings"])
