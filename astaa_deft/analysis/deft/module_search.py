"""A module replayed on its frames from a clean run, under one generated fault at a time, judged like a live run.

:class:`ModuleBench` reads a clean recorded run once: the module's input
streams as it received them, its recorded output times, and a baseline
replay of every frame (its outputs, and the module's state pickled along the
way). :meth:`ModuleBench.run` applies one :class:`~.stream_faults.StreamFault`
to the streams (as the wire would deliver it), rebuilds the frames with
DeFT's rules, restores the module's state just before the first frame the
fault changes, and replays from there: the outputs go, at the recorded
times, to a :class:`~astaa_deft.engine.monitor.MonitorSet` holding the spec's
invariants that read only this module's output. A finding is

* an invariant broken by the replayed outputs (the same violation text as live);
* the module's exception (its process would die: ``exceptions: crash``; or,
  for a module whose replay does not say so, an exception its step raised);
* a step running past ``hang_after`` (a hang);
* frames it no longer answers where the baseline did (a swallowed error).

Replay stops once the module is back in the baseline's state on unchanged
frames (the fault's effect died out): the rest is the baseline's, fed to the
monitors without stepping. :meth:`ModuleBench.field_reads` perturbs each
input field in every message and says which ones change any output.

Runs in the process that builds it (single-threaded, so ``hang_after`` can
interrupt a step); the campaign runs benches in worker processes of its own.
"""

from __future__ import annotations

import json
import time
import traceback
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, replace

from astaa_deft.analysis.deft.baseline_walk import BaselineWalk
from astaa_deft.analysis.deft.replay import ReplayPlanner, StepHang, make_planner, within_limit
from astaa_deft.analysis.deft.stream_faults import (
    PERTURBATIONS, FaultKind, FaultNotApplicable, FieldReads, Frame, Received, StreamFault, apply_fault,
    first_changed, frame_key, frame_origins, leaf_paths, output_frames, perturb_field, recorded_streams,
    smaller_faults, trigger_frames,
)
from astaa_deft.engine.monitor import MonitorSet, format_violation, with_typed_invariants
from astaa_deft.engine.monitor.error_signature import signature_of_output
from astaa_deft.engine.monitor.base import ReplayJudges
from astaa_deft.engine.monitor.kinds import invariant_class
from astaa_deft.io.codecs import get_codec
from astaa_deft.io.codecs.base import DecodeError
from astaa_deft.io.log import records as rec
from astaa_deft.io.log.reader import LogContents
from astaa_deft.io.statefile import MAX_NAME, StateReader
from astaa_deft.model.json import DecodedMessage, JsonObject
from astaa_deft.model.replay_module import ReplayModule, StepExceptions
from astaa_deft.model.sut import Spec
from astaa_deft.model.vocabulary import TextEnum

SNAPSHOT_EVERY = 1  # frames between pickled baseline states (a restore then replays at most this many - 1)
MAX_SNAPSHOTS = 2000
SILENT_AFTER = 5  # answers the baseline gave after the fault where the replay gave none: the module went silent
PROBE_FRAMES = 1500  # frames a field-read probe replays (from the run's first: start-up reads count)


class FindingKind(TextEnum):
    INVARIANT = "invariant"  # the replayed outputs broke an invariant on the module's output
    CRASH = "crash"  # the module raised where its process would die
    EXCEPTION = "exception"  # the module's step raised (its node may catch it: confirmed live or module-level only)
    HANG = "hang"  # a step ran past hang_after
    SILENT = "silent"  # it stopped answering frames the baseline answered


