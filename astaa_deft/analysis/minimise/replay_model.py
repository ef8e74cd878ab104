"""The planner replay of a recorded run, with any subset of its mutations applied.

For a failing invariant that reads only the planner's output, a whole-system
re-run is not needed: the planner is deterministic on its own (docs/deft.md).
A test of a subset of mutations (:meth:`ReplayModel.run`)

1. rebuilds the planner's input streams with those mutations applied and
   every other one reverted (:class:`~.mutations.ReceivedStreams`);
2. takes, for every recorded planner output, its most likely frame — the
   first candidate of :func:`astaa_deft.analysis.deft.frames.candidates`, with the
   same never-older-than-the-previous-frame rule as extraction (the output
   times are the recorded ones: the replay is open-loop; an output is paired
   with the trigger before its log time, or — ``output_clock`` "published",
   for a recording whose outputs were logged in bursts — before its
   publisher's stamp);
3. replays the planner (``planner.replay.factory``, in-process) over the
   frames in order and feeds its outputs, at the recorded outputs' times, to
   a :class:`~astaa_deft.engine.monitor.MonitorSet` holding only that invariant;
4. answers FAIL at the first violation, PASS if none.

Cost. The replay of the run with every mutation reverted (the baseline) is
done once per process, keeping a planner snapshot every few frames. A test
replays only where its subset makes a difference: from the first frame it
changes until the planner is back in the baseline's state (the effect of a
mutation usually dies out within a few frames), and stops at the first
violation. Decoded messages are cached by origin. Frames whose inputs do not
decode are not used: an undecodable input is dropped, as a module's
deserialiser would.

This module builds the model (the log read, the frames of any subset) and
runs a test; the baseline replay and its snapshots are :mod:`.replay_baseline`,
the judging of one test's outputs :mod:`.replay_judge`, and the records
(:class:`Job`, :class:`ReplaySetup`, :class:`ReplayAnswer`, :class:`Frame`,
in :mod:`.replay_records`, re-exported here) cross the pipes to the workers
pickled. It runs in whichever process builds the model; the worker processes
that run tests in isolation are :mod:`.replay_pool`, the tester ddmin calls
is :mod:`.replay_tester`.
"""

from __future__ import annotations

import functools
from collections.abc import Hashable, Mapping, Sequence
from dataclasses import replace

from astaa_deft.io.codecs import get_codec
from astaa_deft.io.codecs.base import DecodeError
from astaa_deft.analysis.deft.frames import OutputContext, Stream, candidates, frame_at, newest_at_or_before, \
    trigger_frame
from astaa_deft.analysis.deft.planner_section import replay_module_of, replay_modules
from astaa_deft.analysis.deft.run_metadata import RunMetadata
from astaa_deft.analysis.deft.replay import ReplayPlanner, make_planner, within_limit
from astaa_deft.model.errors import InputError, Problem
from astaa_deft.io.log import layout
from astaa_deft.io.log import records as rec
from astaa_deft.io.log.reader import LogContents, LoggedMessage, read_log
from astaa_deft.engine.monitor import MonitorSet, with_typed_invariants
from astaa_deft.engine.monitor.base import ReplayJudges
from astaa_deft.engine.monitor.kinds import invariant_class
from astaa_deft.engine.monitor.verdict import IMPLICIT
from astaa_deft.engine.spec.stored import spec_from_log
from astaa_deft.engine.spec.executes import untrusted_spec_refusal, what_spec_runs
from astaa_deft.model.json import DecodedMessage
from astaa_deft.model.sut import Spec
from astaa_deft.engine.spec.replay_section import ReplayModule
from astaa_deft.analysis.minimise.ddmin import Outcome, TestResult
from astaa_deft.analysis.minimise.mutations import (
    Delivered,
    FieldSelection,
    ReceivedStreams,
    read_mutations,
    sent_stream,
)
from astaa_deft.analysis.minimise.replay_baseline import Baseline
from astaa_deft.analysis.minimise.replay_judge import STOPPED, ReplayJudge
from astaa_deft.analysis.minimise.replay_records import Frame, Job, ReplayAnswer, ReplaySetup

