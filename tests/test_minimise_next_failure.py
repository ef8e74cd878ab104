"""Which failure `astaa-deft minimise` keeps when the run's first one happens without any of the mutations.

One run of tests/sut/ramp_limit.yaml is recorded through the star proxy
with benign mutations (debug fields no module reads, a few speeds set to the
target) and one culprit: a NaN speed in the first state 1 s after the
first (the twentieth or so, however late a loaded machine starts the
source). The controller breaks 'u_limit' by itself by its tenth answer —
with or without mutations — and 'finite_u' only because of the NaN. Minimising the
run's first violation alone would stop at "nothing to minimise"; minimise
goes on to the next failure and finds the culprit. Both invariants are
judged on the controller's module replay: no whole-system re-run.
"""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import pytest

from astaa_deft.analysis.minimise.workflow import MinimiseOptions, minimise_log
from astaa_deft.cli.commands import minimise as command
from astaa_deft.engine.intercept import load_interceptor
from astaa_deft.engine.monitor import check_log, with_typed_invariants
from astaa_deft.engine.session import RunOptions, run_session
from astaa_deft.engine.spec.loader import load_spec
from astaa_deft.io.log import layout
from astaa_deft.io.log.reader import read_log

SUT = Path(__file__).parent / "sut"
SPEC_PATH = SUT / "ramp_limit.yaml"
SPEC = load_spec(SPEC_PATH)

POLICIES = """
  <policy id="note"><channel>state</channel><select every="3"/><set><field path="debug.note" value="x"/></set></policy>
  <policy id="score"><channel>state</channel><select every="4"/>
    <set><field path="debug.score" value="1.5"/></set></policy>
  <policy id="calm"><channel>state</channel><window from="0.5"/><select every="7" limit="4"/>
    <set><field path="v" value="10.0"/></set></policy>
  <policy id="culprit"><channel>state</channel><window from="1"><after channel="state" message="1"/></window>
    <select limit="1"/>
    <set><field path="v" value="dict:float.nan"/></set></policy>
"""


@pytest.fixture(scope="module")
def run(tmp_path_factory) -> Path:
    directory = tmp_path_factory.mktemp("ramp")
    policy = directory / "ramp.xml"
    policy.write_text(f'<?xml version="1.0" encoding="UTF-8"?>\n<testcase id="ramp" seed="1">'
                      f"<description>test</description>{POLICIES}</testcase>\n")
    log = directory / "ramp.mcap"
    run_session(SPEC, RunOptions(mode="star", interceptor=load_interceptor(policy, SPEC), record=log,
                                 run_dir=directory / "run", attachments={layout.POLICY_ATTACHMENT: policy},
                                 time_limit=20))
    return log


def test_the_run_breaks_the_limit_first_and_finite_u_after_the_culprit(run):
    log = read_log(run)
    firsts: dict[str, int] = {}
    for v in sorted(check_log(log, with_typed_invariants(SPEC)).violations, key=lambda v: v.time_ns):
        firsts.setdefault(v.invariant, v.time_ns)
    assert list(firsts) == ["u_limit", "finite_u"]
    assert sum(1 for _ in log.on(layout.MUTATIONS_TOPIC)) > 10


def test_minimise_goes_on_to_the_next_failure_and_finds_the_culprit(run, tmp_path):
    lines: list[str] = []
    report = minimise_log(run, tmp_path / "out", MinimiseOptions(spec_path=SPEC_PATH, confirm=0),
                          progress=lines.append)
    assert report.reproduced and report.complete, report.verdict
    body = report.summary
    assert body["failure"]["invariant"] == "finite_u"
    assert body["tester"] == "replay"
    assert body["mutations"]["after"] == 1 and body["mutations"]["before"] > 10
    [event] = body["culprit_events"]
    assert [f["path"] for f in event["fields"]] == ["v"] and event["fields"][0]["new"] == {"float": "nan"}
    [note] = [n for n in body["notes"] if "u_limit" in n]
    assert "u_limit at +" in note and "happens without any of the mutations: minimising the run's next " \
                                       "failure, finite_u" in note
    assert any(line.startswith("note: u_limit") for line in lines)
    assert json.loads((tmp_path / "out" / "summary.json").read_text()) == body


def test_a_named_invariant_that_needs_no_mutation_stops_there(run, tmp_path, capsys):
    code = command.minimise(run, tmp_path / "out", MinimiseOptions(spec_path=SPEC_PATH, invariant="u_limit",
                                                                   confirm=0), verbose=False)
    assert code == 1
    body = json.loads((tmp_path / "out" / "summary.json").read_text())
    assert body["failure"]["invariant"] == "u_limit"
    assert "happens without any of the mutations" in body["verdict"] and "finite_u" not in body["verdict"]
    assert "nothing to minimise" in capsys.readouterr().out


@pytest.mark.parametrize("live_only", [False, True], ids=["replay", "live"])
def test_when_every_failure_tried_needs_no_mutation_the_report_is_the_first_ones(run, tmp_path, live_only):
    # The same stack, its NaN check swapped for a bound its own answers break too (u stays below 0); live,
    # each failure costs its reproduction run and the run with no mutation.
    stack = tmp_path / "stack"
    stack.mkdir()
    for script in ("modlevel_ctrl.py", "modlevel_source.py", "node_loop.py"):
        shutil.copy(SUT / script, stack / script)
    spec = stack / "ramp_limit.yaml"
    spec.write_text(SPEC_PATH.read_text().replace("field: u, finite: true}", "field: u, min: 0.0}").replace(
        "{name: finite_u,", "{name: u_positive,"))
    report = minimise_log(run, tmp_path / "out", MinimiseOptions(spec_path=spec, confirm=0, live_only=live_only))
    assert not report.reproduced and not report.complete
    assert report.summary["failure"]["invariant"] in {"u_limit", "u_positive"}
    other = ({"u_limit", "u_positive"} - {report.summary["failure"]["invariant"]}).pop()
    assert report.verdict.startswith("the failure happens without any of the mutations")
    assert f"so do the run's next failures tried: {other} at +" in report.verdict
