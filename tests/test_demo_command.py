"""`astaa-deft demo`, the README's first command, as a user runs it: the whole pipeline on the bundled stack
(record, DeFT, ASTAA, minimise, fuzz), each step doing its job, everything under ``--out``."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

STEPS = ["== 1/5 record:", "== 2/5 DeFT:", "== 3/5 ASTAA:", "== 4/5 minimise:", "== 5/5 fuzz:"]


@pytest.mark.slow  # ~1-2 min: five real runs of the stack, an extraction, a minimisation, a short campaign
@pytest.mark.promise
def test_the_demo_command_runs_every_step_and_each_does_its_job(tmp_path: Path):
    out = tmp_path / "astaa-deft-demo"
    res = subprocess.run([sys.executable, "-m", "astaa_deft.cli", "demo", "--out", str(out)], capture_output=True,
                         text=True, cwd=tmp_path, timeout=600)
    text = res.stdout + res.stderr
    assert res.returncode == 0, text[-4000:]
    assert "demo problem" not in text and "Traceback" not in text, text[-4000:]
    assert [line[:line.index(":") + 1] for line in res.stdout.splitlines() if line.startswith("== ")] == STEPS
    assert "verdict: Pass" in res.stdout.split(STEPS[1])[0]  # the clean drive
    for made in ("clean.mcap", "planner-tests/deft.json", "intercepted.mcap", "minimised/summary.json",
                 "campaign/journal.sqlite", "campaign/report.html"):
        assert (out / made).is_file(), made
