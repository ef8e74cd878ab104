"""Exact planner snapshots by fork: candidates tried in parallel from one state.

A deep copy of a planner is not always the planner: extension objects
round-trip through ``__getstate__`` and come back different in the last bits
(plans 8e-15 m apart), so nothing replayed from a copy reproduces at θ = 0.
A forked process is: copy-on-write memory keeps native state bit for bit.

How it runs (POSIX only):

* the calling process forks a *supervisor*, which makes itself the reaper of
  every descendant and forks the first *runner*;
* the runner walks the outputs (the ordinary extraction loop). For an output
  with several candidate frames it forks one child per candidate (at most
  ``jobs`` at a time), each stepping its own copy of the planner on its
  frame and reporting the comparison back;
* the first candidate in order that is accepted wins (or, if none is, the
  closest); the winning child *becomes* the runner — it holds the planner
  state that frame produced, untouched by any other — and the old runner and
  the other children exit;
* the runner sends progress and finally the whole extraction to the caller
  over a pipe.

A candidate that runs past its time limit (derived from the recorded cycle
time, in CPU seconds: load does not count against it) is stopped and counts
as not reproduced — unless the limit was a tight one learned from the
accepted steps and no other candidate is accepted: then it runs again under
the full limit.
"""

from __future__ import annotations

import contextlib
import ctypes
import math
import os
import select
import signal
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from typing import Any, Generic, NoReturn, TypeVar, cast

from astaa_deft.engine.bus.process_launch import guarded_fork
from astaa_deft.io.pipe_messages import BULK_LIMIT, FrameError, decode_pickle, encode_pickle, fd_reader, read_frame, \
    write_fd
from astaa_deft.model.errors import InputError, Problem

PR_SET_CHILD_SUBREAPER = 36
M = TypeVar("M")  # a runner's progress message
R = TypeVar("R")  # what a runner finally returns
S = TypeVar("S")  # what one candidate's (or copy's) run returns
MIN_LIMIT_S = 2.0
LIMIT_FACTOR = 10.0  # a candidate may take this many recorded cycles before it is stopped


WALL_LIMIT_FACTOR = 10.0  # a candidate that uses no CPU (blocked) is stopped after this many limits of wall time
_CLOCK_TICKS = os.sysconf("SC_CLK_TCK") if hasattr(os, "sysconf") else 100


def _cpu_seconds(pid: int, wall_s: float) -> float:
    """CPU time (user + system) a child has used so far; its wall time where /proc cannot tell."""
    try:
        with open(f"/proc/{pid}/stat", "rb") as stat:
            fields = stat.read().rsplit(b")", 1)[1].split()
        return (int(fields[11]) + int(fields[12])) / _CLOCK_TICKS  # utime, stime
    except (OSError, IndexError, ValueError):
        return wall_s


_unreaped: list[int] = []


def reap_later(pid: int) -> None:
    """A child told to exit (or killed) is reaped once it has, never waited for.

    On a loaded machine the child may not run for a while; waiting for it
    held the runner up for a scheduling round trip per child. Children not
    reaped when this process exits go to the supervisor, which reaps them.
    """
    _unreaped.append(pid)
    for waiting in list(_unreaped):
        try:
            finished, _ = os.waitpid(waiting, os.WNOHANG)
        except ChildProcessError:  # not ours (a forked copy inherited the list) or already reaped
            finished = waiting
        if finished:
            _unreaped.remove(waiting)


def can_fork() -> bool:
    return hasattr(os, "fork")


def _fork(what: str) -> int:
    """``os.fork`` from a process with one Python thread (else ``UnsafeFork``).

    Native threads are let be: the forked processes run only the planner,
    never what such a thread serves (a BLAS pool, which numpy starts on
    import and which stops itself across a fork; the Zenoh runtime of a
    caller that ran a session).
    """
    return guarded_fork(what, native_threads_ok=True)


def candidate_limit(cycle_s: float) -> float:
    """Seconds one candidate may take: ten recorded cycles, at least two seconds."""
    return max(MIN_LIMIT_S, LIMIT_FACTOR * cycle_s)


def _send(fd: int, obj: object) -> None:
    """``obj`` as one pickle frame (pipe_messages) on ``fd``: the planner's own objects, between forked copies of
    this process only."""
    write_fd(fd, encode_pickle(obj))


def _receive(fd: int, *, what: str) -> object:
    """The next object :func:`_send` wrote on ``fd``.

    Raises ``EOFError`` at the channel's clean end and :class:`FrameError`
    (naming ``what``) for a frame cut short (its writer died mid-frame) or garbled.
    """
    got = read_frame(fd_reader(fd), source=what, max_bytes=BULK_LIMIT)
    if got is None:
        raise EOFError(what)
    return decode_pickle(*got, source=what)


