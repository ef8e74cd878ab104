"""The fault families a real stack needs: sustained values and stamp / sequence faults, drawn by the
generator and the campaign strategies with their seeded RNG, valid against the XSD and the spec, stamps
reached even where the spec calls them brittle, and a sustained case holding its value on a live run."""

from __future__ import annotations

import json
import random
from collections import Counter
from pathlib import Path

import pytest

from astaa_deft.orchestration.campaign.strategies import STRATEGIES
from astaa_deft.engine.intercept import generate as gen
from astaa_deft.engine.intercept.faults import FAMILIES
from astaa_deft.orchestration.campaign.strategies.random import SEMANTIC_EVERY
from astaa_deft.engine.intercept import load_dictionary, load_testcase
from astaa_deft.engine.intercept.testcase import Selection, parse_testcase
from astaa_deft.io.log.reader import read_log
from astaa_deft.engine.spec.loader import load_spec
from proxy_helpers import ECHO_SPEC, received, run_proxy

ROOT = Path(__file__).resolve().parent.parent
OMPL_SPEC = load_spec(ROOT / "examples" / "ompl_stack" / "spec.yaml")  # brittle: [Header.stamp, Header.seq]
DICTIONARY = load_dictionary()


def family(description: str) -> str:
    return description.split(":")[0]


def test_every_family_is_drawn_deterministically_and_every_case_validates(tmp_path):
    report = gen.generate_to_directory(OMPL_SPEC, tmp_path / "a",
                                       gen.GenerateOptions(count=300, seed=11, duration=20.0))
    again = gen.generate_to_directory(OMPL_SPEC, tmp_path / "b", gen.GenerateOptions(count=300, seed=11, duration=20.0))
    assert [p.read_bytes() for p in report.paths] == [p.read_bytes() for p in again.paths]
    # every family but the campaign's message faults: ASTAA's shapes, sustained, stamp and the semantic ones
    assert set(report.shapes) == {"single", "multi_field", "repeated", "sustained", "stamp", "boundary", "angle",
                                  "units", "arrays", "type", "siblings", "stale"}
    assert 0.12 <= report.shapes["sustained"] / 300 <= 0.28 and 0.03 <= report.shapes["stamp"] / 300 <= 0.12
    drawn = Counter()
    for path in report.paths:
        testcase = load_testcase(path, OMPL_SPEC, DICTIONARY)  # the XSD, then channels, fields and values
        drawn[family(testcase.description)] += 1
        [policy] = testcase.policies
        assert 0.0 <= policy.window.start < policy.window.end <= 20.0
    assert drawn["sustained"] == report.shapes["sustained"] and drawn["stamp"] == report.shapes["stamp"]


def test_stamps_are_reached_though_brittle_and_only_by_the_stamp_family():
    brittle = {("ego", "header.stamp"), ("ego", "header.seq"), ("obstacles", "header.stamp"),
               ("obstacles", "header.seq"), ("plan", "header.stamp"), ("plan", "header.seq")}
    by_family: dict[str, set[tuple[str, str, str]]] = {}
    for testcase in gen.generate(OMPL_SPEC, DICTIONARY, 600, seed=2):  # ~5 % stamp faults: ~30 of them
        [policy] = testcase.policies
        for assignment in getattr(policy.action, "fields", ()):  # set policies (not remove, swap)
            by_family.setdefault(family(testcase.description), set()).add(
                (policy.channels[0], assignment.path, assignment.value))
    stamp_fields = {(channel, path) for channel, path, _ in by_family.pop("stamp")}
    assert stamp_fields == brittle  # every stamp and sequence number of the three consumed channels
    assert not {(channel, path) for cases in by_family.values() for channel, path, _ in cases} & brittle


