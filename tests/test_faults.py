"""Faults during a run, each one real: the tool, its recorder, its bus router or a
module killed with SIGKILL; SIGINT and SIGTERM; the log's disk full.

Each test runs `astaa-deft proxy` on the echo SUT as a real process, induces
the fault, and checks the same four things: every process the tool started is
gone soon after (polled, with a generous bound; the time taken is printed), the
log is readable up to the fault, the exit code tells the truth, and the verdict
is never Pass about a run that was not fully observed.

Processes are found as descendants of the tool (by parent pid, snapshotted
before the fault) and stopped only by their pid.
"""

from __future__ import annotations

import json
import os
import resource
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from astaa_deft.io.log.reader import read_log
from proxy_helpers import ECHO_SPEC, SUT_DIR, alive, received

TOOL = Path(sys.executable).with_name("astaa-deft")  # the installed entry point: no cwd on sys.path
GONE_BOUND = 10.0  # from the fault; generous: the target is 5 s, printed per test


def _children() -> dict[int, list[int]]:
    kids: dict[int, list[int]] = {}
    for entry in os.listdir("/proc"):
        if not entry.isdigit():
            continue
        try:
            with open(f"/proc/{entry}/stat") as fh:
                ppid = int(fh.read().rsplit(") ", 1)[1].split()[1])
        except (OSError, IndexError, ValueError):
            continue
        kids.setdefault(ppid, []).append(int(entry))
    return kids


def descendants(pid: int) -> dict[int, str]:
    """Every live descendant of ``pid`` (pid → command line), found through parent pids."""
    kids, out, todo = _children(), {}, [pid]
    while todo:
        for child in kids.get(todo.pop(), []):
            try:
                out[child] = Path(f"/proc/{child}/cmdline").read_bytes().replace(b"\0", b" ").decode()
            except OSError:
                continue
            todo.append(child)
    return out


def helper_pid(started: dict[int, str], module: str) -> int:
    """The pid of the tool's helper running ``python ... -m module``."""
    found = [pid for pid, cmd in started.items() if f"-m {module}" in cmd]
    assert len(found) == 1, started
    return found[0]


def wait_gone(pids, bound: float = GONE_BOUND) -> tuple[list[int], float]:
    t0 = time.monotonic()
    while time.monotonic() - t0 < bound and any(alive(p) for p in pids):
        time.sleep(0.05)
    return [p for p in pids if alive(p)], time.monotonic() - t0


class ToolRun:
    """`astaa-deft proxy` on the echo SUT at 500 Hz, recorded; stopped only by the test's fault."""

    def __init__(self, tmp_path: Path, *extra: str, preexec_fn=None, params: tuple[str, ...] = ()):
        self.run_dir, self.log = tmp_path / "run", tmp_path / "run.mcap"
        args = [str(TOOL), "proxy", "--spec", str(ECHO_SPEC), "--record", str(self.log), "--run-dir",
                str(self.run_dir), "--param", "count=1000000", "--param", "rate=500", *params, *extra]
        self.out_path, self.err_path = tmp_path / "tool.out", tmp_path / "tool.err"
        with open(self.out_path, "wb") as out, open(self.err_path, "wb") as err:
            self.proc = subprocess.Popen(args, stdout=out, stderr=err, stdin=subprocess.DEVNULL,
                                         preexec_fn=preexec_fn)
        self.started: dict[int, str] = {}
        self.fault_at = time.monotonic()

    def fault(self, pid: int, sig: signal.Signals) -> None:
        self.fault_at = time.monotonic()
        os.kill(pid, sig)

    def wait_flowing(self, messages: int = 300, timeout: float = 60.0) -> None:
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline and len(received(self.run_dir / "listener.out")) < messages:
            assert self.proc.poll() is None, self.output()
            time.sleep(0.05)
        assert len(received(self.run_dir / "listener.out")) >= messages, self.output()
        self.started = descendants(self.proc.pid)

    def finish(self, timeout: float = 60.0) -> int:
        try:
            return self.proc.wait(timeout=timeout)
        finally:
            if self.proc.poll() is None:
                self.proc.kill()
                self.proc.wait()

    def output(self) -> str:
        return self.out_path.read_text(errors="replace") + self.err_path.read_text(errors="replace")

    def all_gone(self, what: str) -> None:
        pids = [self.proc.pid, *self.started]
        left, _ = wait_gone(pids, max(0.5, GONE_BOUND - (time.monotonic() - self.fault_at)))
        print(f"{what}: every started process gone {time.monotonic() - self.fault_at:.2f} s after the fault")
        assert left == [], f"still running after {what}: {[self.started.get(p, 'tool') for p in left]}"

    def stop_leftovers(self) -> None:
        for pid in [*self.started, self.proc.pid]:
            if alive(pid):
                os.kill(pid, signal.SIGKILL)


