"""The participant action: rendered into the demo's prediction messages through the real engine and
codec, read from and written back to XML, and clear errors for a spec without a mapping or a bad one."""

from __future__ import annotations

import copy
from pathlib import Path

import pytest

from astaa_deft.io.codecs import get_codec
from astaa_deft.model.errors import InputError
from astaa_deft.engine.intercept import Interceptor, load_dictionary, parse_testcase
from astaa_deft.engine.intercept.actions.participant import MappingError, Participant, Waypoint, read_mappings
from astaa_deft.engine.spec.loader import load_spec, load_spec_text

ROOT = Path(__file__).resolve().parent.parent
SPEC_PATH = ROOT / "specs" / "demo_av.yaml"
SPEC = load_spec(SPEC_PATH)
JSON = get_codec("json")


def policy_xml(action: str, channel: str = "prediction", window: str = "") -> str:
    return (f'<testcase id="tc" seed="1"><description/><policy id="p1"><channel>{channel}</channel>{window}'
            f'{action}</policy></testcase>')


def prediction(stamp: float, seq: int = 1) -> bytes:
    return JSON.encode({"header": {"seq": seq, "stamp": stamp}, "obstacles": [
        {"id": 1, "kind": "vehicle", "length": 4.6, "width": 1.9,
         "trajectory": [{"t": stamp, "x": 50.0, "y": 0.0, "heading": 0.0}]}]})


MOVING = ('<participant id="902" kind="vehicle" x="30" y="3.5" t="1"><at t="3" x="50" y="3.5"/>'
          '<at t="5" x="50" y="7"/></participant>')


def test_a_moving_participant_is_appended_with_its_true_predicted_trajectory():
    engine = Interceptor(parse_testcase(policy_xml(MOVING).encode(), "tc.xml", SPEC), SPEC, load_dictionary())
    [delivery] = engine.on_message("prediction", ("planning",), prediction(2.0), 0.5)
    message = JSON.decode(delivery.payload)
    assert [o["id"] for o in message["obstacles"]] == [1, 902]
    added = message["obstacles"][1]
    assert added["kind"] == "vehicle" and added["length"] == 4.6
    trajectory = added["trajectory"]
    assert len(trajectory) == 51 and trajectory[0]["t"] == 2.0 and trajectory[-1]["t"] == 7.0
    assert trajectory[0]["x"] == pytest.approx(40.0) and trajectory[0]["y"] == pytest.approx(3.5)
    assert trajectory[10]["x"] == pytest.approx(50.0)  # t = 3: the first waypoint
    assert trajectory[20]["y"] == pytest.approx(5.25) and trajectory[30]["y"] == pytest.approx(7.0)  # t = 4, 5
    assert trajectory[-1] == {"t": 7.0, "x": 50.0, "y": 7.0, "heading": pytest.approx(1.5707963)}
    assert delivery.event is not None and delivery.event.action == "participant"
    assert delivery.event.detail["participant"] == 902 and delivery.event.detail["x"] == pytest.approx(40.0)


def test_a_static_participant_stays_put_and_other_channels_are_untouched():
    static = '<participant id="901" kind="cone" x="60" y="-2.9" length="0.5" width="0.5"/>'
    engine = Interceptor(parse_testcase(policy_xml(static).encode(), "tc.xml", SPEC), SPEC, load_dictionary())
    for stamp in (0.0, 4.0):
        [delivery] = engine.on_message("prediction", ("planning",), prediction(stamp), stamp)
        cone = JSON.decode(delivery.payload)["obstacles"][-1]
        assert {(p["x"], p["y"]) for p in cone["trajectory"]} == {(60.0, -2.9)}
    payload = JSON.encode({"header": {"seq": 1, "stamp": 0.0}, "x": 1.0})
    [untouched] = engine.on_message("localization", ("planning",), payload, 0.1)
    assert untouched.payload is payload and untouched.event is None


def test_only_messages_inside_the_window_get_the_participant():
    engine = Interceptor(parse_testcase(policy_xml(MOVING, window='<window from="1" to="2"/>').encode(), "tc.xml",
                                        SPEC), SPEC, load_dictionary())
    counts = []
    for now in (0.5, 1.5, 2.5):
        [delivery] = engine.on_message("prediction", ("planning",), prediction(now), now)
        counts.append(len(JSON.decode(delivery.payload)["obstacles"]))
    assert counts == [1, 2, 1]


def test_xml_round_trip():
    case = parse_testcase(policy_xml(MOVING).encode(), "tc.xml", SPEC)
    action = case.policies[0].action
    assert action == Participant(id=902, kind="vehicle", x=30.0, y=3.5, heading=0.0, length=4.6, width=1.9, t=1.0,
                                 path=(Waypoint(3.0, 50.0, 3.5), Waypoint(5.0, 50.0, 7.0)))
    assert parse_testcase(case.to_xml(), "again.xml", SPEC) == case


def test_waypoint_times_must_increase():
    bad = '<participant id="1" x="0" y="0" t="4"><at t="3" x="1" y="1"/></participant>'
    with pytest.raises(InputError) as err:
        parse_testcase(policy_xml(bad).encode(), "tc.xml", SPEC)
    assert "waypoint times must increase" in str(err.value)


