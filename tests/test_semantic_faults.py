"""The semantic fault families: one registered module each, their rules and actions, valid
cases for any spec, the earlier families' draws unchanged, and on the semantic zoo (tests/sut/
semantic_zoo.yaml, driven through a real Interceptor without processes) each family reaching its own
seeded defect and no other family reaching it."""

from __future__ import annotations

import hashlib
import math
import random
from collections import Counter
from pathlib import Path

import pytest

from astaa_deft.io.codecs import get_codec
from astaa_deft.model.errors import InputError
from astaa_deft.engine.intercept import Interceptor, load_testcase, parse_testcase
from astaa_deft.engine.intercept import generate as gen
from astaa_deft.engine.intercept.dictionary import FieldSite, NotApplicable, ValueContext
from astaa_deft.engine.intercept.faults import FAMILIES, weights
from astaa_deft.model.sut import FieldType
from astaa_deft.engine.spec.loader import load_spec
from zoo_helpers import DICTIONARY, SEMANTIC, ZOO_SPEC, reached

ROOT = Path(__file__).resolve().parent.parent
FAULTS_DIR = ROOT / "astaa_deft" / "engine" / "intercept" / "faults"
OMPL_SPEC = load_spec(ROOT / "examples" / "ompl_stack" / "spec.yaml")
JSON = get_codec("json")


def family(description: str) -> str:
    return description.split(":")[0]


# ---------------------------------------------------------------- the registry

def test_every_family_is_one_module_of_the_package_registered_by_name():
    assert set(FAMILIES.names()) == set(gen.EXCEPTIONAL) | set(SEMANTIC)
    modules = {path.stem for path in FAULTS_DIR.glob("*.py")} - {"__init__", "base"}
    assert {type(f).__module__.rsplit(".", 1)[1] for f in FAMILIES.values()} == modules  # one file each
    ranks = [f.rank for f in FAMILIES.values()]
    assert len(set(ranks)) == len(ranks)
    assert list(weights())[:6] == list(gen.EXCEPTIONAL)  # the earlier families keep their place in the draw
    assert {f.name for f in FAMILIES.values() if f.semantic} == set(SEMANTIC)


def test_the_earlier_families_draw_byte_for_byte_what_they_drew_before_the_semantic_ones():
    """The hash of the release before the registry (generate.py's if-chain) for this spec, count and seed."""
    digest = hashlib.sha256()
    for testcase in gen.generate(OMPL_SPEC, DICTIONARY, 400, seed=3, families=gen.EXCEPTIONAL):
        digest.update(testcase.to_xml())
    assert digest.hexdigest() == "19851caaea7f6453475967aa2b43ddd0be4b57170cdb426808ee46e71fa9eb2e"


def test_an_unknown_family_is_an_input_error_naming_the_known_ones(tmp_path):
    with pytest.raises(InputError, match="unknown fault family 'bondary'") as caught:
        gen.generate_to_directory(ZOO_SPEC, tmp_path / "out",
                                  gen.GenerateOptions(count=3, seed=1, families=["bondary"]))
    assert "boundary" in caught.value.problems[0].fix


# ---------------------------------------------------------------- the values

def rule(name: str, current, kind: str = "float64", **declared):
    entry = next(e for e in DICTIONARY.entries.values() if e.rule == name)
    site = FieldSite(FieldType(kind=kind, **declared))
    return entry.resolve(ValueContext(site=site, current=current, container={}, key="f", previous=lambda: current))


def test_semantic_rules_give_plausible_but_wrong_values():
    assert rule("at_max", 3.0, minimum=0.0, maximum=30.0) == 30.0
    assert rule("at_min", 3.0, "int32", minimum=-5, maximum=5) == -5
    assert rule("sign_flipped", 2.5) == -2.5
    assert rule("plus_2pi", 0.1) == pytest.approx(0.1 + 2 * math.pi)
    assert rule("minus_pi", 0.1) == pytest.approx(0.1 - math.pi)
    assert rule("unwrapped", 0.1) == pytest.approx(0.1 + 4 * math.pi)
    assert (rule("times_1000", 2.5), rule("div_1000", 2500.0)) == (2500.0, 2.5)
    assert rule("times_1000", 7, "uint32") == 7000
    assert rule("rad_to_deg", math.pi) == pytest.approx(180.0)
    assert rule("deg_to_rad", 180.0) == pytest.approx(math.pi)
    points = [{"id": i, "s": float(i)} for i in range(6)]
    assert rule("reversed", points, "array") == points[::-1]
    shuffled = rule("shuffled", points, "array")
    assert shuffled != points and sorted(shuffled, key=lambda p: p["id"]) == points
    assert rule("cut_to_half", points, "array") == points[:3]
    assert [p["id"] for p in rule("element_duplicated", points, "array")] == [0, 1, 2, 3, 3, 4, 5]
    assert [p["id"] for p in rule("two_swapped", points, "array")] == [1, 0, 2, 3, 4, 5]
    for name, current in (("sign_flipped", 0.0), ("times_1000", float("nan")), ("reversed", [1])):
        with pytest.raises(NotApplicable):
            rule(name, current, "array" if name == "reversed" else "float64")