@pytest.fixture
def tool_run(tmp_path):
    runs: list[ToolRun] = []

    def start(*extra: str, **kw) -> ToolRun:
        runs.append(ToolRun(tmp_path, *extra, **kw))
        return runs[-1]

    yield start
    for r in runs:
        r.stop_leftovers()


def logged_seqs(log: Path) -> set[int]:
    return {json.loads(m.data)["header"]["seq"] for m in read_log(log).on("test/data")}


# --- the tool itself ------------------------------------------------------------------------------------------

def test_kill_9_of_the_tool_leaves_nothing_running_and_a_finished_log(tool_run):
    run = tool_run()
    run.wait_flowing()
    recorder = helper_pid(run.started, "astaa_deft.engine.session.recorder")
    run.fault(run.proc.pid, signal.SIGKILL)
    assert run.finish() == -signal.SIGKILL
    run.all_gone("kill -9 of the tool")
    # The recorder finished the log on its parent's death: readable, and no traceback in its own log.
    recorder_log = (run.run_dir / "recorder.log").read_text()
    assert "Traceback" not in recorder_log and "BrokenPipeError" not in recorder_log, recorder_log
    contents = read_log(run.log)
    assert contents.finished and not contents.damage
    delivered = {json.loads(p)["header"]["seq"] for k, p, _ in received(run.run_dir / "listener.out")
                 if k == "test/data"}
    assert len(delivered) >= 300
    assert sorted(delivered - logged_seqs(run.log)) == []  # every message the listener got is in the log
    assert not alive(recorder)
    # Nothing in it claims a verdict: the tool that would have given one is gone; the recorder says so,
    # and a check of the log gives its findings but withholds a Pass.
    assert contents.events("verdict") == []
    check = subprocess.run([str(TOOL), "check", str(run.log)], capture_output=True, text=True, timeout=60)
    assert check.returncode == 3, check.stdout + check.stderr
    assert "verdict: Pass" not in check.stdout and "verdict withheld: the tool was lost" in check.stdout
    assert "Traceback" not in check.stderr


@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM], ids=["SIGINT", "SIGTERM"])
def test_a_stop_signal_ends_the_run_cleanly(tool_run, sig):
    run = tool_run()
    run.wait_flowing()
    run.fault(run.proc.pid, sig)
    code = run.finish()
    out = run.output()
    assert code == 0, out
    assert f"stopped (signal {sig.name})" in out
    assert "verdict: Pass" in out and "Traceback" not in out
    run.all_gone(sig.name)
    contents = read_log(run.log)
    assert contents.finished and not contents.damage
    assert contents.events("verdict")[-1]["class"] == "Pass"
    recorded = logged_seqs(run.log)
    delivered = {json.loads(p)["header"]["seq"] for k, p, _ in received(run.run_dir / "listener.out")
                 if k == "test/data"}
    assert delivered <= recorded  # everything delivered before the stop is in the log



def test_a_recorder_stopped_before_the_dying_tool_is_reparented_still_notes_the_tool_lost(tool_run):
    # The race behind a Pass on a killed run (seen under load): the reaper sees a killed tool's pipe close
    # and stops the recorder before the kernel has moved the recorder to a new parent, so "my parent is
    # still the tool" looked like an orderly end. Widened here: the recorder is stopped while the tool
    # lives, without the tool's run_stopped announcement, and the tool is killed just after.
    run = tool_run()
    run.wait_flowing()
    recorder = helper_pid(run.started, "astaa_deft.engine.session.recorder")
    os.kill(recorder, signal.SIGTERM)
    time.sleep(0.2)
    run.fault(run.proc.pid, signal.SIGKILL)
    run.finish()
    run.all_gone("a recorder stopped, then the tool killed")
    contents = read_log(run.log)
    assert contents.finished and not contents.damage
    check = subprocess.run([str(TOOL), "check", str(run.log)], capture_output=True, text=True, timeout=60)
    assert "verdict: Pass" not in check.stdout, check.stdout
    assert check.returncode == 3 and "verdict withheld: the tool was lost" in check.stdout, check.stdout

