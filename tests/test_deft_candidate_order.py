"""Extraction cost on a real run: candidates tried in the order earlier outputs won, wrong ones cut.

Measured on the OMPL stack: ~1 output in 5 needed a candidate other than
the first (its planner gets the ego pose and the obstacles of one simulator
tick in either order; when busy it plans on the oldest unanswered trigger,
not the newest), and each wrong candidate tried first could make RRT*
search for seconds. The run itself says which way of deriving a frame
wins: the outputs already extracted (search_policy.WinningPatterns). A
candidate running far longer than the accepted steps did is cut, and run
again under the full limit only if no other candidate is accepted
(search_policy.StepBudget, ForkedSearch's retry).
"""

from __future__ import annotations

import time
from dataclasses import replace

import pytest

from astaa_deft.analysis.deft.extract import IN_TURN, Speculation, extract, search_note
from astaa_deft.analysis.deft.extract.speculation import step_in_turn
from astaa_deft.analysis.deft.fork_replay import ForkedSearch, can_fork, run_supervised
from astaa_deft.analysis.deft.frames import Candidate, OutputContext, Stream, candidates, read_times
from astaa_deft.analysis.deft.frames.read_at import AT_OUTPUT, AT_PREVIOUS, AT_START
from astaa_deft.analysis.deft.frames.rules.after import AFTER
from astaa_deft.analysis.deft.frames.rules.as_logged import AS_LOGGED
from astaa_deft.analysis.deft.frames.rules.busy import BUSY
from astaa_deft.analysis.deft.frames.rules.cycle_end import CYCLE_END
from astaa_deft.analysis.deft.frames.rules.first import FIRST
from astaa_deft.analysis.deft.frames.rules.newest import NEWEST
from astaa_deft.analysis.deft.frames.rules.oldest import OLDEST
from astaa_deft.analysis.deft.replay import make_planner
from astaa_deft.analysis.deft.search_policy import (
    EXPENSIVE_TRIES, PER_TRIGGER, SearchMemory, StepBudget, WinningPatterns, first_cycle_first,
    likely_ways, nearest_first,
)
from astaa_deft.io.log.reader import read_log

from lossy_log import write_lossy_log
from proxy_helpers import SUT_DIR

MS = 1_000_000


# -- the pure logic ----------------------------------------------------------------------------------
def test_candidates_say_how_they_were_derived():
    # Triggers at 0, 100, 200 ms; the previous frame used trigger 0; the previous output came at 150 ms.
    streams = {"obstacles": Stream("obstacles", [0, 100 * MS, 200 * MS]),
               "ego": Stream("ego", [k * 50 * MS for k in range(6)])}
    found = candidates(OutputContext(streams=streams, trigger="obstacles", output_ns=240 * MS,
                                     previous={"obstacles": 0, "ego": 0}, lookback_ns=0, previous_output_ns=150 * MS))
    first = found[0]  # the newest trigger with the ego pose at its own time
    assert first.choice == {"obstacles": 2, "ego": 4}
    # … and the first trigger logged after the previous output (a module that drops triggers while busy), and
    # a plain replay's frame (the newest trigger, the inputs as logged before it).
    assert first.patterns == {(NEWEST, (("ego", 0),)), (AFTER, (("ego", 0),)), (AS_LOGGED, ())}
    later = next(c for c in found if c.choice == {"obstacles": 1, "ego": 2})
    # Trigger 1 was the newest when the previous output was logged (its cycle's end), and the oldest not yet
    # answered.
    assert later.patterns == {(BUSY, (("ego", 0),)), (CYCLE_END, (("ego", 0),)), (OLDEST, (("ego", 0),))}
    # The ego pose logged after trigger 1 (at 150 ms) but before the output: the planner got it first.
    assert any(c.patterns == {(BUSY, (("ego", 1),)), (CYCLE_END, (("ego", 1),)), (OLDEST, (("ego", 1),))}
               for c in found)


