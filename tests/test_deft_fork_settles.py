"""A candidate that reproduces the recorded output exactly is kept at once (measured on the OMPL stack).

Before: the search waited for every earlier candidate to report, so a wrong
frame that made the planner search for seconds (or until its time limit)
held up a candidate already known to reproduce the output field for field.
"""

from __future__ import annotations

import time

import pytest

from astaa_deft.analysis.deft.fork_replay import ForkedSearch, can_fork, run_supervised

pytestmark = pytest.mark.skipif(not can_fork(), reason="fork-based replay needs os.fork (POSIX)")


def test_an_exact_later_candidate_does_not_wait_for_an_earlier_one_still_searching():
    def body(send):
        search = ForkedSearch(2, send)

        def run(index: int) -> str:
            if index == 0:
                time.sleep(120)  # a wrong frame: the planner searches on and on
                return "wrong"
            return "exact"

        kept = search.search(2, run, accepted=lambda r: r == "exact", closeness=lambda r: 0.0 if r == "exact" else 1.0,
                             limit_s=30.0, settles=lambda r: r == "exact")
        return (kept.index if kept else None, kept.result if kept else None, search.timeouts)

    index, result, timeouts = run_supervised(body, on_message=lambda message: None)
    assert (index, result) == (1, "exact")
    assert timeouts == 0  # candidate 0 was stopped because 1 settled it, not because it ran out of time


def test_the_idle_cores_are_asked_only_when_two_candidates_could_run_at_once():
    # Measuring the idle cores waits out a window of 0.1 s: an extraction whose searches never run two
    # candidates at once (a cheap module's outputs, each with one candidate) must not pay it.
    def body(send):
        asked = []
        search = ForkedSearch(lambda: asked.append("asked") or 2, send)
        lone = search.search(1, lambda index: "exact", accepted=lambda r: r == "exact", closeness=lambda r: 0.0,
                             limit_s=30.0)
        before = len(asked)
        pair = search.search(2, lambda index: "exact" if index == 1 else "wrong", accepted=lambda r: r == "exact",
                             closeness=lambda r: 0.0 if r == "exact" else 1.0, limit_s=30.0)
        return before, len(asked), lone.result if lone else None, pair.index if pair else None, search.jobs

    before, after, lone, pair, jobs = run_supervised(body, on_message=lambda message: None)
    assert (before, lone) == (0, "exact")  # one candidate: nothing asked
    assert (after, pair, jobs) == (1, 1, 2)  # asked once, when the second could start beside the first