@dataclass(frozen=True, kw_only=True)
class ModuleVerdict:
    """One fault's replay: what failed (``kind`` None: nothing), where, and what it cost."""

    module: str
    fault: StreamFault
    kind: FindingKind | None = None
    invariant: str | None = None  # the broken invariant (INVARIANT; CRASH when a process invariant judged it)
    error: str | None = None  # the error signature (``KeyError in control.py:step``), as live findings carry
    detail: str = ""
    frame: int | None = None  # the failing frame's index
    steps: int = 0  # module steps replayed
    seconds: float = 0.0
    applicable: bool = True

    @property
    def failed(self) -> bool:
        return self.kind is not None

    @property
    def signature(self) -> str:
        """The failure signature of the bucket key: the invariant, the error, or the kind."""
        if self.kind == FindingKind.INVARIANT:
            return f"invariant {self.invariant}"
        if self.error:
            return f"{self.kind} {self.error}"
        return str(self.kind)

    @property
    def bucket_key(self) -> tuple[str, str, str]:
        """One bucket per (module, failure signature, field family)."""
        return (self.module, self.signature, self.fault.family)

    def to_json(self) -> JsonObject:
        return {"module": self.module, "fault": self.fault.to_json(),
                "kind": None if self.kind is None else self.kind.value, "invariant": self.invariant,
                "error": self.error, "detail": self.detail[:600], "frame": self.frame, "steps": self.steps,
                "seconds": round(self.seconds, 6), "applicable": self.applicable}

    @classmethod
    def from_json(cls, r: StateReader) -> ModuleVerdict:
        """The verdict as ``to_json`` wrote it (InputError naming the file and the field when one is damaged)."""
        module, fault, kind, invariant, error, detail, frame, steps, seconds, applicable = r.fields(
            "module", "fault", "kind", "invariant", "error", "detail", "frame", "steps", "seconds", "applicable")
        found = kind.text(choices=tuple(k.value for k in FindingKind), optional=True)
        return cls(module=module.string(MAX_NAME), fault=StreamFault.from_json(fault),
                   kind=None if found is None else FindingKind(found),
                   invariant=invariant.text(MAX_NAME, optional=True), error=error.text(optional=True),
                   detail=detail.string(), frame=frame.integer(optional=True), steps=steps.whole(),
                   seconds=seconds.real(0), applicable=bool(applicable.flag()))


def judged_invariants(spec: Spec, entry: ReplayModule) -> Spec:
    """``spec`` with only the invariants a replay of ``entry`` can judge: those reading only its output
    (a deadline only for a module replayed per trigger, whose timing the replay keeps); a process invariant
    where the module's exceptions are its crash."""
    typed = with_typed_invariants(spec)
    kept = []
    for invariant in typed.invariants:
        judges = invariant_class(invariant.kind).replay_judges  # the kind's trait, never its name
        if judges is ReplayJudges.PROCESS:
            if entry.exceptions == StepExceptions.CRASH and getattr(invariant, "module", None) in (None, entry.module):
                kept.append(invariant)
            continue
        if judges is ReplayJudges.TIMING and not entry.per_trigger:
            continue
        if invariant_class(invariant.kind).crash_kind:  # a module's log or its exceptions: no replay output shows
            continue
        channels = MonitorSet(replace(typed, invariants=(invariant,)), 0).channels()
        if channels == {entry.output}:
            kept.append(invariant)
    return replace(typed, invariants=tuple(kept))


