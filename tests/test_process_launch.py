"""The one process launcher (astaa_deft/engine/bus/process_launch.py): children that die with the tool, guarded forks.

Real processes throughout: a stand-in "tool" runs as a Python child of the
test, starts its own children through the launcher and is killed with
SIGKILL; every process is signalled by the id the test was told.
"""

from __future__ import annotations

import contextlib
import os
import signal
import subprocess
import sys
import textwrap
import threading
from pathlib import Path

import pytest

from astaa_deft.engine.bus import process_launch
from astaa_deft.engine.bus.process_launch import UnsafeFork
from astaa_deft.engine.bus.processes import process_running as _alive, python_module

from conftest import wait_for

needs_linux = pytest.mark.skipif(not sys.platform.startswith("linux"), reason="the parent-death signal is Linux's")

# A stand-in for the tool: starts `sleep` from a thread that then ends, says the child's pid once that thread
# has ended, then waits to be killed. START picks how the child is started.
TOOL = textwrap.dedent("""
    import ctypes, os, signal, subprocess, sys, threading
    from astaa_deft.engine.bus import process_launch

    def launcher():
        return process_launch.start(["sleep", "120"])

    def preexec_in_thread():  # the old way: the parent-death signal armed by preexec_fn
        arm = lambda: ctypes.CDLL(None, use_errno=True).prctl(1, signal.SIGTERM, 0, 0, 0)
        return subprocess.Popen(["sleep", "120"], start_new_session=True, preexec_fn=arm)

    started = []
    thread = threading.Thread(target=lambda: started.append({START}()))
    thread.start()
    thread.join()
    print(started[0].pid, flush=True)
    sys.stdin.read()  # until the test kills us
""")


def _tool(start: str) -> tuple[subprocess.Popen, int]:
    tool = subprocess.Popen([*python_module("astaa_deft")[:-2], "-c", TOOL.replace("{START}", start)],
                            stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True,
                            env={**os.environ, "PYTHONPATH": os.pathsep.join(sys.path)})
    assert tool.stdout is not None
    line = tool.stdout.readline()
    assert line.strip().isdigit(), f"the stand-in tool did not start a child (exit {tool.poll()})"
    return tool, int(line)


def _end(tool: subprocess.Popen, child: int) -> None:
    with contextlib.suppress(ProcessLookupError):
        tool.kill()
    tool.wait(timeout=10)
    if _alive(child):
        with contextlib.suppress(ProcessLookupError):
            os.kill(child, signal.SIGKILL)


@needs_linux
def test_a_child_started_from_a_thread_that_ended_lives_while_the_tool_lives_and_dies_with_it():
    tool, child = _tool("launcher")
    try:
        # The starting thread has ended (the tool printed the pid after join): a signal bound to that thread
        # would have been sent by now. The child runs on.
        assert not wait_for(lambda: not _alive(child), timeout=1.0), "the child died with the thread that started it"
        assert tool.poll() is None
        tool.kill()  # SIGKILL: no clean-up of the tool's runs
        tool.wait(timeout=10)
        assert wait_for(lambda: not _alive(child), timeout=10.0), "the child outlived the tool killed with SIGKILL"
    finally:
        _end(tool, child)


@needs_linux
def test_the_old_way_the_parent_death_signal_followed_the_thread_that_started_the_child():
    # Why the launcher forks from one long-lived thread: armed by preexec_fn in a thread that then ends,
    # the child gets its parent-death signal at that thread's end although the tool still runs.
    tool, child = _tool("preexec_in_thread")
    try:
        assert wait_for(lambda: not _alive(child), timeout=10.0)
        assert tool.poll() is None
    finally:
        _end(tool, child)


@needs_linux
def test_a_child_of_a_tool_that_died_before_the_signal_was_armed_exits_at_once(tmp_path: Path):
    # The wrapper is told the tool's pid; a child whose parent is already another process does not run.
    wrapper = [sys.executable, "-I", "-S", "-c", process_launch._WRAPPER, "1", str(int(signal.SIGTERM)), "2",
               "sh", "-c", f"touch {tmp_path / 'ran'}"]
    done = subprocess.run(wrapper, timeout=30)
    assert done.returncode == 128 + signal.SIGTERM
    assert not (tmp_path / "ran").exists()


