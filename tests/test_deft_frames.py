"""DeFT frame reconstruction heuristics, on crafted message streams (times in ms → ns)."""

from __future__ import annotations

import pkgutil
from collections.abc import Iterator

import astaa_deft.analysis.deft.frames.rules as rules_package
from astaa_deft.analysis.deft.frames import (
    FRAME_RULES, FrameRule, OutputContext, Stream, Trigger, candidates, frame_at, newest_at_or_before,
    trigger_candidates,
)
from astaa_deft.analysis.deft.frames.rule import register
from astaa_deft.analysis.deft.search_policy import likely_ways

MS = 1_000_000


def streams(**times_ms):
    return {name: Stream(name, [int(t * MS) for t in ts]) for name, ts in times_ms.items()}


def test_newest_at_or_before():
    times = [10, 20, 30]
    assert newest_at_or_before(times, 5) == -1
    assert newest_at_or_before(times, 20) == 1
    assert newest_at_or_before(times, 29) == 1
    assert newest_at_or_before(times, 99) == 2


def test_trigger_bound_first_candidate_is_the_snapshot_at_the_trigger():
    s = streams(trigger=[100, 200], pose=[90, 110, 190, 205, 215], route=[5])
    c = candidates(OutputContext(streams=s, trigger="trigger", output_ns=int(220 * MS), previous={}, lookback_ns=0))
    # The trigger is the newest at or before the output; the first frame time is the trigger's.
    assert c[0].choice["trigger"] == 1
    assert c[0].frame_time == 200 * MS
    assert c[0].choice["pose"] == 2  # newest pose at or before 200 ms (190)


def test_later_candidates_follow_in_time_order_and_stay_before_the_output():
    s = streams(trigger=[100, 200], pose=[90, 110, 190, 205, 215, 230], route=[5])
    c = candidates(OutputContext(streams=s, trigger="trigger", output_ns=int(220 * MS), previous={}, lookback_ns=0))
    newest = [x for x in c if x.choice["trigger"] == 1]
    assert c[:3] == newest  # the newest trigger's candidates come first
    assert [x.choice["pose"] for x in newest] == [2, 3, 4]  # 190, then 205, then 215 — never 230 (after t_P)
    assert [x.frame_time for x in newest] == [200 * MS, 205 * MS, 215 * MS]
    # A first output may answer an older trigger (a slow first cycle): those follow, also before t_P.
    assert all(x.choice["trigger"] == 0 for x in c[3:]) and all(x.choice["pose"] != 5 for x in c)


def test_monotonic_per_channel():
    s = streams(trigger=[100, 200], pose=[90, 150, 190])
    # The previous frame already used pose #2 (190 ms): a frame may not go back to #1.
    c = candidates(OutputContext(streams=s, trigger="trigger", output_ns=int(120 * MS), previous={"pose": 2},
                                 lookback_ns=0))
    assert c[0].choice["pose"] == 2


def test_lone_message_is_reused_even_if_logged_after_the_frame_time():
    s = streams(trigger=[100], pose=[90], route=[150])
    c = candidates(OutputContext(streams=s, trigger="trigger", output_ns=int(160 * MS), previous={}, lookback_ns=0))
    assert c[0].choice["route"] == 0


def test_an_input_with_no_message_yet_is_left_out_of_the_frame():
    # A module's first cycles may run before an input's first message: the frame lacks it.
    s = streams(trigger=[100], pose=[150, 160])
    c = candidates(OutputContext(streams=s, trigger="trigger", output_ns=int(120 * MS), previous={}, lookback_ns=0))
    assert [dict(x.choice) for x in c] == [{"trigger": 0}]
    assert frame_at(s, "trigger", 0, 120 * MS, {}) is None  # a complete frame: none yet
    assert frame_at(s, "trigger", 0, 120 * MS, {}, absent=True) == {"trigger": 0}


def test_a_frame_without_an_input_is_as_likely_as_its_time():
    # At the trigger's own time pose had not arrived (a module latching its inputs then had none); later it had.
    s = streams(trigger=[100], pose=[110, 160])
    c = candidates(OutputContext(streams=s, trigger="trigger", output_ns=int(120 * MS), previous={}, lookback_ns=0))
    assert [dict(x.choice) for x in c] == [{"trigger": 0}, {"trigger": 0, "pose": 0}]


