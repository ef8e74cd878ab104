"""A horizon from the stack: clean runs go to the scenario's end the spec's run: section declares
(capped by its time_limit), and the cases' horizon derives from them. Real runs of tests/sut/scenario.yaml."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

from astaa_deft.engine.spec.loader import load_spec
from astaa_deft.orchestration.campaign.campaign import (
    CLEAN_RUN_CAP, DEFAULT_HORIZON, HORIZON_SLACK, Campaign, CampaignConfig, clean_horizon, derived_horizon,
)
from astaa_deft.orchestration.journal.journal import Journal
from astaa_deft.orchestration.journal.model import CaseOutcome

SUT = Path(__file__).parent / "sut"
SCENARIO = SUT / "scenario.yaml"


def done(seconds: float) -> CaseOutcome:
    return CaseOutcome(status="done", verdict="Pass", summary="Pass", seconds=seconds)


def test_clean_runs_are_bounded_by_the_specs_run_section_and_cases_by_the_clean_runs():
    assert clean_horizon(load_spec(SCENARIO), None) == 90  # run: time_limit
    assert clean_horizon(load_spec(SCENARIO), 7.0) == 7.0  # --horizon, as given
    assert clean_horizon(load_spec(SUT / "steady.yaml"), None) == DEFAULT_HORIZON  # no run: section, no end
    ended = load_spec(SCENARIO)
    from dataclasses import replace

    no_limit = replace(ended, run=replace(ended.run, time_limit=None))
    assert clean_horizon(no_limit, None) == CLEAN_RUN_CAP  # an end without a limit
    assert derived_horizon([done(40.0), done(42.0)], 90.0) == round(42.0 * HORIZON_SLACK, 1)
    assert derived_horizon([done(80.0)], 90.0) == 90.0  # never past the clean runs' own bound
    assert derived_horizon([], 90.0) == 90.0


def test_a_resumed_campaign_derives_its_horizon_again_and_keeps_a_given_one():
    from astaa_deft.orchestration.journal.rows import CampaignMeta

    config = CampaignConfig(spec_path=SCENARIO, out=Path("c"))
    assert config.resuming(CampaignMeta(horizon=14.5, horizon_derived=True)).horizon is None
    assert config.resuming(CampaignMeta(horizon=8.0)).horizon == 8.0  # --horizon 8 then (or an older journal)


def fuzz(out: Path, done_after: int, *extra: str) -> Journal:
    journal = Journal(out)
    Campaign(CampaignConfig(spec_path=SCENARIO, out=out, cases=1, workers=1, baseline_runs=1, reruns=0, minimise=False,
                            report=False, params={"done_after": [str(done_after)]}), journal,
             say=lambda text: None).run()
    return journal


def test_by_default_the_baseline_ends_with_the_scenario_and_the_horizon_derives_from_it(tmp_path: Path):
    journal = fuzz(tmp_path / "c", 30)  # a 3 s scenario
    try:
        baseline = journal.outcome(journal.planned("b-0001"))
        assert baseline is not None and baseline.reason == "scenario over", baseline
        meta = journal.meta()
        assert meta.horizon_derived
        assert meta.horizon == round(baseline.seconds * HORIZON_SLACK, 1)
        notes = [n.text for n in journal.notes() if n.topic == "horizon"]
        assert notes and "longest clean run" in notes[0] and "90 s" in notes[0], notes
    finally:
        journal.close()


@pytest.mark.slow
@pytest.mark.promise
def test_a_40_s_scenario_is_run_to_its_end_by_default_baselines(tmp_path: Path):
    journal = fuzz(tmp_path / "c", 400)  # 400 status messages at 10 Hz: 40 s
    try:
        baseline = journal.outcome(journal.planned("b-0001"))
        assert baseline is not None and baseline.reason == "scenario over", baseline  # not "horizon"
        assert baseline.seconds >= 40.0
        assert journal.meta().horizon >= 40.0
    finally:
        journal.close()


LONG_ROAD = """name: long_road
description: the demo's lane_follow on a longer road, about 40 s to the goal line
road: {lanes: 2, lane_width: 3.5, length: 600}
speed_limit: 13.0
time_limit: 80
ego: {lane: 0, x: 10, speed: 5}
goal: {x: 490, lane: 0}
"""


@pytest.mark.slow
def test_decictor_starts_with_defaults_on_a_stack_whose_scenario_outlasts_the_old_20_s_horizon(tmp_path: Path):
    # With a fixed 20 s horizon the clean baseline never reached the goal of a longer scenario, and
    # `--strategy decictor` stopped at once ("baseline did not reach its goal cleanly — check --horizon").
    from astaa_deft.demo.bundled import demo_spec_path

    scenario = tmp_path / "long_road.yaml"
    scenario.write_text(LONG_ROAD)
    out = tmp_path / "d"
    env = {k: v for k, v in os.environ.items() if k != "PYTHONPATH"} | {"PYTHONPATH": str(Path.cwd())}
    res = subprocess.run([sys.executable, "-m", "astaa_deft.cli", "fuzz", "--spec", str(demo_spec_path()), "-o",
                          str(out), "--strategy", "decictor", "--cases", "1", "--baseline", "1", "--workers", "1",
                          "--no-minimise", "--params", f"scenario={scenario}"],
                         capture_output=True, text=True, timeout=900, env=env)
    assert res.returncode in (0, 1), res.stdout + res.stderr
    assert "did not reach its goal" not in res.stdout + res.stderr
    journal = Journal(out)
    try:
        baseline = journal.outcome(journal.planned("b-0001"))
        assert baseline is not None and baseline.reason == "goal reached", baseline
        assert baseline.seconds > 30.0, baseline  # past the old 20 s horizon
        assert journal.planned("c-000001").finished
    finally:
        journal.close()
