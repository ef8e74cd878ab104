"""The campaign's module-level search: faults on a module's input streams as the wire delivers them, a real
module replayed under them from a real recorded run and judged like a live run, fields nothing reads, and a
real campaign on tests/sut/modlevel.yaml whose module-level findings are confirmed live."""

from __future__ import annotations

import json
import math
import re
import sqlite3
from pathlib import Path

import pytest

from astaa_deft.analysis.deft.fault_plan import plan_faults
from astaa_deft.analysis.deft.module_search import FindingKind, ModuleBench
from astaa_deft.analysis.deft.planner_section import replay_module_of
from astaa_deft.analysis.deft.stream_faults import (
    FaultKind, FaultNotApplicable, FieldReads, StreamFault, apply_fault, field_family, fields_nothing_reads,
    recorded_streams, smaller_faults, trigger_frames,
)
from astaa_deft.engine.intercept import generate as gen
from astaa_deft.engine.intercept.dictionary import load_dictionary
from astaa_deft.engine.spec.loader import load_spec
from astaa_deft.io.log.reader import read_log
from astaa_deft.io.statefile import StateReader
from astaa_deft.orchestration.campaign.campaign import Campaign, CampaignConfig
from astaa_deft.orchestration.journal.journal import Journal
from astaa_deft.orchestration.campaign.report import render
from astaa_deft.orchestration.campaign.module_level import read_state, replayed_entries, status_lines

SPEC = Path(__file__).parent / "sut" / "modlevel.yaml"
MS = 1_000_000


def _streams(n: int = 5):
    return recorded_streams({"a": [(i * 100 * MS, {"stamp": i, "v": float(i)}) for i in range(n)],
                             "b": [(i * 100 * MS + 50 * MS, {"w": i}) for i in range(n)]})


# -- faults on streams (pure) -----------------------------------------------------------------------------

def test_drop_takes_the_message_away():
    out = apply_fault(_streams(), StreamFault(channel="a", kind=FaultKind.DROP, index=2))
    assert [r.message["stamp"] for r in out["a"]] == [0, 1, 3, 4]


def test_delay_lets_later_messages_overtake_it():
    out = apply_fault(_streams(), StreamFault(channel="a", kind=FaultKind.DELAY, index=1, delay_ms=250))
    assert [r.message["stamp"] for r in out["a"]] == [0, 2, 3, 1, 4]
    assert out["a"][3].time_ns == 350 * MS


def test_reorder_delivers_it_right_after_the_next_and_the_module_reads_old_data_last():
    streams = apply_fault(_streams(), StreamFault(channel="a", kind=FaultKind.REORDER, index=1))
    assert [r.message["stamp"] for r in streams["a"]] == [0, 2, 1, 3, 4]
    frames = trigger_frames(streams, "a")
    assert [f["a"].message["stamp"] for f in frames] == [0, 2, 1, 3, 4]  # stamp 1 arrives after stamp 2


def test_duplicate_delivers_a_copy_right_after():
    out = apply_fault(_streams(), StreamFault(channel="a", kind=FaultKind.DUPLICATE, index=3))
    assert [(r.message["stamp"], r.copy) for r in out["a"]] == [(0, 0), (1, 0), (2, 0), (3, 0), (3, 1), (4, 0)]


def test_set_and_hold_rewrite_only_their_messages():
    base = _streams()
    one = apply_fault(base, StreamFault(channel="a", kind=FaultKind.SET, index=1, path="v", value=math.nan))
    assert [math.isnan(r.message["v"]) for r in one["a"]] == [False, True, False, False, False]
    held = apply_fault(base, StreamFault(channel="a", kind=FaultKind.HOLD, index=1, path="v", value=9.0, count=3))
    assert [r.message["v"] for r in held["a"]] == [0.0, 9.0, 9.0, 9.0, 4.0]
    assert [r.message["v"] for r in base["a"]] == [0.0, 1.0, 2.0, 3.0, 4.0]  # the recorded streams untouched
    with pytest.raises(FaultNotApplicable):
        apply_fault(base, StreamFault(channel="a", kind=FaultKind.SET, index=1, path="nope", value=1.0))


