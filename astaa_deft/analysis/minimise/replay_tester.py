"""The replay tester ddmin calls: does a subset of mutations still break the invariant in a planner replay?

A test is a :class:`~.replay_model.Job` answered by a
:class:`~.replay_pool.ReplayPool` (the model, :mod:`.replay_model`, says how).
The answer is deterministic, so a subset is tested once (:class:`DeftTester`
caches by subset, on top of ddmin's own cache). Whether the replay can judge
an invariant at all is :func:`~.replay_model.replayable`.
"""

from __future__ import annotations

import threading
from pathlib import Path

from astaa_deft.analysis.minimise.ddmin import Outcome, TestResult
from astaa_deft.analysis.minimise.replay_model import Job, ReplayAnswer, ReplaySetup
from astaa_deft.analysis.minimise.replay_pool import ReplayPool


class DeftTester:
    """Jobs to answers through a pool, each distinct job run once (the replay is deterministic)."""

    def __init__(self, pool: ReplayPool):
        self.pool = pool
        self._cache: dict[Job, ReplayAnswer] = {}
        self._lock = threading.Lock()
        self.runs = 0
        self.hits = 0

    def answer(self, job: Job) -> ReplayAnswer:
        with self._lock:
            if job in self._cache:
                self.hits += 1
                return self._cache[job]
        answer = self.pool.run(job)
        with self._lock:
            self.runs += 1
            if answer.result.outcome is not Outcome.UNRESOLVED or "died" not in answer.result.detail:
                self._cache[job] = answer
        return answer

    def __call__(self, job: Job) -> TestResult:
        return self.answer(job).result


def default_setup(log_path: Path, spec_path: Path | None, invariant: str) -> ReplaySetup:
    return ReplaySetup(log_path=str(log_path), spec_path=str(spec_path) if spec_path is not None else None,
                       invariant=invariant)
