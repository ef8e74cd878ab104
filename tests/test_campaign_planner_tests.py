"""A bucket the planner caused gets DeFT module tests of the planner, runnable by plain pytest.

A real recording of the demo stack through the star with the planner fed a
NaN speed limit (seeded defect 1), then the campaign's own step that writes
the tests; pytest runs them in a child process without the log: the frames
replay exactly, and the suite's invariant oracle fails while the planner
still breaks the bucket's invariant.
"""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

from astaa_deft.orchestration.campaign.campaign import REPLAY_TESTS_SUFFIX, Campaign, CampaignConfig
from astaa_deft.orchestration.journal.journal import Bucket, Journal
from astaa_deft.orchestration.campaign.runner import CaseLimits, run_case
from astaa_deft.cli.commands.demo import demo_spec_path
from astaa_deft.engine.intercept.dictionary import load_dictionary
from astaa_deft.engine.intercept.testcase import parse_testcase
from astaa_deft.engine.spec.loader import load_spec
from astaa_deft.engine.monitor import check_log
from astaa_deft.io.log.reader import read_log
from stack_timing import unexplained

NAN_LIMIT = b"""<testcase id="nan-limit" seed="1"><description>defect 1</description>
  <policy id="p1"><channel>routing</channel><window from="0.5"><after channel="command" message="1"/></window>
    <set><field path="speed_limit" value="dict:float.nan"/></set></policy>
</testcase>"""


ATTEMPTS = 3  # runs of the case that may end, before the defect is judged, on a deadline the stack missed


def _bucket(name: str, module: str) -> Bucket:
    return Bucket(bucket=name, signature="sig", verdict="Silent", invariant="planned_speed", module=module,
                  family="routing:speed_limit:set", first_case="c-000001", without_mutation=False, cases=1, reruns=0,
                  rerun_failures=0, merged_into=None, created_at=0.0, created_after_cases=1)


def test_a_planner_caused_bucket_gets_deft_module_tests_that_fail_on_it(tmp_path: Path, monkeypatch):
    spec = load_spec(demo_spec_path())
    dictionary = load_dictionary()
    testcase = parse_testcase(NAN_LIMIT, "nan-limit", spec, dictionary)
    for attempt in range(ATTEMPTS):
        outcome = run_case(spec, testcase, {"scenario": "lane_follow", "defects": "on"}, tmp_path / f"case{attempt}",
                           limits=CaseLimits(horizon=8.0), dictionary=dictionary)
        assert outcome.status == "done" and outcome.mutations > 0, outcome
        if any(f.invariant == "planned_speed" for f in outcome.findings):
            break
        # On a loaded machine a module can really miss its deadline before the overspeed plan is judged, and the
        # case ends there: only such a miss, shown by the module's own publish stamps, may stand in for the
        # finding (a true finding of a run that never got to the defect); then the next run tries again.
        log = read_log(Path(outcome.log_path))
        assert unexplained(check_log(log, spec).violations, log, spec) == [], outcome
    assert any(f.invariant == "planned_speed" for f in outcome.findings), outcome  # the overspeed plan was seen
    monkeypatch.chdir(tmp_path)
    out = Path("campaign")  # relative, as `fuzz -o campaign/` gives it
    said: list[str] = []
    journal = Journal(out)
    try:
        campaign = Campaign(CampaignConfig(spec_path=demo_spec_path(), out=out), journal, say=said.append)
        assert campaign._module_to_replay(_bucket("B001", "planning")) == "planning"
        assert campaign._module_to_replay(_bucket("B002", "control")) == "control"  # a replay: entry of the demo's spec
        tests = campaign._replay_tests(_bucket("B001", "planning"), Path(outcome.log_path), "planning")
        checked = journal.module_tests()["B001"]  # the campaign ran them once: they fail on the defect
        assert checked.fails_on_defect is True and "its oracle fails" in checked.detail, checked
    finally:
        journal.close()
    assert tests == out / "tests" / f"B001{REPLAY_TESTS_SUFFIX}" and (tests / "deft.json").is_file()
    assert any("they fail on the defect (its oracle fails" in line for line in said), said
    Path(outcome.log_path).unlink()  # the suite stands on its own
    run = subprocess.run([sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider", str(tests)],
                         capture_output=True, text=True, cwd=tmp_path, timeout=300)
    # the frames replay exactly (they pass); the invariant oracle fails: the replayed plans break planned_speed
    assert run.returncode == 1, run.stdout[-2000:]
    assert " passed" in run.stdout and "1 failed" in run.stdout
    assert "oracle_invariant" in run.stdout and "planned_speed" in run.stdout
