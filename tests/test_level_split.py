"""The budget's split between the module-level search and the live hunt, from what each level measured (pure),
and a real budgeted campaign on tests/sut/modlevel.yaml that decides it and says why."""

from __future__ import annotations

from pathlib import Path

import pytest

from astaa_deft.orchestration.campaign.level_split import MAX_SHARE, MIN_SHARE, LevelMeasure, decide_split

SPEC = Path(__file__).parent / "sut" / "modlevel.yaml"


def test_the_same_measurements_give_the_same_split():
    module, live = LevelMeasure(cases=300, cost=0.01, findings=2), LevelMeasure(cases=0, cost=20.0, findings=0)
    assert decide_split(module=module, live=live, budget=600) == decide_split(module=module, live=live, budget=600)


def test_a_cheap_level_that_finds_gets_the_most_the_live_hunt_leaves():
    split = decide_split(module=LevelMeasure(cases=300, cost=0.01, findings=3),
                         live=LevelMeasure(cases=0, cost=20.0, findings=0), budget=600)
    assert split.share == MAX_SHARE and split.seconds == 300.0
    assert "at most half" in split.why and "3 in 300 case(s)" in split.why


def test_a_search_that_found_nothing_in_many_costly_cases_gets_the_least():
    split = decide_split(module=LevelMeasure(cases=5000, cost=1.0, findings=0),
                         live=LevelMeasure(cases=10, cost=2.0, findings=4), budget=1000)
    assert split.share == MIN_SHARE and split.seconds == pytest.approx(50.0)


def test_in_between_the_share_is_the_module_levels_part_of_the_two_worths():
    module, live = LevelMeasure(cases=98, cost=1.0, findings=0), LevelMeasure(cases=8, cost=1.0, findings=0)
    # worths 1/100 and 1/10 finds per core-second: the module level's part is 1/11
    split = decide_split(module=module, live=live, budget=1100)
    assert split.share == pytest.approx(1 / 11) and MIN_SHARE < split.share < MAX_SHARE
    assert split.seconds == pytest.approx(100.0)


def test_more_findings_at_the_same_cost_never_lower_the_share():
    live = LevelMeasure(cases=20, cost=5.0, findings=1)
    shares = [decide_split(module=LevelMeasure(cases=400, cost=0.5, findings=f), live=live, budget=100).share
              for f in range(6)]
    assert shares == sorted(shares)


@pytest.mark.slow
@pytest.mark.promise  # a whole --budget 90 campaign: the split's pure rule is judged above in the default run
def test_a_budgeted_campaign_decides_the_split_from_its_first_round_and_says_why(tmp_path: Path):
    from astaa_deft.orchestration.campaign.campaign import Campaign, CampaignConfig
    from astaa_deft.orchestration.journal.journal import Journal
    from astaa_deft.orchestration.campaign.module_level import read_state, status_lines

    out = tmp_path / "campaign"
    out.mkdir()
    said: list[str] = []
    config = CampaignConfig(spec_path=SPEC, out=out, budget=90.0, params={"seconds": ["3"]}, reruns=1,
                            minimise=False, report=False, module_level=True)
    journal = Journal(out)
    try:
        Campaign(config, journal, say=said.append).run()
    finally:
        journal.close()
    state = read_state(out)
    assert state is not None and state.split is not None
    split = state.split
    assert split.module.cases > 0 and split.module.findings > 0 and split.live.cost > 0  # measured, both levels
    assert split == decide_split(module=split.module, live=split.live, budget=90.0)  # the rule, nothing else
    assert any(line.startswith("module level: module level ") and "of the budget" in line for line in said), said
    journal = Journal(out)
    try:
        lines = status_lines(out, journal)
        notes = [n.text for n in journal.notes("module-level") if "of the budget" in n.text]
    finally:
        journal.close()
    assert any(line.startswith("split: module level") for line in lines), lines
    assert notes
