"""The ddmin engine on synthetic testers: correctness, 1-minimality, cost, caching, parallelism."""

from __future__ import annotations

import random
import statistics
import threading
import time
from collections import Counter
from concurrent.futures import ThreadPoolExecutor
from typing import Callable, Iterable, Sequence

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from astaa_deft.analysis.minimise import (
    DDOptions,
    FailsWithoutItems,
    NotReproducible,
    Outcome,
    OutcomeCache,
    TestResult,
    ddmin,
    minimise_groups,
)

FAIL = TestResult(Outcome.FAIL)
PASS = TestResult(Outcome.PASS)


def fails_if_any(*culprit_sets: Iterable[int]) -> Callable[[Sequence[int]], TestResult]:
    """Deterministic tester: the failure reproduces iff the subset contains one of the culprit sets."""
    sets = [frozenset(c) for c in culprit_sets]

    def tester(subset: Sequence[int]) -> TestResult:
        present = set(subset)
        return FAIL if any(c <= present for c in sets) else PASS

    return tester


def assert_one_minimal(result: Sequence[int], tester: Callable[[Sequence[int]], TestResult]) -> None:
    assert tester(result).outcome is Outcome.FAIL
    for i in range(len(result)):
        assert tester(result[:i] + result[i + 1 :]).outcome is not Outcome.FAIL, f"{result[i]} can go"


# --- results -------------------------------------------------------------------


@pytest.mark.parametrize(
    "culprits, expected",
    [([{5}], [5]), ([{3, 17}], [3, 17]), ([{0}], [0]), ([{99}], [99]), ([{0, 50, 99}], [0, 50, 99])],
)
def test_finds_the_culprits(culprits, expected):
    tester = fails_if_any(*culprits)
    result = ddmin(list(range(100)), tester)
    assert result.minimal == expected
    assert result.indices == tuple(expected)
    assert result.complete
    assert_one_minimal(result.minimal, tester)


def test_either_of_two_causes_gives_a_one_minimal_failing_set():
    tester = fails_if_any({3, 17}, {5})
    result = ddmin(list(range(100)), tester)
    assert result.minimal in ([5], [3, 17])
    assert_one_minimal(result.minimal, tester)


def test_threshold_failure_is_reduced_to_exactly_k_items():
    """Failure iff at least k items remain (e.g. queue overflow): any k items are 1-minimal."""
    k = 7
    result = ddmin(list(range(60)), lambda s: FAIL if len(s) >= k else PASS)
    assert len(result.minimal) == k
    assert_one_minimal(result.minimal, lambda s: FAIL if len(s) >= k else PASS)


def test_items_are_arbitrary_and_subsets_keep_their_order():
    items = [("msg", i, "pose.x") for i in range(40)]
    seen: list[list] = []

    def tester(subset):
        seen.append(list(subset))
        return FAIL if items[11] in subset and items[30] in subset else PASS

    assert ddmin(items, tester).minimal == [items[11], items[30]]
    for subset in seen:
        assert subset == sorted(subset, key=items.index)


def test_unresolved_never_counts_as_failing():
    """Subsets without item 0 cannot even start: unresolved, so ddmin must keep item 0."""

    def tester(subset):
        if 0 not in subset:
            return TestResult(Outcome.UNRESOLVED, "system did not start")
        return FAIL if 9 in subset else PASS

    result = ddmin(list(range(30)), tester, DDOptions(check_full=True))
    assert result.minimal == [0, 9]
    assert Outcome.UNRESOLVED in {outcome for _, outcome in result.history}


def test_single_item_and_no_items():
    assert ddmin([42], lambda s: FAIL if s else PASS).minimal == [42]
    assert ddmin([], lambda s: PASS, DDOptions(check_full=False)).minimal == []


# --- cost ------------------------------------------------------------------------


def test_tests_per_single_culprit_among_100():
    """One culprit among 100: about 2 tests per halving plus the 2 start-up checks.

    Measured: 9..15 tests over all 100 positions (mean 11.9). ddmin is deterministic, so the bound is the
    measured figure: a change that costs even one more test on some position shows here.
    """
    runs = [ddmin(list(range(100)), fails_if_any({c})).tests_run for c in range(100)]
    print(f"\none culprit in 100: min {min(runs)}, mean {statistics.mean(runs):.1f}, max {max(runs)} tests")
    assert max(runs) <= 15 and sum(runs) <= 1190  # mean 11.9


