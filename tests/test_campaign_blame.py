"""Blame and root-cause dedupe: the first module whose output departed from its unmutated twins' is to
blame, and buckets of one root cause (same module, wrong output, failure, field family) are one bucket."""

from __future__ import annotations

from pathlib import Path

import pytest

from astaa_deft.engine.spec.loader import load_spec
from astaa_deft.orchestration.campaign.blame import RunSeries, bin_features, blame, departures, features
from astaa_deft.orchestration.campaign.campaign import Campaign, CampaignConfig
from astaa_deft.orchestration.journal.journal import Journal
from astaa_deft.orchestration.journal.model import CaseOutcome
from astaa_deft.orchestration.campaign.signature import field_family
from astaa_deft.engine.intercept.testcase import parse_testcase
from astaa_deft.orchestration.campaign.strategies.base import Proposal, Strategy

from blame_series import series

SUT = Path(__file__).parent / "sut"
PIPE = SUT / "pipe.yaml"
NAN = float("nan")


def test_features_fold_arrays_count_non_finite_values_and_keep_short_strings():
    f = features({"x": 1.0, "p": [{"v": 1.0}, {"v": 3.0}], "s": "ok", "n": NAN, "b": True})
    assert f["x"] == 1.0 and f["p[].v"] == 2.0 and f["p#len"] == 2.0 and f["s=ok"] == 1.0
    assert f["n#nonfinite"] == 1.0 and "n" not in f and f["b"] == 1.0


def test_the_first_module_whose_output_departs_is_blamed_not_the_one_downstream():
    spec = load_spec(PIPE)
    calm = [1.0 + 0.01 * i for i in range(40)]
    twin_a = series({"pose": calm, "command": calm})
    twin_b = series({"pose": [v + 0.02 for v in calm], "command": [v + 0.02 for v in calm]})
    # Mutated at 2.0 s (bin 4): the command goes non-finite at 2.1 s.
    failing = series({"pose": calm, "command": calm[:21] + [NAN] * 19}, mutated_at=4, mutated=("pose",))
    found = departures(failing, [twin_a, twin_b])
    assert [(d.channel, d.how) for d in found] == [("command", "non-finite")]
    verdict = blame(spec, failing, [twin_a, twin_b], invariant="finite_speed", finding_module="relay")
    assert verdict.module == "relay" and verdict.output == "command"
    assert verdict.chain == "pose → relay → command (non-finite: v#nonfinite) → finite_speed"


def test_twin_to_twin_noise_is_not_a_departure_and_nothing_departing_blames_the_findings_module():
    spec = load_spec(PIPE)
    wobbly_a = [1.0 + (0.3 if i % 7 == 0 else 0.0) for i in range(40)]
    wobbly_b = [1.0 + (0.3 if i % 5 == 0 else 0.0) for i in range(40)]
    failing = series({"pose": wobbly_b, "command": wobbly_a}, mutated_at=2, mutated=("pose",))
    twins = [series({"pose": wobbly_a, "command": wobbly_a}), series({"pose": wobbly_b, "command": wobbly_b})]
    assert departures(failing, twins) == []
    verdict = blame(spec, failing, twins, invariant="finite_speed", finding_module="relay")
    assert verdict.module == "relay" and verdict.how == "finding" and verdict.output is None


def test_a_string_no_twin_ever_had_departs_at_once_and_a_varying_one_does_not():
    def statuses(values: list[str], mutated_at: int | None = None) -> RunSeries:
        bins = {"pose": bin_features((0.1 * i, {"v": 1.0}) for i in range(40)),
                "command": bin_features((0.1 * i + 0.01, {"status": v}) for i, v in enumerate(values))}
        return RunSeries(bins, mutated_at, ("pose",) if mutated_at is not None else ())

    varying = ["ok" if i % 6 else "replan" for i in range(40)]
    twins = [statuses(varying), statuses(["ok" if i % 4 else "replan" for i in range(40)])]
    assert departures(statuses(["ok" if i % 5 else "replan" for i in range(40)], mutated_at=2), twins) == []
    stale = statuses(varying[:25] + ["stale input"] * 15, mutated_at=2)
    assert [(d.channel, d.feature, d.bin) for d in departures(stale, twins)] == [("command", "status=stale input", 5)]


