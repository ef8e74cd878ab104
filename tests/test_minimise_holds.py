"""Held faults in minimisation: a policy's mutations on consecutive messages are one item, shortened at its ends.

Pure parts (grouping, shortening) on synthetic testers; the stage on the live path with a tester that
stands for a planner bridging two bad inputs and failing on the third (examples/ompl_stack's defect 1).
"""

from __future__ import annotations

import math
from collections.abc import Sequence

from astaa_deft.analysis.minimise.ddmin import Outcome, TestResult, shorten
from astaa_deft.analysis.minimise.failure import Failure
from astaa_deft.analysis.minimise.holds import flatten, held_runs
from astaa_deft.analysis.minimise.mutations import Mutation, Step
from astaa_deft.analysis.minimise.stages import minimise_live
from astaa_deft.model.records import FieldChange

FAIL = TestResult(Outcome.FAIL)
PASS = TestResult(Outcome.PASS)


def mutation(number: int, policy: str, index: int, channel: str = "obstacles", fields=None) -> Mutation:
    changes = fields if fields is not None else (FieldChange("obstacles[0].length", 4.5, -1.0),)
    return Mutation(number=number, channel=channel, steps=(Step(policy, "set", {}),), consumers=("planning",),
                    message_index=index, time=index * 0.1, at=index * 0.1, fields=tuple(changes),
                    original=b"{}", original_time_ns=0, delivered=b"{}", delivered_time_ns=0)


def three_in_a_row(numbers: Sequence[int], held: Sequence[int]) -> bool:
    """The planner fails once three consecutive messages of the hold are bad (one or two are bridged)."""
    mine = sorted(set(numbers) & set(held))
    return any(mine[i + 2] == mine[i] + 2 and mine[i + 1] == mine[i] + 1 for i in range(len(mine) - 2))


def test_one_policy_on_consecutive_messages_is_one_run_and_a_gap_or_another_policy_starts_another():
    ms = [mutation(1, "hold", 10), mutation(2, "noise", 3, channel="ego"), mutation(3, "hold", 11),
          mutation(4, "hold", 12), mutation(5, "hold", 20), mutation(6, "noise", 4, channel="ego")]
    assert held_runs(ms) == [(1, 3, 4), (2, 6), (5,)]
    assert flatten([(5,), (1, 3, 4)]) == [1, 3, 4, 5]


def test_shorten_keeps_a_contiguous_slice_cut_at_its_ends_in_logarithmic_tests():
    run = list(range(40))
    needed = {17, 18, 19}
    result = shorten(run, lambda part: FAIL if needed <= set(part) else PASS)
    assert result.kept == [17, 18, 19] and result.complete
    assert result.tests_run <= 2 * math.ceil(math.log2(40))


def test_shorten_to_the_first_message_when_one_is_enough():
    result = shorten(list(range(25)), lambda part: FAIL if 0 in part else PASS)
    assert result.kept == [0]


def test_shorten_out_of_tests_returns_the_shortest_slice_that_failed():
    result = shorten(list(range(64)), lambda part: FAIL if {30, 31} <= set(part) else PASS, max_tests=2)
    assert not result.complete and result.tests_run == 2
    assert {30, 31} <= set(result.kept)
    assert result.kept == list(range(result.kept[0], result.kept[-1] + 1))  # contiguous


class ThirdBadInARow:
    """Stands for whole-system re-runs of a planner that bridges two bad obstacle sizes and dies on the third."""

    repeats = 1

    def __init__(self, held: Sequence[int]):
        self.held = held
        self.calls: list[list[int]] = []

    def __call__(self, chosen: Sequence[tuple[Mutation, object]]) -> TestResult:
        numbers = [m.number for m, _ in chosen]
        self.calls.append(numbers)
        return FAIL if three_in_a_row(numbers, self.held) else PASS


def test_live_minimisation_keeps_a_held_fault_held_and_shortens_it_to_what_the_defect_needs():
    # 30 messages of a held negative length on obstacles, among 20 benign one-message mutations on ego.
    held = [mutation(n, "negative-length", 100 + n) for n in range(1, 31)]
    noise = [mutation(100 + k, f"noise-{k}", 5 * k, channel="ego",
                      fields=(FieldChange("v", 1.0, 2.0), FieldChange("x", 0.0, 0.5))) for k in range(20)]
    mutations = sorted(held + noise, key=lambda m: m.number)
    tester = ThirdBadInARow([m.number for m in held])
    failure = Failure(invariant="(module exit)", kind="process", module="planning", channel=None, at=3.0,
                      detail="killed by SIGABRT", crash="Abort")
    result = minimise_live(tester, mutations, failure, FAIL, max_tests=40)  # type: ignore[arg-type]
    kept = sorted(result.kept)
    # The hold's first three messages (the failure at its original time), and a quarter of that back at each
    # end (the closed loop's timing varies from run to run), tested once more.
    assert kept == [1, 2, 3, 4], kept
    assert three_in_a_row(kept, tester.held) and tester.calls[-1] == [1, 2, 3, 4]
    # Never a thinned hold: every test kept the held messages it had as one contiguous run.
    for call in tester.calls:
        mine = [n for n in call if n <= 30]
        assert mine == list(range(mine[0], mine[-1] + 1)) if mine else True, call
    hold = next(s for s in result.stages if s.name == "hold")
    assert (hold.before, hold.after) == (30, 4)
    assert len(tester.calls) <= 25