__all__ = ["Frame", "Job", "ReplayAnswer", "ReplayModel", "ReplaySetup", "load_spec_for", "replay_entry_for",
           "replayable", "run_params"]


def load_spec_for(log: LogContents, spec_path: str | None, *, trust_log_spec: bool) -> Spec:
    """The spec a minimisation runs: the user's file, or (``spec_path`` None) the one stored in the log.

    The log's own spec names programs (module commands, replay factories)
    that a minimisation runs; it is used only with ``trust_log_spec``, else
    InputError lists what it would run and the two ways on (spec/executes.py).
    InputError too when the log holds no readable spec.
    """
    if spec_path is not None:
        from astaa_deft.engine.spec.loader import load_spec

        return load_spec(spec_path)
    spec = spec_from_log(log, f"{log.path}:{layout.SPEC_ATTACHMENT}")
    if spec is None:
        raise InputError(Problem(str(log.path), None, None, "the log holds no spec",
                                 "give the SUT spec with --spec sut.yaml"))
    if not trust_log_spec and what_spec_runs(spec):
        raise untrusted_spec_refusal(spec, str(log.path), command="minimise",
                                     why="module replays and whole-system re-runs")
    return spec


def run_params(log: LogContents) -> dict[str, str]:
    """The params the run was recorded with: the replayed planner must be built the same way."""
    return RunMetadata.of(log).params


def replayable(spec: Spec, invariant_name: str, failure_module: str | None = None) -> str | None:
    """None if a module replay can judge this failure, else why not (the live tester is used then)."""
    entry, why = replay_entry_for(spec, invariant_name, failure_module)
    return None if entry is not None else why


def replay_entry_for(spec: Spec, invariant_name: str, failure_module: str | None = None
                     ) -> tuple[ReplayModule | None, str]:
    """The first replayable module (the planner first) that can judge the failure, or (None, why none can)."""
    entries = replay_modules(spec)
    if not entries:
        return None, "the spec has no 'planner' section"
    reasons = []
    for entry in entries:
        why = _why_not(spec, entry, invariant_name, failure_module)
        if why is None:
            return entry, ""
        reasons.append(why)
    return None, "; ".join(dict.fromkeys(reasons))


def _why_not(spec: Spec, cfg: ReplayModule, invariant_name: str, failure_module: str | None) -> str | None:
    """None if ``cfg``'s replay can judge the failure, else why not."""
    is_planner = cfg.where == "planner"
    if not cfg.factory:
        return ("the planner has no in-process replay ('planner.replay.factory')" if is_planner
                else f"module '{cfg.module}' has no in-process replay ('{cfg.where}.factory')")
    crash_shown = cfg.per_trigger and cfg.exceptions == "crash"
    if invariant_name == IMPLICIT:
        if crash_shown and failure_module == cfg.module:
            return None
        return "a module crashed" if is_planner or failure_module != cfg.module else (
            f"module '{cfg.module}' crashed, but its replay does not show crashes ('exceptions: crash')")
    spec = with_typed_invariants(spec)
    invariant = next((i for i in spec.invariants if i.name == invariant_name), None)
    if invariant is None:
        return f"'{invariant_name}' is not an invariant of the spec"
    judges = invariant_class(invariant.kind).replay_judges
    if judges is ReplayJudges.PROCESS and crash_shown and not is_planner:
        # The module's exception is its process's abnormal exit: judged by this very invariant.
        return None if failure_module == cfg.module else f"'{invariant_name}' broke for another module"
    timing_replayed = cfg.per_trigger and judges is ReplayJudges.TIMING
    if judges is not ReplayJudges.VALUES and not timing_replayed:
        return f"'{invariant_name}' is a {invariant.kind} invariant: timing and processes are not replayed"
    channels = MonitorSet(replace(spec, invariants=(invariant,)), 0).channels()
    if channels != {cfg.output}:
        whose = "the planner's output" if is_planner else f"module '{cfg.module}''s output"
        return (f"'{invariant_name}' reads {', '.join(sorted(channels)) or 'no channel'}, "
                f"not only {whose} '{cfg.output}'")
    return None