def test_each_child_leads_its_own_process_group_and_its_streams_are_as_asked():
    process = process_launch.start(["sh", "-c", "cat; cut -d' ' -f5 /proc/$$/stat"], stdin=subprocess.PIPE,
                                   stdout=subprocess.PIPE, text=True)
    out, _ = process.communicate("hello\n", timeout=30)
    assert out.split() == ["hello", str(process.pid)]
    assert process.returncode == 0


def test_a_command_that_cannot_run_raises_what_popen_raises(tmp_path: Path):
    with pytest.raises(FileNotFoundError, match="no-such-command-anywhere"):
        process_launch.start(["no-such-command-anywhere"])
    script = tmp_path / "not-executable.sh"
    script.write_text("#!/bin/sh\necho ran\n")
    with pytest.raises(PermissionError):
        process_launch.start([str(script)])


def test_run_stops_the_whole_group_of_a_child_that_runs_too_long(tmp_path: Path):
    marker = tmp_path / "grandchild.pid"
    with pytest.raises(subprocess.TimeoutExpired):
        process_launch.run(["sh", "-c", f"sleep 120 & echo $! > {marker}; wait"], timeout=2.0)
    assert wait_for(marker.is_file, timeout=5.0)
    grandchild = int(marker.read_text())
    try:
        assert wait_for(lambda: not _alive(grandchild), timeout=10.0), "the child's own child outlived the stop"
    finally:
        if _alive(grandchild):
            os.kill(grandchild, signal.SIGKILL)


def test_the_fork_guard_raises_while_a_second_thread_runs():
    stop = threading.Event()
    other = threading.Thread(target=stop.wait, name="a-second-thread")
    other.start()
    try:
        with pytest.raises(UnsafeFork, match=r"a test fork: forked only from a single-threaded .*a-second-thread"):
            process_launch.guarded_fork("a test fork")
        with pytest.raises(UnsafeFork):  # native threads let be: Python's own still count
            process_launch.guarded_fork("a test fork", native_threads_ok=True)
    finally:
        stop.set()
        other.join()


def test_a_fork_waits_for_a_thread_that_is_ending():
    # A closed Zenoh session's callback thread ends a moment after the close (later on a loaded machine): the
    # fork waits for it rather than refusing, and forks alone. (Native threads let be, as a forked replay
    # does: this test process has its own.)
    ending = threading.Thread(target=lambda: threading.Event().wait(0.3), name="an-ending-thread")
    ending.start()
    pid = process_launch.guarded_fork("a test fork", native_threads_ok=True)
    if pid == 0:
        os._exit(7)
    assert not ending.is_alive()
    assert os.waitstatus_to_exitcode(os.waitpid(pid, 0)[1]) == 7


FORK_AFTER = textwrap.dedent("""
    import os, sys
    from astaa_deft.engine.bus import process_launch
    from astaa_deft.engine.bus import zenoh_config as zc

    def fork_once():
        pid = process_launch.guarded_fork("a test fork")
        if pid == 0:
            os._exit(7)
        return os.waitstatus_to_exitcode(os.waitpid(pid, 0)[1])

    print("alone", fork_once(), flush=True)
    process_launch.run(["true"], timeout=30)  # the process starter's thread now runs, idle
    print("after a start", fork_once(), flush=True)
    session = zc.open_session(zc.config_dict(mode="peer", listen=[zc.loopback_endpoint()]))
    try:
        fork_once()
    except process_launch.UnsafeFork as exc:
        print("with zenoh", "native one(s)" in str(exc), flush=True)
    pid = process_launch.guarded_fork("a test fork", native_threads_ok=True)
    if pid == 0:
        os._exit(0)
    os.waitpid(pid, 0)
    print("native ok", flush=True)
    session.close()
""")