def test_lookback_candidates_come_last_newest_first():
    # pose #1 was logged 2 ms before the trigger: the planner may not have had it yet.
    s = streams(trigger=[100], pose=[80, 98, 105])
    c = candidates(OutputContext(streams=s, trigger="trigger", output_ns=int(110 * MS), previous={},
                                 lookback_ns=10 * MS))
    assert [x.choice["pose"] for x in c] == [1, 2, 0]  # at trigger, later, then just before #1


def test_candidates_are_distinct_message_sets():
    s = streams(trigger=[100], pose=[90, 101, 102], speed=[95, 101])
    c = candidates(OutputContext(streams=s, trigger="trigger", output_ns=int(110 * MS), previous={}, lookback_ns=0))
    sets = [tuple(sorted(x.choice.items())) for x in c]
    assert len(sets) == len(set(sets))
    assert len(c) == 3  # at 100, at 101 (pose #1 and speed #1 together), at 102


def test_a_per_trigger_frame_may_use_an_input_logged_just_after_the_answer():
    # Seen under load (control replayed from a demo run): the planner's trajectories 34-36 reached the
    # recorder in one burst, 3.9 ms after the command that control had computed from trajectory 34. With
    # the answer's log time as the bound, that frame was no candidate: the replay diverged from there on.
    streams = {"localization": Stream("localization", [0, 20 * MS, 40 * MS]),
               "trajectory": Stream("trajectory", [-50 * MS, 24 * MS, 26 * MS])}
    answered = 20 * MS + 100_000  # the answer to localization 1, logged before trajectory 1
    without = trigger_candidates(streams, "localization", 1, {"trajectory": 0}, lookback_ns=0, answered_at=answered)
    assert {"localization": 1, "trajectory": 1} not in without
    found = trigger_candidates(streams, "localization", 1, {"trajectory": 0}, lookback_ns=0, answered_at=answered,
                               skew_ns=5 * MS)
    assert found[0] == {"localization": 1, "trajectory": 0}  # the frame at the trigger still comes first
    assert {"localization": 1, "trajectory": 1} in found and {"localization": 1, "trajectory": 2} not in found


def test_a_burst_of_outputs_answers_the_last_triggers_before_it():
    # Seen under load: control, still without a trajectory, queued three localizations and answered
    # them all at once when its first trajectory came. Before, each of the first two was taken to be
    # answered with nothing (its answer was logged after the next trigger) and the pairing slipped.
    from types import SimpleNamespace

    from astaa_deft.analysis.deft.extract.per_trigger import answered_in_turn

    triggers = [0, 20 * MS, 40 * MS, 60 * MS, 80 * MS]
    burst = [SimpleNamespace(log_time=t) for t in (62 * MS, 62 * MS + 300_000, 62 * MS + 500_000, 81 * MS)]
    assert [answered_in_turn(triggers, i, burst, 0) for i in range(4)] == [False, True, True, True]
    # One output a period: a trigger whose answer comes after the next trigger got none (as before).
    steady = [SimpleNamespace(log_time=t) for t in (45 * MS, 65 * MS)]
    assert [answered_in_turn(triggers, i, steady, 0) for i in range(3)] == [False, False, True]


