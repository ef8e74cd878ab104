"""Planner replays in worker processes of our own, with a per-test timeout.

Safety. Replays run in worker processes (:class:`ReplayPool`): a planner
that hangs is killed after a per-test timeout and the test answers
UNRESOLVED (a hang is another failure than the invariant being minimised),
so ddmin does not reduce towards it; a planner that raises answers
UNRESOLVED too (:meth:`~.replay_model.ReplayModel.run`) — the real module
may never have let such an input reach the planner (the demo's planning
module drops malformed messages before planning), so a replay crash says
nothing about the invariant.

A worker is ``python -m astaa_deft.analysis.minimise.replay_pool READ_FD WRITE_FD``:
it receives a :class:`~.replay_model.ReplaySetup`, builds its
:class:`~.replay_model.ReplayModel` once, then answers pickled
:class:`~.replay_model.Job` records with :class:`~.replay_model.ReplayAnswer`
records until told to stop.
"""

from __future__ import annotations

import contextlib
import os
import queue
import signal
import subprocess
import sys
import threading
from collections.abc import Sequence

from astaa_deft.engine.bus import process_launch
from astaa_deft.engine.bus.processes import python_module, stop_process
from astaa_deft.model.errors import AstaaDeftError, InputError, Problem
from astaa_deft.analysis.minimise.ddmin import Outcome, TestResult
from astaa_deft.analysis.minimise.replay_model import Job, ReplayAnswer, ReplayModel, ReplaySetup

MIN_TEST_TIMEOUT = 20.0  # s: a test that takes longer than this (and 10x the baseline) is a hang
WORKER_START_TIMEOUT = 300.0  # s: loading the log and replaying the baseline once
PARALLEL_PAYS_SECONDS = 0.3  # a second worker only when one replay takes at least this long


def _worker_main(argv: Sequence[str]) -> int:
    """A worker process: build the model once, then answer jobs until told to stop (None).

    Started as ``python -m astaa_deft.analysis.minimise.replay_pool READ_FD WRITE_FD``
    (not through ``multiprocessing``'s spawn, which re-runs the caller's main
    script: a benchmark or notebook without a ``__main__`` guard would fork
    itself over and over).
    """
    from multiprocessing.connection import Connection

    jobs, answers = Connection(int(argv[0]), writable=False), Connection(int(argv[1]), readable=False)
    setup = jobs.recv()
    try:
        model = ReplayModel(setup)
    except InputError as exc:
        answers.send(("error", exc.problems))
        return 2
    except Exception as exc:  # the planner cannot be replayed here: the parent re-runs the system instead
        answers.send(("unavailable", f"{type(exc).__name__}: {exc}"))
        return 2
    answers.send(("ready", model.baseline_seconds))
    while True:
        try:
            job = jobs.recv()
        except EOFError:
            return 0
        if job is None:
            return 0
        answers.send(model.run(job))


class ReplayUnavailable(AstaaDeftError):
    """The module cannot be replayed in a worker (its state cannot be snapshotted, its factory fails): the input
    is fine, the tester is not available; the minimisation re-runs the whole system instead."""


class _Worker:
    """One worker process of ours, and the two pipes to it."""

    def __init__(self, setup: ReplaySetup):
        from multiprocessing.connection import Connection

        job_read, job_write = os.pipe()
        answer_read, answer_write = os.pipe()
        self.process = process_launch.start(
            [*python_module("astaa_deft.analysis.minimise.replay_pool"), str(job_read), str(answer_write)],
            pass_fds=(job_read, answer_write), stdout=None, stderr=None)
        os.close(job_read)
        os.close(answer_write)
        self.jobs = Connection(job_write, readable=False)
        self.answers = Connection(answer_read, writable=False)
        self.jobs.send(setup)
        self.where = setup.log_path

    def wait_ready(self, timeout: float) -> float:
        if not self.answers.poll(timeout):
            self.kill()
            raise InputError(Problem(self.where, None, None, f"the planner replay did not start within {timeout:g} s",
                                     "is the planner's baseline replay hanging?"))
        try:
            kind, value = self.answers.recv()
        except EOFError:
            self.kill()
            raise InputError(Problem(self.where, None, None, "the planner replay's worker exited while loading the log",
                                     "see its error output above")) from None
        if kind == "error":
            self.kill()
            raise InputError(value)
        if kind == "unavailable":
            self.kill()
            raise ReplayUnavailable(f"the planner replay cannot start: {value}")
        return float(value)

    def kill(self) -> None:
        """End this worker now (a hung planner does not get to finish its frame)."""
        stop_process(self.process, grace=0.0, sig=signal.SIGKILL)
        self._close()

    def stop(self) -> None:
        with contextlib.suppress(OSError, ValueError):
            self.jobs.send(None)
        try:
            self.process.wait(timeout=5)
        except subprocess.TimeoutExpired:
            stop_process(self.process, grace=2.0)
        self._close()

    def _close(self) -> None:
        for conn in (self.jobs, self.answers):
            with contextlib.suppress(OSError):
                conn.close()