def in_two_forks(run: Callable[[], S], timeout_s: float) -> tuple[S, S] | None:
    """``run()`` in two forked copies of this process (each from the same memory, bit for bit), their
    results; None when a copy died or ran past ``timeout_s`` (wall). Measures whether a module's step is
    bit-stable across copies of its state: two copies stepped on the same frame must answer the same."""
    results: list[S | None] = []
    children: list[tuple[int, int]] = []
    for _ in range(2):
        read_end, write_end = os.pipe()
        pid = _fork("a copy measuring bit stability")
        if pid == 0:
            os.close(read_end)
            try:
                result = run()
            except BaseException:  # noqa: BLE001 - a child must never return into the caller's loop
                result = None
            with contextlib.suppress(OSError):
                _send(write_end, result)
            os._exit(0)
        os.close(write_end)
        children.append((pid, read_end))
    deadline = time.monotonic() + timeout_s
    for pid, read_end in children:
        ready, _, _ = select.select([read_end], [], [], max(0.0, deadline - time.monotonic()))
        result = None
        if ready:
            with contextlib.suppress(EOFError, FrameError):
                # A forked copy of this very process ran ``run``: what it sent back is an S.
                result = cast(S, _receive(read_end, what="a copy's result pipe"))
        else:
            with contextlib.suppress(ProcessLookupError):
                os.kill(pid, signal.SIGKILL)
        os.close(read_end)
        reap_later(pid)
        results.append(result)
    first, second = results
    if first is None or second is None:
        return None
    return first, second


_Running = tuple[int, int, int, float]
"""A candidate's child while it runs: (pid, the fd its result comes on, the fd its verdict goes down, started)."""


@dataclass(kw_only=True)
class Tried(Generic[S]):
    """What a candidate's child reported: its comparison and whether the output equals the recording."""

    index: int
    result: S | None  # whatever the candidate's run returned, or None if the child died or ran out of time
    timed_out: bool = False
    # The child that reported, while it waits for the verdict (None: it died or ran out of time).
    pid: int | None = None
    go_fd: int | None = None  # the pipe its verdict goes down: b"1" carry on as the runner, b"0" exit


