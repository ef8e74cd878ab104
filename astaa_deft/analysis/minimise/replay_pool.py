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
:class:`~.replay_model.ReplayModel` once, then answers
:class:`~.replay_model.Job` records with :class:`~.replay_model.ReplayAnswer`
records until told to stop, each a typed message in a frame of
:mod:`astaa_deft.io.pipe_messages`.
"""

from __future__ import annotations

import contextlib
import dataclasses
import os
import queue
import select
import signal
import subprocess
import sys
import threading
from collections.abc import Sequence
from dataclasses import dataclass
from types import TracebackType
from typing import ClassVar

from astaa_deft.engine.bus import process_launch
from astaa_deft.engine.bus.processes import python_module, stop_process
from astaa_deft.io import pipe_messages
from astaa_deft.io.pipe_messages import FieldlessMessage, FrameError, fd_reader
from astaa_deft.model.errors import AstaaDeftError, InputError, Problem
from astaa_deft.model.json import JsonObject, JsonValue
from astaa_deft.analysis.minimise.ddmin import Outcome, TestResult
from astaa_deft.analysis.minimise.replay_model import Job, ReplayAnswer, ReplayModel, ReplaySetup

MIN_TEST_TIMEOUT = 20.0  # s: a test that takes longer than this (and 10x the baseline) is a hang
WORKER_START_TIMEOUT = 300.0  # s: loading the log and replaying the baseline once
PARALLEL_PAYS_SECONDS = 0.3  # a second worker only when one replay takes at least this long


# -- the messages (pipe_messages frames): setup, jobs and stop to the worker; ready, bad input, unavailable and
# answers from it --------------------------------------------------------------------------------------------


def _optional_str(value: JsonValue) -> str | None:
    return None if value is None else str(value)


def _optional_int(value: JsonValue) -> int | None:
    if value is not None and not isinstance(value, int):
        raise ValueError(f"an integer or null, not {value!r}")
    return value


def _number(value: JsonValue) -> float:
    if not isinstance(value, (int, float)):
        raise ValueError(f"a number, not {value!r}")
    return float(value)


def _ints(value: JsonValue) -> tuple[int, ...]:
    if not isinstance(value, list) or not all(isinstance(i, int) for i in value):
        raise ValueError(f"a list of integers, not {value!r}")
    return tuple(i for i in value if isinstance(i, int))


@dataclass(frozen=True)
class SetupMessage:
    """The worker's first message: what to build its :class:`ReplayModel` from."""

    TAG: ClassVar[str] = "setup"
    setup: ReplaySetup

    def to_json(self) -> JsonObject:
        return dict(dataclasses.asdict(self.setup))

    @classmethod
    def from_json(cls, data: JsonObject) -> SetupMessage:
        return cls(ReplaySetup(
            log_path=str(data["log_path"]), spec_path=_optional_str(data["spec_path"]),
            invariant=str(data["invariant"]), module=_optional_str(data["module"]),
            output=_optional_str(data["output"]), failure_module=_optional_str(data["failure_module"]),
            trust_log_spec=bool(data["trust_log_spec"]), output_clock=str(data["output_clock"])))


@dataclass(frozen=True)
class JobMessage:
    """One test for the worker to replay."""

    TAG: ClassVar[str] = "job"
    job: Job

    def to_json(self) -> JsonObject:
        kept: list[JsonValue] = [[number, None if selection is None else list(selection)]
                                 for number, selection in self.job.kept]
        return {"kept": kept, "frames": None if self.job.frames is None else list(self.job.frames)}

    @classmethod
    def from_json(cls, data: JsonObject) -> JobMessage:
        kept, frames = data["kept"], data["frames"]
        if not isinstance(kept, list):
            raise ValueError(f"kept is a list, not {kept!r}")
        pairs: list[tuple[int, tuple[int, ...] | None]] = []
        for entry in kept:
            if not isinstance(entry, list) or len(entry) != 2 or not isinstance(entry[0], int):
                raise ValueError(f"a kept mutation is [number, selection], not {entry!r}")
            pairs.append((entry[0], None if entry[1] is None else _ints(entry[1])))
        return cls(Job(tuple(pairs), None if frames is None else _ints(frames)))


@dataclass(frozen=True)
class StopMessage(FieldlessMessage):
    """No more jobs: the worker exits."""

    TAG: ClassVar[str] = "stop"


@dataclass(frozen=True)
class ReadyMessage:
    """The worker built its model: the baseline replay took ``baseline_seconds``."""

    TAG: ClassVar[str] = "ready"
    baseline_seconds: float

    def to_json(self) -> JsonObject:
        return {"baseline_seconds": self.baseline_seconds}

    @classmethod
    def from_json(cls, data: JsonObject) -> ReadyMessage:
        return cls(_number(data["baseline_seconds"]))


