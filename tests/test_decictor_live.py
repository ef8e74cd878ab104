"""Decictor through the real stack: the seed run and a cone-on-the-shoulder case run live through the proxy
(real subprocesses, real Zenoh, real MCAP); the strategy judges them from their logs, the finding becomes a
bucket's DeFT module tests whose path-consistency test fails with the defect and passes without it."""

from __future__ import annotations

from pathlib import Path

import pytest

from astaa_deft.orchestration.journal.journal import Journal, NewBucket
from astaa_deft.orchestration.journal.model import MUTATED, BucketSignature, FailureKey, PlannedCase
from astaa_deft.orchestration.campaign.runner import CaseLimits, run_case
from astaa_deft.orchestration.campaign.strategies.decictor import INVARIANT, DecictorStrategy, scene_testcase
from astaa_deft.cli.commands.demo import demo_spec_path
from astaa_deft.analysis.decictor.module_test import check_suite
from astaa_deft.analysis.decictor.search import Scene
from astaa_deft.model.errors import InputError
from astaa_deft.engine.intercept.actions.participant import Participant
from astaa_deft.engine.intercept.dictionary import load_dictionary
from astaa_deft.engine.intercept.testcase import parse_testcase
from astaa_deft.engine.spec.loader import load_spec, load_spec_text

SPEC_PATH = demo_spec_path()
CONE = Participant(id=901, kind="cone", x=60.0, y=-3.0, heading=0.0, length=0.5, width=0.5)


def test_a_spec_without_lanes_stops_the_strategy_with_a_clear_error():
    text = Path(SPEC_PATH).read_text()
    section = text.index("\ndecictor:")
    start = text.index("\n  lanes:", section)
    end = text.index("\n  ego:", section)
    spec = load_spec_text(text[:start] + text[end:])
    with pytest.raises(InputError) as err:
        DecictorStrategy(spec, load_dictionary(), 0, 15.0)
    assert "no 'lanes': the consistency check needs the ego's lanes" in str(err.value)


@pytest.mark.slow
@pytest.mark.promise
def test_the_cone_case_runs_live_is_judged_and_becomes_a_failing_module_test(tmp_path: Path):
    spec = load_spec(SPEC_PATH)
    strategy = DecictorStrategy(spec, load_dictionary(), 0, 15.0)
    seed = run_case(spec, None, {}, tmp_path / "cases" / "b-0001", limits=CaseLimits(horizon=15.0))
    assert seed.status == "done", seed
    strategy.observe_baseline("b-0001", seed)
    assert strategy.search is not None, strategy.why_no_seed

    proposed = scene_testcase(Scene((CONE,), "add"), "tc-000001", 1, "prediction")
    testcase = parse_testcase(proposed.to_xml(), "tc", spec, load_dictionary())
    mutated = run_case(spec, testcase, {}, tmp_path / "cases" / "c-000001", limits=CaseLimits(horizon=15.0))
    judged = strategy.judge("c-000001", testcase, mutated)
    assert judged.findings and judged.findings[0].invariant == INVARIANT, judged.summary
    assert judged.findings[0].module == "planning" and judged.failed

    journal = Journal(tmp_path)
    journal.plan(PlannedCase(case_id="c-000001", kind=MUTATED, number=1, seed=0, params={}, testcase=testcase,
                             strategy="decictor"))
    journal.started("c-000001")
    signature = BucketSignature(FailureKey(judged.verdict, INVARIANT, "planning"), "prediction:*:participant")
    journal.add_bucket(NewBucket(name="B001", signature=signature, verdict=judged.verdict, invariant=INVARIANT,
                                 module="planning", first_case="c-000001", without_mutation=False, after_cases=1))
    journal.finished("c-000001", judged, signature=signature, bucket="B001")
    said: list[str] = []
    strategy.finish(journal, tmp_path, Path(SPEC_PATH), said.append)
    tests = tmp_path / "tests" / "B001"
    assert (tests / "test_decictor_consistency.py").is_file() and (tmp_path / "decictor.html").is_file()
    problem = check_suite(tests, overrides="")
    assert problem is not None and "worst lane 1" in problem
    assert check_suite(tests, overrides="defects=off") is None
    journal.close()
