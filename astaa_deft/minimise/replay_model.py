"""The planner replay of a recorded run, with any subset of its mutations applied.

For a failing invariant that reads only the planner's output, a whole-system
re-run is not needed: the planner is deterministic on its own (docs/deft.md).
A test of a subset of mutations (:meth:`ReplayModel.run`)

1. rebuilds the planner's input streams with those mutations applied and
   every other one reverted (:class:`~.mutations.ReceivedStreams`);
2. takes, for every recorded planner output, its most likely frame — the
   first candidate of :func:`astaa_deft.deft.frames.candidates`, with the
   same never-older-than-the-previous-frame rule as extraction (the output
   times are the recorded ones: the replay is open-loop);
3. replays the planner (``planner.replay.factory``, in-process) over the
   frames in order and feeds its outputs, at the recorded outputs' times, to
   a :class:`~astaa_deft.monitor.MonitorSet` holding only that invariant;
4. answers FAIL at the first violation, PASS if none.

Cost. The replay of the run with every mutation reverted (the baseline) is
done once per process, keeping a planner snapshot every few frames. A test
replays only where its subset makes a difference: from the first frame it
changes until the planner is back in the baseline's state (the effect of a
mutation usually dies out within a few frames), and stops at the first
violation. Decoded messages are cached by origin. Frames whose inputs do not
decode are not used: an undecodable input is dropped, as a module's
deserialiser would.

This module runs in whichever process builds the model; the worker processes
that run tests in isolation are :mod:`.replay_pool`, the tester ddmin calls
is :mod:`.replay_tester`. Its records (:class:`Job`, :class:`ReplaySetup`,
:class:`ReplayAnswer`) cross the pipes to the workers pickled.
"""

from __future__ import annotations

import copy
import json
import pickle
import time
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, replace
from typing import Any

from ..codecs import get_codec
from ..codecs.base import DecodeError
from ..deft.frames import Stream, candidates, frame_at, newest_at_or_before
from ..deft.planner_section import planner_of
from ..deft.replay import make_planner
from ..errors import InputError, Problem
from ..log import layout
from ..log import records as rec
from ..log.reader import LoggedMessage, read_log
from ..monitor import MonitorSet, format_violation, with_typed_invariants
from ..session.check import spec_from_log
from ..spec.model import Spec
from .ddmin import Outcome, TestResult
from .mutations import (
    Delivered,
    FieldSelection,
    ReceivedStreams,
    read_mutations,
    sent_stream,
)

SNAPSHOTS = 400  # planner snapshots kept along the baseline replay (at most)


@dataclass(frozen=True)
class Job:
    """One test: the kept mutations (number → field selection) and, for stage 2, the frames replayed.

    ``frames`` None: every output's frame, continuing from the baseline's
    snapshots. A tuple of output indices: only those frames, in order, from a
    fresh planner (the scaffolding search).
    """

    kept: tuple[tuple[int, FieldSelection], ...]
    frames: tuple[int, ...] | None = None

    @classmethod
    def of(cls, kept: Mapping[int, FieldSelection], frames: Sequence[int] | None = None) -> Job:
        return cls(tuple(sorted(kept.items())), None if frames is None else tuple(sorted(frames)))


@dataclass(frozen=True)
class ReplayAnswer:
    result: TestResult
    failing_output: int | None = None  # index of the output whose replay broke the invariant


@dataclass(frozen=True)
class ReplaySetup:
    """What a worker needs to build its own :class:`ReplayModel` (plain, picklable data)."""

    log_path: str
    spec_path: str | None  # None: the spec stored in the log
    invariant: str


@dataclass(frozen=True)
class Frame:
    output: int  # index into the recorded outputs
    inputs: tuple[tuple[str, Delivered], ...]
    frame_time_ns: int
    trigger_time_ns: int

    @property
    def key(self) -> tuple:
        return tuple(d.key for _, d in self.inputs)


def load_spec_for(log, spec_path: str | None) -> Spec:
    if spec_path is not None:
        from ..spec_loader import load_spec

        return load_spec(spec_path)
    spec = spec_from_log(log, f"{log.path}:{layout.SPEC_ATTACHMENT}")
    if spec is None:
        raise InputError(Problem(str(log.path), None, None, "the log holds no spec",
                                 "give the SUT spec with --spec sut.yaml"))
    return spec


