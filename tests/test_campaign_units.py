"""Campaign pieces that need no SUT: signatures, params, strategies, the journal, bad input."""

from __future__ import annotations

import json
import sqlite3
import subprocess
import sys
from dataclasses import replace
from pathlib import Path

import pytest

from astaa_deft.orchestration.campaign import signature as sig
from astaa_deft.orchestration.campaign.campaign import default_workers, param_grid
from astaa_deft.orchestration.journal.journal import Journal, Minimisation, NewBucket
from astaa_deft.orchestration.journal.model import (
    MUTATED, BucketSignature, CaseOutcome, FailureKey, Finding, PlannedCase,
)
from astaa_deft.orchestration.campaign.strategies import STRATEGIES
from astaa_deft.cli.commands.demo import demo_spec_path
from astaa_deft.cli.commands.fuzz import parse_budget, parse_params
from astaa_deft.model.errors import InputError
from astaa_deft.engine.intercept import generate as gen
from astaa_deft.engine.intercept.faults import FAMILIES
from astaa_deft.orchestration.campaign.strategies.random import SEMANTIC_EVERY
from astaa_deft.engine.intercept.dictionary import load_dictionary
from astaa_deft.engine.intercept.actions.set import Assignment, Set
from astaa_deft.engine.intercept.testcase import TestCase, parse_testcase
from astaa_deft.io.output_place import OutputError
from astaa_deft.engine.spec.loader import load_spec


@pytest.fixture(scope="module")
def demo():
    return load_spec(demo_spec_path()), load_dictionary()


