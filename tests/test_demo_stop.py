"""Ctrl-C and SIGTERM stop the demo where it is: the exit code says which, no later step starts, nothing it
started is left running, and what it wrote stays readable."""

from __future__ import annotations

import json
import signal
import subprocess
import sys

import pytest

from astaa_deft.io.log.reader import read_log

# Runs the demo as its child, under PR_SET_CHILD_SUBREAPER so that whatever the demo starts and leaves behind
# becomes this helper's (and so is found, by its parent pid, and stopped): no name matching, no other process.
# Once the demo prints the marker line it sends the signal, then reports the exit code, the seconds from the
# signal to the exit and every descendant still alive.
HELPER = r"""
import ctypes, json, os, signal, subprocess, sys, time
out, marker, sig, delay = sys.argv[1], sys.argv[2], signal.Signals[sys.argv[3]], float(sys.argv[4])
ctypes.CDLL(None, use_errno=True).prctl(36, 1, 0, 0, 0)
log = open(os.path.join(out, "demo.out"), "w")
demo = subprocess.Popen([sys.executable, "-m", "astaa_deft.cli", "demo", "--out", out], stdout=log,
                        stderr=subprocess.STDOUT, cwd=out)
deadline = time.monotonic() + 600
while demo.poll() is None and time.monotonic() < deadline:
    if marker in open(os.path.join(out, "demo.out")).read():
        break
    time.sleep(0.1)
time.sleep(delay)
sent = time.monotonic()
demo.send_signal(sig)
try:
    code = demo.wait(timeout=120)
except subprocess.TimeoutExpired:
    demo.kill()
    code = demo.wait()
seconds = time.monotonic() - sent

def descendants():
    found, parents = [], {os.getpid()}
    changed = True
    while changed:
        changed = False
        for name in os.listdir("/proc"):
            if not name.isdigit() or int(name) in found:
                continue
            try:
                stat = open(f"/proc/{name}/stat").read()
            except OSError:
                continue
            fields = stat[stat.rindex(")") + 2:].split()
            if int(fields[1]) in parents and fields[0] != "Z":
                found.append(int(name)); parents.add(int(name)); changed = True
    return found

def reap():  # the orphans that already ended
    while True:
        try:
            if os.waitpid(-1, os.WNOHANG) == (0, 0):
                return
        except ChildProcessError:
            return

# Helpers that end on their own once the tool is gone (a run's reaper) get until 10 s after the signal: the
# bound of a hang, not a speed figure (how fast a stop is, printed here, is measured on a quiet machine: README).
while True:
    reap()
    pids = descendants()
    if not pids or time.monotonic() > sent + 10.0:
        break
    time.sleep(0.05)
gone = time.monotonic() - sent
left = {}
for pid in pids:
    try:
        left[pid] = open(f"/proc/{pid}/cmdline").read().replace("\0", " ")[:200]
        os.kill(pid, signal.SIGKILL)
    except OSError:
        pass
print(json.dumps({"code": code, "seconds": seconds, "gone": gone, "left": left}))
"""


# A stop that takes longer is a hang: several times the slowest stop seen on a loaded 2-core machine (5.7 s at
# load 14); how fast a stop is belongs to the figures, not to a test.
HANG_S = 30.0


def _stop_demo(tmp_path, marker: str, sig: signal.Signals, delay: float) -> tuple[dict, str]:
    done = subprocess.run([sys.executable, "-c", HELPER, str(tmp_path), marker, sig.name, str(delay)],
                          capture_output=True, text=True, timeout=900)
    assert done.returncode == 0, done.stderr
    output = (tmp_path / "demo.out").read_text()
    return json.loads(done.stdout.strip().splitlines()[-1]), output


def test_ctrl_c_during_deft_stops_the_demo_there(tmp_path):
    result, output = _stop_demo(tmp_path, "== 2/5", signal.SIGINT, 1.0)
    print(f"SIGINT during DeFT: exit {result['code']} {result['seconds']:.2f} s after the signal, every process it "
          f"started gone after {result['gone']:.2f} s")
    assert result["code"] == 130, output
    assert result["left"] == {}, f"still running 10 s after the signal: {result['left']}"
    assert result["seconds"] <= HANG_S, result
    assert "== 3/5" not in output and "demo stopped by SIGINT during step 2" in output, output
    assert "Traceback" not in output
    assert read_log(tmp_path / "clean.mcap").finished  # what it wrote before the stop stays readable


@pytest.mark.slow
def test_sigterm_during_the_campaign_stops_the_demo_with_its_journal_readable(tmp_path):
    result, output = _stop_demo(tmp_path, "== 5/5", signal.SIGTERM, 8.0)
    print(f"SIGTERM during fuzz: exit {result['code']} {result['seconds']:.2f} s after the signal, every process it "
          f"started gone after {result['gone']:.2f} s")
    assert result["code"] == 143, output
    assert result["left"] == {}, f"still running 10 s after the signal: {result['left']}"
    assert result["seconds"] <= HANG_S, result
    assert "demo stopped by SIGTERM during step 5" in output and "Traceback" not in output, output
    status = subprocess.run([sys.executable, "-m", "astaa_deft.cli", "fuzz", "--status", "-o",
                             str(tmp_path / "campaign")], capture_output=True, text=True, timeout=60)
    assert status.returncode == 0, status.stdout + status.stderr


def test_a_demo_into_a_folder_with_results_starts_afresh_and_says_so(tmp_path, capsys):
    """Never the earlier campaign shown as new: the demo's own outputs go, anything else there stays."""
    from astaa_deft.cli.commands.demo import _start_fresh

    (tmp_path / "campaign").mkdir()
    (tmp_path / "campaign" / "journal.sqlite").write_bytes(b"earlier")
    (tmp_path / "clean.mcap").write_bytes(b"earlier")
    (tmp_path / "notes.txt").write_text("mine")
    _start_fresh(tmp_path)
    said = capsys.readouterr().out
    assert "starting afresh: the earlier demo's clean.mcap, campaign" in said
    assert not (tmp_path / "campaign").exists() and not (tmp_path / "clean.mcap").exists()
    assert (tmp_path / "notes.txt").read_text() == "mine"