def test_tests_for_two_culprits_among_100():
    """Two culprits (interacting mutations) in 100, 50 seeded pairs: measured mean 39.24, at most 50 tests
    (deterministic: the bound is the measured figure)."""
    rng = random.Random(1)
    runs = []
    for _ in range(50):
        pair = rng.sample(range(100), 2)
        result = ddmin(list(range(100)), fails_if_any(pair))
        assert result.minimal == sorted(pair)
        runs.append(result.tests_run)
    print(f"\ntwo culprits in 100: mean {statistics.mean(runs):.1f}, max {max(runs)} tests")
    assert max(runs) <= 50 and sum(runs) <= 1962  # mean 39.24


# --- caching -----------------------------------------------------------------------


def counting(tester):
    calls: Counter[tuple] = Counter()

    def counted(subset):
        calls[tuple(subset)] += 1
        return tester(subset)

    return counted, calls


@pytest.mark.parametrize("parallel", [1, 4])
def test_each_distinct_subset_is_tested_once(parallel):
    tester, calls = counting(fails_if_any({3, 17, 40}))
    result = ddmin(list(range(64)), tester, DDOptions(parallel=parallel))
    assert result.minimal == [3, 17, 40]
    assert calls and max(calls.values()) == 1
    assert result.tests_run == sum(calls.values()) == len(result.history) == len(result.results)
    assert result.cache_hits > 0  # the split in a later round meets configurations met before


def test_a_shared_cache_answers_a_second_run_without_testing():
    cache = OutcomeCache()
    first = ddmin(list(range(50)), fails_if_any({8, 9}), cache=cache)
    tester, calls = counting(fails_if_any({8, 9}))
    second = ddmin(list(range(50)), tester, cache=cache)
    assert second.minimal == first.minimal == [8, 9]
    assert second.tests_run == 0 and not calls
    assert second.cache_hits >= first.tests_run - 1


# --- parallel ------------------------------------------------------------------------


def jittery(tester, seed: int):
    """The same answers, arriving in a scrambled order, with the peak concurrency recorded."""
    lock = threading.Lock()
    rng = random.Random(seed)
    state = {"now": 0, "peak": 0}

    def run(subset):
        with lock:
            delay = rng.random() * 0.002
            state["now"] += 1
            state["peak"] = max(state["peak"], state["now"])
        time.sleep(delay)
        with lock:
            state["now"] -= 1
        return tester(subset)

    return run, state


@pytest.mark.parametrize("culprits", [[{5}], [{3, 17}], [{3, 17}, {5}], [{1, 2, 60, 61}], [{10, 11}, {40}, {70, 71}]])
def test_parallel_gives_the_sequential_result(culprits):
    sequential = ddmin(list(range(80)), fails_if_any(*culprits))
    tester, state = jittery(fails_if_any(*culprits), seed=len(culprits))
    parallel = ddmin(list(range(80)), tester, DDOptions(parallel=4))
    assert parallel.minimal == sequential.minimal
    assert parallel.tests_run >= sequential.tests_run  # speculative tests only add
    assert 1 < state["peak"] <= 4


def test_a_callers_executor_is_used_and_left_open():
    with ThreadPoolExecutor(3) as pool:
        tester, state = jittery(fails_if_any({4, 44}), seed=7)
        result = ddmin(list(range(64)), tester, DDOptions(parallel=3), executor=pool)
        assert result.minimal == [4, 44]
        assert pool.submit(lambda: "still open").result() == "still open"
    assert state["peak"] <= 3


@pytest.mark.parametrize("parallel", [1, 3])
def test_a_tester_bug_propagates(parallel):
    def tester(subset):
        if len(subset) == 25:
            raise RuntimeError("tester bug")
        return fails_if_any({3})(subset)

    with pytest.raises(RuntimeError, match="tester bug"):
        ddmin(list(range(100)), tester, DDOptions(parallel=parallel))


def test_a_tester_must_return_a_test_result():
    with pytest.raises(TypeError, match="expected a TestResult"):
        ddmin([1, 2], lambda s: True)  # type: ignore[arg-type, return-value]


# --- start-up checks ---------------------------------------------------------------------


def test_not_reproducible_when_the_full_set_passes():
    with pytest.raises(NotReproducible, match="gives pass, not fail: all green"):
        ddmin(list(range(10)), lambda s: TestResult(Outcome.PASS, "all green"))


def test_not_reproducible_when_the_full_set_is_unresolved():
    with pytest.raises(NotReproducible) as caught:
        ddmin(list(range(10)), lambda s: TestResult(Outcome.UNRESOLVED, "timeout"))
    assert caught.value.result.outcome is Outcome.UNRESOLVED