def test_random_strategy_covers_every_channel_and_field_first_with_values_class_by_class(demo):
    spec, dictionary = demo
    strategy = STRATEGIES["random"](spec, dictionary, 7, 20.0)
    targets = {(t.channel.name, str(t.path)): t for t in gen.mutation_targets(spec, dictionary)}
    channels = {channel for channel, _ in targets}
    length = strategy.round_length
    # every field once, one message fault per channel, stamp faults on about 7 % of a round (one per channel)
    stamp_probes = round(gen.STAMP_SHARE * (len(targets) + len(channels)))
    assert length == len(targets) + len(channels) + stamp_probes
    # every SEMANTIC_EVERY-th case probes a semantic fault family (tests/test_semantic_faults.py): the others
    # make the rounds
    semantic = {f.name for f in FAMILIES.values() if f.semantic}
    proposed = [parse_testcase(strategy.propose(n).testcase.to_xml(), "t", spec, dictionary)
                for n in range(1, 2 * length * SEMANTIC_EVERY // (SEMANTIC_EVERY - 1) + 1)]
    exceptional = [c for c in proposed if c.description.split(":")[0] not in semantic]
    assert len(exceptional) == 2 * length
    for round_number in (0, 1):
        cases = exceptional[round_number * length:(round_number + 1) * length]
        fields, faults, stamps = {}, set(), set()
        for case in cases:
            [policy] = case.policies
            if case.description.startswith("stamp:"):
                [assignment] = policy.action.fields
                stamps.add(policy.channels[0])
                if round_number == 0:  # the first round's stamp fault: NaN
                    assert assignment == Assignment("header.stamp", "dict:time.nan")
            elif isinstance(policy.action, Set):
                [assignment] = policy.action.fields
                fields[(policy.channels[0], assignment.path)] = assignment.value
            else:
                faults.add(policy.channels[0])
        assert set(fields) == set(targets) and faults == channels and len(stamps) == stamp_probes
        for key, ref in fields.items():  # the round's class of each field's values: non-finite first, then extreme
            classes = [c for c in gen.VALUE_CLASSES if any(gen.value_class(e) == c for e in targets[key].values)]
            entry = next(e for e in targets[key].values if e.ref == ref)
            assert gen.value_class(entry) == classes[round_number % len(classes)], (key, ref)
        # channels take turns: the first len(channels) cases touch every channel
        assert {c.policies[0].channels[0] for c in cases[:len(channels)]} == channels
    # same seed, same case; after the coverage rounds, every other case is ASTAA's weighted draw
    again = STRATEGIES["random"](spec, dictionary, 7, 20.0)
    assert all(again.propose(n) == strategy.propose(n) for n in (1, 2, 5, 4 * length + 1, 4 * length + 2))


def test_value_classes_come_from_the_values_not_their_names():
    from astaa_deft.engine.intercept.dictionary.model import Entry

    assert gen.value_class(Entry(group="float", name="x", value=float("nan"))) == "non_finite"
    assert gen.value_class(Entry(group="float", name="x", value=-float("inf"))) == "non_finite"
    assert gen.value_class(Entry(group="float", name="x", value=1e16)) == "extreme"
    assert gen.value_class(Entry(group="int", name="x", value=2**63 - 1)) == "extreme"
    assert gen.value_class(Entry(group="array", name="x", value=[])) == "empty"
    assert gen.value_class(Entry(group="array", name="x", value=None)) == "null"
    assert gen.value_class(Entry(group="float", name="x", value=-0.0)) == "zero"
    assert gen.value_class(Entry(group="float", name="x", value=5e-324)) == "tiny"
    assert gen.value_class(Entry(group="float", name="x", rule="above_max")) == "bound"
    assert gen.value_class(Entry(group="int", name="x", rule="width_overflow")) == "extreme"


def test_calibrated_windows_count_from_the_anchor_and_fall_inside_the_live_run(demo):
    from astaa_deft.orchestration.campaign.strategies.base import Timing

    spec, dictionary = demo
    for name in ("random", "guided"):
        strategy = STRATEGIES[name](spec, dictionary, 3, 20.0)
        strategy.calibrate(Timing("command", 6.0))
        for n in range(1, 200, 7):
            for policy in parse_testcase(strategy.propose(n).testcase.to_xml()).policies:
                window = policy.window
                assert (window.anchor_channel, window.anchor_message) == ("command", 1)
                assert 0 <= window.start <= 6.0 and window.end is not None and window.end <= 6.0 + 5.0


def test_live_timing_takes_the_channel_that_came_last_and_the_shortest_live_run():
    from astaa_deft.orchestration.campaign.campaign import live_timing
    from astaa_deft.orchestration.campaign.strategies.base import Timing

    clean = [CaseOutcome(status="done", verdict="Pass", summary="", seconds=12.3,
                         first_seen={"a": 0.1, "b": 1.5, "c": 1.6}),
             CaseOutcome(status="done", verdict="Pass", summary="", seconds=13.0,
                         first_seen={"a": 0.2, "b": 1.4, "c": 2.1})]
    assert live_timing(clean, 20.0) == Timing("c", 10.5)  # 12.3 - 1.6 = 10.7, rounded down to 0.5 s
    assert live_timing(clean, 8.0) == Timing("c", 8.0)
    assert live_timing([CaseOutcome(status="done", verdict="Pass", summary="", seconds=5.0)],
                       20.0) == Timing(None, 20.0)


def test_guided_strategy_mutates_its_corpus_deterministically(demo):
    spec, dictionary = demo

    def run() -> list[tuple[str | None, str]]:
        guided = STRATEGIES["guided"](spec, dictionary, 3, 20.0)
        first = guided.propose(1)
        guided.observe("c-1", first.testcase,
                       CaseOutcome(status="done", verdict="Pass", summary="", margins={"speed_limit": 2.0}))
        return [(p.parent, p.testcase.to_xml().decode()) for p in (guided.propose(n) for n in range(2, 12))]

    a, b = run(), run()
    assert a == b
    children = [xml for parent, xml in a if parent == "c-1"]
    assert children, "half the proposals should derive from the corpus"
    for xml in children:  # every child is a valid test case for the spec
        parse_testcase(xml.encode(), "child", spec, dictionary)


def test_guided_corpus_keeps_only_cases_that_came_closer(demo):
    spec, dictionary = demo
    guided = STRATEGIES["guided"](spec, dictionary, 3, 20.0)
    xml = guided.propose(1).testcase
    guided.observe("a", xml, CaseOutcome(status="done", verdict="Pass", summary="", margins={"i": 2.0}))
    guided.observe("b", xml, CaseOutcome(status="done", verdict="Pass", summary="", margins={"i": 3.0}))
    guided.observe("c", xml, CaseOutcome(status="done", verdict="Pass", summary="", margins={"i": 1.0}))
    assert [case for case, _ in guided.corpus] == ["a", "c"]


def test_signature_separates_mutation_families_and_folds_indices(demo):
    spec, dictionary = demo
    outcome = CaseOutcome(status="done", verdict="Silent", summary="",
        findings=[Finding(invariant="speed_limit", crash="Silent", module=None, channel="status", detail="")])
    one = parse_testcase(STRATEGIES["random"](spec, dictionary, 25, 8.0).propose(1).testcase.to_xml())
    assert sig.mutation_family(one) == "trajectory:points:set"
    assert sig.signature(outcome, None).text().endswith(sig.NO_MUTATION)
    assert sig.failure_key(outcome).text() == "Silent|speed_limit|-"
    xml = one.to_xml().decode().replace('path="points"', 'path="points[3].v"')
    assert sig.signature(outcome, parse_testcase(xml.encode())).text().endswith("trajectory:points[].v:set")


def test_params_spread_over_every_combination():
    assert parse_params(["scenario=a,b", "defects=off"]) == {"scenario": ["a", "b"], "defects": ["off"]}
    assert param_grid({"scenario": ["a", "b"], "defects": ["off"]}) == [
        {"defects": "off", "scenario": "a"}, {"defects": "off", "scenario": "b"}]
    assert param_grid({}) == [{}]
    with pytest.raises(InputError):
        parse_params(["scenario"])


def test_budget_and_default_workers():
    assert parse_budget("30m") == 1800 and parse_budget("90s") == 90 and parse_budget("2h") == 7200
    with pytest.raises(InputError):
        parse_budget("soon")
    assert default_workers(4, cores=2) >= 2  # modules mostly sleep: more runs than cores
    assert default_workers(40, cores=2) == 1


def test_journal_requeues_only_cases_in_flight(tmp_path: Path):
    journal = Journal(tmp_path)
    for n in range(1, 4):
        journal.plan(PlannedCase(case_id=f"c-{n}", kind=MUTATED, number=n, seed=1, params={},
                                 testcase=TestCase(id=f"tc-{n}", seed=n, description="x", policies=())))
        journal.started(f"c-{n}")
    journal.finished("c-1", CaseOutcome(status="done", verdict="Pass", summary="ok"))
    journal.close()
    again = Journal(tmp_path)
    assert again.requeue_running() == 2
    assert [c.case_id for c in again.pending()] == ["c-2", "c-3"]
    assert again.case("c-1").status == "done"
    assert again.outcome(again.case("c-1")).summary == "ok"


def test_journal_on_a_read_only_file_is_one_clear_message(tmp_path: Path):
    journal = Journal(tmp_path)
    journal.plan(PlannedCase(case_id="c-1", kind=MUTATED, number=1, seed=1, params={}, testcase=None))
    journal.close()
    ro = sqlite3.connect(f"file:{tmp_path / 'journal.sqlite'}?mode=ro", uri=True)
    journal.db = ro
    with pytest.raises(OutputError, match="cannot write the campaign journal"):  # exit 4: the place, not the input
        journal.started("c-1")


def _fuzz(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "astaa_deft.cli", "fuzz", *args], capture_output=True, text=True,
                          timeout=120)


def test_bad_input_is_one_message_exit_2(tmp_path: Path):
    bad_spec = tmp_path / "bad.yaml"
    bad_spec.write_text("name: [unclosed\n")
    done = _fuzz("--spec", str(bad_spec), "-o", str(tmp_path / "c1"), "--cases", "1")
    assert done.returncode == 2 and "Traceback" not in done.stderr and "bad.yaml" in done.stderr
    empty = tmp_path / "empty.yaml"
    empty.write_text("")
    done = _fuzz("--spec", str(demo_spec_path()), "-o", str(tmp_path / "c2"), "--cases", "1", "--dictionary",
                 str(empty))
    assert done.returncode == 2 and "Traceback" not in done.stderr and "empty.yaml" in done.stderr
    done = _fuzz("--status", "-o", str(tmp_path / "nowhere"))
    assert done.returncode == 2 and "no campaign journal" in done.stderr
    done = _fuzz("-o", str(tmp_path / "c3"))  # no spec: a NameError traceback once
    assert done.returncode == 2 and "Traceback" not in done.stderr and "--spec" in done.stderr
    done = _fuzz("--spec", str(demo_spec_path()), "-o", str(tmp_path / "c4"))
    assert done.returncode == 2 and "Traceback" not in done.stderr and "--cases" in done.stderr


def test_a_sut_that_never_starts_stops_the_campaign_at_once(tmp_path: Path):
    spec = tmp_path / "dead.yaml"
    spec.write_text((Path(__file__).parent / "sut" / "echo.yaml").read_text().replace(
        '"{spec_dir}/listener.py"', '"-c", "import sys; sys.exit(3)"', 1).replace(
        "name: echo", "name: dead\n# copied from tests/sut/echo.yaml\n"))
    (tmp_path / "listener.py").write_text((Path(__file__).parent / "sut" / "listener.py").read_text())
    (tmp_path / "talker.py").write_text((Path(__file__).parent / "sut" / "talker.py").read_text())
    out = tmp_path / "camp"
    done = _fuzz("--spec", str(spec), "-o", str(out), "--cases", "50", "--horizon", "3", "--baseline", "1")
    assert done.returncode == 2, done.stderr
    assert "campaign stopped: the SUT does not start" in done.stderr and "Traceback" not in done.stderr
    rows = sqlite3.connect(out / "journal.sqlite").execute("SELECT kind, status FROM cases").fetchall()
    assert rows == [("baseline", "error")]  # no generated case burnt


def _signature(crash: str, invariant: str, module: str, family: str) -> BucketSignature:
    return BucketSignature(FailureKey(crash, invariant, module), family)


def test_buckets_whose_minimised_culprits_coincide_are_merged_into_the_first(tmp_path: Path):
    from astaa_deft.orchestration.campaign.campaign import culprit_family, merge_same_culprits

    journal = Journal(tmp_path)
    try:
        culprit = "routing:speed_limit = dict:float.nan"
        for n, (invariant, exit_code, found) in enumerate([("planned_speed", 0, culprit), ("speed_limit", 0, culprit),
                                                           ("finite_plan", 1, culprit), ("control_alive", 0, "x")],
                                                          start=1):
            name = f"B00{n}"
            journal.add_bucket(NewBucket(name=name, signature=_signature("Silent", invariant, "planning", "fam"),
                                         verdict="Silent", invariant=invariant, module="planning", first_case=f"c-{n}",
                                         without_mutation=False, after_cases=n))
            journal.minimised(Minimisation(bucket=name, status="minimised" if exit_code == 0 else "not reproduced",
                                           exit_code=exit_code, minimal_xml="<xml/>", culprit=found, out_dir=None,
                                           tests_dir=None, seconds=1.0, detail=""))
        # the same field with another value (and another array index) is the same culprit
        journal.add_bucket(NewBucket(name="B005", signature=_signature("Silent", "planned_speed", "planning", "fam2"),
                                     verdict="Silent", invariant="planned_speed", module="planning", first_case="c-5",
                                     without_mutation=False, after_cases=5))
        journal.minimised(Minimisation(bucket="B005", status="minimised", exit_code=0, minimal_xml="<xml/>",
                                       culprit="routing:speed_limit = dict:float.inf", out_dir=None, tests_dir=None,
                                       seconds=1.0, detail=""))
        journal.add_bucket(NewBucket(name="B006", signature=_signature("Abort", "modules_alive", "control", "f"),
                                     verdict="Abort", invariant="modules_alive", module="control", first_case="c-6",
                                     without_mutation=False, after_cases=6))
        journal.minimised(Minimisation(bucket="B006", status="minimised", exit_code=0, minimal_xml="<xml/>",
                                       culprit="trajectory:points[2].v = dict:float.nan", out_dir=None, tests_dir=None,
                                       seconds=1.0, detail=""))
        # message faults on one channel breaking the same invariant in the same module: one bug
        for name, fault, invariant in (("B007", "reorder", "finite_command"), ("B008", "delay", "finite_command"),
                                       ("B009", "drop", "control_alive")):
            journal.add_bucket(NewBucket(name=name, signature=_signature("Silent", invariant, "control", fault),
                                         verdict="Silent", invariant=invariant, module="control",
                                         first_case=f"c-{name}", without_mutation=False, after_cases=7))
            journal.minimised(Minimisation(bucket=name, status="minimised", exit_code=0, minimal_xml="<xml/>",
                                           culprit=f"localization:{fault}", out_dir=None, tests_dir=None, seconds=1.0,
                                           detail=""))
        assert merge_same_culprits(journal) == [("B002", "B001"), ("B005", "B001"), ("B008", "B007")]
        assert {b.bucket: b.merged_into for b in journal.buckets()} == {
            "B001": None, "B002": "B001", "B003": None, "B004": None, "B005": "B001", "B006": None, "B007": None,
            "B008": "B007", "B009": None}
        assert merge_same_culprits(journal) == []  # on resume: nothing merged twice
        assert [b.bucket for b in journal.buckets(include_merged=False)] == ["B001", "B003", "B004", "B006", "B007",
                                                                             "B009"]
        assert culprit_family("trajectory:points[2].v = dict:float.nan; a:b = 1") == "a:b; trajectory:points[].v"
        assert culprit_family("localization:reorder") == "localization:(message fault)"
    finally:
        journal.close()


def test_a_finding_on_the_channel_the_case_itself_mutates_is_not_a_failure(demo):
    spec, _ = demo
    xml = parse_testcase(b'<testcase id="t" seed="1"><description>x</description><policy id="p">'
                         b'<channel>command</channel><set><field path="acceleration" value="dict:float.nan"/></set>'
                         b'</policy></testcase>')
    own = Finding(invariant="finite_command", crash="Silent", module="control", channel="command",
                  detail="acceleration nan")
    crash = Finding(invariant="modules_alive", crash="Abort", module="simulator", channel=None, detail="exit 1")
    only_own = CaseOutcome(status="done", verdict="Silent", summary="Silent: finite_command", findings=[own],
                           margins={"finite_command": 0.0,
"finite_plan": 0.3})
    judged = sig.without_self_inflicted(only_own, xml, spec)
    assert not judged.failed and judged.verdict == "Pass" and "finite_command" in judged.summary
    assert judged.margins == {"finite_plan": 0.3}  # guided search: the mutation did not come closer by itself
    both = sig.without_self_inflicted(
        CaseOutcome(status="done", verdict="Abort", summary="Abort: …", findings=[own, crash]), xml, spec)
    assert both.failed and both.verdict == "Abort" and sig.primary(both) == crash
    # another channel's invariant, or a clean run, is judged as the monitors said
    other = CaseOutcome(status="done", verdict="Silent", summary="Silent: finite_plan",
                        findings=[Finding(invariant="finite_plan", crash="Silent", module="planning",
          channel="trajectory", detail="v nan")])
    assert sig.without_self_inflicted(other, xml, spec).failed
    assert sig.without_self_inflicted(only_own, None, spec) is only_own


# The first journals: no cost columns, no bucket kinds or twins, no minimisation times.
FIRST_SCHEMA = """
CREATE TABLE meta (key TEXT PRIMARY KEY, value TEXT NOT NULL);
CREATE TABLE cases (
    case_id TEXT PRIMARY KEY, kind TEXT NOT NULL, number INTEGER NOT NULL, seed INTEGER NOT NULL,
    params TEXT NOT NULL, testcase_xml TEXT, strategy TEXT NOT NULL, parent TEXT,
    status TEXT NOT NULL DEFAULT 'planned',
    verdict TEXT, summary TEXT, signature TEXT, failure_key TEXT, bucket TEXT, outcome TEXT,
    planned_at REAL, started_at REAL, finished_at REAL, seconds REAL, log_path TEXT, worker TEXT
);
CREATE TABLE buckets (
    bucket TEXT PRIMARY KEY, signature TEXT NOT NULL, verdict TEXT NOT NULL, invariant TEXT NOT NULL,
    module TEXT, family TEXT NOT NULL, first_case TEXT NOT NULL, without_mutation INTEGER NOT NULL,
    cases INTEGER NOT NULL DEFAULT 1, reruns INTEGER NOT NULL DEFAULT 0, rerun_failures INTEGER NOT NULL DEFAULT 0,
    merged_into TEXT, created_at REAL NOT NULL, created_after_cases INTEGER NOT NULL
);
CREATE TABLE minimisations (
    bucket TEXT PRIMARY KEY, status TEXT NOT NULL, exit_code INTEGER, minimal_xml TEXT, culprit TEXT,
    out_dir TEXT, tests_dir TEXT, seconds REAL, detail TEXT
);
"""


def test_a_journal_of_the_first_version_reads_as_typed_rows(tmp_path: Path):
    from astaa_deft.orchestration.journal.model import BucketKind, CaseKind, CaseStatus
    from astaa_deft.orchestration.campaign.report import write_report

    db = sqlite3.connect(tmp_path / "journal.sqlite")
    db.executescript(FIRST_SCHEMA)
    db.execute("INSERT INTO meta VALUES ('spec', '\"/x/demo_av.yaml\"'), ('seed', '3'), ('timing',"
               " '{\"anchor\": \"trajectory\", \"live\": 4.5}')")
    outcome = '{"status": "done", "verdict": "Silent", "summary": "Silent: …", "findings": [], "reason": "violation"}'
    db.execute("INSERT INTO cases VALUES ('b-0001', 'baseline', 1, 3, '{\"scenario\": \"lane_follow\"}', NULL,"
               " 'baseline', NULL, 'done', 'Silent', 'Silent: …', 'Silent|?|?|(no mutation)', 'Silent|?|?', 'B001',"
               " ?, 1.0, 2.0, 3.0, 1.0, NULL, NULL)", (outcome,))
    db.execute("INSERT INTO buckets VALUES ('B001', 'Silent|?|?|(no mutation)', 'Silent', '?', NULL,"
               " '(no mutation)', 'b-0001', 1, 1, 0, 0, NULL, 1.0, 1)")
    db.execute("INSERT INTO minimisations VALUES ('B001', 'error', 2, NULL, NULL, NULL, NULL, 1.5, 'bad input')")
    db.commit()
    db.close()
    journal = Journal(tmp_path)
    try:
        [case] = journal.cases()
        assert (case.kind, case.status, case.params, case.cpu) == (CaseKind.BASELINE, CaseStatus.DONE,
                                                                   {"scenario": "lane_follow"}, None)
        assert case.outcome() is not None and case.outcome().reason == "violation"
        [bucket] = journal.buckets()
        assert bucket.kind == BucketKind.BASELINE and (bucket.controls, bucket.control_failures) == (0, 0)
        assert journal.minimisations()["B001"].started_at is None
        meta = journal.meta()
        assert (meta.spec, meta.seed, meta.timing.anchor, meta.timing.live) == ("/x/demo_av.yaml", 3, "trajectory",
                                                                                4.5)
        assert journal.rate(bucket) == (1, 1)  # the clean run filed under it
    finally:
        journal.close()
    assert "1 failing without mutation" in write_report(tmp_path).read_text()


def test_every_strategy_declares_the_campaigns_hooks_and_the_defaults_change_nothing():
    from astaa_deft.orchestration.campaign.strategies import Proposal, Strategy

    assert all(issubclass(cls, Strategy) for cls in STRATEGIES.values())

    class Minimal(Strategy):
        name = "minimal"

        def __init__(self, spec, dictionary, seed: int, duration: float) -> None:
            self.seed = seed

        def propose(self, number: int) -> Proposal:
            return Proposal(TestCase(id=f"tc-{number}", seed=self.seed, description="", policies=()))

    strategy = Minimal(None, None, 3, 20.0)
    outcome = CaseOutcome(status="done", verdict="Silent", summary="Silent: …")
    assert strategy.judge("c-1", TestCase(id="tc-1", seed=3, description="", policies=()),
                          outcome) is outcome  # the monitors' verdict stands
    assert not strategy.exports_own_findings  # the campaign minimises its buckets
    assert strategy.propose(1).testcase == TestCase(id="tc-1", seed=3, description="", policies=())


def test_vocabularies_and_signatures_keep_their_text_forms():
    import json

    from astaa_deft.orchestration.journal.model import BucketKind, CaseKind
    from astaa_deft.orchestration.campaign.payload import case_json
    from astaa_deft.orchestration.campaign.standing import BucketStatus

    assert (f"{CaseKind.RERUN}", str(BucketKind.BASELINE), f"{BucketStatus.WITHOUT_MUTATION:18}|") == (
        "rerun", "baseline", "without mutation  |")
    assert json.dumps(case_json(PlannedCase(case_id="c-1", kind=MUTATED, number=1, seed=2, params={},
                                            testcase=None))).startswith(
        '{"case_id": "c-1", "kind": "mutated"')
    signature = BucketSignature(FailureKey("Silent", "speed_limit", "-"), "routing:speed_limit:set")
    assert signature.text() == "Silent|speed_limit|-|routing:speed_limit:set"
    assert BucketSignature.clean(signature.failure).text() == "Silent|speed_limit|-|(no mutation)"


def test_a_test_case_is_an_object_until_the_payload_or_the_journal_stores_it(demo, tmp_path: Path):
    """The payload and the journal keep a case's text; read back, it is the same test case (checked against the
    worker's spec and dictionary), and a clean run stays without one."""
    from astaa_deft.orchestration.campaign.payload import CasePayload

    spec, dictionary = demo
    testcase = STRATEGIES["random"](spec, dictionary, 7, 20.0).propose(1).testcase
    case = PlannedCase(case_id="c-000001", kind=MUTATED, number=1, seed=7, params={}, testcase=testcase)
    payload = CasePayload(spec="spec.yaml", case=case, run_dir="run", horizon=5.0, dictionaries=(), settle=1.0,
                          known=())
    received = CasePayload.from_json(json.loads(json.dumps(payload.to_json())))
    assert received.to_json() == payload.to_json()  # a pool forwards it as it came
    assert received.testcase(spec, dictionary) == testcase == payload.testcase(spec, dictionary)
    clean = CasePayload.from_json(CasePayload(spec="spec.yaml", case=replace(case, testcase=None), run_dir="run",
                                              horizon=5.0, dictionaries=(), settle=None, known=()).to_json())
    assert clean.testcase(spec, dictionary) is None
    journal = Journal(tmp_path)
    journal.plan(case)
    (row,) = journal.pending(MUTATED)
    assert parse_testcase(row.testcase_xml.encode(), "journal", spec, dictionary) == testcase
    journal.close()


def test_a_campaign_runs_the_spec_its_command_loaded_without_reading_the_file_again(tmp_path: Path):
    from astaa_deft.orchestration.campaign.campaign import Campaign, CampaignConfig

    spec = load_spec(demo_spec_path())
    gone = tmp_path / "moved-away.yaml"  # the command loaded and checked it; the file need not be read again
    journal = Journal(tmp_path / "c")
    try:
        campaign = Campaign(CampaignConfig(spec_path=gone, out=tmp_path / "c", cases=1, workers=1), journal,
                            say=lambda line: None, spec=spec)
        assert campaign.spec is spec
        with pytest.raises(InputError):  # without it, the campaign loads the spec itself
            Campaign(CampaignConfig(spec_path=gone, out=tmp_path / "c", cases=1, workers=1), journal,
                     say=lambda line: None)
    finally:
        journal.close()
