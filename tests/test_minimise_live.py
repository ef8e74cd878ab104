"""Whole-system minimisation of the demo's control defects (2–4): slow, about a minute and a half each.

Each run hides one triggering mutation among 100+ benign ones (the same
noise as tests/test_minimise_demo.py). The failure is in control or in the
closed loop, which no planner replay shows, so every test re-runs the whole
stack through the proxy; the minimal test case must then fail live again.
"""

from __future__ import annotations

import json

import pytest
from test_minimise_demo import NOISE, SPEC_PATH, record

from astaa_deft.analysis.minimise.workflow import MinimiseOptions
from astaa_deft.cli.commands import minimise as command
from astaa_deft.io.log import layout
from astaa_deft.io.log.reader import read_log

CULPRITS = {  # defect → (its policy, the field it sets, the invariant that breaks first)
    2: ("""<policy id="culprit"><channel>localization</channel><consumer>control</consumer><window from="3"/>
         <select limit="1"/><set><field path="heading" value="dict:float.big_1e16"/></set></policy>""",
        "heading", "control_alive"),
    3: ("""<policy id="culprit"><channel>trajectory</channel><window from="3"/><select limit="1"/>
         <set><field path="points" value="dict:array.empty"/></set></policy>""", "points", "modules_alive"),
    4: ("""<policy id="culprit"><channel>localization</channel><consumer>control</consumer><window from="3"/>
         <select limit="1"/><set><field path="header.stamp" value="dict:time.jump_back"/></set></policy>""",
        "header.stamp", "finite_command"),
}


# The culprits anchored to control's first command: the stack is driving when they hit, however long a loaded
# machine takes to start it.
ANCHORED = {
    defect: (policy.replace('<window from="3"/>',
                            '<window from="1"><after channel="command" message="1"/></window>'), field, invariant)
    for defect, (policy, field, invariant) in CULPRITS.items()}


def mutations_recorded(log) -> int:
    """The mutations the recording holds: what its own run made (a loaded machine makes fewer in 7 s)."""
    return len(read_log(log).on(layout.MUTATIONS_TOPIC))


@pytest.mark.slow
@pytest.mark.promise
@pytest.mark.parametrize("defect", sorted(ANCHORED))
def test_live_minimisation_finds_the_culprit_and_it_fails_again_live(defect, tmp_path):
    """Every mutation the recording holds — the culprit among the noise — is minimised to the culprit alone by
    whole-system runs, and that one mutation fails live again."""
    policy, field, invariant = ANCHORED[defect]
    log = record(tmp_path, f"defect{defect}", NOISE + policy, 7.0)
    recorded = mutations_recorded(log)
    assert recorded >= 20, f"only {recorded} mutations recorded: the noise did not run"  # the search has work
    code = command.minimise(log, tmp_path / "out",
                            MinimiseOptions(spec_path=SPEC_PATH, confirm=1, live_only=True))  # control has a replay
    body = json.loads((tmp_path / "out" / "summary.json").read_text())
    assert code == 0, body["verdict"]
    assert body["tester"] == "live" and body["failure"]["invariant"] == invariant
    assert body["mutations"]["before"] == recorded and body["mutations"]["after"] == 1
    [event] = body["culprit_events"]
    assert [f["path"] for f in event["fields"]] == [field]
    assert body["confirmation"]["failures"] == body["confirmation"]["runs"] == 1
    assert (tmp_path / "out" / "minimal.mcap").exists()  # the failing confirmation run's log


# The same defects on the module replay (the spec's replay: section names control): seconds, not minutes.
@pytest.mark.slow
@pytest.mark.parametrize("defect", sorted(ANCHORED))
def test_control_defects_minimise_on_the_module_replay(defect, tmp_path):
    policy, field, invariant = ANCHORED[defect]
    log = record(tmp_path, f"defect{defect}", NOISE + policy, 7.0)
    code = command.minimise(log, tmp_path / "out", MinimiseOptions(spec_path=SPEC_PATH, confirm=1))
    body = json.loads((tmp_path / "out" / "summary.json").read_text())
    assert code == 0, body["verdict"]
    assert body["tester"] == "replay" and body["failure"]["invariant"] == invariant
    assert body["mutations"]["after"] == 1
    [event] = body["culprit_events"]
    assert [f["path"] for f in event["fields"]] == [field]
    assert body["confirmation"]["failures"] == body["confirmation"]["runs"] == 1


@pytest.mark.slow
@pytest.mark.promise
def test_live_tests_run_in_parallel_isolated_sessions(tmp_path):
    """--jobs 2: two whole-system runs at a time, each its own session; the same culprit is found."""
    policy, field, invariant = ANCHORED[4]
    log = record(tmp_path, "defect4", NOISE + policy, 7.0)
    code = command.minimise(log, tmp_path / "out",
                            MinimiseOptions(spec_path=SPEC_PATH, confirm=2, live_only=True, jobs=2))
    body = json.loads((tmp_path / "out" / "summary.json").read_text())
    assert code == 0, body["verdict"]
    assert body["tester"] == "live" and body["failure"]["invariant"] == invariant
    [event] = body["culprit_events"]
    assert [f["path"] for f in event["fields"]] == [field]
    assert body["confirmation"]["failures"] == body["confirmation"]["runs"] == 2