class ForkedSearch(Generic[M]):
    """Inside the runner: try candidates in forked children; the winner carries on as the runner.

    ``send_to_caller`` passes the runner's progress messages (M) on to the
    caller of :func:`run_supervised`, whichever process is the runner.
    """

    def __init__(self, jobs: int | Callable[[], int], send_to_caller: Callable[[M], None]) -> None:
        self._jobs = jobs  # a callable is asked once, when two candidates could first run at once
        self.send_to_caller = send_to_caller
        self.timeouts = 0  # candidates stopped by a time limit
        self.cut = 0  # of those, stopped by a tight limit (see search's retry_limit_s)
        self.retried = 0  # cut candidates run again under the full limit (no other was accepted)
        self.retried_kept = 0  # searches whose kept candidate was one of those

    @property
    def jobs(self) -> int:
        """Candidates run at once (at least one)."""
        if callable(self._jobs):
            self._jobs = self._jobs()
        return max(1, self._jobs)

    def _counters(self) -> dict[str, int]:
        return {"timeouts": self.timeouts, "cut": self.cut, "retried": self.retried,
                "retried_kept": self.retried_kept}

    def search(self, count: int, run: Callable[[int], S | None], *, accepted: Callable[[S], bool],
               closeness: Callable[[S], float], limit_s: float,
               settles: Callable[[S], bool] = lambda result: False,
               retry_limit_s: float | None = None, rival: float = math.inf) -> Tried[S] | None:
        """Try candidates 0..count-1; return (in the surviving process) the one kept, or None.

        ``run(i)`` steps the planner on candidate i and returns a picklable
        result; it runs in a child. The process that returns from here holds
        the planner state after the kept candidate (or, for None, the state
        from before: no candidate ran in it). A result that ``settles`` the
        search (the recorded output reproduced field for field: no earlier
        candidate can do better) is kept at once, without waiting for the
        earlier ones — a wrong frame may make the planner search for seconds.

        ``limit_s`` may be a tight limit (a guess from the steps seen so far):
        with ``retry_limit_s``, if no candidate is accepted, those cut by
        ``limit_s`` run again from the same state under ``retry_limit_s`` —
        the tight limit only saves time spent on wrong frames, it never costs
        an output.

        ``rival``: the closeness of a candidate outside this search, measured
        already; when none here is accepted and the closest is farther than
        it, none is kept (None: the caller steps the rival again instead).
        """
        running: dict[int, _Running] = {}
        done: dict[int, Tried[S]] = {}
        queue = list(range(count))
        limit, retrying = limit_s, False
        winner: int | None = None
        while True:
            timeouts_before = self.timeouts
            while winner is None and (queue or running):
                while queue and (not running or len(running) < self.jobs):
                    index = queue.pop(0)
                    child = self._spawn(index, run, running, done)
                    if child is None:  # in the child: it won, and carries on as the runner
                        return self._won
                    running[index] = child
                self._collect(running, done, limit)
                winner = next((i for i in sorted(done) if (result := done[i].result) is not None
                               and settles(result)), None)
                if winner is None:
                    winner = self._decide(done, count, accepted, closeness=closeness)
            if retrying or retry_limit_s is None or retry_limit_s <= limit_s:
                break
            self.cut += self.timeouts - timeouts_before
            cut = sorted(i for i, tried in done.items() if tried.timed_out)
            if winner is not None or not cut:
                break
            for index in cut:  # nothing accepted: the cut candidates get the full limit after all
                del done[index]
            queue, limit, retrying = list(cut), retry_limit_s, True
            self.retried += len(cut)
        if winner is None:
            winner = self._decide(done, count, accepted, closeness=closeness, final=True)
            kept = done[winner].result if winner is not None else None
            assert winner is None or kept is not None  # _decide keeps only a candidate that reported
            if kept is not None and not accepted(kept) and closeness(kept) > rival:
                winner = None  # the rival outside this search is closer
        if retrying and winner is not None and winner in cut:
            self.retried_kept += 1
        for pid, result_fd, go_fd, _ in running.values():  # still running: not needed
            os.kill(pid, signal.SIGKILL)
            os.close(result_fd)
            os.close(go_fd)
            reap_later(pid)
        if winner is None:
            for tried in done.values():
                self._release(tried, go=False)
            return None  # nothing to keep: this process, untouched, carries on
        for index, tried in done.items():
            self._release(tried, go=index == winner, counters=self._counters())
        os._exit(0)  # the winner carries on from here; this runner's state is the old one

    # -- the pieces ------------------------------------------------------------
    def _spawn(self, index: int, run: Callable[[int], Any], running: dict[int, _Running], done: dict[int, Tried]
               ) -> _Running | None:
        """Fork the child that tries candidate ``index``: its handle here; None in the child, once it won."""
        result_r, result_w = os.pipe()
        go_r, go_w = os.pipe()
        pid = _fork("a candidate's replay")
        if pid == 0:
            os.close(result_r)
            os.close(go_w)
            # The siblings' pipes are the runner's business; a winner must not carry them on.
            for _, sibling_result, sibling_go, _ in running.values():
                os.close(sibling_result)
                os.close(sibling_go)
            for tried in done.values():
                if tried.go_fd is not None:
                    os.close(tried.go_fd)
            try:
                result = run(index)
            except BaseException as exc:  # noqa: BLE001 - a child must never return into the caller's loop
                result = None
                _ = exc
            try:
                _send(result_w, result)
            except OSError:
                os._exit(0)
            os.close(result_w)
            verdict = os.read(go_r, 1)
            if verdict != b"1":
                os._exit(0)
            with contextlib.suppress(EOFError, FrameError):  # the runner's counters: ours predate it
                counters = _receive(go_r, what="the runner's verdict pipe")
                if isinstance(counters, dict):
                    self.__dict__.update(counters)
            os.close(go_r)
            self._won: Tried[Any] = Tried(index=index, result=result)  # in the child that won: its candidate, as tried
            return None
        os.close(result_w)
        os.close(go_r)
        return pid, result_r, go_w, time.monotonic()

    def _collect(self, running: dict[int, _Running], done: dict[int, Tried], limit_s: float) -> None:
        """Wait for at least one running child to report (or to run out of time).

        A candidate's time is the CPU time it used, not the wall time since
        it started: on a loaded machine (other work, or the other candidates)
        a right frame would otherwise run out of time. A child that uses no
        CPU (blocked) is stopped after ``WALL_LIMIT_FACTOR`` times the limit.
        """
        now = time.monotonic()
        spent = {index: _cpu_seconds(pid, now - started) for index, (pid, _, _, started) in running.items()}
        # CPU time grows no faster than wall time: no child can reach its limit before this.
        wait = min(min(limit_s - spent[i], WALL_LIMIT_FACTOR * limit_s - (now - started))
                   for i, (_, _, _, started) in running.items())
        fds = {result_fd: index for index, (_, result_fd, _, _) in running.items()}
        ready, _, _ = select.select(list(fds), [], [], max(0.0, wait))
        for fd in ready:
            index = fds[fd]
            pid, result_fd, go_fd, _ = running.pop(index)
            try:
                result = _receive(result_fd, what="a candidate's result pipe")
            except (EOFError, FrameError):
                result = None
            os.close(result_fd)
            done[index] = Tried(index=index, result=result, pid=pid, go_fd=go_fd)
        now = time.monotonic()
        for index, (pid, result_fd, go_fd, started) in list(running.items()):
            wall = now - started
            if wall >= WALL_LIMIT_FACTOR * limit_s or _cpu_seconds(pid, wall) >= limit_s:
                os.kill(pid, signal.SIGKILL)
                reap_later(pid)
                os.close(result_fd)
                os.close(go_fd)
                del running[index]
                self.timeouts += 1
                done[index] = Tried(index=index, result=None, timed_out=True)

    @staticmethod
    def _decide(done: dict[int, Tried], count: int, accepted: Callable[[Any], bool], *,
                closeness: Callable[[Any], float], final: bool = False) -> int | None:
        """The first candidate in order that is accepted, once all before it have reported."""
        for index in range(count):
            if index not in done:
                if not final:
                    return None  # an earlier one may still be accepted
                continue
            result = done[index].result
            if result is not None and accepted(result):
                return index
        if not final:
            return None
        reported = [t for t in done.values() if t.result is not None]
        if not reported:
            return None
        return min(reported, key=lambda t: (closeness(t.result), t.index)).index

    @staticmethod
    def _release(tried: Tried, go: bool, counters: dict[str, int] | None = None) -> None:
        """Tell a reported child its verdict: carry on as the runner (with the runner's ``counters``) or exit."""
        pid, go_fd = tried.pid, tried.go_fd
        if pid is None or go_fd is None:
            return
        with contextlib.suppress(OSError):
            os.write(go_fd, b"1" if go else b"0")
            if go:
                _send(go_fd, counters or {})
        os.close(go_fd)
        if not go:
            reap_later(pid)