def test_a_trigger_logged_as_the_previous_output_was_is_not_the_one_its_cycle_end_had():
    # A module taking the newest trigger when its cycle ends (newest_latched): trigger 3 logged 0.05 ms after
    # the previous output (or within the skew after it) reached it after that cycle had ended; the next cycle
    # answered trigger 2. Before: trigger 3 was "busy" (the newest at the output plus the skew) and "after",
    # trigger 2 only "busy" like every trigger of the lookback — a wrong expensive step first on ~1 output in 8.
    triggers = Stream("a", [k * 50 * MS for k in range(6)])
    b = Stream("b", [k * 50 * MS for k in range(6)])
    skew = 5 * MS
    for logged in (150 * MS + 50_000, 146 * MS):  # the previous output: just after trigger 3, or 4 ms before it
        found = candidates(OutputContext(streams={"a": triggers, "b": b}, trigger="a", output_ns=240 * MS,
                                         previous={"a": 1, "b": 1}, lookback_ns=100 * MS,
                                         previous_output_ns=logged + skew, skew_ns=skew))
        end = [c for c in found if any(rule == CYCLE_END for rule, _ in c.patterns)]
        assert {c.choice["a"] for c in end} == {2}
        by_trigger = {c.choice["a"]: c for c in reversed(found) if c.choice["b"] == c.choice["a"]}
        assert (AFTER, (("b", 0),)) in by_trigger[3].patterns
        assert not any(rule == BUSY for rule, _ in by_trigger[3].patterns)
        # In the generic order the cycle's end comes right after the newest trigger.
        assert [c.choice["a"] for c in found if c.choice["b"] == c.choice["a"]][:3] == [4, 2, 3]
    assert CYCLE_END in likely_ways()


def test_after_names_the_first_trigger_the_idle_module_got_and_the_one_a_queue_let_in():
    # Before: "after" was the trigger after the newest at the previous output plus the skew, so a trigger
    # logged 1-4 ms after that output (the one a module dropping triggers while busy answers) was only
    # "busy", and "after" named the next one: a wrong expensive step first on ~1 output in 5 (drop_latched);
    # and a trigger logged just before the output (it reached the idle module after it) was never "after".
    triggers = Stream("a", [k * 50 * MS for k in range(10)])
    b = Stream("b", [k * 100 * MS for k in range(5)])
    skew = 5 * MS
    found = candidates(OutputContext(streams={"a": triggers, "b": b}, trigger="a", output_ns=460 * MS,
                                     previous={"a": 2, "b": 1}, lookback_ns=0, previous_output_ns=301 * MS + skew,
                                     skew_ns=skew))
    after = [c for c in found if any(rule == AFTER for rule, _ in c.patterns)]
    assert {c.choice["a"] for c in after} == {7}  # trigger 7 at 350 ms: the first after 301 ms
    found = candidates(OutputContext(streams={"a": triggers, "b": b}, trigger="a", output_ns=460 * MS,
                                     previous={"a": 2, "b": 1}, lookback_ns=0, previous_output_ns=300_500_000 + skew,
                                     skew_ns=skew))
    # Trigger 6 logged at 300 ms, half a millisecond before the output: the module may have had it after, or
    # have had it while still busy and dropped it — then trigger 7, the first logged after the output, is the
    # answer: both are "after". (Before: 6 alone; on drop_latched the right frame, 7, was then not among an
    # expensive output's 8 likeliest, and the warm state carried the miss on: 7 of 32 outputs → 32 of 32.)
    assert {c.choice["a"] for c in found if any(rule == AFTER for rule, _ in c.patterns)} == {6, 7}
    # The oldest of a queue two deep: the trigger that found room when the cycle of the output three back
    # started (the output before it was logged), "after 3".
    found = candidates(OutputContext(streams={"a": triggers, "b": b}, trigger="a", output_ns=460 * MS,
                                     previous={"a": 2, "b": 1}, lookback_ns=0, previous_output_ns=420 * MS + skew,
                                     skew_ns=skew, earlier_outputs_ns=[360 * MS, 170 * MS]))
    assert {c.choice["a"] for c in found if any(rule == f"{AFTER} 3" for rule, _ in c.patterns)} == {4}
    assert f"{AFTER} 3" in likely_ways()