@pytest.mark.parametrize("name", ["random", "guided"])
def test_campaign_strategies_hold_a_third_of_their_field_probes_and_try_a_nan_stamp_in_the_first_round(name):
    strategy = STRATEGIES[name](OMPL_SPEC, DICTIONARY, 5, 20.0)
    length = (strategy.fresh if name == "guided" else strategy).round_length
    proposed = [parse_testcase(strategy.propose(n).testcase.to_xml(), "t", OMPL_SPEC, DICTIONARY)
                for n in range(1, 4 * length * SEMANTIC_EVERY // (SEMANTIC_EVERY - 1) + 1)]
    semantic = {f.name for f in FAMILIES.values() if f.semantic}
    # every SEMANTIC_EVERY-th case probes a semantic family (tests/test_semantic_faults.py); of the others,
    # two pure coverage rounds, then rounds and weighted draws
    assert [family(c.description) in semantic for c in proposed[:30]] == [
        n % SEMANTIC_EVERY == SEMANTIC_EVERY - 1 for n in range(30)]
    cases = [c for n, c in enumerate(proposed) if n % SEMANTIC_EVERY != SEMANTIC_EVERY - 1][:4 * length]
    families = Counter(family(c.description) for c in cases)
    field_probes = families["sustained"] + families["one field of one message"]
    assert 0.2 <= families["sustained"] / field_probes <= 0.5
    # a round's stamp share (the weighted draws' share is the stamp weight's, smaller next to the semantic ones)
    rounds = Counter(family(c.description) for c in cases[:2 * length])
    assert 0.05 <= rounds["stamp"] / (2 * length) <= 0.10
    first_round = [c.policies[0] for c in cases[:length] if family(c.description) == "stamp"]
    assert {(p.channels[0], p.action.fields[0].path, p.action.fields[0].value) for p in first_round} == {
        ("ego", "header.stamp", "dict:time.nan"), ("obstacles", "header.stamp", "dict:time.nan")}
    for case in cases:
        [policy] = case.policies
        if family(case.description) == "sustained":
            assert policy.selection == Selection() or 5 <= (policy.selection.limit or 0) <= 50


def first_sustained_for_n_messages(spec, anchor: str):
    """The first weighted draw, in seeded order, that holds one value on the next N messages."""
    targets = gen.targets_to_mutate(spec, DICTIONARY, include_brittle=False)
    for number in range(1, 500):
        testcase = gen.weighted_testcase(f"tc-{number}", random.Random(f"live/{number}"), targets, 1.5, anchor=anchor)
        [policy] = testcase.policies
        if family(testcase.description) == "sustained" and policy.selection.limit is not None:
            return testcase
    raise AssertionError("no sustained case in 500 draws")


def test_a_sustained_case_holds_its_value_on_n_consecutive_messages_of_a_live_run(tmp_path):
    spec = load_spec(ECHO_SPEC)
    testcase = first_sustained_for_n_messages(spec, anchor="data")
    [policy] = testcase.policies
    held = policy.selection.limit
    assert held is not None and 5 <= held <= 50
    policy_path = tmp_path / "tc.xml"
    policy_path.write_bytes(testcase.to_xml())
    run_dir, log_path = tmp_path / "run", tmp_path / "run.mcap"
    res = run_proxy(ECHO_SPEC, "--policy", str(policy_path), "--record", str(log_path), "--duration", "4",
                    "--run-dir", str(run_dir), "--param", "count=400", "--param", "rate=200")
    assert res.returncode in (0, 1), res.stdout + res.stderr
    got = [json.loads(p) for k, p, _ in received(run_dir / "listener.out") if k == "test/data"]
    mutations = [json.loads(m.data) for m in read_log(log_path).on("/astaa/mutations")]
    assert len(got) == 400 and len(mutations) == held  # exactly N messages changed, no more
    changed = [m["header"]["seq"] for m in got if m["value"] != m["header"]["seq"] * 0.5]  # NaN too
    assert len(changed) == held and changed == list(range(changed[0], changed[0] + held))  # N in a row
    indices = [event["message_index"] for event in mutations]
    assert indices == list(range(indices[0], indices[0] + held))
    assert all(event["fields"][0]["path"] == "value" for event in mutations)
