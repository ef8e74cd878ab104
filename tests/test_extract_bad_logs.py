"""`extract` on a log its planner cannot read: one clear input error (exit 2), never a traceback.

The forked replay (deft/fork_replay.py) finds the problem in its runner
process; the InputError it raises there must reach the user as the same
InputError, not as "RuntimeError: the replay process failed".
"""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

from astaa_deft.analysis.deft.fork_replay import can_fork
from astaa_deft.analysis.deft.workflow import ExtractOptions, extract_module_tests
from astaa_deft.model.errors import InputError
from astaa_deft.io.log.writer import LogWriter
from astaa_deft.engine.spec.loader import load_spec
from test_log import write_finished_log

ROOT = Path(__file__).resolve().parent.parent
DEMO_SPEC = ROOT / "astaa_deft" / "data" / "specs" / "demo_av.yaml"

pytestmark = pytest.mark.skipif(not can_fork(), reason="the forked replay needs os.fork (POSIX)")


def other_spec_log(path: Path) -> Path:
    """An intact, finished log of another system (tests/test_log.py's): none of the demo planner's channels."""
    return write_finished_log(path)


def outputs_only_log(path: Path) -> Path:
    """A demo log in which the planner's outputs survive but none of its input channels can be read."""
    spec = load_spec(DEMO_SPEC)
    writer = LogWriter(path, spec)
    trajectory = writer.bus_channel(spec.channel("trajectory"))
    for i in range(10):
        body = {"header": {"seq": i, "stamp": 1.0 + i * 0.1}, "points": []}
        writer.message(trajectory, 1_000_000_000 + i * 100_000_000, json.dumps(body).encode())
    writer.finish()
    return path


def run_extract(log: Path, out: Path) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "astaa_deft.cli", "extract", str(log), "--spec", str(DEMO_SPEC),
                           "-o", str(out)], capture_output=True, text=True, timeout=300)


@pytest.mark.parametrize("make_log", [outputs_only_log, other_spec_log], ids=["no-input-readable", "other-spec"])
def test_extract_on_a_log_the_planner_cannot_read_is_one_input_error(tmp_path, make_log):
    log = make_log(tmp_path / "run.mcap")
    res = run_extract(log, tmp_path / "tests")
    assert res.returncode == 2, res.stdout + res.stderr
    assert "Traceback" not in res.stderr and "RuntimeError" not in res.stderr
    errors = [line for line in res.stderr.splitlines() if line.startswith("astaa-deft: error:")]
    assert len(errors) == 1, res.stderr
    assert str(log) in errors[0] and "the log has no channel" in errors[0]
    assert "record the run with this spec" in errors[0]  # the fix


def test_the_forked_runner_raises_the_input_error_itself(tmp_path):
    """The library call (forked candidates) raises InputError with the problem's file and fix intact."""
    log = other_spec_log(tmp_path / "run.mcap")
    with pytest.raises(InputError) as caught:
        extract_module_tests(log, DEMO_SPEC, tmp_path / "tests", ExtractOptions(jobs=2))
    (problem,) = caught.value.problems
    assert problem.file == str(log) and "the log has no channel" in problem.message and problem.fix
