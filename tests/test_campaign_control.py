"""What a campaign blames, and on how many runs at once: real runs of a small SUT (tests/sut/steady.yaml).

* a case that applied no mutation is a clean run: its failure is a baseline finding, never a mutation's;
* a failure is a bug only once a re-run reproduces it and its unmutated twin does not fail that way;
* an invariant every clean run breaks is a known baseline finding: it neither shortens the live time nor
  ends a case, and counts in a case only where the case makes it worse;
* the runs at once come from what one run costs: fewer for a module that burns a core;
* the baseline runs every value of the params grid.
"""

from __future__ import annotations

from pathlib import Path

import pytest

from astaa_deft.orchestration.campaign import known as known_mod
from astaa_deft.orchestration.campaign.calibration import run_share, workers_for
from astaa_deft.orchestration.campaign.campaign import Campaign, CampaignConfig
from astaa_deft.orchestration.journal.journal import Journal
from astaa_deft.orchestration.journal.model import CaseOutcome, ChannelRate, Finding
from astaa_deft.orchestration.campaign.runner import CaseLimits, run_case
from astaa_deft.engine.intercept.testcase import parse_testcase
from astaa_deft.orchestration.campaign.strategies.base import Proposal, Strategy
from astaa_deft.engine.spec.loader import load_spec

SUT = Path(__file__).parent / "sut"
STEADY = SUT / "steady.yaml"
KNOWN = SUT / "known.yaml"


def xml_of(policy: str) -> str:
    return f'<testcase id="t" seed="1"><description>x</description>{policy}</testcase>'


# One mutation of 'aux' (nobody judges it) 0.2 s into the live run; a window that never opens (no mutation);
# a dropped 'aux' message (another mutation family).
SET_AUX = ('<policy id="p1"><channel>aux</channel><window from="0.2" to="30"><after channel="aux" message="1"/>'
           '</window><select limit="1"/><set><field path="value" value="dict:float.nan"/></set></policy>')
NEVER = ('<policy id="p1"><channel>aux</channel><window from="0.2" to="30"><after channel="aux" message="1000000"/>'
         '</window><select limit="1"/><set><field path="value" value="dict:float.nan"/></set></policy>')
DROP_AUX = ('<policy id="p1"><channel>aux</channel><window from="0.2" to="30"><after channel="aux" message="1"/>'
            '</window><select limit="1"/><drop/></policy>')


class Fixed(Strategy):
    """A strategy that proposes the given test cases in order (the campaign's interface, nothing mocked)."""

    name = "fixed"

    def __init__(self, cases: list[str]):
        self.cases = cases

    def propose(self, number: int) -> Proposal:
        return Proposal(parse_testcase(xml_of(self.cases[number - 1]).encode()))  # the campaign holds an object

    def observe(self, case_id: str, testcase_xml: str | None, outcome: CaseOutcome) -> None:
        pass


def campaign(out: Path, spec: Path, cases: list[str], *, workers: int | None = 1, minimise: bool = False,
             horizon: float = 4.0, **config) -> Journal:
    journal = Journal(out)
    run = Campaign(CampaignConfig(spec_path=spec, out=out, cases=len(cases), workers=workers, horizon=horizon,
                                  settle=2.0, minimise=minimise, report=False, **config), journal,
                   say=lambda text: None)
    run.strategy = Fixed(cases)  # type: ignore[assignment]
    run.run()
    return journal


def launches(tmp_path: Path, failing: str) -> dict[str, list[str]]:
    counter = tmp_path / "launches"
    counter.mkdir()
    return {"counter_dir": [str(counter)], "fail_launches": [failing]}


def test_a_case_that_applied_no_mutation_is_never_filed_in_a_mutation_bucket(tmp_path: Path):
    # One run at a time: launch 1 is the baseline (passes), launch 2 the case, whose window never opens.
    journal = campaign(tmp_path / "c", STEADY, [NEVER], params=launches(tmp_path, "2"), baseline_runs=1)
    try:
        case = journal.case("c-000001")
        outcome = journal.outcome(case)
        assert outcome is not None and outcome.failed and outcome.mutations == 0, outcome
        [bucket] = journal.buckets()
        assert bucket.kind == "baseline" and bucket.without_mutation and bucket.family == "(no mutation)"
        assert case.bucket == bucket.bucket
        assert not [r for r in journal.cases() if r.kind in ("rerun", "control")]  # nothing to confirm
    finally:
        journal.close()