def test_a_trigger_logged_just_after_an_output_may_be_the_one_it_answers():
    # Seen under load: control's first command was logged 0.04 ms before the localization it answered.
    # Read in the recorder's order, the localization before it got that answer from a trajectory logged
    # after it (which also matched: the vehicle had not moved yet), every later pairing slipped by one and
    # 51 of 310 frames reproduced where a plain replay's pairing holds. Within the skew, the trigger before
    # may have got no answer, so the plain frame (answering nothing) stands.
    from types import SimpleNamespace

    from astaa_deft.analysis.deft.extract.per_trigger import answered_in_turn

    triggers = [0, 20 * MS, 40 * MS + 40_000, 60 * MS]
    first = [SimpleNamespace(log_time=t) for t in (40 * MS, 61 * MS)]
    assert answered_in_turn(triggers, 1, first, 0)  # in the recorder's order, trigger 1 came last before it
    assert not answered_in_turn(triggers, 1, first, 0, skew_ns=5 * MS)
    assert answered_in_turn(triggers, 2, first, 0, skew_ns=5 * MS)
    # Beyond the skew the recorder's order stands.
    assert answered_in_turn(triggers, 1, first, 0, skew_ns=MS // 100)


def test_a_timer_module_that_planned_twice_on_one_trigger_gets_that_trigger_proposed_again():
    # A planner on a timer planned at 150 ms and again at 250 ms on the obstacles of 100 ms; new obstacles were
    # logged at 290 ms, within the recorder's skew (50 ms) after the second plan. Every trigger rule starts
    # after the previous frame's (100 ms) and "as logged" takes the newest within the skew (290 ms): only the
    # frame at the newest trigger logged by the output itself is the one the module used, as a plain replay.
    s = streams(trigger=[0, 100, 290], pose=[95, 240, 285])
    skew = 50 * MS
    c = candidates(OutputContext(streams=s, trigger="trigger", output_ns=250 * MS + skew, previous={"trigger": 1,
                                 "pose": 0}, lookback_ns=0, previous_output_ns=150 * MS + skew, skew_ns=skew))
    by_output = [x for x in c if any(rule == "as logged by the output" for rule, _ in x.patterns)]
    assert [dict(x.choice) for x in by_output] == [{"trigger": 1, "pose": 0}]
    assert c[-1] is by_output[0]  # a plain replay's frame, tried last
    assert all(x.choice["trigger"] == 2 for x in c[:-1])
    # Without a trigger in the skew, "as logged" already is that frame: no second copy of it.
    c = candidates(OutputContext(streams=s, trigger="trigger", output_ns=250 * MS, previous={"trigger": 1,
                                 "pose": 0}, lookback_ns=0, previous_output_ns=150 * MS, skew_ns=0))
    assert not any(rule == "as logged by the output" for x in c for rule, _ in x.patterns)


# -- the frame rules' extension point ----------------------------------------------------------------------------


def test_every_module_of_the_rules_package_registers_its_rule_on_the_registry():
    modules = {info.name for info in pkgutil.iter_modules(rules_package.__path__)}
    registered = {rule.triggers.__module__.rsplit(".", 1)[-1] if rule.triggers is not None
                  else rule.frame.__module__.rsplit(".", 1)[-1]
                  for rule in FRAME_RULES.values() if rule.triggers is not None or rule.frame is not None}
    assert registered == modules  # each rule module is on the registry, and nothing else places a trigger
    assert {"newest", "cycle end", "busy", "after", "oldest", "between", "first", "first heard",
            "as logged", "as logged by the output"} <= set(FRAME_RULES.names())


def test_a_rule_registered_on_the_registry_places_its_trigger_and_is_gone_once_taken_out():
    s = streams(trigger=[100, 200, 300], pose=[90, 190, 290])
    ctx = OutputContext(streams=s, trigger="trigger", output_ns=int(320 * MS), previous={"trigger": 0, "pose": 0},
                        lookback_ns=0)
    before = candidates(ctx)
    assert not any(way == "second newest" for c in before for way, _ in c.patterns)

    def second_newest(ctx: OutputContext) -> Iterator[Trigger]:
        if ctx.oldest <= ctx.newest - 1:
            yield ctx.newest - 1, "second newest"

    register(FrameRule(name="second newest", order=5, triggers=second_newest, likely=True))
    try:
        found = candidates(ctx)
        # Its order (5) puts its trigger before the newest's: its frame at the trigger's own time comes first.
        assert found[0].choice == {"trigger": 1, "pose": 1}
        assert ("second newest", (("pose", 0),)) in found[0].patterns
        assert "second newest" in likely_ways()
    finally:
        FRAME_RULES.unregister("second newest")
    assert candidates(ctx) == before and "second newest" not in likely_ways()


def test_the_ways_a_module_follows_are_the_likely_rules_and_a_between_trigger_is_not_one():
    assert likely_ways() == {"newest", "busy", "cycle end", "oldest", "first", "first heard", "after", "after 2",
                             "after 3", "after 4", "at output", "at cycle start", "at previous output"}