class ReplayPool:
    """Replays in worker processes, with a per-test timeout a hanging planner cannot escape.

    Not ``concurrent.futures.ProcessPoolExecutor``: a task there cannot be
    timed out (the hung worker keeps its slot until the pool is torn down).
    Here each worker is a process of our own; a test that overruns its
    timeout kills just that worker and a fresh one takes its place.
    ``run`` is thread-safe: ddmin's threads share the workers.
    """

    def __init__(self, setup: ReplaySetup, workers: int = 2, timeout: float | None = None):
        self.setup = setup
        self._idle: queue.Queue[_Worker] = queue.Queue()
        self._all: list[_Worker] = []
        self._lock = threading.Lock()
        self.timeouts = 0
        self.workers = 0
        try:
            # All at once (loading and the baseline replay take seconds); the extra
            # ones are let go if a replay turns out too short for parallel tests to pay.
            started = [self._spawn() for _ in range(max(1, workers))]
            self.baseline_seconds = started[0].wait_ready(WORKER_START_TIMEOUT)
            self.timeout = timeout if timeout is not None else max(MIN_TEST_TIMEOUT, 10 * self.baseline_seconds)
            self._idle.put(started[0])
            self.workers = 1
            if self.baseline_seconds >= PARALLEL_PAYS_SECONDS:
                for worker in started[1:]:
                    worker.wait_ready(WORKER_START_TIMEOUT)
                    self._idle.put(worker)
                    self.workers += 1
            else:
                for worker in started[1:]:
                    self._retire(worker)
        except BaseException:
            self.close()
            raise

    def _retire(self, worker: _Worker) -> None:
        worker.kill()
        with self._lock:
            self._all.remove(worker)

    def _spawn(self) -> _Worker:
        worker = _Worker(self.setup)
        with self._lock:
            self._all.append(worker)
        return worker

    def run(self, job: Job) -> ReplayAnswer:
        worker = self._idle.get()
        try:
            worker.jobs.send(job)
            if worker.answers.poll(self.timeout):
                answer = worker.answers.recv()
                self._idle.put(worker)
                return answer
            why = f"the replay took over {self.timeout:.0f} s (a hanging planner?): stopped"
            self.timeouts += 1
        except (EOFError, OSError) as exc:
            why = f"the replay worker died ({type(exc).__name__})"
        self._replace(worker)
        return ReplayAnswer(TestResult(Outcome.UNRESOLVED, why))

    def _replace(self, worker: _Worker) -> None:
        self._retire(worker)
        fresh = self._spawn()
        fresh.wait_ready(WORKER_START_TIMEOUT)
        self._idle.put(fresh)

    def close(self) -> None:
        with self._lock:
            workers, self._all = list(self._all), []
        for worker in workers:
            worker.stop()

    def __enter__(self) -> ReplayPool:
        return self

    def __exit__(self, *exc) -> None:
        self.close()


if __name__ == "__main__":
    # Run as a worker: the module's own copy under its real name (not ``__main__``), so
    # nothing this worker pickles back to the parent names a module the parent does not know.
    from astaa_deft.analysis.minimise import replay_pool as _real

    sys.exit(_real._worker_main(sys.argv[1:]))