def test_a_held_value_and_a_delay_shrink_to_their_smallest_forms():
    held = StreamFault(channel="a", kind=FaultKind.HOLD, index=2, path="v", value=1.0, count=12)
    assert [(f.kind, f.count) for f in smaller_faults(held)] == [(FaultKind.SET, 1), (FaultKind.HOLD, 3),
                                                                  (FaultKind.HOLD, 6)]
    late = StreamFault(channel="a", kind=FaultKind.DELAY, index=2, delay_ms=200.0)
    assert smaller_faults(late) == [] and smaller_faults(StreamFault(channel="a", kind=FaultKind.DROP, index=2)) == []


def test_field_families_fold_fields_to_their_object_and_message_faults_to_the_channel():
    assert field_family("pose.x") == "pose.{…}"
    assert field_family("points[3].v") == "points[].{…}"
    assert StreamFault(channel="loc", kind=FaultKind.SET, index=0, path="speed").family == "loc:.{…}"
    assert StreamFault(channel="loc", kind=FaultKind.DROP, index=0).family == \
        StreamFault(channel="loc", kind=FaultKind.REORDER, index=4).family == "loc:(message)"


def test_a_fault_survives_its_json_form_with_a_nan():
    fault = StreamFault(channel="a", kind=FaultKind.HOLD, index=3, path="v", value=math.nan, value_ref="@f.nan",
                        count=4)
    back = StreamFault.from_json(StateReader("fault", fault.to_json(), ""))
    assert math.isnan(back.value) and back.count == 4 and back.value_ref == "@f.nan"  # type: ignore[arg-type]


def test_a_damaged_verdict_a_worker_wrote_is_one_input_error_naming_its_file_and_field():
    from astaa_deft.analysis.deft.module_search import ModuleVerdict
    from astaa_deft.model.errors import InputError

    verdict = ModuleVerdict(module="m", fault=StreamFault(channel="a", kind=FaultKind.DROP, index=2), steps=4)
    assert ModuleVerdict.from_json(StateReader("w0.jsonl", verdict.to_json(), "")) == verdict
    damaged = {**verdict.to_json(), "fault": {**verdict.fault.to_json(), "index": "2"}}
    with pytest.raises(InputError, match=r"w0\.jsonl.*field 'verdict\.fault\.index' must be a whole number"):
        ModuleVerdict.from_json(StateReader("w0.jsonl", damaged, "", field="verdict"))


def test_only_fields_every_consumer_leaves_unread_are_left_out():
    reads = [FieldReads(module="m1", read=(("s", "x"),), unread=(("s", "debug"), ("t", "note"))),
             FieldReads(module="m2", read=(), unread=(("s", "debug"),))]
    consumers = {"s": ("m1", "m2"), "t": ("m1", "live_only")}  # t: a module that is not replayed reads it
    assert fields_nothing_reads(consumers, reads) == [("s", "debug")]


def test_live_generation_leaves_unread_fields_out_and_keeps_message_faults():
    spec = load_spec(SPEC)
    targets = gen.FaultTargets.of(spec, load_dictionary([]))
    narrowed, left = gen.without_fields(targets, [("state", "debug.note"), ("state", "debug.score")])
    assert left > 0
    paths = {str(t.path) for name, family in narrowed.by_family.items() if name != "message"  # no field written
             for ts in family.values() for t in ts}
    assert not any(p.startswith("debug.") for p in paths) and "v" in paths
    assert narrowed.by_family["message"] == targets.by_family["message"]


def test_the_fault_plan_is_deterministic_and_covers_message_faults_on_every_input():
    spec = load_spec(SPEC)
    targets = gen.FaultTargets.of(spec, load_dictionary([])).by_family["single"]
    times = {"state": [i * 50 * MS for i in range(100)]}
    args = dict(module="ctrl", inputs=("state",), times=times, window=(1000 * MS, 4000 * MS), targets=targets)
    plan = plan_faults(**args, seed=3)
    assert plan == plan_faults(**args, seed=3) and plan != plan_faults(**args, seed=4)
    assert {f.kind for f in plan} >= {FaultKind.DROP, FaultKind.DELAY, FaultKind.DUPLICATE, FaultKind.REORDER}
    assert all(20 <= f.index <= 80 for f in plan)  # inside the live window