def test_a_recorder_behind_at_the_stop_still_records_everything_delivered(tool_run):
    """The stop waits for the recorder to catch up (it sees the run_stopped event), not a fixed 0.3 s."""
    run = tool_run()
    run.wait_flowing()
    recorder = helper_pid(run.started, "astaa_deft.engine.session.recorder")
    os.kill(recorder, signal.SIGSTOP)  # the recorder falls behind: what it has not read waits in its socket
    try:
        time.sleep(1.0)
        run.fault(run.proc.pid, signal.SIGINT)
        time.sleep(1.5)  # the tool has stopped the modules and is ending the run meanwhile
    finally:
        os.kill(recorder, signal.SIGCONT)
    code = run.finish()
    assert code == 0, run.output()
    run.all_gone("SIGINT with the recorder behind")
    delivered = {json.loads(p)["header"]["seq"] for k, p, _ in received(run.run_dir / "listener.out")
                 if k == "test/data"}
    missing = delivered - logged_seqs(run.log)
    assert not missing, f"{len(missing)} of {len(delivered)} delivered messages are not in the log"


def test_silence_while_the_run_stops_is_no_finding(tmp_path):
    """A module slow to exit after SIGTERM (its channel silent meanwhile) is the tool's shutdown, not a hang."""
    slow_exit = ('command: ["{python}", "%s/talker.py"' % SUT_DIR,
                 'command: ["sh", "-c", "trap \'sleep 1.5; exit 0\' TERM; \\"$0\\" \\"$@\\" & wait; wait", '
                 '"{python}", "%s/talker.py"' % SUT_DIR)
    spec = spec_variant(tmp_path, slow_exit, ("brittle:", "invariants:\n  - {name: data_alive, kind: deadline, "
                                                          "channel: data, max_gap: 0.3}\nbrittle:"))
    res = run_tool(spec, tmp_path, "--duration", "3", "--param", "count=100000", "--param", "rate=100")
    assert res.returncode == 0, res.stdout + res.stderr
    assert "verdict: Pass" in res.stdout
    assert read_log(tmp_path / "run.mcap").events("verdict")[-1]["class"] == "Pass"


# --- the tool's helpers -----------------------------------------------------------------------------------------

def test_kill_9_of_the_recorder_is_reported_and_is_no_pass(tool_run):
    run = tool_run()
    run.wait_flowing(1500)  # a few 64 KiB chunks in the file: a recorder killed outright loses only the last
    run.fault(helper_pid(run.started, "astaa_deft.engine.session.recorder"), signal.SIGKILL)
    code = run.finish()
    out = run.output()
    assert code == 3, out
    assert "the recorder stopped" in out and "killed by SIGKILL" in out
    assert "verdict: Pass" not in out and "verdict withheld" in out
    assert "Traceback" not in out
    run.all_gone("kill -9 of the recorder")
    contents = read_log(run.log)  # readable up to its last complete chunk
    assert contents.truncated
    assert len(logged_seqs(run.log)) > 0


def test_kill_9_of_the_bus_router_is_reported_and_is_no_pass(tool_run):
    run = tool_run("--passive")
    run.wait_flowing()
    run.fault(helper_pid(run.started, "astaa_deft.engine.bus.router"), signal.SIGKILL)
    code = run.finish()
    out = run.output()
    assert code == 3, out
    assert "the bus router stopped" in out and "killed by SIGKILL" in out
    assert "verdict: Pass" not in out and "verdict withheld" in out
    assert "Traceback" not in out
    run.all_gone("kill -9 of the bus router")
    contents = read_log(run.log)
    assert not contents.damage
    assert len(logged_seqs(run.log)) >= 300