@dataclass(frozen=True)
class BadInputMessage:
    """The worker found bad input (the log, the spec): the parent raises these problems as an InputError."""

    TAG: ClassVar[str] = "bad_input"
    problems: tuple[Problem, ...]

    def to_json(self) -> JsonObject:
        return {"problems": [dict(dataclasses.asdict(problem)) for problem in self.problems]}

    @classmethod
    def from_json(cls, data: JsonObject) -> BadInputMessage:
        problems = data["problems"]
        if not isinstance(problems, list):
            raise ValueError("problems must be a list")
        read: list[Problem] = []
        for problem in problems:
            if not isinstance(problem, dict):
                raise ValueError(f"a problem is an object, not {problem!r}")
            read.append(Problem(str(problem["file"]), _optional_int(problem["line"]),
                                _optional_int(problem["column"]), str(problem["message"]), str(problem["fix"])))
        return cls(tuple(read))


@dataclass(frozen=True)
class UnavailableMessage:
    """The module cannot be replayed in a worker (``reason``): the parent re-runs the whole system instead."""

    TAG: ClassVar[str] = "unavailable"
    reason: str

    def to_json(self) -> JsonObject:
        return {"reason": self.reason}

    @classmethod
    def from_json(cls, data: JsonObject) -> UnavailableMessage:
        return cls(str(data["reason"]))


@dataclass(frozen=True)
class AnswerMessage:
    """A job's answer."""

    TAG: ClassVar[str] = "answer"
    answer: ReplayAnswer

    def to_json(self) -> JsonObject:
        result = self.answer.result
        return {"outcome": result.outcome.value, "detail": result.detail, "failure_rate": result.failure_rate,
                "failing_output": self.answer.failing_output}

    @classmethod
    def from_json(cls, data: JsonObject) -> AnswerMessage:
        rate = data["failure_rate"]
        result = TestResult(Outcome(data["outcome"]), str(data["detail"]), None if rate is None else _number(rate))
        return cls(ReplayAnswer(result, _optional_int(data["failing_output"])))


_TO_WORKER = (SetupMessage, JobMessage, StopMessage)
_FROM_WORKER = (ReadyMessage, BadInputMessage, UnavailableMessage, AnswerMessage)


def _worker_main(argv: Sequence[str]) -> int:
    """A worker process: build the model once, then answer jobs until told to stop; its exit code.

    Started as ``python -m astaa_deft.analysis.minimise.replay_pool READ_FD WRITE_FD``
    (not through ``multiprocessing``'s spawn, which re-runs the caller's main
    script: a benchmark or notebook without a ``__main__`` guard would fork
    itself over and over). Reads setup, job and stop messages on READ_FD;
    writes ready, bad input, unavailable and answer messages on WRITE_FD.
    Exits 0 when stopped or at the end of its input, 2 when it could not
    build the model, and raises :class:`FrameError` on a garbled message.
    """
    read, answers = fd_reader(int(argv[0])), int(argv[1])
    source = "the replay worker's job pipe"
    first = pipe_messages.receive(read, (SetupMessage,), source=source)
    if first is None:
        return 0
    try:
        model = ReplayModel(first.setup)
    except InputError as exc:
        pipe_messages.send_fd(answers, BadInputMessage(tuple(exc.problems)))
        return 2
    except Exception as exc:  # the planner cannot be replayed here: the parent re-runs the system instead
        pipe_messages.send_fd(answers, UnavailableMessage(f"{type(exc).__name__}: {exc}"))
        return 2
    pipe_messages.send_fd(answers, ReadyMessage(model.baseline_seconds))
    while True:
        message = pipe_messages.receive(read, (JobMessage, StopMessage), source=source)
        if not isinstance(message, JobMessage):
            return 0
        pipe_messages.send_fd(answers, AnswerMessage(model.run(message.job)))


class ReplayUnavailable(AstaaDeftError):
    """The module cannot be replayed in a worker (its state cannot be snapshotted, its factory fails): the input
    is fine, the tester is not available; the minimisation re-runs the whole system instead."""