def test_a_spec_without_an_in_process_replay_has_no_module_to_search(tmp_path):
    text = re.sub(r'      factory: "[^"]*"\n', '      command: ["true"]\n', SPEC.read_text())
    spec_path = tmp_path / "modlevel.yaml"
    spec_path.write_text(text)
    entries, skipped = replayed_entries(load_spec(spec_path))
    assert entries == [] and len(skipped) == 2 and all("no in-process replay" in why for why in skipped)


# -- a real module replayed from a real run ---------------------------------------------------------------

@pytest.fixture(scope="module")
def recorded(tmp_path_factory):
    from astaa_deft.cli.commands.proxy import run_bus
    from astaa_deft.engine.session import RunOptions

    spec = load_spec(SPEC)
    path = tmp_path_factory.mktemp("modlevel") / "clean.mcap"
    run_bus(spec, RunOptions(mode="passive", record=path, params={"seconds": "3"}), 20.0, verbose=False)
    return spec, read_log(path)


def test_a_replayed_module_fails_under_faults_like_the_live_stack(recorded):
    spec, log = recorded
    bench = ModuleBench(spec, replay_module_of(spec, "ctrl"), log, {"seconds": "3"})
    assert bench.error is None and len(bench.frames) > 30 and not bench.known
    middle = len(bench.streams["state"]) // 2
    nan = bench.run(StreamFault(channel="state", kind=FaultKind.SET, index=middle, path="v", value=math.nan))
    assert nan.kind == FindingKind.INVARIANT and nan.invariant == "finite_u" and nan.frame == middle
    late = bench.run(StreamFault(channel="state", kind=FaultKind.REORDER, index=middle))
    assert late.kind == FindingKind.CRASH and late.error == "ValueError in modlevel_ctrl.py:step"
    assert late.invariant == "modules_alive"  # the process invariant judges the crash, as live
    debug = bench.run(StreamFault(channel="state", kind=FaultKind.SET, index=middle, path="debug.score", value=1e300))
    assert not debug.failed and debug.applicable
    reads = bench.field_reads()
    assert set(reads.unread) == {("state", "debug.note"), ("state", "debug.score")}
    assert ("state", "v") in reads.read


def test_the_defect_off_nothing_fails(recorded):
    spec, log = recorded
    bench = ModuleBench(spec, replay_module_of(spec, "ctrl"), log, {"defects": "0", "seconds": "3"})
    faults = [StreamFault(channel="state", kind=kind, index=20) for kind in (FaultKind.REORDER, FaultKind.DROP)]
    faults.append(StreamFault(channel="state", kind=FaultKind.SET, index=20, path="v", value=math.inf))
    assert [bench.run(f).failed for f in faults] == [False, False, False]


# -- a real campaign --------------------------------------------------------------------------------------

def _campaign(tmp_path: Path, **kw) -> Path:
    out = tmp_path / "campaign"
    config = CampaignConfig(spec_path=SPEC, out=out, cases=1, params={"seconds": ["3"]}, reruns=1, minimise=False,
                            module_level_seconds=10.0, report=False, **{"module_level": True, **kw})
    out.mkdir()
    journal = Journal(out)
    try:
        Campaign(config, journal, say=lambda line: None).run()
    finally:
        journal.close()
    return out