@dataclass
class Shadow:
    """In the runner: a forked copy of it that follows one output behind (see :func:`shadow`)."""

    pid: int
    word_fd: int  # the runner's word on each output goes down this pipe


@dataclass
class Following:
    """Returned by :func:`shadow` in the copy: it follows the runner, reading its word from ``word_fd``."""

    word_fd: int


def shadow() -> Shadow | Following:
    """Fork a copy of this process that follows it; here the handle, in the copy :class:`Following`.

    The runner steps an output's first candidate itself and tells the copy
    what became of it (:func:`tell`): the copy, waiting at that output in
    the state from before it, steps the same candidate when it was right —
    on the other core, while the runner goes on — and takes over when it
    was wrong (:func:`hand_over`), searching the others from the exact state
    before the output. A right first candidate then costs one step in each
    process and no fork; a wrong one, the copy's remaining lag (one output
    at most). The runner must :func:`drop` its copy before it forks anything
    else that could outlive it (a candidate search's winner must not inherit
    the word pipe).
    """
    word_r, word_w = os.pipe()
    pid = _fork("the replay's shadow copy")
    if pid == 0:
        os.close(word_w)
        return Following(word_r)
    os.close(word_r)
    return Shadow(pid, word_w)


def tell(copy: Shadow, word: object) -> None:
    """The runner's word on the output the copy waits at; the copy reads it with :func:`next_word`."""
    _send(copy.word_fd, word)


def next_word(following: Following, *, at_end: object = None) -> object:
    """In the copy: the runner's next word; when there is none (dropped, or the runner ended or died) the copy
    exits — or, given ``at_end``, returns that (a checkpoint copy takes over from a runner that died)."""
    try:
        return _receive(following.word_fd, what="the runner's word pipe")
    except (EOFError, OSError, FrameError):
        if at_end is None:
            os._exit(0)
        return at_end


@contextlib.contextmanager
def cpu_limit(seconds: float) -> Iterator[None]:
    """This process is killed (SIGPROF at its default action) once it has used ``seconds`` more CPU time:
    a step in native code that never returns to the interpreter is stopped too. Only for a runner whose
    checkpoint copy takes over when it dies."""
    previous = signal.signal(signal.SIGPROF, signal.SIG_DFL)
    signal.setitimer(signal.ITIMER_PROF, seconds)
    try:
        yield
    finally:
        signal.setitimer(signal.ITIMER_PROF, 0)
        signal.signal(signal.SIGPROF, previous)