def test_fails_without_items():
    tester, calls = counting(lambda s: FAIL)
    with pytest.raises(FailsWithoutItems):
        ddmin(list(range(10)), tester)
    assert list(calls) == [tuple(range(10)), ()]  # nothing else was tried


def test_check_full_off_trusts_the_caller():
    tester, calls = counting(fails_if_any({2}))
    assert ddmin(list(range(10)), tester, DDOptions(check_full=False)).minimal == [2]
    assert tuple(range(10)) not in calls and () not in calls


# --- budget and flaky testers ----------------------------------------------------------------


@pytest.mark.parametrize("parallel", [1, 4])
def test_max_tests_returns_the_best_so_far(parallel):
    tester = fails_if_any({3, 17, 20, 40})
    result = ddmin(list(range(100)), tester, DDOptions(parallel=parallel, max_tests=8))
    assert not result.complete
    assert result.tests_run <= 8
    assert tester(result.minimal).outcome is Outcome.FAIL
    assert 4 < len(result.minimal) <= 50


def test_max_tests_zero_keeps_the_full_set():
    result = ddmin(list(range(10)), fails_if_any({3}), DDOptions(check_full=False, max_tests=0))
    assert (result.minimal, result.complete, result.tests_run) == (list(range(10)), False, 0)


def test_a_flaky_testers_failure_rate_reaches_the_result():
    """A tester that repeats a flaky run and decides by rate: ddmin keeps the rate of every test."""
    rng = random.Random(3)

    def tester(subset):
        p = 0.6 if 12 in subset else 0.02  # true failure probability
        rate = sum(rng.random() < p for _ in range(20)) / 20
        return TestResult(Outcome.FAIL if rate >= 0.3 else Outcome.PASS, f"{rate:.0%} of 20 runs", rate)

    result = ddmin(list(range(40)), tester)
    assert result.minimal == [12]
    assert [config for config, _ in result.history] == list(result.results)
    for config, outcome in result.history:
        kept = result.results[config]
        assert kept.outcome is outcome and kept.failure_rate is not None and "of 20 runs" in kept.detail


def test_progress_messages():
    messages: list[str] = []
    ddmin(list(range(16)), fails_if_any({6}), DDOptions(progress=messages.append))
    assert messages[0].startswith("16 items in 2 chunks")
    assert messages[-1].startswith("done: 1 items")


def test_bad_arguments():
    with pytest.raises(ValueError):
        ddmin([1], lambda s: FAIL, DDOptions(parallel=0))
    with pytest.raises(ValueError):
        ddmin([1], lambda s: FAIL, DDOptions(max_tests=-1))


# --- groups -------------------------------------------------------------------------------------


def test_minimise_groups_keeps_the_fields_that_matter():
    groups = {f"msg{m}": [(f"msg{m}", f) for f in ("pose.x", "pose.y", "speed", "header.stamp")] for m in range(12)}
    culprits = {("msg2", "speed"), ("msg9", "pose.y")}

    def tester(chosen):
        return FAIL if culprits <= set(chosen) else PASS

    result = minimise_groups(groups, tester)
    assert result.minimal == {"msg2": [("msg2", "speed")], "msg9": [("msg9", "pose.y")]}
    assert result.complete
    assert result.groups.minimal == ["msg2", "msg9"]
    assert result.tests_run == result.groups.tests_run + result.items.tests_run


# --- properties ------------------------------------------------------------------------------------


@st.composite
def problems(draw):
    n = draw(st.integers(1, 64))
    culprit = st.sets(st.integers(0, n - 1), min_size=1, max_size=4)
    return n, draw(st.lists(culprit, min_size=1, max_size=3))


@settings(max_examples=150, deadline=None)
@given(problems())
def test_property_result_fails_and_is_one_minimal(problem):
    n, culprits = problem
    tester, calls = counting(fails_if_any(*culprits))
    result = ddmin(list(range(n)), tester)
    assert result.complete
    assert_one_minimal(result.minimal, fails_if_any(*culprits))
    assert max(calls.values()) == 1
    if len(culprits) == 1:  # a single cause is found exactly
        assert result.minimal == sorted(culprits[0])


@settings(max_examples=30, deadline=None)
@given(problems())
def test_property_parallel_equals_sequential(problem):
    n, culprits = problem
    sequential = ddmin(list(range(n)), fails_if_any(*culprits))
    parallel = ddmin(list(range(n)), fails_if_any(*culprits), DDOptions(parallel=3))
    assert parallel.minimal == sequential.minimal
