"""Exact replay by fork: candidates tried from the very planner state, in parallel, not from deep copies.

The planner (tests/sut/lossy_state_planner.py) loses bits through its
pickled state as extension objects do. In the crafted log the planner used
the older of two poses on every second cycle, so its most likely candidate
is wrong there and a second must be tried from the same state: restored from
a deep copy, every later plan is a little off (nothing reproduces at θ = 0);
forked, all do.
"""

from __future__ import annotations

import os
import subprocess
import sys
import time

import pytest

from astaa_deft.analysis.deft.extract import extract, near_miss_note
from astaa_deft.analysis.deft.fork_replay import can_fork
from astaa_deft.analysis.deft.replay import make_planner
from astaa_deft.analysis.deft.idle_cores import cpu_sample, idle_cores, idle_share
from astaa_deft.io.log.reader import read_log
from astaa_deft.engine.spec.loader import load_spec

from lossy_log import SPEC, write_lossy_log
from proxy_helpers import SUT_DIR

pytestmark = pytest.mark.skipif(not can_fork(), reason="fork-based replay needs os.fork (POSIX)")

CYCLES = 12


@pytest.fixture()
def crafted(tmp_path, monkeypatch):
    monkeypatch.syspath_prepend(str(SUT_DIR))
    # Every second cycle the pose logged with its tick came too late for the planner.
    return write_lossy_log(tmp_path, [k % 2 == 1 for k in range(CYCLES)], "lossy.mcap")


def test_deep_copies_of_a_lossy_state_do_not_reproduce_at_zero(crafted):
    spec, log_path = crafted
    ex = extract(read_log(log_path), spec, make_planner(spec, {}))
    assert ex.outputs == CYCLES and len(ex.frames) == CYCLES
    assert ex.accepted_at(0.0) < CYCLES  # why forking exists: copies plan a little off
    assert ex.accepted_at(1e-6) == CYCLES
    # The user is told why, with the distances and the flag that sets θ.
    note = near_miss_note(ex)
    assert note is not None and "--threshold 1e-09" in note and "median" in note
    near = sum(1 for f in ex.frames if 0 < f.comparison.distance <= 1e-9)
    assert near > 0 and f"{near} output(s) match within 1e-09 m" in note


@pytest.mark.parametrize("jobs", [1, 2])
def test_forked_candidates_reproduce_every_output_exactly(crafted, jobs):
    spec, log_path = crafted
    seen = []
    ex = extract(read_log(log_path), spec, make_planner(spec, {}), jobs=jobs,
                 on_output=lambda done, total, outcome: seen.append((done, total)))
    assert ex.outputs == CYCLES and len(ex.frames) == CYCLES and not ex.skipped
    assert ex.accepted_at(0.0) == CYCLES
    assert all(f.exact for f in ex.frames)
    assert near_miss_note(ex) is None
    assert [f.candidates_tried for f in ex.frames][:2] == [1, 2]  # odd cycles needed the second candidate
    assert seen[-1] == (CYCLES, CYCLES)  # progress reached the caller from the replay process


def test_factory_next_to_the_spec_is_found_without_pythonpath(tmp_path):
    """Found 9: a planner module beside the spec is imported from the spec's directory."""
    (tmp_path / "beside_spec_planner.py").write_text((SUT_DIR / "lossy_state_planner.py").read_text())
    spec_path = tmp_path / "lossy.yaml"
    spec_path.write_text(SPEC.replace("lossy_state_planner:LossyStatePlanner",
                                      "beside_spec_planner:LossyStatePlanner"))
    planner = make_planner(load_spec(spec_path), {})
    assert type(planner.obj).__name__ == "LossyStatePlanner"


def test_factory_nowhere_is_one_clear_error(tmp_path):
    from astaa_deft.model.errors import InputError

    spec_path = tmp_path / "lossy.yaml"
    spec_path.write_text(SPEC.replace("lossy_state_planner:LossyStatePlanner", "no_such_planner_mod:P"))
    with pytest.raises(InputError) as caught:
        make_planner(load_spec(spec_path), {})
    assert "spec's directory" in str(caught.value) and "PYTHONPATH" in str(caught.value)


def spin(seconds: float) -> None:
    end = time.process_time() + seconds
    while time.process_time() < end:
        pass


@pytest.mark.skipif(not os.path.exists("/proc/stat"), reason="idle time is read from /proc/stat")
def test_a_forked_process_counts_the_cpu_time_of_the_line_it_was_forked_from_as_its_own():
    # The forked search asks for the idle cores in the replay's runner, a grandchild of the process that took
    # the first sample: the CPU time that line of processes spent since (reading the log, stepping cheap
    # outputs) is ours, about to wait for the candidates, not another's load.
    start = cpu_sample()
    assert start is not None
    spin(0.2)
    read, write = os.pipe()
    child = os.fork()
    if child == 0:
        grandchild = os.fork()
        if grandchild == 0:
            spin(0.2)
            now = cpu_sample()
            os.write(write, repr(now.own_seconds - start.own_seconds if now else -1.0).encode())
            os._exit(0)
        os.waitpid(grandchild, 0)
        os._exit(0)
    os.waitpid(child, 0)
    own = float(os.read(read, 100).decode())
    os.close(read)
    os.close(write)
    # Both spins (and a little of the forks), nothing of the others' load; /proc/stat counts whole clock ticks
    # (10 ms), so each of the three readings may be short by up to one.
    assert 0.4 - 0.03 <= own < 0.4 + 0.3, own


@pytest.mark.skipif(not os.path.exists("/proc/stat"), reason="idle time is read from /proc/stat")
def test_idle_cores_counts_a_core_kept_busy_now_as_busy():
    # The candidates' parallelism follows the cores idle right now, not the minute's load average (which
    # still counts a recording that just ended). A process spinning while it measures keeps one core busy.
    cpus = os.cpu_count() or 1
    assert 1 <= idle_cores() <= cpus
    spinner = subprocess.Popen([sys.executable, "-c", "while True: pass"])
    try:
        time.sleep(0.2)  # running
        start = cpu_sample()
        assert start is not None
        time.sleep(0.5)
        share = idle_share(start)
    finally:
        spinner.kill()
        spinner.wait()
    assert share is not None and 0.0 <= share <= 1.0 - 1.0 / cpus + 0.1
