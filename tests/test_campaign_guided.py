"""The guided strategy steers only by evidence: a case clearly closer to breaking an invariant than the
clean baseline runs. Without any, it proposes the random strategy's cases in the same order (so it is
never slower than random on a defect only the first visit of a value finds); a resumed search goes on
with its schedule where it was."""

from __future__ import annotations

from dataclasses import replace

import pytest

from astaa_deft.orchestration.journal.model import MUTATED, CaseOutcome, PlannedCase
from astaa_deft.orchestration.campaign.strategies import STRATEGIES
from astaa_deft.demo.bundled import demo_spec_path
from astaa_deft.engine.intercept.dictionary import load_dictionary
from astaa_deft.engine.intercept.testcase import TestCase
from astaa_deft.engine.spec.loader import load_spec

BASELINE = CaseOutcome(status="done", verdict="Pass", summary="", margins={"planned_speed": 2.0, "finite_command": 0.5})


@pytest.fixture(scope="module")
def demo():
    return load_spec(demo_spec_path()), load_dictionary(())


def _body(testcase: TestCase) -> TestCase:
    """A test case without its id (guided numbers its cases itself)."""
    return replace(testcase, id="-")


def test_without_evidence_guided_proposes_the_random_cases_in_order(demo):
    spec, dictionary = demo
    guided = STRATEGIES["guided"](spec, dictionary, 5, 20.0)
    random = STRATEGIES["random"](spec, dictionary, 5, 20.0)
    guided.observe_baseline("b-0001", BASELINE)
    for n in range(1, 31):
        proposal = guided.propose(n)
        assert proposal.parent is None
        assert _body(proposal.testcase) == _body(random.propose(n).testcase)
        # Jitter of a clean stack, a few % closer than the baseline: no evidence of anything.
        guided.observe(f"c-{n}", proposal.testcase,
            CaseOutcome(status="done", verdict="Pass", summary="",
                        margins={"planned_speed": 1.9, "finite_command": 0.48}))
    assert guided.corpus == []


def test_a_case_clearly_closer_than_the_baseline_is_steered_by(demo):
    spec, dictionary = demo
    guided = STRATEGIES["guided"](spec, dictionary, 5, 20.0)
    guided.observe_baseline("b-0001", BASELINE)
    first = guided.propose(1)
    guided.observe("c-1", first.testcase,
                   CaseOutcome(status="done", verdict="Pass", summary="", margins={"planned_speed": 0.8}))
    assert [case for case, _ in guided.corpus] == ["c-1"]
    parents = [guided.propose(n).parent for n in range(2, 22)]
    assert "c-1" in parents and None in parents  # half steered, half the schedule


def test_a_resumed_guided_search_goes_on_with_its_schedule(demo):
    spec, dictionary = demo
    first = STRATEGIES["guided"](spec, dictionary, 5, 20.0)
    first.observe_baseline("b-0001", BASELINE)
    planned = []
    for n in range(1, 11):
        proposal = first.propose(n)
        planned.append((f"c-{n:06d}", proposal.testcase, proposal.parent))
        if n == 3:  # evidence: the corpus holds c-3 from here on
            first.observe("c-000003", proposal.testcase,
                          CaseOutcome(status="done", verdict="Pass", summary="", margins={"planned_speed": 0.5}))
    resumed = STRATEGIES["guided"](spec, dictionary, 5, 20.0)
    resumed.observe_baseline("b-0001", BASELINE)
    resumed.resume([PlannedCase(case_id=case_id, kind=MUTATED, number=n, seed=5, params={}, testcase=xml,
                                strategy="guided", parent=parent)
                    for n, (case_id, xml, parent) in enumerate(planned, start=1)])
    resumed.observe("c-000003", planned[2][1],
                    CaseOutcome(status="done", verdict="Pass", summary="", margins={"planned_speed": 0.5}))
    already = {_body(xml) for _, xml, parent in planned if parent is None}
    fresh = [p for p in (resumed.propose(n) for n in range(11, 31)) if p.parent is None]
    assert fresh and not any(_body(p.testcase) in already for p in fresh)
    continuing = STRATEGIES["random"](spec, dictionary, 5, 20.0)
    next_index = sum(1 for _, _, parent in planned if parent is None) + 1
    assert _body(fresh[0].testcase) == _body(continuing.propose(next_index).testcase)