def test_a_campaign_confirms_its_module_level_findings_live(tmp_path):
    out = _campaign(tmp_path)
    state = read_state(out)
    assert state is not None and state.modules == ("ctrl", "watch") and state.cases > 0
    found = {(f.verdict.module, f.verdict.signature) for f in state.findings}
    assert found == {("ctrl", "invariant finite_u"), ("ctrl", "crash ValueError in modlevel_ctrl.py:step"),
                     ("watch", "crash OverflowError in modlevel_watch.py:step")}  # one bucket each, its module's
    assert all(f.tests_fail for f in state.findings), [(f.name, f.tests_fail) for f in state.findings]  # each
    # DeFT module test fails on its defect
    assert {("state", "debug.note"), ("state", "debug.score")} <= set(state.unread)
    journal = Journal(out)
    lines = status_lines(out, journal)
    page = render(journal, out)
    journal.close()
    assert "<h2>Module level</h2>" in page and "M001" in page
    assert sum("confirmed live" in line for line in lines) == 3, lines
    journal = Journal(out)
    module_of = {journal.planned(f.case_id).bucket: f.verdict.module for f in state.findings if f.case_id}
    blames = journal.blames()
    first_cases = {b.bucket: b.first_case for b in journal.buckets()}
    journal.close()
    assert {bucket: blames[bucket].module for bucket in module_of} == module_of  # each blamed on its module
    for bucket in module_of:  # a bucket its module-level case opened says the replay showed it
        assert not first_cases[bucket].startswith("m-") or "module level" in (blames[bucket].replay or "")
    assert lines[0].startswith("module level:") and lines[1].startswith("live:")
    db = sqlite3.connect(out / "journal.sqlite")
    live = [xml for (xml,) in db.execute("SELECT testcase_xml FROM cases WHERE kind='mutated' AND strategy='random'")]
    assert live and not any("debug." in xml for xml in live)  # fields nothing reads are left out live


@pytest.mark.slow
def test_without_module_level_the_campaign_runs_live_as_before(tmp_path):
    out = _campaign(tmp_path, module_level=False)
    assert read_state(out) is None and not (out / "module_level").exists()


def test_a_damaged_state_file_is_one_input_error_naming_it(tmp_path):
    from astaa_deft.model.errors import InputError
    from astaa_deft.orchestration.campaign.module_level_state import ModuleLevelState, state_path

    path = state_path(tmp_path)
    path.parent.mkdir()
    path.write_text('{"findings": [{"name": "M001"}]}')  # a finding without its verdict
    with pytest.raises(InputError, match="state.json"):
        read_state(tmp_path)
    path.write_text("not json")
    with pytest.raises(InputError, match="state.json"):
        read_state(tmp_path)
    state = ModuleLevelState(modules=("ctrl",), cases=3, unread=(("state", "debug.note"),))
    path.write_text(json.dumps(state.to_json()))
    assert read_state(tmp_path) == state


@pytest.fixture(scope="module")
def demo_recorded(tmp_path_factory):
    from astaa_deft.cli.commands.demo import demo_spec_path
    from astaa_deft.cli.commands.proxy import run_bus
    from astaa_deft.engine.session import RunOptions

    spec = load_spec(demo_spec_path())
    path = tmp_path_factory.mktemp("demo") / "clean.mcap"
    run_bus(spec, RunOptions(mode="passive", record=path, params={}), 40.0, verbose=False)
    return spec, read_log(path)


def test_the_demo_controls_seeded_defects_at_module_level_and_nothing_with_them_off(demo_recorded):
    spec, log = demo_recorded
    entry = replay_module_of(spec, "control")
    on = ModuleBench(spec, entry, log, {}, settle_s=3.0)
    off = ModuleBench(spec, entry, log, {"defects": "off"}, settle_s=3.0)
    middle = len(on.streams["localization"]) // 2
    faults = [StreamFault(channel="localization", kind=FaultKind.REORDER, index=middle),  # seeded defect 4
              StreamFault(channel="localization", kind=FaultKind.SET, index=middle, path="heading",
                          value=-1.7976931348623157e308),  # seeded defect 2: a hang
              StreamFault(channel="localization", kind=FaultKind.DROP, index=middle)]
    found = [on.run(f) for f in faults]
    assert [v.kind for v in found] == [FindingKind.INVARIANT, FindingKind.HANG, None], [v.detail for v in found]
    assert found[0].invariant == "finite_command"
    # defects off: no finding, and the settle cut leaves no false deadline (control_alive) at the cut
    assert [off.run(f).kind for f in faults] == [None, None, None]