def test_a_full_disk_for_the_log_is_reported_and_is_no_pass(tool_run):
    run = tool_run()
    run.wait_flowing()
    # A full disk for the log alone: cap the size of the files the recorder may write (RLIMIT_FSIZE)
    # a few chunks beyond what it has written so far; the SUT's own files stay unlimited.
    recorder = helper_pid(run.started, "astaa_deft.engine.session.recorder")
    cap = run.log.stat().st_size + 48 * 1024
    resource.prlimit(recorder, resource.RLIMIT_FSIZE, (cap, cap))
    run.fault_at = time.monotonic()
    code = run.finish(timeout=120)
    out = run.output()
    assert code == 3, out
    assert "the recorder stopped" in out and "cannot write the log" in out
    assert "verdict: Pass" not in out and "verdict withheld" in out
    assert "Traceback" not in out
    run.all_gone("a full disk")
    assert run.log.stat().st_size <= cap
    contents = read_log(run.log)  # every chunk written before the disk filled
    assert not contents.intact and contents.damage
    assert len(logged_seqs(run.log)) >= 300


# --- a module -------------------------------------------------------------------------------------------------

def test_kill_9_of_a_module_ends_the_run_with_abort(tool_run):
    run = tool_run()
    run.wait_flowing()
    listener = json.loads((run.run_dir / "processes.json").read_text())["listener"]
    run.fault(listener, signal.SIGKILL)
    code = run.finish()
    out = run.output()
    assert code == 1, out
    assert "module 'listener'" in out and "killed by SIGKILL" in out and "(on_crash: end_run)" in out
    assert "verdict: Abort" in out
    run.all_gone("kill -9 of a module")
    contents = read_log(run.log)
    assert contents.finished and not contents.damage
    assert contents.events("verdict")[-1]["class"] == "Abort"


def spec_variant(tmp_path: Path, *replacements: tuple[str, str]) -> Path:
    text = ECHO_SPEC.read_text().replace("{spec_dir}", str(SUT_DIR))
    for old, new in replacements:
        assert old in text
        text = text.replace(old, new)
    path = tmp_path / "sut.yaml"
    path.write_text(text)
    return path


def run_tool(spec: Path, tmp_path: Path, *args: str) -> subprocess.CompletedProcess:
    return subprocess.run([str(TOOL), "proxy", "--spec", str(spec), "--record", str(tmp_path / "run.mcap"),
                           "--run-dir", str(tmp_path / "run"), *args], capture_output=True, text=True, timeout=120)


KEEP_RUNNING = ("    on_crash: keep_running", "")


def test_a_module_crash_ends_the_run_promptly_by_default(tmp_path):
    # No --duration: before, the run went on after the crash until someone stopped it.
    res = run_tool(spec_variant(tmp_path, KEEP_RUNNING), tmp_path, "--param", "crash_after=50")
    assert res.returncode == 1, res.stdout + res.stderr
    assert "stopped (module 'talker'" in res.stdout and "exit code 3 (on_crash: end_run)" in res.stdout
    assert "verdict: Abort" in res.stdout
    assert read_log(tmp_path / "run.mcap").events("verdict")[-1]["class"] == "Abort"
    pids = json.loads((tmp_path / "run" / "processes.json").read_text())
    assert [m for m, p in pids.items() if alive(p)] == []


def test_a_module_never_ready_is_exit_2_and_no_pass_in_the_log(tmp_path):
    spec = spec_variant(tmp_path, KEEP_RUNNING, ('ready: {log: "listener: subscribed"}',
                                                 'ready: {log: "never printed", timeout: 1}'))
    res = run_tool(spec, tmp_path, "--duration", "30")
    assert res.returncode == 2, res.stdout + res.stderr
    assert "module 'listener' not ready: no output line matching 'never printed' within 1 s" in res.stderr
    assert "Traceback" not in res.stderr
    verdicts = read_log(tmp_path / "run.mcap").events("verdict")
    assert verdicts and verdicts[-1]["class"] == "Restart", verdicts
    pids = json.loads((tmp_path / "run" / "processes.json").read_text())
    assert [m for m, p in pids.items() if alive(p)] == []