def test_a_failure_its_unmutated_twin_shows_too_is_flaky_not_a_bug(tmp_path: Path):
    # One run at a time. Launches: 1 baseline (passes); 2 case 1 (fails), 3 its re-run (fails), 4 its twin
    # (fails): flaky. From then on the worker's crash is a known baseline finding: case 2 (launch 5) fails the
    # same way, no earlier, so it is not blamed on its mutation either.
    journal = campaign(tmp_path / "c", STEADY, [SET_AUX, DROP_AUX], params=launches(tmp_path, "2,3,4,5"),
                       baseline_runs=1, reruns=1)
    try:
        order = [r.case_id for r in sorted(journal.cases(), key=lambda r: r.started_at)]
        assert order == ["b-0001", "c-000001", "r-B001-1", "t-B001-1", "c-000002"]
        [bucket] = journal.buckets()
        assert bucket.family == "aux:value:set"
        assert (bucket.kind, bucket.rerun_failures, bucket.reruns, bucket.control_failures, bucket.controls) == \
            ("flaky", 1, 1, 1, 1)
        twin = journal.case("t-B001-1")
        assert twin.testcase_xml is None and twin.params == journal.case("c-000001").params
        second = journal.outcome(journal.case("c-000002"))
        assert second is not None and second.mutations == 1 and second.verdict == "Pass", second
        assert "known baseline finding" in second.summary
    finally:
        journal.close()


def test_a_failure_that_reproduces_while_its_twin_passes_is_a_bug(tmp_path: Path):
    # Launches: 1 baseline (passes); 2 the case (fails), 3 its re-run (fails), 4 its twin (passes).
    journal = campaign(tmp_path / "c", STEADY, [SET_AUX], params=launches(tmp_path, "2,3"), baseline_runs=1,
                       reruns=1)
    try:
        [bucket] = journal.buckets()
        assert (bucket.kind, bucket.rerun_failures, bucket.reruns, bucket.control_failures, bucket.controls) == \
            ("bug", 1, 1, 0, 1)
        assert bucket.family == "aux:value:set" and bucket.invariant == "(module exit)"
    finally:
        journal.close()


def test_a_baseline_finding_neither_shrinks_the_live_time_nor_ends_cases(tmp_path: Path):
    # Every clean run breaks data_small within a second; the stack runs on to the 4 s horizon.
    journal = campaign(tmp_path / "c", KNOWN, [SET_AUX], baseline_runs=1, workers=1)
    try:
        baseline = journal.outcome(journal.case("b-0001"))
        assert baseline is not None and baseline.reason == "horizon"  # not ended at its violation
        assert [f.invariant for f in baseline.findings] == ["data_small"]
        timing = journal.meta().timing
        # to the scenario's end, not to the first violation (~0.5 s)
        assert timing is not None and timing.live >= 2.0, timing
        case = journal.outcome(journal.case("c-000001"))
        assert case is not None and case.mutations == 1 and case.reason == "settled", case  # not "violation"
        assert case.verdict == "Pass" and "known baseline finding" in case.summary, case
        [bucket] = journal.buckets()
        assert bucket.kind == "baseline" and bucket.invariant == "data_small"
    finally:
        journal.close()


def test_a_known_baseline_finding_counts_only_where_a_case_makes_it_worse():
    clean = [CaseOutcome(status="done", verdict="Silent", summary="",
        findings=[Finding(invariant="data_small", crash="Silent", module="talker", channel="data", detail="", at=2.0)],
        violating={"data_small": 10})]
    known = known_mod.known_findings(clean)
    same = CaseOutcome(status="done", verdict="Silent", summary="s",
        findings=[Finding(invariant="data_small", crash="Silent", module="talker", channel="data", detail="", at=2.2)],
        violating={"data_small": 8})
    earlier = CaseOutcome(status="done", verdict="Silent", summary="s",
        findings=[Finding(invariant="data_small", crash="Silent", module="talker", channel="data", detail="", at=0.4)])
    oftener = CaseOutcome(status="done", verdict="Silent", summary="s",
        findings=[Finding(invariant="data_small", crash="Silent", module="talker", channel="data", detail="",
                          at=2.1)] * 2)
    assert known_mod.judged(same, known).verdict == "Pass"
    assert known_mod.judged(earlier, known).verdict == "Silent"
    assert known_mod.judged(oftener, known).verdict == "Silent"


def test_calibration_picks_fewer_runs_at_once_for_a_module_that_burns_a_core(tmp_path: Path):
    spec = load_spec(STEADY)
    shares = {}
    for burn in ("0", "1"):
        outcome = run_case(spec, None, {"burn": burn}, tmp_path / f"burn{burn}", limits=CaseLimits(horizon=3.0))
        assert outcome.status == "done" and outcome.cpu > 0 and outcome.rss_mb > 0, outcome
        shares[burn] = run_share([outcome])
    assert shares["1"] is not None and shares["0"] is not None
    # A busy loop wants a core of its own; on a loaded machine it gets less of one, but clearly more than a
    # module that sleeps.
    assert shares["1"].cores > shares["0"].cores + 0.1, shares
    workers = {burn: workers_for(share, cores=2, memory_mb=None) for burn, share in shares.items() if share}
    assert workers["0"] > workers["1"], (workers, shares)