@needs_linux
def test_a_single_threaded_process_forks_also_after_starting_a_child_and_one_with_a_zenoh_runtime_does_not():
    done = subprocess.run([*python_module("astaa_deft")[:-2], "-c", FORK_AFTER], capture_output=True, text=True,
                          timeout=60, env={**os.environ, "PYTHONPATH": os.pathsep.join(sys.path)})
    expected = ["alone 7", "after a start 7", "with zenoh True", "native ok"]
    assert done.stdout.splitlines() == expected, done.stderr[-2000:]


# A Zenoh session and publisher nobody closed, left in a reference cycle (garbage the collector has not
# reached yet), then a fork: the child and its own forked child collect garbage. Collected there, their
# finalisers would wait forever for the Zenoh runtime's threads, which a forked process does not have.
FORK_WITH_ZENOH_GARBAGE = textwrap.dedent("""
    import gc, os, signal, sys, time
    from astaa_deft.engine.bus import process_launch
    from astaa_deft.engine.bus import zenoh_config as zc

    def ended(pid, within_s=20.0):  # the child's exit code, or "hung" (then it is killed)
        deadline = time.monotonic() + within_s
        while time.monotonic() < deadline:
            done, status = os.waitpid(pid, os.WNOHANG)
            if done:
                return os.waitstatus_to_exitcode(status)
            time.sleep(0.05)
        os.kill(pid, signal.SIGKILL)
        os.waitpid(pid, 0)
        return "hung"

    session = zc.open_session(zc.config_dict(mode="peer", listen=[zc.loopback_endpoint()]))
    holder = {"publisher": session.declare_publisher("fork/garbage"), "session": session}
    holder["self"] = holder
    del holder, session
    child = process_launch.guarded_fork("a test fork", native_threads_ok=True)
    if child == 0:
        grandchild = process_launch.guarded_fork("a test fork")
        if grandchild == 0:
            gc.collect()
            os._exit(7)
        gc.collect()
        os._exit(7 if ended(grandchild) == 7 else 1)
    print("child", ended(child), flush=True)
    print("parent collects", gc.collect() > 0, flush=True)
""")


@needs_linux
def test_a_forked_child_never_runs_the_finaliser_of_a_zenoh_session_its_parent_left_as_garbage():
    done = subprocess.run([*python_module("astaa_deft")[:-2], "-c", FORK_WITH_ZENOH_GARBAGE], capture_output=True,
                          text=True, timeout=120, env={**os.environ, "PYTHONPATH": os.pathsep.join(sys.path)})
    assert done.stdout.splitlines() == ["child 7", "parent collects True"], done.stderr[-2000:]


SESSION_CHILD = textwrap.dedent("""
    import os, sys
    from astaa_deft.engine.bus import process_launch

    pid = process_launch.fork_session_child("a test child")
    if pid == 0:
        sys.stdin.read()  # until the stand-in tool dies (then the parent-death signal ends us)
        os._exit(0)
    print(pid, os.getpgid(pid) == pid, os.getsid(pid) == pid, flush=True)
    sys.stdin.read()  # until the test kills us
""")


@needs_linux
def test_a_session_child_leads_its_group_when_the_fork_returns_and_dies_with_the_tool():
    tool = subprocess.Popen([*python_module("astaa_deft")[:-2], "-c", SESSION_CHILD], stdin=subprocess.PIPE,
                            stdout=subprocess.PIPE, text=True,
                            env={**os.environ, "PYTHONPATH": os.pathsep.join(sys.path)})
    assert tool.stdout is not None
    words = tool.stdout.readline().split()
    assert len(words) == 3 and words[0].isdigit(), f"the stand-in tool did not fork (exit {tool.poll()})"
    child = int(words[0])
    try:
        assert words[1:] == ["True", "True"]  # its own group and session before fork_session_child returned
        assert _alive(child)
        tool.kill()
        tool.wait(timeout=10)
        assert wait_for(lambda: not _alive(child), timeout=10.0), "the child outlived the tool that forked it"
    finally:
        _end(tool, child)
