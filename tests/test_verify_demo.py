"""verify and export end to end on the demo stack with its seeded defects (slow: a campaign, then live checks).

The demo's spec, with control's seeded defects switched by a param of their own (control_defects) beside the
stack's (defects): a campaign of two test cases — an empty trajectory (defect 3, control crashes) and a NaN
speed limit (defect 1, the planner overspeeds) — files two bugs, minimised. Then, against the stack as it is:
every defect off → every bucket fixed (exit 0); defects on → every confirmed bucket still failing (exit 1);
only control's defects off → exactly control's bucket fixed. The exported suite fails with the defects on and
passes with them off.
"""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

import pytest

from astaa_deft.demo.bundled import demo_spec_path
from astaa_deft.orchestration.journal.journal import open_existing
from test_verify import run_campaign, verify

# Defect 3 (control crashes on an empty trajectory) and defect 1 (a NaN speed limit: the planner overspeeds), each
# acting once the whole stack runs (after control's first command), however long the start-up takes.
EMPTY_POINTS = ('<testcase id="empty" seed="1"><description>defect 3</description><policy id="p1">'
                '<channel>trajectory</channel><window from="0.5"><after channel="command" message="1"/></window>'
                '<select limit="1"/><set><field path="points" value="dict:array.empty"/></set></policy></testcase>')
NAN_LIMIT = ('<testcase id="nan" seed="1"><description>defect 1</description><policy id="p1">'
             '<channel>routing</channel><window from="0.5"><after channel="command" message="1"/></window>'
             '<set><field path="speed_limit" value="dict:float.nan"/></set></policy></testcase>')
CONTROL = '"-m", "astaa_deft.demo.control", "--scenario", "{scenario}", "--defects", "{defects}"]'


def split_spec(tmp_path: Path) -> Path:
    text = demo_spec_path().read_text()
    assert CONTROL in text
    text = text.replace(CONTROL, CONTROL.replace("{defects}", "{control_defects}"))
    text = text.replace('  defects: "on"', '  defects: "on"\n  control_defects: "on"', 1)
    spec = tmp_path / "demo_split.yaml"
    spec.write_text(text)
    return spec


@pytest.mark.slow
@pytest.mark.promise
def test_verify_and_export_on_the_demo_with_its_seeded_defects(tmp_path: Path):
    spec = split_spec(tmp_path)
    out = tmp_path / "campaign"
    run_campaign(out, spec, {}, cases=[EMPTY_POINTS, NAN_LIMIT], horizon=12.0, minimise=True)
    journal = open_existing(out)
    try:
        bugs = {b.bucket: b for b in journal.buckets(include_merged=False) if b.is_bug}
        ran = [(r.case_id, r.verdict, r.summary) for r in journal.cases()]
    finally:
        journal.close()
    by_module = {b.module: name for name, b in bugs.items()}
    assert set(by_module) == {"control", "planning"}, (bugs, ran)
    off = ("--param", "defects=off", "--param", "control_defects=off")

    fixed = verify(str(out), *off, "--runs", "1", "--label", "all-off", spec=spec)
    assert fixed.returncode == 0, fixed.stdout + fixed.stderr
    assert f"{len(bugs)}/{len(bugs)} bucket(s) fixed" in fixed.stdout, fixed.stdout

    failing = verify(str(out), "--runs", "1", "--label", "all-on", spec=spec)
    assert failing.returncode == 1, failing.stdout + failing.stderr
    for name in bugs:
        assert f"{name} still failing: 1/1" in failing.stdout, failing.stdout

    one = verify(str(out), "--param", "control_defects=off", "--runs", "1", "--label", "control-fixed",
                 spec=spec)
    assert one.returncode == 1, one.stdout + one.stderr
    assert f"{by_module['control']} fixed: 0/1" in one.stdout, one.stdout
    assert f"{by_module['planning']} still failing: 1/1" in one.stdout, one.stdout

    regress = tmp_path / "regress"
    done = subprocess.run([sys.executable, "-m", "astaa_deft.cli", "export", str(out), "-o", str(regress),
                           "--spec", str(spec)], capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stdout + done.stderr

    def pytest_regress(*args: str) -> subprocess.CompletedProcess:
        return subprocess.run([sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider", str(regress), *args],
                              capture_output=True, text=True, timeout=600, cwd=tmp_path)

    on = pytest_regress()
    assert on.returncode == 1, on.stdout
    for name in bugs:
        assert re.search(rf"FAILED .*test_{name}_", on.stdout), on.stdout
    clean = pytest_regress(*off)
    assert clean.returncode == 0, clean.stdout