class ReplayModel:
    """A run's planner replay with any subset of its mutations, in this process.

    ``baseline=False`` skips the baseline replay: enough for :meth:`frames`
    and :meth:`replay` (what the orchestrating process needs), not for :meth:`run`.
    """

    def __init__(self, setup: ReplaySetup, baseline: bool = True, *, spec: Spec | None = None) -> None:
        log = read_log(setup.log_path)
        # ``spec``: setup.spec_path's, as this process loaded it already (a worker loads its own)
        spec = with_typed_invariants(spec if spec is not None else
                                     load_spec_for(log, setup.spec_path, trust_log_spec=setup.trust_log_spec))
        if setup.module is not None:
            entry: ReplayModule | None = replay_module_of(spec, setup.module, setup.output)
            why_not = _why_not(spec, entry, setup.invariant, setup.failure_module) if entry else None
        else:
            entry, why_not = replay_entry_for(spec, setup.invariant, setup.failure_module)
        if why_not or entry is None:
            raise InputError(Problem(setup.log_path, None, None, f"no planner replay: {why_not}", "use --live-only"))
        self.spec = spec
        self.cfg = entry
        self.failure_module = setup.failure_module
        self.params = {**spec.params, **run_params(log)}
        invariant = next((i for i in spec.invariants if i.name == setup.invariant), None)
        # A crash no invariant names (IMPLICIT) is judged by the module's exception alone.
        self.crash_fails = invariant is None
        self.judged = replace(spec, invariants=(invariant,) if invariant is not None else ())
        self.mlog = read_mutations(log, spec)
        self.streams = ReceivedStreams(self.mlog, self.cfg.module, self.cfg.inputs)
        missing = [name for name in self.cfg.inputs if not self.streams.has(name)]
        if missing:
            whose = "the planner's" if self.cfg.where == "planner" else f"module '{self.cfg.module}''s"
            raise InputError(Problem(str(log.path), None, None,
                                     f"the log has no messages on {whose} input(s) {', '.join(missing)}",
                                     "record the run with this spec"))
        self.outputs: list[LoggedMessage] = sent_stream(self.mlog, log, self.cfg.output)
        self.start_ns = self.mlog.start_ns
        stopping = [e.time_ns for e in log.records(rec.RunStopping) if e.time_ns]
        self.end_ns = int(stopping[0]) if stopping else max((m.log_time for m in self.outputs), default=self.start_ns)
        # Replay only up to the output that failed in the run. The frames after it carry the
        # failure's own consequences (in closed loop the ego is already speeding), which would
        # make the failure look independent of every mutation.
        failed_at = (_first_failure_ns(log, self.judged) if invariant is not None
                     else _first_crash_ns(log, self.cfg.module))
        # Per-trigger frames: every trigger message up to the failure (a crash or hang has no output).
        self.until_ns: int | None = failed_at if self.cfg.per_trigger else None
        if failed_at is not None and self.cfg.per_trigger:
            self.end_ns = min(self.end_ns, failed_at + 1)
        elif failed_at is not None:
            # On the clock the monitor judged by: a message's publish time (the source timestamp the
            # recorder kept, e.g. a ROS 2 message's, which precedes its log time), else its log time.
            self.outputs = [m for m in self.outputs if m.publish_time <= failed_at]
            self.end_ns = min(self.end_ns, self.outputs[-1].log_time if self.outputs else failed_at)
        self.lookback_ns = int(self.cfg.lookback_ms * 1e6)
        self.output_clock = setup.output_clock
        self._skew_ns = int(self.cfg.skew_ms * 1e6)
        self._codecs = {name: get_codec(spec.channel(name).encoding) for name in self.cfg.inputs}
        self._decoded: dict[Hashable, DecodedMessage | None] = {}  # by Delivered.key
        self.baseline: Baseline | None = Baseline(self) if baseline else None

    @property
    def baseline_seconds(self) -> float:
        """What the baseline replay took (0: none made)."""
        return self.baseline.seconds if self.baseline is not None else 0.0

    # -- frames ------------------------------------------------------------
    def decode(self, channel: str, delivered: Delivered) -> DecodedMessage | None:
        """``delivered`` as ``channel``'s codec decodes it (None: it does not decode), decoded once."""
        if delivered.key not in self._decoded:
            try:
                self._decoded[delivered.key] = self._codecs[channel].decode(delivered.data)
            except DecodeError:
                self._decoded[delivered.key] = None
        return self._decoded[delivered.key]

    def frames(self, kept: Mapping[int, FieldSelection]) -> list[Frame | None]:
        """The most likely frame of every recorded output (None where an input had no message yet).

        Per-trigger modules: one frame per trigger message the module received up to the failure.
        """
        built = self.streams.build(kept)
        usable = {name: [d for d in stream if self.decode(name, d) is not None] for name, stream in built.items()}
        streams = {name: Stream(name, [d.time_ns for d in msgs]) for name, msgs in usable.items()}
        trigger = self.cfg.trigger
        if self.cfg.per_trigger:
            out_t: list[Frame | None] = []
            previous_t: dict[str, int] = {}
            for t_index, t_t in enumerate(streams[trigger].times):
                if self.until_ns is not None and t_t > self.until_ns:
                    break
                picked = trigger_frame(streams, trigger, t_index, previous_t)
                previous_t = picked
                out_t.append(Frame(len(out_t), tuple((name, usable[name][i]) for name, i in sorted(picked.items())),
                                   t_t, t_t))
            return out_t
        trigger_times = streams[trigger].times
        previous: dict[str, int] = {}
        out: list[Frame | None] = []
        for index, output in enumerate(self.outputs):
            output_ns = self.paired_at(output)
            t_index = newest_at_or_before(trigger_times, output_ns)
            if t_index < 0:
                out.append(None)
                continue
            t_t = trigger_times[t_index]
            choice = frame_at(streams, trigger, t_index, t_t, previous)
            frame_time = t_t
            if choice is None:  # the trigger time does not work: the candidate search decides
                options = candidates(OutputContext(streams=streams, trigger=trigger, output_ns=output_ns,
                                                   previous=previous, lookback_ns=self.lookback_ns))
                if not options:
                    out.append(None)
                    continue
                choice, frame_time = dict(options[0].choice), options[0].frame_time
            previous = choice
            out.append(Frame(index, tuple((name, usable[name][i]) for name, i in sorted(choice.items())),
                             frame_time, t_t))
        return out

    def paired_at(self, output: LoggedMessage) -> int:
        """The time an output is paired with its trigger at: its log time, or (``output_clock`` "published")
        its publisher's stamp, never past its log time. A trigger logged by then was published before it; the
        skew is not added: a module stalled by load publishes its answers just before the next trigger is
        logged (one ROS 2 planner 0.6 ms before)."""
        if self.output_clock == "published":
            return min(output.log_time, output.publish_time)
        return output.log_time

    def late_outputs(self) -> int:
        """Outputs logged more than the skew after their publisher stamped them (a loaded recorder's bursts)."""
        return sum(1 for m in self.outputs if m.log_time - m.publish_time > self._skew_ns)

    def frame_message(self, frame: Frame) -> dict[str, DecodedMessage]:
        """The module's input for ``frame``: channel → decoded message (a frame holds decodable inputs only)."""
        return {name: message for name, d in frame.inputs if (message := self.decode(name, d)) is not None}

    # -- replay ------------------------------------------------------------
    def fresh_planner(self) -> ReplayPlanner:
        """A new replay of the module, in its initial state (the caller closes it)."""
        return make_planner(self.spec, self.params, entry=self.cfg)

    def step(self, planner: ReplayPlanner, frame: Frame) -> DecodedMessage | None:
        """The module's answer to ``frame`` (StepHang past ``hang_after``; the module's own exceptions)."""
        return within_limit(functools.partial(planner.step, self.frame_message(frame)), self.cfg.hang_after)

    def output_time(self, frame: Frame) -> int:
        """When ``frame``'s output is judged: the recorded output's time (per trigger: the trigger's)."""
        return frame.trigger_time_ns if self.cfg.per_trigger else self.outputs[frame.output].log_time

    def output_sequence(self, frame: Frame) -> int:
        return frame.output + 1 if self.cfg.per_trigger else self.outputs[frame.output].sequence

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
        judge = ReplayJudge(self)
        if job.frames is not None:
            chosen = [frame for i in job.frames if i < len(frames) and (frame := frames[i]) is not None]
            if self.cfg.per_trigger:
                return judge.judge_last(self.fresh_planner(), chosen)
            return judge.judge(self.fresh_planner(), chosen)
        base = self.baseline
        assert base is not None, "a model built with baseline=False runs scaffolding tests only"
        planner = None  # None: in step with the baseline, whose outputs are known
        try:
            for k, frame in enumerate(frames):
                # (more trigger messages than the baseline's: a duplicate kept)
                unchanged = k < len(base.keys) and (frame.key if frame is not None else None) == base.keys[k]
                if (self.cfg.per_trigger and base.error_frame is not None and k >= base.error_frame):
                    unchanged = False  # the baseline's module crashed or hung here: the step itself is judged
                if planner is not None and unchanged and base.converged(planner, k):
                    planner.close()
                    planner = None
                if planner is None and unchanged:
                    if frame is None:
                        continue
                    if base.error_frame is not None and k >= base.error_frame:
                        return ReplayAnswer(TestResult(Outcome.UNRESOLVED,
                                                       f"the planner raised on {base.error}"))
                    found = judge.feed(frame, base.outputs[k])
                    if found:
                        return ReplayAnswer(TestResult(Outcome.FAIL, found), frame.output)
                    continue
                if planner is None:
                    planner = base.restore(k)
                if frame is None:
                    continue
                answer = judge.judged_step(planner, frame)
                if answer is STOPPED:
                    return judge.silence(frames[k + 1:], frame.output)
                if answer is not None:
                    return answer
        finally:
            if planner is not None:
                planner.close()
        return judge.finish()

    def replay(self, frames: Sequence[Frame]) -> list[tuple[Frame, DecodedMessage | None, str | None]]:
        """(frame, replayed output, error) for ``frames`` in order from a fresh planner (for the outputs)."""
        planner = self.fresh_planner()
        out: list[tuple[Frame, DecodedMessage | None, str | None]] = []
        try:
            for frame in frames:
                try:
                    out.append((frame, self.step(planner, frame), None))
                except Exception as exc:  # StepHang included
                    out.append((frame, None, f"{type(exc).__name__}: {exc}"))
                    break
        finally:
            planner.close()
        return out

def _first_crash_ns(log: LogContents, module: str) -> int | None:
    """When ``module`` first exited abnormally in the run (None if it never did)."""
    exits = [e for e in map(rec.decode, log.events("process_exit")) if isinstance(e, rec.ProcessExit)]
    times = [e.time_ns for e in exits if e.module == module and not e.during_shutdown and (e.returncode or e.signal)]
    return min(times) if times else None


def _first_failure_ns(log: LogContents, judged: Spec) -> int | None:
    """When the run's recorded outputs first broke the judged invariant (None if they never did)."""
    from astaa_deft.engine.monitor import check_log

    found = check_log(log, judged).violations
    return min(v.time_ns for v in found) if found else None
