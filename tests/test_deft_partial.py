"""Long extractions: progress where no terminal is, partial results, a stop, --resume.

Real runs of examples/ompl_stack through the star, recorded to real MCAP
files; real `astaa-deft extract` subprocesses under `timeout`, and the
library's extraction with its forked replay.
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
import ompl  # noqa: F401  -- in the test extra; the stack's planner needs it (a venv without it fails, not skips)

from astaa_deft.cli.commands.console import PLAIN_PERIOD_S, PlainLines
from astaa_deft.analysis.deft.checkpoint import STATE
from astaa_deft.analysis.deft.workflow import ExtractOptions, extract_module_tests

STACK = Path(__file__).resolve().parent.parent / "examples" / "ompl_stack"
SPEC = STACK / "spec.yaml"
GOAL_X = "35"  # past the parked car: about 8 s of simulated time


def cli(*args: str) -> list[str]:
    return [sys.executable, "-m", "astaa_deft.cli", *args]


def drive(tmp: Path, name: str, *params: str) -> Path:
    log = tmp / f"{name}.mcap"
    res = subprocess.run(cli("proxy", "--spec", str(SPEC), "--record", str(log), "--run-dir", str(tmp / name),
                             "--param", f"goal_x={GOAL_X}", *params), capture_output=True, text=True, timeout=240)
    assert log.is_file(), res.stdout + res.stderr
    return log


def checked_frames(out: Path) -> int:
    """The module tests on disk: frames with a check (a frame kept only for the module's state has none)."""
    try:
        return sum(1 for f in json.loads((out / "deft.json").read_text())["frames"] if f["check"])
    except (OSError, ValueError, KeyError, TypeError):
        return 0


# -- progress without a terminal --------------------------------------------------------------------
def test_plain_progress_repeats_the_latest_state_while_nothing_changes():
    read_fd, write_fd = os.pipe()
    with os.fdopen(read_fd) as reader, os.fdopen(write_fd, "w") as writer:
        assert not writer.isatty()
        lines = PlainLines("extract", period_s=0.05, stream=writer)
        lines.show("1/3 outputs")  # then nothing: a step that takes minutes
        got = [reader.readline() for _ in range(3)]
        lines.close()
    assert all(line.startswith("extract: 1/3 outputs (") and "elapsed)" in line for line in got), got
    assert PLAIN_PERIOD_S <= 30  # a CI log hears from a long command at least every 30 s


# -- partial results, a stop, and going on ------------------------------------------------------------


@pytest.fixture(scope="module")
def heavy_log(tmp_path_factory) -> Path:
    """The planner at ~0.5 s CPU every cycle (a full RRT* search each time)."""
    return drive(tmp_path_factory.mktemp("heavy"), "heavy", "--param", "iterations=900", "--param", "reuse=0")


@pytest.mark.slow
@pytest.mark.promise
def test_an_extraction_stopped_by_timeout_leaves_the_decided_tests_and_a_summary(heavy_log, tmp_path):
    out = tmp_path / "tests"
    # `timeout` passes its stop on to the command as it does when its time is up (SIGTERM). The stop comes
    # once the first tests are on disk, however fast or loaded the machine is.
    proc = subprocess.Popen(["timeout", "900", *cli("extract", str(heavy_log), "--spec", str(SPEC), "-o", str(out))],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        deadline = time.monotonic() + 600
        while checked_frames(out) == 0 and proc.poll() is None and time.monotonic() < deadline:
            time.sleep(0.2)
        assert proc.poll() is None, "the extraction ended before it could be stopped"
        proc.send_signal(signal.SIGTERM)
        stdout, stderr = proc.communicate(timeout=120)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    assert proc.returncode == 143, stdout + stderr  # 128 + SIGTERM, as a shell reports it
    assert "Traceback" not in stderr, stderr
    summary = [line for line in stdout.splitlines() if line.startswith("interrupted after ")]
    assert summary and "--resume" in summary[0], stdout
    assert any(line.startswith("extract: ") and " outputs" in line for line in stderr.splitlines()), stderr
    written = checked_frames(out)
    assert written >= 1 and (out / STATE).is_file() and (out / "frames.mcap").is_file()
    decided = json.loads((out / STATE).read_text())["decided"]
    assert written == sum(1 for d in decided if d.get("accepted"))
    # The tests written run, and pass, from a fresh planner.
    res = subprocess.run([sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider", str(out)],
                         capture_output=True, text=True, timeout=600, cwd=tmp_path)
    assert res.returncode == 0 and f"{written} passed" in res.stdout, res.stdout + res.stderr


@pytest.fixture(scope="module")
def light_log(tmp_path_factory) -> Path:
    return drive(tmp_path_factory.mktemp("light"), "light")


@pytest.mark.slow
@pytest.mark.promise
def test_resume_goes_on_after_the_outputs_decided_before(light_log, tmp_path):
    out = tmp_path / "tests"
    stop_after = 6

    def stop(done: int, total: int) -> None:  # a Ctrl-C arriving while output 6 is reported
        if done == stop_after:
            raise KeyboardInterrupt

    first = extract_module_tests(light_log, SPEC, out, progress=stop)
    assert first.interrupted and len(first.extraction.frames) == stop_after - 1
    assert checked_frames(out) == first.accepted and (out / STATE).is_file()

    resumed = extract_module_tests(light_log, SPEC, out, ExtractOptions(resume=True))
    assert not resumed.interrupted and resumed.resumed == stop_after - 1
    ex = resumed.extraction
    assert ex.accepted_at(0.0) == ex.outputs and not ex.skipped  # every output, as in one go
    assert [f.inputs for f in ex.frames[:stop_after - 1]] == [f.inputs for f in first.extraction.frames]
    assert checked_frames(out) == ex.outputs and not (out / STATE).exists()


def test_resume_without_an_interrupted_extraction_is_a_clear_error(light_log, tmp_path):
    res = subprocess.run(cli("extract", str(light_log), "--spec", str(SPEC), "-o", str(tmp_path / "none"),
                             "--resume"), capture_output=True, text=True, timeout=120)
    assert res.returncode == 2, res.stdout + res.stderr
    assert "no interrupted extraction to resume here" in res.stderr and "drop --resume" in res.stderr
    assert "Traceback" not in res.stderr