def test_the_newest_trigger_before_the_output_itself_is_newest_too():
    # A trigger logged within the recorder's skew after the output most likely came after the cycle had
    # started: the newest trigger before the output itself is "newest" too. Before: it was only "between",
    # and drop_cycle_none lost an output a plain replay reproduces (its right frame was not among the 8 tried).
    triggers = Stream("a", [k * 50 * MS for k in range(6)])
    b = Stream("b", [k * 50 * MS + 10 * MS for k in range(6)])
    skew = 5 * MS
    output = 250 * MS - 200_000  # trigger 5 logged 0.2 ms after the output
    found = candidates(OutputContext(streams={"a": triggers, "b": b}, trigger="a", output_ns=output + skew,
                                     previous={"a": 1, "b": 1}, lookback_ns=0, previous_output_ns=120 * MS + skew,
                                     skew_ns=skew))
    newest = {c.choice["a"] for c in found if any(rule == NEWEST for rule, _ in c.patterns)}
    assert newest == {4, 5}
    # Its frame as the module latched it when the trigger came (b 3, logged at 160 ms) is among them.
    assert any(c.choice == {"a": 4, "b": 3} and any(rule == NEWEST for rule, _ in c.patterns) for c in found)


def test_a_trigger_logged_just_before_the_previous_output_leaves_the_one_before_a_cycle_end_too():
    # A module publishing a while after its cycle ended: trigger 3 logged 1.2 ms before the previous output
    # may have come after that end. Both it and trigger 2 are "cycle end". Before: 3 alone; on slow_planner
    # the right frame (trigger 2) was then not among the 8 tried and the warm state carried the miss on
    # (3 → 13 of 13 outputs at θ = 0 on one log).
    triggers = Stream("a", [k * 50 * MS for k in range(6)])
    b = Stream("b", [k * 50 * MS + 10 * MS for k in range(6)])
    found = candidates(OutputContext(streams={"a": triggers, "b": b}, trigger="a", output_ns=240 * MS,
                                     previous={"a": 1, "b": 1}, lookback_ns=0, previous_output_ns=151_200_000))
    assert {c.choice["a"] for c in found if any(rule == CYCLE_END for rule, _ in c.patterns)} == {2, 3}
    # A trigger logged 10 ms before the output: the end's alone.
    found = candidates(OutputContext(streams={"a": triggers, "b": b}, trigger="a", output_ns=240 * MS,
                                     previous={"a": 1, "b": 1}, lookback_ns=0, previous_output_ns=160 * MS))
    assert {c.choice["a"] for c in found if any(rule == CYCLE_END for rule, _ in c.patterns)} == {3}


def test_a_slow_module_that_ended_a_cycle_with_a_trigger_waiting_read_its_next_inputs_then():
    # slow_planner (0.5-1.2 s a cycle, 10 Hz triggers, the newest inputs read when a cycle starts): its second
    # output's frame is the one at the first output, and a message logged 1 ms before that output came after
    # the read. Before: the frame at the output (a read the step's cost rules out) and the one at the
    # output minus the previous step's cost came first — 4 steps of 0.5 s for the second output.
    triggers = Stream("a", [k * 100 * MS for k in range(12)])
    b = Stream("b", [k * 100 * MS + 30 * MS for k in range(12)])
    c = Stream("c", [k * 100 * MS + 99 * MS for k in range(12)])  # c 5 logged 1 ms before the first output
    streams = {"a": triggers, "b": b, "c": c}
    first_output, output = 600 * MS, 1_150 * MS
    slow = read_times(streams, "a", {"a": 0, "b": 0, "c": 0}, output_ns=output, previous_output_ns=first_output,
                      step_ns=500 * MS)
    # (just before c 5: the frame with c 4)
    assert slow == [(first_output, AT_PREVIOUS), (599 * MS - 1, AT_PREVIOUS), (output - 500 * MS, AT_START),
                    (output, AT_OUTPUT)]
    # A cheap step, or no trigger waiting when the previous cycle ended (the module idle): a plain replay's
    # frame first.
    cheap = read_times(streams, "a", {"a": 0}, output_ns=output, previous_output_ns=first_output, step_ns=2 * MS)
    assert [rule for _, rule in cheap] == [AT_OUTPUT, AT_START, AT_PREVIOUS, AT_PREVIOUS]
    idle = read_times(streams, "a", {"a": 6}, output_ns=output, previous_output_ns=first_output, step_ns=500 * MS)
    assert idle[0] == (output, AT_OUTPUT)
    # A first output: no previous one to read at.
    assert read_times(streams, "a", {}, output_ns=first_output) == [(first_output, AT_OUTPUT)]