class _Worker:
    """One worker process of ours, and the two pipes to it (used by one thread at a time)."""

    def __init__(self, setup: ReplaySetup) -> None:
        job_read, job_write = os.pipe()
        answer_read, answer_write = os.pipe()
        try:
            self.process = process_launch.start(
                [*python_module("astaa_deft.analysis.minimise.replay_pool"), str(job_read), str(answer_write)],
                pass_fds=(job_read, answer_write), stdout=None, stderr=None)
        except BaseException:
            for fd in (job_write, answer_read):
                os.close(fd)
            raise
        finally:
            os.close(job_read)
            os.close(answer_write)
        self._jobs, self._answers = job_write, answer_read
        self._closed = False
        self.where = setup.log_path
        self.send(SetupMessage(setup))

    def send(self, message: SetupMessage | JobMessage | StopMessage) -> None:
        """``message`` to the worker; raises ``OSError`` when it has gone."""
        pipe_messages.send_fd(self._jobs, message)

    def answer_within(self, timeout: float) -> bool:
        """Whether the worker's next message (or its end) is there within ``timeout`` seconds."""
        ready, _, _ = select.select([self._answers], [], [], timeout)
        return bool(ready)

    def receive(self) -> ReadyMessage | BadInputMessage | UnavailableMessage | AnswerMessage:
        """The worker's next message; raises ``EOFError`` when it exited, :class:`FrameError` mid-frame."""
        message = pipe_messages.receive(fd_reader(self._answers), _FROM_WORKER,
                                        source=f"the replay worker of {self.where}")
        if not isinstance(message, (ReadyMessage, BadInputMessage, UnavailableMessage, AnswerMessage)):
            raise EOFError("the replay worker exited")
        return message

    def wait_ready(self, timeout: float) -> float:
        """The baseline replay's seconds once the worker is ready.

        Raises InputError (bad input, a worker that did not start within
        ``timeout`` or died while loading) or :class:`ReplayUnavailable`,
        after killing the worker.
        """
        if not self.answer_within(timeout):
            self.kill()
            raise InputError(Problem(self.where, None, None, f"the planner replay did not start within {timeout:g} s",
                                     "is the planner's baseline replay hanging?"))
        try:
            message = self.receive()
        except (EOFError, FrameError):
            self.kill()
            raise InputError(Problem(self.where, None, None, "the planner replay's worker exited while loading the log",
                                     "see its error output above")) from None
        if isinstance(message, BadInputMessage):
            self.kill()
            raise InputError(message.problems)
        if isinstance(message, UnavailableMessage):
            self.kill()
            raise ReplayUnavailable(f"the planner replay cannot start: {message.reason}")
        if not isinstance(message, ReadyMessage):
            self.kill()
            raise ReplayUnavailable(f"the planner replay's worker answered {message.TAG!r} before it was ready")
        return message.baseline_seconds

    def kill(self) -> None:
        """End this worker now (a hung planner does not get to finish its frame)."""
        stop_process(self.process, grace=0.0, sig=signal.SIGKILL)
        self._close()

    def stop(self) -> None:
        """Tell the worker to stop and wait for it (stopped by signal after 5 s)."""
        with contextlib.suppress(OSError):
            if not self._closed:
                self.send(StopMessage())
        try:
            self.process.wait(timeout=5)
        except subprocess.TimeoutExpired:
            stop_process(self.process, grace=2.0)
        self._close()

    def _close(self) -> None:
        if not self._closed:
            self._closed = True
            for fd in (self._jobs, self._answers):
                with contextlib.suppress(OSError):
                    os.close(fd)


class ReplayPool:
    """Replays in worker processes, with a per-test timeout a hanging planner cannot escape.

    Not ``concurrent.futures.ProcessPoolExecutor``: a task there cannot be
    timed out (the hung worker keeps its slot until the pool is torn down).
    Here each worker is a process of our own; a test that overruns its
    timeout kills just that worker and a fresh one takes its place.
    ``run`` is thread-safe: ddmin's threads share the workers.
    """

    def __init__(self, setup: ReplaySetup, workers: int = 2, timeout: float | None = None) -> None:
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
        """``job``'s answer from an idle worker; UNRESOLVED (the worker replaced) when it died or overran."""
        worker = self._idle.get()
        try:
            worker.send(JobMessage(job))
            if worker.answer_within(self.timeout):
                message = worker.receive()
                if not isinstance(message, AnswerMessage):
                    raise FrameError(f"the replay worker answered {message.TAG!r} to a job")
                self._idle.put(worker)
                return message.answer
            why = f"the replay took over {self.timeout:.0f} s (a hanging planner?): stopped"
            self.timeouts += 1
        except (EOFError, OSError, FrameError) as exc:
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

    def __exit__(self, kind: type[BaseException] | None, exc: BaseException | None,
                 trace: TracebackType | None) -> None:
        self.close()


if __name__ == "__main__":
    # Run as a worker: the module's own copy under its real name (not ``__main__``), so its message classes
    # are the ones every other module of the worker imports.
    from astaa_deft.analysis.minimise import replay_pool as _real

    sys.exit(_real._worker_main(sys.argv[1:]))