class ModuleBench:
    """One module of one clean run, ready to replay any fault (module doc)."""

    def __init__(self, spec: Spec, entry: ReplayModule, log: LogContents, params: Mapping[str, str], *,
                 settle_s: float | None = None) -> None:
        """``settle_s``: a fault is judged until this long after the last frame it changed (as a live case ends
        ``--settle`` s after its last mutation could act); None: to the run's end."""
        self.spec, self.entry = spec, entry
        self.settle_ns = None if settle_s is None else int(settle_s * 1e9)
        self.params = {**spec.params, **params}
        recorded: dict[str, list[tuple[int, DecodedMessage]]] = {}
        for name in entry.inputs:
            codec = get_codec(spec.channel(name).encoding)
            decoded = []
            for message in sorted(log.on(spec.channel(name).key), key=lambda m: m.log_time):
                try:
                    decoded.append((message.log_time, codec.decode(message.data)))
                except DecodeError:
                    continue  # a deserialiser drops it
            recorded[name] = decoded
        self.streams = recorded_streams(recorded)
        self.output_times = [m.log_time for m in sorted(log.on(spec.channel(entry.output).key),
                                                        key=lambda m: m.log_time)]
        self.start_ns = _run_start(log)
        stopping = [e.time_ns for e in log.records(rec.RunStopping) if e.time_ns]
        last = max([t for s in self.streams.values() for t in (r.time_ns for r in s)] + self.output_times,
                   default=self.start_ns)
        self.end_ns = int(stopping[0]) if stopping else last
        self.judged = judged_invariants(spec, entry)
        self.lookback_ns = int(entry.lookback_ms * 1e6)
        started = time.perf_counter()
        self.frames = self.frames_of(self.streams)
        self.keys = [frame_key(f) for f in self.frames]
        stride = max(SNAPSHOT_EVERY, len(self.frames) // MAX_SNAPSHOTS + 1)
        planner = self.fresh()
        try:  # past a frame the unmutated replay fails on, no fault can be judged: the frames end there
            self.walk = BaselineWalk(self.frames, planner, self.step, stride=stride, pad=False)
        finally:
            planner.close()
        self.outputs: list[DecodedMessage | None] = self.walk.outputs
        self.error: str | None = None  # the baseline replay itself raised or hung here (no fault can be judged past)
        if self.walk.error_frame is not None:
            self.error = f"frame {self.walk.error_frame}: {self.walk.error}"
            self.frames = self.frames[:self.walk.error_frame]
            self.keys = self.keys[:self.walk.error_frame]
        self.baseline_seconds = time.perf_counter() - started
        self.known: set[str] = set()
        self.known = self._baseline_violations()  # invariants the unmutated replay breaks: not a fault's finding

    # -- replay ---------------------------------------------------------------------------------------------
    def fresh(self) -> ReplayPlanner:
        return make_planner(self.spec, self.params, entry=self.entry)

    def frames_of(self, streams: Mapping[str, Sequence[Received]]) -> list[Frame | None]:
        if self.entry.per_trigger:
            return list(trigger_frames(streams, self.entry.trigger))
        return output_frames(streams, self.entry.trigger, self.output_times, self.lookback_ns)

    def step(self, planner: ReplayPlanner, frame: Frame) -> DecodedMessage | None:
        inputs = {name: received.message for name, received in frame.items()}
        return within_limit(lambda: planner.step(inputs), self.entry.hang_after)

    def output_time(self, k: int, frame: Frame | None) -> int:
        if self.entry.per_trigger:
            assert frame is not None
            return frame[self.entry.trigger].time_ns
        return self.output_times[k]

    def restore(self, k: int) -> ReplayPlanner:
        """A module in the baseline's state just before frame ``k``."""
        s, state = self.walk.state(k)
        planner = self.fresh()
        planner.restore(state)
        for i in range(s, k):
            frame = self.frames[i]
            if frame is not None:
                self.step(planner, frame)
        return planner

    def _converged(self, planner: ReplayPlanner, k: int) -> bool:
        return self.walk.converged(planner, k)

    def _baseline_violations(self) -> set[str]:
        monitors = MonitorSet(self.judged, self.start_ns)
        found = []
        for k, frame in enumerate(self.frames):
            if frame is None and self.entry.per_trigger:
                continue
            found += self._feed(monitors, k, frame, output=self.outputs[k])
        found += monitors.finish(self.end_ns)
        return {v.invariant for v in found}

    def _feed(self, monitors: MonitorSet, k: int, frame: Frame | None, *, output: DecodedMessage | None) -> list:
        time_ns = self.output_time(k, frame)
        found = list(monitors.on_tick(time_ns))
        if output is not None or not self.entry.per_trigger:
            found += monitors.on_message(self.entry.output, time_ns, output, k + 1)
        return [v for v in found if v.invariant not in self.known]

    # -- one fault ------------------------------------------------------------------------------------------
    def run(self, fault: StreamFault) -> ModuleVerdict:
        """Replay the module under ``fault`` and judge it (module doc)."""
        started = time.perf_counter()
        verdict = ModuleVerdict(module=self.entry.module, fault=fault)
        try:
            streams = apply_fault(self.streams, fault)
        except FaultNotApplicable as exc:
            return replace(verdict, applicable=False, detail=str(exc))
        frames = self.frames_of(streams)
        if self.error is not None:  # judged only up to where the baseline replay itself stopped
            frames = frames[:len(self.frames)]
        k0 = first_changed(self.frames, frames)
        if k0 is None:
            return replace(verdict, detail="the fault changes no frame", seconds=time.perf_counter() - started)
        found = self._replay(self._settled(frames), k0)
        return replace(found, module=self.entry.module, fault=fault, seconds=time.perf_counter() - started)

    def _settled(self, frames: list[Frame | None]) -> list[Frame | None]:
        """The frames judged: up to ``settle_s`` after the last one the fault changed (all of them without)."""
        if self.settle_ns is None:
            return frames
        changed = [k for k, frame in enumerate(frames) if k >= len(self.keys) or frame_key(frame) != self.keys[k]]
        if not changed or changed[-1] >= len(self.frames):
            return frames  # the frames shifted to the end (a trigger dropped or doubled): judged to the end
        until = self.output_time(changed[-1], frames[changed[-1]]) + self.settle_ns
        kept = [k for k in range(len(frames)) if k <= changed[-1] or self._time_of(k, frames[k]) <= until]
        return frames[:kept[-1] + 1]

    def _time_of(self, k: int, frame: Frame | None) -> int:
        if frame is None and self.entry.per_trigger:
            return 0
        return self.output_time(k, frame)

    def _replay(self, frames: Sequence[Frame | None], k0: int) -> ModuleVerdict:
        monitors = MonitorSet(self.judged, self.start_ns)
        nothing = ModuleVerdict(module=self.entry.module, fault=_NO_FAULT)
        for k in range(min(k0, len(self.frames))):  # the monitors' state before the fault: the baseline's
            self._feed(monitors, k, self.frames[k], output=self.outputs[k])
        planner: ReplayPlanner | None = self.restore(min(k0, len(self.frames) - 1)) if self.frames else self.fresh()
        steps = 0
        answered_base = answered = 0
        try:
            for k in range(k0, len(frames)):
                frame = frames[k]
                unchanged = k < len(self.keys) and frame_key(frame) == self.keys[k]
                if planner is not None and unchanged and self._converged(planner, k):
                    planner.close()
                    planner = None
                if planner is None:
                    output = self.outputs[k] if unchanged else None
                    if not unchanged:  # changed again after converging: back to replaying
                        planner = self.restore(k)
                    else:
                        found = self._feed(monitors, k, frame, output=output)
                        if found:
                            return self._violated(found, k, steps)
                        continue
                if frame is None:
                    if not self.entry.per_trigger:
                        self._feed(monitors, k, frame, output=None)
                    continue
                steps += 1
                try:
                    output = self.step(planner, frame)
                except StepHang as exc:
                    return replace(nothing, kind=FindingKind.HANG, frame=k, steps=steps,
                                   detail=f"module '{self.entry.module}' hangs on frame {k}: {exc}")
                except Exception as exc:
                    return self._raised(monitors, exc, k=k, frame=frame, steps=steps)
                base = self.outputs[k] if k < len(self.outputs) else None
                answered_base += base is not None
                answered += output is not None
                if output is None and not self.entry.per_trigger:
                    return replace(nothing, kind=FindingKind.SILENT, frame=k, steps=steps,
                                   detail=f"module '{self.entry.module}' gave no output on frame {k}, where the run "
                                          f"recorded one")
                found = self._feed(monitors, k, frame, output=output)
                if found:
                    return self._violated(found, k, steps)
        finally:
            if planner is not None:
                planner.close()
        cut = len(frames) < len(self.frames) and frames  # judged up to its settle time: the run ends there
        end_ns = self._time_of(len(frames) - 1, frames[-1]) if cut else self.end_ns
        found = [v for v in monitors.finish(end_ns) if v.invariant not in self.known]
        if found:
            return self._violated(found, None, steps)
        if self.entry.per_trigger and answered == 0 and answered_base >= SILENT_AFTER:
            return replace(nothing, kind=FindingKind.SILENT, frame=k0, steps=steps,
                           detail=f"module '{self.entry.module}' answered none of the {answered_base} frames after "
                                  f"frame {k0} that the baseline answered (a swallowed error?)")
        return replace(nothing, steps=steps, detail="passed")

    def _violated(self, found: list, k: int | None, steps: int) -> ModuleVerdict:
        first = found[0]
        return ModuleVerdict(module=self.entry.module, fault=_NO_FAULT, kind=FindingKind.INVARIANT,
                             invariant=first.invariant, frame=k, steps=steps,
                             detail=format_violation(first, self.start_ns))

    def _raised(self, monitors: MonitorSet, exc: Exception, *, k: int, frame: Frame, steps: int) -> ModuleVerdict:
        lines = "".join(traceback.format_exception(exc)).splitlines()
        signature = signature_of_output(lines)
        error = signature.text() if signature is not None else type(exc).__name__
        what = f"module '{self.entry.module}' raised {type(exc).__name__}: {str(exc)[:200]} on frame {k}"
        if self.entry.exceptions == StepExceptions.CRASH:
            found = monitors.on_process_exit(self.entry.module, 1, None, self.output_time(k, frame),
                                             during_shutdown=False, stderr_tail="\n".join(lines[-40:]))
            invariant = found[0].invariant if found else None
            return ModuleVerdict(module=self.entry.module, fault=_NO_FAULT, kind=FindingKind.CRASH,
                                 invariant=invariant, error=error, frame=k, steps=steps, detail=what)
        return ModuleVerdict(module=self.entry.module, fault=_NO_FAULT, kind=FindingKind.EXCEPTION, error=error,
                             frame=k, steps=steps, detail=what)

    def minimised(self, verdict: ModuleVerdict) -> ModuleVerdict:
        """The smallest form of a failing verdict's fault that fails the same way (same bucket): a held value
        on one message, or on fewer (:func:`~.stream_faults.smaller_faults`); the verdict itself else."""
        for smaller in smaller_faults(verdict.fault):
            again = self.run(smaller)
            if again.failed and again.bucket_key == verdict.bucket_key:
                return again
        return verdict

    # -- which fields it reads ------------------------------------------------------------------------------
    def field_reads(self, *, first_frame: int = 0, budget_s: float | None = None) -> FieldReads:
        """Perturb each leaf field of each input in every message; a field is read when any output of the
        ``PROBE_FRAMES`` frames from ``first_frame`` on changes (or the module raises, or stops answering)."""
        started = time.perf_counter()
        end = min(len(self.frames), first_frame + PROBE_FRAMES)
        probed: list[tuple[str, str]] = []
        for name in self.entry.inputs:
            seen: dict[str, None] = {}
            for received in self.streams.get(name, ()):
                for path in leaf_paths(received.message):
                    seen.setdefault(path, None)
            probed.extend((name, path) for path in seen)
        read: list[tuple[str, str]] = []
        unread: list[tuple[str, str]] = []
        notes: list[str] = []
        baseline = [_canonical(o) for o in self.outputs[first_frame:end]]
        for channel, path in probed:
            if budget_s is not None and time.perf_counter() - started > budget_s:
                notes.append(f"stopped after {len(read) + len(unread)} of {len(probed)} fields: the time box")
                break
            probes = [s for way in range(PERTURBATIONS) if (s := perturb_field(self.streams, channel, path, way))]
            if not probes:
                continue
            if any(_changes_output(self, streams, first=first_frame, end=end, baseline=baseline) for streams in probes):
                read.append((channel, path))
            else:
                unread.append((channel, path))
        return FieldReads(module=self.entry.module, read=tuple(read), unread=tuple(unread),
                          probed_frames=end - first_frame, seconds=time.perf_counter() - started,
                          notes=tuple(notes))


_NO_FAULT = StreamFault(channel="", kind=FaultKind.DROP, index=0)  # a placeholder: run() puts the fault in


def _changes_output(bench: ModuleBench, streams: Mapping[str, Sequence[Received]], *, first: int, end: int,
                    baseline: Sequence[str]) -> bool:
    frames = bench.frames_of(streams)
    if [frame_origins(f) for f in frames[first:end]] != [frame_origins(f) for f in bench.frames[first:end]]:
        return True  # the frames themselves moved (a field the frame rule reads, e.g. a stamp)
    planner = bench.restore(first) if bench.frames else bench.fresh()
    try:
        for k in range(first, end):
            frame = frames[k]
            if frame is None:
                continue
            try:
                output = bench.step(planner, frame)
            except Exception:
                return True
            if _canonical(output) != baseline[k - first]:
                return True
    finally:
        planner.close()
    return False


def _canonical(message: object) -> str:
    return json.dumps(message, sort_keys=True, default=repr)


def _run_start(log: LogContents) -> int:
    started = [r.time_ns for r in map(rec.decode, log.events("run_started")) if isinstance(r, rec.RunStarted)
               and r.time_ns]
    if started:
        return started[0]
    bus = [m.log_time for m in log.messages if not m.topic.startswith("/astaa/")]
    return min(bus) if bus else 0