def test_a_first_output_the_search_widens_reaches_back_to_the_logs_first_triggers():
    # timer_heavy_noisy under load: its first cycle (a timer tick after trigger 3) ended 900 ms after the first
    # trigger, 14 triggers after it; a first output's usual reach (10 back from the newest) left it out.
    a = Stream("a", [k * 50 * MS for k in range(18)])
    b = Stream("b", [k * 100 * MS + 13 * MS for k in range(9)])
    ctx = OutputContext(streams={"a": a, "b": b}, trigger="a", output_ns=899 * MS, previous={}, lookback_ns=0,
                        module_started_in_log=True)
    assert {"a": 3, "b": 1} not in [c.choice for c in candidates(ctx)]
    assert {"a": 3, "b": 1} in [c.choice for c in candidates(replace(ctx, first_reach=40))]


def test_an_expensive_outputs_tries_are_not_all_one_triggers():
    # Eight frames of one trigger (other inputs' offsets) ranked first left the next trigger's likeliest out.
    same = [Candidate(frame_time=0, choice={"a": 7, "b": k},
                      patterns=frozenset({(CYCLE_END, (("b", k),))})) for k in range(10)]
    other = [Candidate(frame_time=0, choice={"a": 6, "b": k},
                       patterns=frozenset({(CYCLE_END, (("b", k),))})) for k in range(6)]
    options, capped = SearchMemory().order(same + other, expensive=True, first=False, trigger="a")
    assert capped and len(options) == EXPENSIVE_TRIES
    assert sum(c.choice["a"] == 7 for c in options) == PER_TRIGGER
    assert [c for c in options if c.choice["a"] == 7] == same[:PER_TRIGGER] and other[0] in options
    # With too few others, the cap gives way: still EXPENSIVE_TRIES tried.
    options, _ = SearchMemory().order(same + other[:1], expensive=True, first=False, trigger="a")
    assert len(options) == EXPENSIVE_TRIES and other[0] in options


def test_the_way_that_won_for_earlier_outputs_is_tried_first():
    # Before: candidates came in one fixed order whatever the run showed; a planner that always plans on
    # the oldest unanswered trigger had its wrong newest-trigger frame tried first on every busy cycle.
    streams = {"obstacles": Stream("obstacles", [0, 100 * MS, 200 * MS]),
               "ego": Stream("ego", [k * 50 * MS for k in range(6)])}
    found = candidates(OutputContext(streams=streams, trigger="obstacles", output_ns=240 * MS,
                                     previous={"obstacles": 0, "ego": 0}, lookback_ns=0, previous_output_ns=150 * MS))
    winning = WinningPatterns()
    assert winning.rank(found) == found  # nothing learned yet: the generic order
    oldest_at_trigger = next(c for c in found if c.choice == {"obstacles": 1, "ego": 2})
    winning.record(oldest_at_trigger)
    ranked = winning.rank(found)
    assert ranked[0] is oldest_at_trigger
    assert sorted(ranked, key=found.index) == found  # the same candidates, none lost or added


def test_a_first_output_tries_first_the_first_trigger_the_planner_could_plan_from():
    # Before: the newest trigger's frames came first; the OMPL planner's first cycle (building its state,
    # ~0.3 s) answered the first trigger it could plan from in every run measured: 3-5 wrong searches first.
    streams = {"obstacles": Stream("obstacles", [0, 100 * MS, 200 * MS, 300 * MS]),
               "ego": Stream("ego", [50 * MS, 150 * MS, 250 * MS])}
    found = candidates(OutputContext(streams=streams, trigger="obstacles", output_ns=320 * MS, previous={},
                                     lookback_ns=100 * MS))
    assert found[0].choice["obstacles"] == 3  # the generic order (a process replay tries only that one)
    ordered = first_cycle_first(found)
    assert ordered[0].choice == {"obstacles": 1, "ego": 0}  # trigger 0 came before any ego pose
    assert (FIRST, (("ego", 0),)) in ordered[0].patterns
    assert sorted(ordered, key=found.index) == found
    # A log that starts after the planner's first triggers (the window does not reach back): no such guess.
    later = {"obstacles": Stream("obstacles", [k * 100 * MS for k in range(20)]),
             "ego": Stream("ego", [k * 50 * MS for k in range(40)])}
    found = candidates(OutputContext(streams=later, trigger="obstacles", output_ns=1920 * MS, previous={},
                                     lookback_ns=0))
    assert first_cycle_first(found) == found


