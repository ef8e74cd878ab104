"""The semantic zoo at module level (tests/sut/semantic_zoo.yaml): three of its modules replayed alone from a
real recorded run, each with one seeded defect — the tracker's reachable only by a message fault (a
duplicate), the range monitor's an invariant the spec states (a standing ego), the headway monitor's a crash
(an empty path) — and a real campaign that finds each at module level, confirms it live on the whole stack,
one bucket each, blamed on its module; the consumer, which has no replay, is fuzzed live."""

from __future__ import annotations

import math
from pathlib import Path

import pytest

from astaa_deft.analysis.deft.module_search import FindingKind, ModuleBench
from astaa_deft.analysis.deft.planner_section import replay_module_of
from astaa_deft.analysis.deft.stream_faults import FaultKind, StreamFault
from astaa_deft.engine.spec.loader import load_spec
from astaa_deft.io.log.reader import read_log
from astaa_deft.orchestration.campaign.campaign import Campaign, CampaignConfig
from astaa_deft.orchestration.campaign.module_level import read_state, replayed_entries, status_lines
from astaa_deft.orchestration.journal.journal import Journal

SPEC = Path(__file__).parent / "sut" / "semantic_zoo.yaml"
PARAMS = {"seconds": "3"}
# Each replayed module's seeded defect: the fault that reaches it and the finding it makes.
DEFECTS = {
    "tracker": (StreamFault(channel="state", kind=FaultKind.DUPLICATE, index=30),
                FindingKind.CRASH, "crash ZeroDivisionError in zoo_tracker.py:estimate"),
    "range": (StreamFault(channel="state", kind=FaultKind.SET, index=30, path="speed", value=0.0),
              FindingKind.INVARIANT, "invariant finite_ttc"),
    "headway": (StreamFault(channel="state", kind=FaultKind.SET, index=30, path="path", value=[]),
                FindingKind.CRASH, "crash IndexError in zoo_headway.py:step"),
}


@pytest.fixture(scope="module")
def recorded(tmp_path_factory):
    from astaa_deft.cli.commands.proxy import run_bus
    from astaa_deft.engine.session import RunOptions

    spec = load_spec(SPEC)
    path = tmp_path_factory.mktemp("semantic-zoo") / "clean.mcap"
    run_bus(spec, RunOptions(mode="passive", record=path, params=PARAMS), 20.0, verbose=False)
    return spec, read_log(path)


def test_the_three_answering_modules_are_replayed_and_the_consumer_is_not():
    entries, skipped = replayed_entries(load_spec(SPEC))
    assert [e.module for e in entries] == ["tracker", "range", "headway"] and skipped == []


@pytest.mark.parametrize("module", DEFECTS)
def test_each_replayed_module_s_defect_is_found_by_its_fault_and_by_nothing_else_of_the_kind(recorded, module):
    spec, log = recorded
    fault, kind, signature = DEFECTS[module]
    bench = ModuleBench(spec, replay_module_of(spec, module), log, PARAMS)
    assert bench.error is None and len(bench.frames) > 30 and not bench.known
    found = bench.run(fault)
    assert found.kind == kind and found.signature == signature, found.detail
    others = {name: bench.run(other) for name, (other, _, _) in DEFECTS.items() if name != module}
    assert not any(v.failed for v in others.values()), {n: v.detail for n, v in others.items()}
    # the message faults that are not a duplicate, and a stale odometer, leave every module alone
    for quiet in (StreamFault(channel="state", kind=FaultKind.REORDER, index=30),
                  StreamFault(channel="state", kind=FaultKind.DELAY, index=30, delay_ms=200.0),
                  StreamFault(channel="state", kind=FaultKind.DROP, index=30),
                  StreamFault(channel="state", kind=FaultKind.SET, index=30, path="speed", value=math.nan)):
        assert not bench.run(quiet).failed, quiet.describe()


@pytest.mark.parametrize("module", DEFECTS)
def test_with_the_defects_off_the_same_faults_find_nothing(recorded, module):
    spec, log = recorded
    bench = ModuleBench(spec, replay_module_of(spec, module), log, {**PARAMS, "defects": "0"})
    assert [bench.run(fault).failed for fault, _, _ in DEFECTS.values()] == [False, False, False]


def test_a_campaign_finds_confirms_and_blames_each_replayed_module_s_defect(tmp_path):
    out = tmp_path / "campaign"
    out.mkdir()
    config = CampaignConfig(spec_path=SPEC, out=out, cases=1, params={"seconds": ["3"]}, reruns=1, minimise=False,
                            module_level_seconds=20.0, report=False, module_level=True)
    journal = Journal(out)
    try:
        Campaign(config, journal, say=lambda line: None).run()
    finally:
        journal.close()
    state = read_state(out)
    assert state is not None and state.modules == ("tracker", "range", "headway")
    found = {(f.verdict.module, f.verdict.signature) for f in state.findings}
    assert found == {(module, signature) for module, (_, _, signature) in DEFECTS.items()}, found  # one each
    tracker = next(f for f in state.findings if f.verdict.module == "tracker")
    assert tracker.verdict.fault.kind == FaultKind.DUPLICATE  # reachable only so
    assert all(f.tests_fail for f in state.findings), [(f.name, f.tests_fail) for f in state.findings]
    journal = Journal(out)
    try:
        lines = status_lines(out, journal)
        module_of = {journal.planned(f.case_id).bucket: f.verdict.module for f in state.findings if f.case_id}
        blames = journal.blames()
    finally:
        journal.close()
    assert sum("confirmed live" in line for line in lines) == 3, lines  # each confirmed on the whole stack
    assert len(module_of) == 3 and {b: blames[b].module for b in module_of} == module_of  # blamed on its module