def drop(copy: Shadow) -> None:
    """The copy is not needed: it reads end-of-file and exits."""
    os.close(copy.word_fd)
    reap_later(copy.pid)


def hand_over(copy: Shadow, word: object) -> None:
    """Tell the copy its last word and exit: this process's state is not the one to carry on."""
    tell(copy, word)
    os.close(copy.word_fd)
    os._exit(0)


@dataclass(frozen=True)
class _Progress:
    """Runner → caller: a progress message for ``on_message``."""

    message: Any


@dataclass(frozen=True)
class _Finished:
    """Runner → caller: what ``body`` returned (the last message)."""

    result: Any


@dataclass(frozen=True)
class _BadInput:
    """Runner → caller: ``body`` raised InputError with these problems (the last message)."""

    problems: tuple[Problem, ...]


@dataclass(frozen=True)
class _Failed:
    """Runner → caller: ``body`` raised anything else (the last message)."""

    why: str


def _supervise(body: Callable[[Callable[[Any], None]], Any], write_fd: int) -> NoReturn:
    """The supervisor (forked): fork the runner, which runs ``body`` and reports on ``write_fd``; reap every
    descendant until none is left; exit."""
    # A group of its own, signals at their defaults: a stop (Ctrl-C, SIGTERM) reaches the caller, which
    # ends the whole group (run_supervised); a forked copy must never run the caller's handlers.
    os.setpgid(0, 0)
    for stop in (signal.SIGINT, signal.SIGTERM):
        signal.signal(stop, signal.SIG_DFL)
    with contextlib.suppress(OSError, AttributeError):
        ctypes.CDLL(None, use_errno=True).prctl(PR_SET_CHILD_SUBREAPER, 1, 0, 0, 0)
    runner = _fork("the replay's runner")
    if runner == 0:
        code = 0
        try:
            result = body(lambda obj: _send(write_fd, _Progress(obj)))
            _send(write_fd, _Finished(result))
        except InputError as exc:  # bad input found by the runner: the caller raises it as it is
            _send(write_fd, _BadInput(tuple(exc.problems)))
        except BaseException as exc:  # noqa: BLE001 - reported to the caller, never raised here
            try:
                _send(write_fd, _Failed(f"{type(exc).__name__}: {exc}"))
            except Exception:  # noqa: BLE001
                code = 1
        os._exit(code)
    os.close(write_fd)
    while True:
        try:
            os.waitpid(-1, 0)
        except ChildProcessError:
            os._exit(0)


CALLER_POLL_S = 0.01  # how often the caller looks for the runner's messages while it has nothing else to do


def run_supervised(body: Callable[[Callable[[M], None]], R], on_message: Callable[[M], None],
                   idle: Callable[[], bool] = lambda: False) -> R:
    """Run ``body(send)`` in a forked runner under a reaping supervisor; return what it finally returned.

    ``send(obj)`` passes a message to ``on_message`` in the caller (progress);
    the runner's return value comes back once the last runner finishes.
    While no message is waiting the caller calls ``idle()`` (a unit of its own
    work; False: nothing left to do for now), never holding the runner up.
    Raises the runner's ``InputError`` as the same InputError (its problems
    cross the pipe), so bad input reaches the user as one clear message;
    RuntimeError when the runner failed otherwise or died without a result.
    """
    read_fd, write_fd = os.pipe()
    supervisor = _fork("the replay's supervisor")
    if supervisor == 0:
        os.close(read_fd)
        _supervise(body, write_fd)
    with contextlib.suppress(OSError):  # (here too: a stop may come before the supervisor runs)
        os.setpgid(supervisor, supervisor)
    os.close(write_fd)
    try:
        while True:
            while not select.select([read_fd], [], [], 0)[0] and idle():
                pass
            try:
                message = _receive(read_fd, what="the replay runner's pipe")
            except (EOFError, FrameError):
                raise RuntimeError("the replay process ended without a result (it crashed)") from None
            if isinstance(message, _Progress):
                on_message(message.message)
            elif isinstance(message, _BadInput):
                raise InputError(message.problems)
            elif isinstance(message, _Failed):
                raise RuntimeError(f"the replay process failed: {message.why}")
            elif isinstance(message, _Finished):
                return message.result
            else:
                raise RuntimeError(f"the replay process sent {type(message).__name__}")
    except BaseException:  # stopped (KeyboardInterrupt) or failed: the runner and its candidates end now
        with contextlib.suppress(OSError):
            os.killpg(supervisor, signal.SIGKILL)
        raise
    finally:
        os.close(read_fd)
        os.waitpid(supervisor, 0)