def test_recent_wins_outweigh_old_ones_and_ties_keep_the_generic_order():
    class Cand:
        def __init__(self, name):
            self.patterns = {name}

    a, b, c = Cand("a"), Cand("b"), Cand("c")
    winning = WinningPatterns(recency=0.5)
    winning.record(a)
    winning.record(a)  # a: 1.5
    winning.record(b)  # a: 0.75, b: 1
    assert winning.rank([a, b, c]) == [b, a, c]
    assert winning.rank([c, a]) == [a, c]
    winning.record(a)  # a: 1.375, b: 0.5
    assert winning.rank([c, b, a]) == [a, b, c]


def test_the_tight_limit_follows_the_accepted_steps():
    budget = StepBudget(factor=3.0, min_s=0.25)
    assert budget.limit(window_s=0.2, full_limit_s=2.0) == 2.0  # nothing known yet: the full limit
    budget.record(step_s=0.18, window_s=0.2)  # replay as fast as the recording
    assert budget.limit(0.2, 2.0) == pytest.approx(0.6)  # three recorded windows
    assert budget.limit(0.01, 2.0) == 0.25  # never below the floor
    assert budget.limit(5.0, 2.0) == 2.0  # never above the full limit
    budget.record(step_s=0.4, window_s=0.2)  # replay twice as slow as recorded (a loaded machine)
    assert budget.limit(0.2, 2.0) == pytest.approx(1.2)
    budget.record(step_s=0.002, window_s=0.0001)  # a tiny step: timer noise, not a slowdown
    assert budget.limit(0.2, 2.0) == pytest.approx(1.2)


def _slow_planner_candidates():
    """A planner slower than its trigger: two seconds of 20 Hz ego poses after each of several triggers."""
    streams = {"obstacles": Stream("obstacles", [k * 100 * MS for k in range(30)]),
               "ego": Stream("ego", [k * 50 * MS + 5 * MS for k in range(60)])}
    # (The previous output 20 ms after trigger 15: a trigger logged as an output was is the next cycle's, AFTER.)
    return candidates(OutputContext(streams=streams, trigger="obstacles", output_ns=2900 * MS,
                                    previous={"obstacles": 5, "ego": 10}, lookback_ns=160 * MS,
                                    previous_output_ns=1520 * MS))


def test_an_expensive_output_tries_the_frames_near_its_likely_triggers_first():
    # A planner of ~0.5-1 s a cycle has hundreds of candidates per output; the generic order tried
    # every later frame of one trigger (each an RRT* search) before the frame at the next trigger's own time.
    found = _slow_planner_candidates()
    assert len(found) > 100
    ordered = nearest_first(found)
    assert sorted(ordered, key=found.index) == found  # the same candidates, none lost or added

    def spread(c):
        return min(max((abs(o) for _, o in offsets), default=0) for _, offsets in c.patterns)

    likely = [c for c in ordered if any(rule in likely_ways() for rule, _ in c.patterns)]  # newest, busy, after …
    head = ordered[:len(likely)]
    assert head == likely  # the newest, busy and oldest triggers' frames before those of triggers between
    assert [spread(c) for c in head] == sorted(spread(c) for c in head)  # nearest their trigger's time first
    assert spread(head[0]) == 0 and spread(head[-1]) > 2


def test_an_expensive_output_learns_from_the_expensive_ones_and_tries_a_few():
    found = _slow_planner_candidates()
    memory = SearchMemory()
    options, capped = memory.order(found, expensive=True, first=False)
    assert capped and len(options) == EXPENSIVE_TRIES and options == nearest_first(found)[:EXPENSIVE_TRIES]
    assert memory.order(found, expensive=False, first=False) == (found, False)  # a cheap output: all, generic
    # The busy trigger's frame one ego pose before its own time won an expensive output: tried first now, and
    # the busy trigger's other frames (its rule won) before the frames of the newest and oldest.
    busy_before = next(c for c in found if (BUSY, (("ego", -1),)) in c.patterns)
    memory.learn(busy_before, step_s=0.8, window_s=1.4, expensive=True)
    options, _ = memory.order(found, expensive=True, first=False)
    assert options[0] is busy_before
    assert all(any(rule == BUSY for rule, _ in c.patterns) for c in options[:4])
    # A cheap output's win teaches the cheap order, not the expensive one.
    newest = found[0]
    memory.learn(newest, step_s=0.001, window_s=0.01)
    assert memory.order(found, expensive=True, first=False)[0][0] is busy_before