def test_a_module_crashing_while_starting_is_exit_1_as_documented(tmp_path):
    spec = spec_variant(tmp_path, KEEP_RUNNING, ('"--key", "test/extra", "--out"', '"--no-such-flag", "--out"'))
    res = run_tool(spec, tmp_path, "--duration", "30")
    assert res.returncode == 1, res.stdout + res.stderr
    assert "module 'listener' exited with code 2 while starting" in res.stderr
    assert "Traceback" not in res.stderr.split("while starting")[0]
    verdicts = read_log(tmp_path / "run.mcap").events("verdict")
    assert verdicts and verdicts[-1]["class"] == "Abort", verdicts


# --- helpers run the installed code ---------------------------------------------------------------------------

def test_helpers_run_the_installed_package_not_the_current_directory(tmp_path):
    """Recorder, bus router and reaper started from a folder holding another `astaa_deft/` still run ours."""
    fake = tmp_path / "checkout" / "astaa_deft"
    for sub in ("", "log", "bus"):
        (fake / sub).mkdir(parents=True, exist_ok=True)
        (fake / sub / "__init__.py").write_text(
            "import os, pathlib\n"
            "pathlib.Path(os.environ['FAKE_MARK']).write_text('the current directory was imported')\n"
            "raise SystemExit(7)\n")
    mark = tmp_path / "imported"
    log = tmp_path / "run.mcap"
    res = subprocess.run([str(TOOL), "proxy", "--spec", str(ECHO_SPEC), "--passive", "--record", str(log),
                          "--duration", "2", "--run-dir", str(tmp_path / "run"), "--param", "count=50"],
                         cwd=fake.parent, env=dict(os.environ, FAKE_MARK=str(mark)),
                         capture_output=True, text=True, timeout=120)
    assert not mark.exists(), res.stdout + res.stderr
    assert res.returncode == 0, res.stdout + res.stderr
    assert len(logged_seqs(log)) == 50


# --- non-finite values on JSON channels -----------------------------------------------------------------------

def _strict(data: bytes):
    """Parse as a strict JSON parser (Foxglove's) does: NaN and ±Infinity are errors."""
    def refuse(token):
        raise ValueError(f"non-standard token {token}")
    return json.loads(data, parse_constant=refuse)


def test_non_finite_mutations_stay_exact_on_the_bus_and_every_logged_message_is_strict_json(tmp_path):
    from astaa_deft.model.tagged import from_tagged
    from astaa_deft.io.log.viewable import VIEWABLE_PREFIX

    policy = tmp_path / "tc.xml"
    policy.write_text("""<?xml version="1.0" encoding="UTF-8"?>
<testcase id="nan" seed="1"><description>non-finite values</description>
  <policy id="p1"><channel>data</channel><select every="4"/>
    <set><field path="value" value="dict:float.nan"/></set></policy>
  <policy id="p2"><channel>data</channel><select every="7"/>
    <set><field path="value" value="dict:float.neg_inf"/></set></policy>
</testcase>
""")
    res = run_tool(ECHO_SPEC, tmp_path, "--policy", str(policy), "--duration", "3",
                   "--param", "count=100", "--param", "rate=200")
    assert res.returncode in (0, 1), res.stdout + res.stderr
    delivered = [p for k, p, _ in received(tmp_path / "run" / "listener.out") if k == "test/data"]
    log = read_log(tmp_path / "run.mcap")
    logged = [m.data for m in log.on("test/data")]
    assert logged == delivered and len(delivered) == 100  # the exact bytes, bare NaN and -Infinity included
    assert sum(b"NaN" in p for p in logged) >= 20 and sum(b"-Infinity" in p for p in logged) >= 10
    twins = {m.log_time: m.data for m in log.on(VIEWABLE_PREFIX + "test/data")}
    not_strict = 0
    for topic, info in log.channels.items():
        if info.message_encoding != "json":
            continue
        for m in log.on(topic):
            try:
                _strict(m.data)
            except ValueError:
                not_strict += 1
                assert not topic.startswith("/astaa/"), (topic, m.data)  # the tool's own topics are always strict
                twin = _strict(twins[m.log_time])  # viewable: a strict twin at the same time
                exact = json.loads(m.data)
                assert from_tagged(twin["value"]) == exact["value"] or exact["value"] != exact["value"]
                assert str(from_tagged(twin["value"])) == str(exact["value"]) and twin["header"] == exact["header"]
    assert not_strict == len(twins) >= 30