def test_the_baseline_runs_every_param_value_and_calibrates_the_runs_at_once(tmp_path: Path):
    # what is asserted (every value run, the runs at once calibrated) does not depend on the live time
    journal = campaign(tmp_path / "c", STEADY, [], workers=None, params={"rate": ["20", "50", "100"]},
                       baseline_runs=1, horizon=2.0)
    try:
        rows = journal.cases("baseline")
        values = [r.params["rate"] for r in rows]
        assert set(values) == {"20", "50", "100"} and values[:3] == ["20", "50", "100"]
        assert all(r.at_once is not None for r in rows)
        meta = journal.meta()
        assert meta.calibrated and meta.workers is not None and meta.workers >= 1
        notes = [n.text for n in journal.notes("concurrency")]
        assert notes and "one run takes" in notes[0], notes
    finally:
        journal.close()


@pytest.mark.slow  # a live minimisation beside eight cases: ~90 s on a loaded machine
@pytest.mark.promise
def test_a_confirmed_bucket_is_minimised_while_the_hunt_goes_on(tmp_path: Path):
    # The worker crashes on a NaN 'aux' value: a bug the case's mutation causes (its twin passes). Two runs at
    # once: the minimisation takes one slot as soon as the bucket is confirmed, cases go on in the other.
    cases = [SET_AUX] + [DROP_AUX] * 7
    journal = campaign(tmp_path / "c", STEADY, cases, workers=2, params={"crash_on_nan": ["1"]}, baseline_runs=1,
                       reruns=1, minimise=True)
    try:
        bug = next(b for b in journal.buckets() if b.family == "aux:value:set")
        assert bug.kind == "bug" and (bug.rerun_failures, bug.control_failures) == (1, 0)
        row = journal.minimisations()[bug.bucket]
        assert row.status in ("minimised", "not reproduced"), row
        later = [r for r in journal.cases("mutated") if r.started_at > row.started_at]
        assert later, "no case started after the minimisation: it did not run alongside the hunt"
        assert row.status == "minimised" and "aux:value" in (row.culprit or ""), row
    finally:
        journal.close()


@pytest.mark.slow  # a live minimisation and eight cases one at a time: ~2 min
@pytest.mark.promise
def test_a_minimisation_holding_the_only_slot_pauses_the_hunt_and_does_not_end_it(tmp_path: Path):
    # One run at once (a heavy stack): the confirmed bucket's minimisation takes the only slot. The campaign
    # waited for nothing then and ended "done" with most of its cases never run.
    cases = [SET_AUX] + [DROP_AUX] * 7
    journal = campaign(tmp_path / "c", STEADY, cases, workers=1, params={"crash_on_nan": ["1"]}, baseline_runs=1,
                       reruns=1, minimise=True)
    try:
        bug = next(b for b in journal.buckets() if b.family == "aux:value:set")
        row = journal.minimisations()[bug.bucket]
        mutated = journal.cases("mutated")
        assert len(mutated) == len(cases) and all(r.status in ("done", "error") for r in mutated), \
            [(r.case_id, r.status) for r in mutated]
        assert [r for r in mutated if r.started_at > row.started_at], "the hunt did not go on after it"
    finally:
        journal.close()


def test_timing_drift_at_concurrency_means_fewer_runs_at_once():
    from astaa_deft.orchestration.campaign.calibration import RunShare, drift, fewer_after_drift, overloaded

    def timed(gap: float, rate: float) -> CaseOutcome:
        return CaseOutcome(status="done", verdict="Pass", summary="",
                           timing={"plan": ChannelRate(count=40, rate=rate, max_gap=gap)})

    solo = timed(0.6, 2.0)
    assert not drift(solo, timed(0.7, 1.9)).drifted  # jitter
    slow = drift(solo, timed(2.7, 0.5))  # planning cycles 0.3-0.6 s -> 2.5-2.8 s: the heavy stack overloaded
    assert slow.drifted and slow.channel == "plan" and slow.ratio >= 4
    assert fewer_after_drift(6, slow) == 1 and fewer_after_drift(4, drift(solo, timed(3.0, 2.0))) == 2
    # a machine in full use swings above its cores; only a clear overload backs off without the twins' timing
    assert not overloaded(2.4, cores=2) and overloaded(3.2, cores=2)
    # the cores other work takes are not there for the runs
    share = RunShare(cores=0.3, rss_mb=300.0, runs=1)
    assert workers_for(share, cores=2, memory_mb=None) == 5
    assert workers_for(share, cores=2, memory_mb=None, other_load=1.5) == 1
    assert workers_for(share, cores=2, memory_mb=600.0) == 1  # memory: half of what is available