def run_params(log) -> dict[str, str]:
    """The params the run was recorded with: the replayed planner must be built the same way."""
    try:
        return json.loads(log.metadata.get(layout.RUN_METADATA, {}).get("params", "{}"))
    except ValueError:
        return {}


def replayable(spec: Spec, invariant_name: str) -> str | None:
    """None if the replay can judge this invariant, else why not (the live tester is used then)."""
    cfg = spec.planner
    if cfg is None:
        return "the spec has no 'planner' section"
    if not cfg.factory:
        return "the planner has no in-process replay ('planner.replay.factory')"
    spec = with_typed_invariants(spec)
    invariant = next((i for i in spec.invariants if i.name == invariant_name), None)
    if invariant is None:
        return f"'{invariant_name}' is not an invariant of the spec"
    if invariant.kind in ("process", "deadline"):
        return f"'{invariant_name}' is a {invariant.kind} invariant: timing and processes are not replayed"
    channels = MonitorSet(replace(spec, invariants=(invariant,)), 0).channels()
    if channels != {cfg.output}:
        return (f"'{invariant_name}' reads {', '.join(sorted(channels)) or 'no channel'}, "
                f"not only the planner's output '{cfg.output}'")
    return None


class ReplayModel:
    """A run's planner replay with any subset of its mutations, in this process.

    ``baseline=False`` skips the baseline replay: enough for :meth:`frames`
    and :meth:`replay` (what the orchestrating process needs), not for :meth:`run`.
    """

    def __init__(self, setup: ReplaySetup, baseline: bool = True):
        log = read_log(setup.log_path)
        spec = with_typed_invariants(load_spec_for(log, setup.spec_path))
        why_not = replayable(spec, setup.invariant)
        if why_not:
            raise InputError(Problem(setup.log_path, None, None, f"no planner replay: {why_not}", "use --live-only"))
        self.spec = spec
        self.cfg = planner_of(spec)
        self.params = {**spec.params, **run_params(log)}
        invariant = next(i for i in spec.invariants if i.name == setup.invariant)
        self.judged = replace(spec, invariants=(invariant,))
        self.mlog = read_mutations(log, spec)
        self.streams = ReceivedStreams(self.mlog, self.cfg.module, self.cfg.inputs)
        missing = [name for name in self.cfg.inputs if not self.streams.has(name)]
        if missing:
            raise InputError(Problem(str(log.path), None, None,
                                     f"the log has no messages on the planner's input(s) {', '.join(missing)}",
                                     "record the run with this spec"))
        self.outputs: list[LoggedMessage] = sent_stream(self.mlog, log, self.cfg.output)
        self.start_ns = self.mlog.start_ns
        stopping = [e.time_ns for e in log.records(rec.RunStopping) if e.time_ns]
        self.end_ns = int(stopping[0]) if stopping else max((m.log_time for m in self.outputs), default=self.start_ns)
        # Replay only up to the output that failed in the run. The frames after it carry the
        # failure's own consequences (in closed loop the ego is already speeding), which would
        # make the failure look independent of every mutation.
        failed_at = _first_failure_ns(log, self.judged)
        if failed_at is not None:
            # On the clock the monitor judged by: a message's publish time (the source timestamp the
            # recorder kept, e.g. a ROS 2 message's, which precedes its log time), else its log time.
            self.outputs = [m for m in self.outputs if m.publish_time <= failed_at]
            self.end_ns = min(self.end_ns, self.outputs[-1].log_time if self.outputs else failed_at)
        self.lookback_ns = int(self.cfg.lookback_ms * 1e6)
        self._codecs = {name: get_codec(spec.channel(name).encoding) for name in self.cfg.inputs}
        self._decoded: dict[Any, Any] = {}
        self.baseline_seconds = 0.0
        if baseline:
            self._baseline()

    # -- frames ------------------------------------------------------------
    def decode(self, channel: str, delivered: Delivered) -> Any:
        if delivered.key not in self._decoded:
            try:
                self._decoded[delivered.key] = self._codecs[channel].decode(delivered.data)
            except DecodeError:
                self._decoded[delivered.key] = None
        return self._decoded[delivered.key]

    def frames(self, kept: Mapping[int, FieldSelection]) -> list[Frame | None]:
        """The most likely frame of every recorded output (None where an input had no message yet)."""
        built = self.streams.build(kept)
        usable = {name: [d for d in stream if self.decode(name, d) is not None] for name, stream in built.items()}
        streams = {name: Stream(name, [d.time_ns for d in msgs]) for name, msgs in usable.items()}
        trigger = self.cfg.trigger
        trigger_times = streams[trigger].times
        previous: dict[str, int] = {}
        out: list[Frame | None] = []
        for index, output in enumerate(self.outputs):
            t_index = newest_at_or_before(trigger_times, output.log_time)
            if t_index < 0:
                out.append(None)
                continue
            t_t = trigger_times[t_index]
            choice = frame_at(streams, trigger, t_index, t_t, previous)
            frame_time = t_t
            if choice is None:  # the trigger time does not work: the candidate search decides
                options = candidates(streams, trigger, output.log_time, previous, self.lookback_ns)
                if not options:
                    out.append(None)
                    continue
                choice, frame_time = dict(options[0].choice), options[0].frame_time
            previous = choice
            out.append(Frame(index, tuple((name, usable[name][i]) for name, i in sorted(choice.items())),
                             frame_time, t_t))
        return out

    def frame_message(self, frame: Frame) -> dict[str, Any]:
        return {name: self.decode(name, d) for name, d in frame.inputs}

    # -- replay ------------------------------------------------------------
    def fresh_planner(self):
        return make_planner(self.spec, self.params)

    def _baseline(self) -> None:
        """Replay with every mutation reverted, once: the snapshots and outputs tests start from.

        Snapshots are pickled: restoring one is a ``pickle.loads``, and two
        planner states are the same when their pickles are (see :meth:`run`).
        A planner that cannot be pickled is deep-copied instead, without that check.
        """
        started = time.perf_counter()
        self.base_frames = self.frames({})
        self.base_keys = [f.key if f else None for f in self.base_frames]
        stride = max(1, len(self.base_frames) // SNAPSHOTS)
        planner = self.fresh_planner()
        self.snapshots: dict[int, Any] = {}
        self._pickled = True
        self.base_outputs: list[Any] = []
        self.base_error: str | None = None
        self.base_error_frame: int | None = None
        for k, frame in enumerate(self.base_frames):
            if k % stride == 0:
                self.snapshots[k] = self._snapshot(planner)
            if frame is None:
                self.base_outputs.append(None)
                continue
            try:
                self.base_outputs.append(planner.step(self.frame_message(frame)))
            except Exception as exc:  # judged by the tests that reach it
                self.base_error = f"output {k}'s frame: {type(exc).__name__}: {exc}"
                self.base_error_frame = k
                self.base_outputs.extend([None] * (len(self.base_frames) - k - 1))
                break
        planner.close()
        self.baseline_seconds = time.perf_counter() - started

    def _snapshot(self, planner) -> Any:
        state = planner.snapshot()
        if self._pickled:
            try:
                return pickle.dumps(state, protocol=pickle.HIGHEST_PROTOCOL)
            except Exception:  # not picklable: deep copies, and no convergence check
                self._pickled = False
                self.snapshots = {k: pickle.loads(v) for k, v in self.snapshots.items()}
        return state

    def _restore(self, k: int):
        """A planner in the baseline's state just before output ``k``'s frame."""
        s = max(i for i in self.snapshots if i <= k)
        planner = self.fresh_planner()
        state = self.snapshots[s]
        planner.restore(pickle.loads(state) if self._pickled else copy.deepcopy(state))
        for i in range(s, k):  # only when snapshots are sparser than frames
            frame = self.base_frames[i]
            if frame is not None:
                planner.step(self.frame_message(frame))
        return planner

    def _converged(self, planner, k: int) -> bool:
        """Is ``planner`` in the state the baseline was in before output ``k``'s frame?"""
        if not self._pickled or k not in self.snapshots or not planner.can_snapshot:
            return False
        try:
            return pickle.dumps(planner.snapshot(), protocol=pickle.HIGHEST_PROTOCOL) == self.snapshots[k]
        except Exception:
            return False

    def run(self, job: Job) -> ReplayAnswer:
        """The test of one job (module doc).

        Stage-1 and stage-3 jobs follow the baseline: where a frame's inputs
        are the baseline's and the planner is in the baseline's state, the
        output is the baseline's and nothing is replayed. The planner runs
        from the first frame the subset changes until its state is the
        baseline's again (same pickle) on a frame with unchanged inputs — a
        mutation's effect usually dies out within a few frames — and again
        at the next change.
        """
        kept = dict(job.kept)
        frames = self.frames(kept)
        monitors = self._monitors()
        if job.frames is not None:
            chosen = [frame for i in job.frames if i < len(frames) and (frame := frames[i]) is not None]
            return self._judge(self.fresh_planner(), chosen, monitors)
        planner = None  # None: in step with the baseline, whose outputs are known
        try:
            for k, frame in enumerate(frames):
                unchanged = (frame.key if frame is not None else None) == self.base_keys[k]
                if planner is not None and unchanged and self._converged(planner, k):
                    planner.close()
                    planner = None
                if planner is None and unchanged:
                    if frame is None:
                        continue
                    if self.base_error_frame is not None and k >= self.base_error_frame:
                        return ReplayAnswer(TestResult(Outcome.UNRESOLVED,
                                                       f"the planner raised on {self.base_error}"))
                    found = self._feed(monitors, frame, self.base_outputs[k])
                    if found:
                        return ReplayAnswer(TestResult(Outcome.FAIL, found), frame.output)
                    continue
                if planner is None:
                    planner = self._restore(k)
                if frame is None:
                    continue
                answer = self._step(planner, monitors, frame)
                if answer is not None:
                    return answer
        finally:
            if planner is not None:
                planner.close()
        return self._finish(monitors)

    def replay(self, frames: Sequence[Frame]) -> list[tuple[Frame, Any, str | None]]:
        """(frame, replayed output, error) for ``frames`` in order from a fresh planner (for the outputs)."""
        planner = self.fresh_planner()
        out: list[tuple[Frame, Any, str | None]] = []
        try:
            for frame in frames:
                try:
                    out.append((frame, planner.step(self.frame_message(frame)), None))
                except Exception as exc:
                    out.append((frame, None, f"{type(exc).__name__}: {exc}"))
                    break
        finally:
            planner.close()
        return out

    def _monitors(self) -> MonitorSet:
        return MonitorSet(self.judged, self.start_ns)

    def _feed(self, monitors: MonitorSet, frame: Frame, message: Any) -> str | None:
        output = self.outputs[frame.output]
        monitors.on_tick(output.log_time)
        found = monitors.on_message(self.cfg.output, output.log_time, message, output.sequence)
        if found:
            return f"{format_violation(found[0], self.start_ns)} (output {frame.output})"
        return None

    def _judge(self, planner, frames: Sequence[Frame], monitors: MonitorSet) -> ReplayAnswer:
        """Replay ``frames`` in order on ``planner`` and judge every output."""
        try:
            for frame in frames:
                answer = self._step(planner, monitors, frame)
                if answer is not None:
                    return answer
        finally:
            planner.close()
        return self._finish(monitors)

    def _step(self, planner, monitors: MonitorSet, frame: Frame) -> ReplayAnswer | None:
        """One replayed output, judged: an answer if it decides the test, else None."""
        try:
            message = planner.step(self.frame_message(frame))
        except Exception as exc:
            return ReplayAnswer(TestResult(Outcome.UNRESOLVED, f"the planner raised {type(exc).__name__}: {exc} "
                                                               f"on output {frame.output}'s frame"))
        found = self._feed(monitors, frame, message)
        return ReplayAnswer(TestResult(Outcome.FAIL, found), frame.output) if found else None

    def _finish(self, monitors: MonitorSet) -> ReplayAnswer:
        found = monitors.finish(self.end_ns)
        if found:
            return ReplayAnswer(TestResult(Outcome.FAIL, format_violation(found[0], self.start_ns)))
        return ReplayAnswer(TestResult(Outcome.PASS))


def _first_failure_ns(log, judged: Spec) -> int | None:
    """When the run's recorded outputs first broke the judged invariant (None if they never did)."""
    from ..monitor import check_log

    found = check_log(log, judged).violations
    return min(v.time_ns for v in found) if found else None