def test_the_earlier_families_never_draw_a_semantic_entry():
    owned = {key for f in FAMILIES.values() for key in f.owns}
    assert owned and all(key in DICTIONARY for key in owned)
    for target in gen.mutation_targets(OMPL_SPEC, DICTIONARY):
        assert not {entry.key for entry in target.values} & owned


# ---------------------------------------------------------------- where they act

def test_each_family_finds_its_own_fields_on_the_zoo():
    targets = gen.FaultTargets.of(ZOO_SPEC, DICTIONARY)

    def fields(name):
        return {str(t.path) for t in targets.by_family[name]["state"]}

    assert fields("angle") == {"pose.heading"}
    assert fields("arrays") == {"path"}
    assert {(str(t.path), str(t.partner)) for t in targets.by_family["siblings"]["state"]} == {
        ("pose.x", "pose.y"), ("pose.y", "pose.heading"), ("speed", "odometer"), ("odometer", "battery")}
    boundary = {str(t.path): [e.name for e in t.values] for t in targets.by_family["boundary"]["state"]}
    assert boundary["speed"][:2] == ["at_max", "at_min"]  # declared bounds first
    assert "at_max" not in boundary["odometer"]  # no declared range: zero, -0 and the sign flip only
    for name in SEMANTIC:  # never a header's stamp or sequence number
        assert not any(str(t.path).startswith("header") for t in targets.by_family[name]["state"])


@pytest.mark.parametrize("spec", [ZOO_SPEC, OMPL_SPEC], ids=["zoo", "ompl"])
def test_every_semantic_case_passes_policy_check(tmp_path, spec):
    report = gen.generate_to_directory(spec, tmp_path / "cases",
                                       gen.GenerateOptions(count=200, seed=4, duration=12.0, families=SEMANTIC))
    assert set(report.shapes) == set(SEMANTIC)
    for path in report.paths:
        testcase = load_testcase(path, spec, DICTIONARY)  # the XSD, then channels, fields and values
        assert family(testcase.description) in SEMANTIC


# ---------------------------------------------------------------- the actions they added

def run_case(policy_xml: str, message: dict) -> tuple[dict, dict]:
    """What one message becomes under one policy on the zoo's channel, and its event's detail."""
    xml = (f'<testcase id="t" seed="1"><description/><policy id="p"><channel>state</channel>{policy_xml}</policy>'
           '</testcase>')
    interceptor = Interceptor(parse_testcase(xml.encode(), "t.xml", ZOO_SPEC, DICTIONARY), ZOO_SPEC, DICTIONARY)
    [delivery] = interceptor.on_message("state", ("consumer",), JSON.encode(message), 0.5)
    assert delivery.event is not None
    return JSON.decode(delivery.payload), dict(delivery.event.detail)


def test_remove_takes_fields_out_and_swap_exchanges_siblings():
    from zoo_helpers import SOURCE

    state = SOURCE.state(3)
    sent, event = run_case('<remove><field path="battery"/><field path="path[*].id"/></remove>', state)
    assert "battery" not in sent and all("id" not in p for p in sent["path"]) and sent["speed"] == state["speed"]
    assert event["removed"][:2] == ["battery", "path[0].id"]
    sent, _ = run_case('<swap a="pose.x" b="pose.y"/>', state)
    assert (sent["pose"]["x"], sent["pose"]["y"]) == (state["pose"]["y"], state["pose"]["x"])
    sent, _ = run_case('<swap a="path[*].id" b="path[*].s"/>', state)
    assert [(p["id"], p["s"]) for p in sent["path"]] == [(p["s"], p["id"]) for p in state["path"]]
    sent, event = run_case('<remove><field path="battery"/></remove>', {k: v for k, v in state.items()
                                                                       if k != "battery"})
    assert event["skipped"] == "no such field in this message"


def test_hold_freezes_fields_at_the_value_before_its_window():
    from zoo_helpers import SOURCE

    xml = ('<testcase id="t" seed="1"><description/><policy id="p"><channel>state</channel>'
           '<window from="0.12"/><select limit="4"/><hold><field path="odometer"/><field path="path[*].s"/></hold>'
           '</policy></testcase>')
    interceptor = Interceptor(parse_testcase(xml.encode(), "t.xml", ZOO_SPEC, DICTIONARY), ZOO_SPEC, DICTIONARY)
    sent = []
    for i in range(1, 9):  # at 0.05 s … 0.4 s: messages 3-6 are selected, 2 is the one before
        [delivery] = interceptor.on_message("state", ("consumer",), JSON.encode(SOURCE.state(i)), i * 0.05)
        sent.append(JSON.decode(delivery.payload)["odometer"])
    real = [SOURCE.state(i)["odometer"] for i in range(1, 9)]
    assert sent == real[:2] + [real[1]] * 4 + real[6:]
    first = Interceptor(parse_testcase(xml.replace('from="0.12"', 'from="0"').encode(), "t.xml", ZOO_SPEC,
                                       DICTIONARY), ZOO_SPEC, DICTIONARY)
    [delivery] = first.on_message("state", ("consumer",), JSON.encode(SOURCE.state(1)), 0.05)
    assert delivery.event.detail["skipped"] == "no previous message on this channel"