def test_an_expensive_outputs_limit_is_about_one_step_of_its_neighbours():
    budget = StepBudget()
    assert budget.neighbour_limit(30.0) == 30.0  # no expensive output accepted yet: the full limit
    budget.record(0.002, 0.005)  # a cheap output's step says nothing about an expensive one
    assert budget.neighbour_limit(30.0) == 30.0
    budget.record(0.6, 1.5, expensive=True)
    budget.record(0.9, 1.2, expensive=True)
    assert budget.neighbour_limit(30.0) == pytest.approx(1.8)  # twice the largest neighbour step (CPU)
    assert budget.neighbour_limit(1.0) == 1.0  # never above the full limit
    for _ in range(5):  # only the last five expensive outputs are neighbours
        budget.record(0.3, 1.0, expensive=True)
    assert budget.neighbour_limit(30.0) == pytest.approx(0.6)


# -- real forked searches ------------------------------------------------------------------------------
def _busy(cpu_seconds: float) -> None:
    """Use this much CPU time, as a planner searching does (limits count CPU time, not waiting)."""
    end = time.process_time() + cpu_seconds
    while time.process_time() < end:
        pass


needs_fork = pytest.mark.skipif(not can_fork(), reason="fork-based replay needs os.fork (POSIX)")


@needs_fork
def test_a_cut_candidate_is_retried_under_the_full_limit_when_no_other_is_accepted():
    # Before: a candidate stopped by its limit counted as not reproduced: a tight limit would lose outputs.
    def body(send):
        search = ForkedSearch(2, send)

        def run(index: int) -> str:
            if index == 0:
                _busy(0.6)  # the right frame, slower than the tight limit guessed
                return "right"
            return "wrong"

        kept = search.search(3, run, accepted=lambda r: r == "right", closeness=lambda r: 0.0 if r == "right" else 1.0,
                             limit_s=0.2, retry_limit_s=30.0)
        return kept.index if kept else None, kept.result if kept else None, search._counters()

    index, result, counters = run_supervised(body, on_message=lambda message: None)
    assert (index, result) == (0, "right")
    assert counters == {"timeouts": 1, "cut": 1, "retried": 1, "retried_kept": 1}


@needs_fork
def test_a_cut_candidate_is_not_retried_when_another_is_accepted():
    def body(send):
        search = ForkedSearch(2, send)

        def run(index: int) -> str:
            if index == 0:
                _busy(60)  # a wrong frame searching on and on
                return "wrong"
            return "right"

        kept = search.search(2, run, accepted=lambda r: r == "right", closeness=lambda r: 0.0 if r == "right" else 1.0,
                             limit_s=0.3, retry_limit_s=120.0)
        return kept.index if kept else None, search._counters()

    started = time.monotonic()
    index, counters = run_supervised(body, on_message=lambda message: None)
    assert index == 1
    assert counters == {"timeouts": 1, "cut": 1, "retried": 0, "retried_kept": 0}
    assert time.monotonic() - started < 60  # the wrong frame was not waited for


@needs_fork
def test_a_candidate_waiting_for_the_cpu_is_not_out_of_time():
    # Before: the limit counted wall time; on a loaded machine a right frame could run past it and the
    # output was lost (seen: a first output at load 14). Limits count the CPU time a candidate used.
    def body(send):
        search = ForkedSearch(1, send)

        def run(index: int) -> str:
            time.sleep(1.0)  # off the CPU: as a step waiting for a core it does not get
            return "right"

        kept = search.search(2, run, accepted=lambda r: r == "right", closeness=lambda r: 0.0, limit_s=0.4)
        return kept.index if kept else None, search.timeouts

    assert run_supervised(body, on_message=lambda message: None) == (0, 0)


CYCLES = 8


@pytest.fixture()
def late_pose_log(tmp_path, monkeypatch):
    """The planner never got the pose logged with its tick in time: it always used the one before."""
    monkeypatch.syspath_prepend(str(SUT_DIR))
    return write_lossy_log(tmp_path, [True] * CYCLES)


