"""The search and the campaign strategy's plumbing, on synthetic observations (no runs): deterministic
proposals, every proposal feasible, the elitist selection keeping the best, findings leaving the pool,
test case XML round trips, and the strategy's clear errors."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

from astaa_deft.orchestration.campaign.strategies.decictor import (
    DecictorStrategy, area_around, scene_of, scene_testcase,
)
from astaa_deft.analysis.decictor.config import read_config
from astaa_deft.analysis.decictor.feasible import ForbiddenRegion, check_placement
from astaa_deft.analysis.decictor.oracle import LaneGrid, RunObservation, straight_lanes
from astaa_deft.analysis.decictor.paths import EgoPath, EgoState
from astaa_deft.analysis.decictor.search import MODES, Search
from astaa_deft.model.errors import InputError
from astaa_deft.engine.intercept.dictionary import load_dictionary
from astaa_deft.engine.intercept.testcase import parse_testcase
from astaa_deft.engine.spec.decictor_section import DecictorSection
from astaa_deft.engine.spec.loader import load_spec, load_spec_text

SPEC_PATH = Path(__file__).resolve().parent.parent / "specs" / "demo_av.yaml"
SPEC = load_spec(SPEC_PATH)
LANES = straight_lanes(2, 3.5, 300.0)


def straight(y: float = 0.0) -> EgoPath:
    return EgoPath(tuple(EgoState(t=k * 0.1, x=10.0 + k * 1.2, y=y, heading=0.0, speed=12.0) for k in range(101)))


SEED = RunObservation(straight(), True)


def search(mode: str, seed: int = 1) -> Search:
    return Search(mode, seed, SEED, LaneGrid(LANES), area=area_around(SEED, LANES),
                  region=ForbiddenRegion(SEED.ego, clearance=1.5))


@pytest.mark.parametrize("mode", MODES)
def test_proposals_are_deterministic_and_feasible(mode):
    a, b = search(mode), search(mode)
    for number in range(1, 9):
        scene = a.propose(number)
        assert scene == b.propose(number)
        for participant in scene.participants:
            check_placement(participant, a.region)
        assert len({p.id for p in scene.participants}) == len(scene.participants)
        a.observe(scene, SEED)
        b.observe(scene, SEED)


def test_selection_keeps_the_best_and_findings_leave_the_pool():
    s = search("decictor")
    scenes = [s.propose(n) for n in range(1, 5)]
    detour = EgoPath(tuple(EgoState(t=st.t, x=st.x, y=3.5 if 50 < st.x < 90 else 0.0, heading=0.0, speed=12.0)
                           for st in straight().states))
    s.observe(scenes[0], RunObservation(straight(0.4), True))  # a little off: the best fitness
    s.observe(scenes[1], RunObservation(detour, True))  # non-optimal: a finding
    s.observe(scenes[2], RunObservation(straight(), False))  # task failed
    s.observe(scenes[3], SEED)
    assert s.stats.findings == 1 and s.stats.task_failed == 1
    assert s.population[0].scene == scenes[0] and s.population[0].fitness > 0
    assert scenes[1] not in [m.scene for m in s.population]


def test_the_seed_must_reach_its_goal():
    with pytest.raises(ValueError, match="seed run must reach its goal"):
        Search("decictor", 1, RunObservation(straight(), False), LaneGrid(LANES), area=area_around(SEED, LANES),
               region=ForbiddenRegion(SEED.ego))


def test_scene_testcase_round_trips_through_a_checked_test_case():
    scene = search("random").propose(3)
    testcase = scene_testcase(scene, "tc-000003", 3, "prediction")
    read = parse_testcase(testcase.to_xml(), "tc", SPEC, load_dictionary())  # valid against XSD, spec and mapping
    assert scene_of(read).participants == scene_of(testcase).participants == scene.participants


def without(key: str) -> str:
    text = SPEC_PATH.read_text()
    section = text.index("\ndecictor:")
    start = text.index(f"\n  {key}:", section)
    end = re.compile(r"\n  [a-z#]").search(text, start + 1)
    return text[:start] + (text[end.start():] if end else "\n")


@pytest.mark.parametrize("key, message", [
    ("lanes", "no 'lanes': the consistency check needs the ego's lanes"),
    ("ego", "no 'ego: {channel: …}'"),
    ("goal", "no 'goal: {channel: …, field: …}'"),
    ("participants", "no 'decictor: participants:' section"),
])
def test_missing_parts_of_the_section_are_named(key, message):
    spec = load_spec_text(without(key))
    with pytest.raises(InputError) as err:
        DecictorStrategy(spec, load_dictionary(), 0, 15.0)
    assert message in str(err.value)


def test_lanes_from_a_file(tmp_path):
    (tmp_path / "lanes.yaml").write_text("lanes:\n  - {id: a, width: 3.5, centre: [[0, 0], [100, 0]]}\n")
    text = SPEC_PATH.read_text().replace(
        "    channel: routing              # straight lanes along +x: lane i centred on y = i * width\n"
        "    straight: {count: lane_count, width: lane_width, length: road_length}\n", "    file: lanes.yaml\n")
    (tmp_path / "spec.yaml").write_text(text)
    config = read_config(load_spec(tmp_path / "spec.yaml"))
    assert config.lanes.file == (tmp_path / "lanes.yaml").resolve()
    (tmp_path / "lanes.yaml").write_text("lanes: 3\n")
    with pytest.raises(InputError, match="not a lanes file"):
        read_config(load_spec(tmp_path / "spec.yaml"))


def test_the_section_is_typed_by_the_loader():
    section = SPEC.decictor
    assert isinstance(section, DecictorSection)
    assert section.ego is not None and section.ego.length == 4.6 and section.ego.x == "x"
    assert section.lanes is not None and section.lanes.channel == "routing" and section.lanes.straight["count"] \
        == "lane_count"
    assert section.clearance == 1.5 and section.dt is None and section.goal is not None


@pytest.mark.parametrize("old, new, message", [
    ("  clearance: 1.5", "  clearance: -1", "decictor.clearance must be a number from 0 to 100, not int -1"),
    ("  clearance: 1.5", "  clearence: 1.5", "unknown key 'clearence' in 'decictor' — did you mean 'clearance'?"),
    ("        length: 4.6, width: 1.9}", "        length: long, width: 1.9}", "decictor.ego.length must be a number"),
    ("  goal: {channel: status, field: goal_reached}", "  goal: {channel: statu, field: goal_reached}",
     "decictor.goal.channel: unknown channel 'statu'"),
    ("    straight: {count: lane_count, width: lane_width, length: road_length}\n", "",
     "decictor.lanes: needs 'file', or 'channel' with 'straight"),
])
def test_a_bad_section_is_refused_at_load_with_its_line(old, new, message):
    text = SPEC_PATH.read_text()
    assert old in text
    with pytest.raises(InputError) as err:
        load_spec_text(text.replace(old, new))
    problem = err.value.problems[0]
    assert message in str(err.value) and problem.line is not None and problem.line > text[:text.index(
        "\ndecictor:")].count("\n")


def test_removal_never_gives_back_the_seed_scene():
    # Regression: removing the only added participant re-ran the seed itself, a scenario that can
    # teach nothing (traces of 54-scenario searches had up to a fifth of them empty).
    for mode in ("decictor", "random-delta"):
        s = search(mode)
        for number in range(1, 41):
            scene = s.propose(number)
            assert scene.participants, (mode, number, scene.operator)
            s.observe(scene, SEED)