def test_a_module_that_falls_silent_departs():
    calm = [1.0] * 40
    failing = series({"pose": calm, "command": calm[:12] + [None] * 28}, mutated_at=2, mutated=("pose",))
    found = departures(failing, [series({"pose": calm, "command": calm})])
    assert [(d.channel, d.how) for d in found] == [("command", "silent")]


def test_a_field_family_folds_sibling_fields_and_leaves_out_values_and_actions():
    assert field_family("ego:x:set") == field_family("ego:y:set") == "ego:.{…}"
    assert field_family("obstacles:obstacles[].length:set") == "obstacles:obstacles[].{…}"
    assert field_family("ego:header.stamp:set") == "ego:header.{…}"
    assert field_family("ego:*:reorder") == "ego:(message)"


NAN_ON = ('<testcase id="t" seed="1"><description>x</description><policy id="p1"><channel>pose</channel>'
          '<window from="0.5" to="30"><after channel="pose" message="1"/></window><select limit="1"/>'
          '<set><field path="{field}" value="dict:float.nan"/></set></policy></testcase>')


class Fixed(Strategy):
    """Proposes the given test cases in order (the campaign's interface, nothing mocked)."""

    name = "fixed"

    def __init__(self, cases: list[str]):
        self.cases = cases

    def propose(self, number: int) -> Proposal:
        return Proposal(parse_testcase(self.cases[number - 1].encode()))  # the campaign holds an object

    def observe(self, case_id: str, testcase_xml: str | None, outcome: CaseOutcome) -> None:
        pass


@pytest.mark.slow  # ~22 s: seven real runs of the pipe stack
@pytest.mark.promise
def test_a_nan_in_x_and_in_y_are_one_bucket_blamed_on_the_relay_with_the_chain_journalled(tmp_path: Path):
    out = tmp_path / "c"
    journal = Journal(out)
    cases = [NAN_ON.format(field="x"), NAN_ON.format(field="y")]
    said: list[str] = []
    run = Campaign(CampaignConfig(spec_path=PIPE, out=out, cases=2, workers=1, baseline_runs=1, reruns=1,
                                  minimise=False, report=False, params={"seconds": ["2"]}), journal, say=said.append)
    run.strategy = Fixed(cases)  # type: ignore[assignment]
    run.run()
    try:
        buckets = journal.buckets()
        assert [b.kind for b in buckets] == ["bug", "bug"], (buckets, said)
        blames = journal.blames()
        first, second = buckets
        assert blames[first.bucket].module == "relay", blames
        assert blames[first.bucket].chain.startswith("pose → relay → command (non-finite"), blames
        assert blames[first.bucket].detail.endswith("2 of 2 failing runs agree"), blames  # the case and its re-run
        assert second.merged_into == first.bucket, (buckets, said)  # one root cause, both culprits kept
        assert {first.family, second.family} == {"pose:x:set", "pose:y:set"}
        assert any("merged into" in n.text for n in journal.notes("blame")), said
    finally:
        journal.close()


@pytest.mark.slow  # ~2-3 min: demo runs, then a minimisation
@pytest.mark.promise
def test_on_the_demo_the_planner_is_blamed_and_its_replay_confirms_it(tmp_path: Path):
    # Seeded defect 1: an infinite routing speed limit makes the planner plan over the limit (planned_speed).
    from astaa_deft.demo.bundled import demo_spec_path

    inf_limit = ('<testcase id="t" seed="1"><description>x</description><policy id="p1"><channel>routing</channel>'
                 '<window from="0"><after channel="command" message="20"/></window><select limit="1"/>'
                 '<set><field path="speed_limit" value="dict:float.inf"/></set></policy></testcase>')
    out = tmp_path / "c"
    journal = Journal(out)
    said: list[str] = []
    run = Campaign(CampaignConfig(spec_path=demo_spec_path(), out=out, cases=1, workers=1, baseline_runs=1, reruns=1,
                                  report=False), journal, say=said.append)
    run.strategy = Fixed([inf_limit])  # type: ignore[assignment]
    run.run()
    try:
        bucket = journal.buckets()[0]
        assert bucket.kind == "bug" and bucket.invariant == "planned_speed", (bucket, said)
        blamed = journal.blames()[bucket.bucket]
        assert blamed.module == "planning" and blamed.chain.startswith("routing → planning → trajectory"), blamed
        assert blamed.replay is not None and "a replay of planning alone" in blamed.replay, (blamed, said)
    finally:
        journal.close()