def test_a_channel_without_mapping_is_a_clear_error():
    with pytest.raises(InputError) as err:
        parse_testcase(policy_xml(MOVING, channel="obstacles").encode(), "tc.xml", SPEC)
    text = str(err.value)
    assert "channel 'obstacles' has no participant mapping" in text and "decictor: participants:" in text


def spec_with(section: str) -> str:
    text = SPEC_PATH.read_text()
    return text[:text.index("\ndecictor:")] + "\n" + section


def test_a_spec_without_decictor_section_names_what_is_missing():
    spec = load_spec_text(spec_with(""))
    with pytest.raises(InputError) as err:
        parse_testcase(policy_xml(MOVING).encode(), "tc.xml", spec)
    assert "no 'decictor: participants:' section" in str(err.value)


@pytest.mark.parametrize("mapping, message", [
    ("{channel: nowhere, array: obstacles, fields: {id: id}}", "unknown channel 'nowhere'"),
    ("{channel: prediction, array: obstacle, fields: {id: id}}", "has no field 'obstacle[*]'"),
    ("{channel: prediction, array: obstacles, fields: {idd: id}}", "'idd' is not a participant attribute"),
    ("{channel: prediction, array: obstacles, fields: {x: x}}", "has no field 'obstacles[*].x'"),
    ("{channel: prediction, array: header, fields: {id: seq}}", "not an array"),
    ("{channel: prediction, array: obstacles, fields: {id: id}, trajectory: {array: trajectory, t: t, x: x}}",
     "missing 'y'"),
])
def test_bad_mappings_are_named(mapping, message):
    # The loader refuses a bad shape or an unknown channel (with its line); the mapping check refuses a field
    # the channel's type lacks.
    with pytest.raises((InputError, MappingError)) as err:
        read_mappings(load_spec_text(spec_with(f"decictor:\n  participants:\n    - {mapping}\n")))
    assert message in str(err.value)


def test_rendering_does_not_touch_the_test_case():
    action = parse_testcase(policy_xml(MOVING).encode(), "tc.xml", SPEC).policies[0].action
    before = copy.deepcopy(action)
    assert action.pose_at(4.0).y == pytest.approx(5.25) and action == before


# ---------------------------------------------------------------- participants on a wall-clock stack

WALL = 1.8e9  # a stack stamping with epoch seconds (2027)


def test_a_participant_at_epoch_seconds_is_accepted_and_applied():
    at_wall = (f'<participant id="903" kind="vehicle" x="30" y="3.5" t="{WALL + 1:.1f}">'
               f'<at t="{WALL + 3:.1f}" x="50" y="3.5"/></participant>')
    case = parse_testcase(policy_xml(at_wall).encode(), "tc.xml", SPEC)  # the XSD, then the spec
    [policy] = case.policies
    assert policy.action.t == WALL + 1 and policy.action.path == (Waypoint(WALL + 3, 50.0, 3.5),)
    assert parse_testcase(case.to_xml(), "again.xml", SPEC) == case  # written back without an exponent
    assert 't="1800000001"' in case.to_xml().decode()
    engine = Interceptor(case, SPEC, load_dictionary())
    [delivery] = engine.on_message("prediction", ("planning",), prediction(WALL + 2), 0.5)
    added = JSON.decode(delivery.payload)["obstacles"][-1]
    assert added["id"] == 903 and added["trajectory"][0]["t"] == WALL + 2
    assert added["trajectory"][0]["x"] == pytest.approx(40.0)  # halfway along its path at its own clock
    assert delivery.event is not None and delivery.event.detail["x"] == pytest.approx(40.0)


def test_decictor_search_on_a_wall_clock_stack_proposes_valid_test_cases():
    from astaa_deft.orchestration.campaign.strategies.decictor import area_around, scene_of, scene_testcase
    from astaa_deft.analysis.decictor.feasible import ForbiddenRegion, check_placement
    from astaa_deft.analysis.decictor.oracle import LaneGrid, RunObservation, straight_lanes
    from astaa_deft.analysis.decictor.paths import EgoPath, EgoState
    from astaa_deft.analysis.decictor.search import Search

    lanes = straight_lanes(2, 3.5, 300.0)
    seed = RunObservation(EgoPath(tuple(EgoState(t=WALL + k * 0.1, x=10.0 + k * 1.2, y=0.0, heading=0.0, speed=12.0)
                                        for k in range(101))), True)
    search = Search("decictor", 1, seed, LaneGrid(lanes), area=area_around(seed, lanes),
                    region=ForbiddenRegion(seed.ego, clearance=1.5))
    participants = 0
    for number in range(1, 9):
        scene = search.propose(number)
        testcase = scene_testcase(scene, f"tc-{number:06d}", number, "prediction")
        read = parse_testcase(testcase.to_xml(), "tc", SPEC, load_dictionary())  # valid: XSD, spec and mapping
        assert scene_of(read).participants == scene.participants
        for participant in scene.participants:
            check_placement(participant, search.region)
            assert WALL <= participant.t <= WALL + 10.0  # on the seed's clock
            participants += 1
        search.observe(scene, seed)
    assert participants