@needs_fork
@pytest.mark.parametrize("jobs", [1, 2])
def test_forked_extraction_tries_first_what_won_before(late_pose_log, jobs):
    # Before: every output tried the pose at the tick's own time first, and it was wrong every time
    # (candidates tried: 2, 2, 2, …); now only the first output pays for finding out.
    spec, log_path = late_pose_log
    ex = extract(read_log(log_path), spec, make_planner(spec, {}), jobs=jobs)
    assert ex.outputs == CYCLES and not ex.skipped
    assert ex.accepted_at(0.0) == CYCLES and all(f.exact for f in ex.frames)
    assert [f.candidates_tried for f in ex.frames] == [2] + [1] * (CYCLES - 1)
    assert ex.reordered == CYCLES - 1
    assert ex.candidates_cut == 0
    # Cheap cycles: the replay process stepped each first candidate itself, a shadow following; only the
    # first output's was wrong (the shadow then tried the next).
    assert (ex.first_stepped_in_runner, ex.first_missed_in_runner) == (CYCLES - 1, 1)
    note = search_note(ex)  # the summary says what the search did
    assert note is not None and f"{CYCLES - 1} output(s) tried first the way earlier outputs" in note
    assert f"{CYCLES} cheap output(s) stepped their first candidate in the replay process (1 wrong" in note


@needs_fork
def test_a_miss_after_hits_is_searched_from_the_state_before_it(tmp_path, monkeypatch):
    # The runner steps several first candidates itself (accepted), then one is wrong: its shadow, one
    # output behind, tries the next candidate from the exact state before the missed output.
    monkeypatch.syspath_prepend(str(SUT_DIR))
    late = [True, True, True, True, False, True, True, False]
    spec, log_path = write_lossy_log(tmp_path, late)
    ex = extract(read_log(log_path), spec, make_planner(spec, {}), jobs=2)
    assert ex.accepted_at(0.0) == len(late) and all(f.exact for f in ex.frames)
    assert [f.candidates_tried for f in ex.frames] == [2, 1, 1, 1, 2, 1, 1, 2]
    assert ex.first_missed_in_runner == 3 and ex.first_stepped_in_runner == 5


def test_in_process_extraction_learns_the_order_too(late_pose_log):
    # From deep copies this planner plans ~1e-9 m off (see test_deft_fork_replay): accept within 1e-6 m.
    spec, log_path = late_pose_log
    spec = replace(spec, planner=replace(spec.planner, threshold=1e-6))
    ex = extract(read_log(log_path), spec, make_planner(spec, {}))
    assert [f.candidates_tried for f in ex.frames] == [2] + [1] * (CYCLES - 1)
    assert ex.accepted_at(1e-6) == CYCLES


@needs_fork
def test_candidates_in_turn_carry_on_from_the_kept_ones_state_and_hand_long_searches_over():
    # Three cheap outputs stepped in the replay process, a shadow one output behind: the first output's
    # first candidate is right, the second's second, the third's third — past IN_TURN (2) candidates
    # the forked search takes over. Whatever was stepped in vain ended with its process: the survivor's
    # state holds exactly the kept candidates' steps.
    assert IN_TURN == 2

    def body(send):
        state: list[tuple[int, int]] = []  # (output, candidate) stepped in this process
        speculation = Speculation()
        search = ForkedSearch(2, send)
        searched = []
        for output, right in enumerate([0, 1, 2]):
            def run(index: int, output=output, right=right) -> str:
                state.append((output, index))
                return "right" if index == right else "wrong"

            kept, in_vain = step_in_turn(3, run, lambda r: r == "right", speculation, in_turn=True)
            if kept is None:
                speculation.let_go()
                order = [i for i in range(3) if i not in in_vain] + sorted(in_vain)
                tried = search.search(3, lambda k, run=run, order=order: run(order[k]),
                                      accepted=lambda r: r == "right", closeness=lambda r: 0.0, limit_s=60.0)
                kept = (order[tried.index], tried.result)
                searched.append((output, in_vain))
            assert kept[1] == "right"
        assert speculation.following is None
        speculation.let_go()
        return state, searched, (speculation.hits, speculation.misses)

    state, searched, counters = run_supervised(body, on_message=lambda message: None)
    assert state == [(0, 0), (1, 1), (2, 2)]
    assert searched == [(2, {0: "wrong", 1: "wrong"})]  # tried in vain, with their outcomes
    assert counters == (1, 2)  # first candidates: one right, two wrong