@pytest.mark.parametrize("policy, says", [
    ('<remove><field path="path[0]"/></remove>', "ends in an array index"),
    ('<remove><field path="pose.z"/></remove>', "Pose has no field 'z'"),
    ('<swap a="path[*].s" b="pose.x"/>', "wildcards are for two fields of one struct"),
    ('<swap a="speed" b="speed"/>', "the same field"),
])
def test_bad_remove_and_swap_policies_are_reported(policy, says):
    xml = f'<testcase id="t" seed="1"><description/><policy id="p"><channel>state</channel>{policy}</policy></testcase>'
    with pytest.raises(InputError, match=says.replace("[", r"\[")):
        parse_testcase(xml.encode(), "t.xml", ZOO_SPEC, DICTIONARY)


def test_the_semantic_schedule_tries_every_value_of_every_target_once_a_pass_the_families_in_turn():
    targets = gen.FaultTargets.of(ZOO_SPEC, DICTIONARY)
    order, totals = gen._semantic_pass(targets)
    assert len(order) == sum(totals.values()) and totals["angle"] == 5 and totals["type"] == 11 * 5
    probes = [gen.semantic_probe(targets, 1, number) for number in range(len(order))]
    assert [probe.family for probe, _ in probes[:7]] == [f.name for f in targets.semantic()]  # one turn each
    for name in SEMANTIC:
        family_ = FAMILIES[name]
        tried = {(str(probe.target.path), lap % family_.visits(probe.target)) for probe, lap in probes
                 if probe.family == name}
        every = {(str(t.path), v) for t in targets.by_family[name]["state"] for v in range(family_.visits(t))}
        assert tried == every, name
    # the next pass starts again, in other seeded orders
    again = [gen.semantic_probe(targets, 1, len(order) + n)[0].family for n in range(7)]
    assert again == [f.name for f in targets.semantic()]


# ---------------------------------------------------------------- the zoo

def zoo_cases():
    """(family, case): generate's weighted draws (every family), the campaign's weighted draws (message
    faults too) and its first 300 semantic probes."""
    cases = [(family(t.description), t) for t in gen.generate(ZOO_SPEC, DICTIONARY, 150, seed=1, duration=3.0)]
    targets = gen.FaultTargets.of(ZOO_SPEC, DICTIONARY)
    for number in range(50):
        testcase = gen.weighted_testcase(f"w{number}", random.Random(number), targets, 3.0, message_faults=True)
        cases.append((family(testcase.description), testcase))
    for number in range(300):  # about 40 probes a family: every zoo target, most of their values
        found = gen.semantic_probe(targets, 1, number)
        assert found is not None
        probe, lap = found
        cases.append((probe.family, gen.probe_testcase(f"s{number}", random.Random(number), probe, lap, duration=3.0)))
    return cases


def test_on_the_zoo_each_family_reaches_its_own_defect_and_no_other_and_defects_off_is_clean():
    hits: Counter[tuple[str, str]] = Counter()
    for name, testcase in zoo_cases():
        defect = reached(testcase, defects=True)
        if defect is not None:
            hits[(name, defect)] += 1
        assert reached(testcase, defects=False) is None, testcase.description
    assert {defect for _, defect in hits} == set(SEMANTIC)  # every seeded defect is reached …
    assert all(name == defect for name, defect in hits), hits  # … by its own family only


def test_a_family_is_one_class_registered_by_name_and_generate_draws_it():
    """What docs/policies.md shows for "Adding a fault family", registered here and taken out again."""
    from astaa_deft.engine.intercept.faults.base import ValueFamily
    from astaa_deft.model.sut import FLOAT_KINDS

    class SpeedLimit(ValueFamily):
        name = "speed_limit"
        weight = 3
        rank = 99
        keys_of_kind = {kind: ("float.at_max", "float.above_max") for kind in FLOAT_KINDS}

        def accepts(self, channel, path, field_type):
            return "speed" in str(path)

    FAMILIES.register(SpeedLimit.name, SpeedLimit())
    try:
        cases = gen.generate(ZOO_SPEC, DICTIONARY, 20, seed=1, families=["speed_limit"])
        assert {(family(c.description), c.policies[0].action.fields[0].path) for c in cases} == {
            ("speed_limit", "speed")}
        assert {c.policies[0].action.fields[0].value for c in cases} == {"dict:float.at_max", "dict:float.above_max"}
        assert "speed_limit" in weights()
    finally:
        FAMILIES.unregister(SpeedLimit.name)
    assert "speed_limit" not in FAMILIES
