"""What a minimisation leaves in its output directory, and the summary it prints.

    DIR/minimal.xml    the minimal test case: pinned policies that replay live through the proxy
    DIR/minimal.mcap   replay: the kept frames' inputs with the minimal mutations applied, the
                       planner's replayed outputs and the mutation events (`astaa-deft check` shows
                       the failure); live: the log of a confirming run
    DIR/tests/         replay only: DeFT module tests over the kept frames (`pytest DIR/tests`) with
                       an invariant oracle that fails while the planner still breaks the invariant
    DIR/summary.json   tests run, cache hits, seconds, before → after per stage, the culprit, rates

The module tests are frame tests with an infinite threshold — they only ask
that the planner steps through the scaffolding frames without raising — and
one oracle test that carries the verdict, so a fixed planner passes the
whole suite even though its outputs change.
"""

from __future__ import annotations

import json
import math
import shutil
from collections.abc import Hashable, Mapping
from dataclasses import asdict, dataclass, replace
from pathlib import Path

from astaa_deft.io.codecs import get_codec
from astaa_deft.analysis.deft.export import export_suite
from astaa_deft.analysis.deft.extract import ExtractedFrame
from astaa_deft.analysis.deft.invariant_oracle import oracle_entry
from astaa_deft.analysis.deft.validator import Comparison
from astaa_deft.model.errors import InputError, Problem
from astaa_deft.engine.intercept.testcase import TestCase, load_testcase
from astaa_deft.io.log import layout
from astaa_deft.io.log import records as log_records
from astaa_deft.io.log.reader import LoggedMessage
from astaa_deft.io.log.writer import LogWriter
from astaa_deft.io.output_place import write_atomic
from astaa_deft.analysis.minimise.mutations import FieldSelection, Mutation
from astaa_deft.analysis.minimise.replay_model import Frame, ReplayModel
from astaa_deft.model.sut import Spec
from astaa_deft.analysis.minimise.stages import Minimisation, TesterKind
from astaa_deft.model.json import JsonObject

MINIMAL_XML = "minimal.xml"
MINIMAL_MCAP = "minimal.mcap"
TESTS_DIR = "tests"
SUMMARY_JSON = "summary.json"


def prepare_directory(out_dir: Path) -> None:
    """A new or empty directory, or one holding an earlier minimisation (replaced)."""
    if out_dir.exists() and not out_dir.is_dir():
        raise InputError(Problem(str(out_dir), None, None, "exists and is not a directory",
                                 "give a new or empty directory with -o"))
    if out_dir.is_dir() and any(out_dir.iterdir()) and not (out_dir / SUMMARY_JSON).exists():
        raise InputError(Problem(str(out_dir), None, None, "is not empty (and holds no earlier minimisation)",
                                 "give a new or empty directory with -o"))
    out_dir.mkdir(parents=True, exist_ok=True)
    for name in (MINIMAL_XML, MINIMAL_MCAP, SUMMARY_JSON):
        (out_dir / name).unlink(missing_ok=True)
    shutil.rmtree(out_dir / TESTS_DIR, ignore_errors=True)


def write_testcase_file(out_dir: Path, testcase: TestCase, spec: Spec) -> Path:
    """DIR/minimal.xml, read back with the spec: what we write must pass ``policy check``."""
    path = out_dir / MINIMAL_XML
    write_atomic(path, testcase.to_xml())
    load_testcase(path, spec)  # an InputError here is a bug in restrict.py, reported as such
    return path


def write_replay_log(path: Path, model: ReplayModel, result: Minimisation, policy_file: Path) -> Path:
    """DIR/minimal.mcap for the replay path (module doc)."""
    spec, cfg = model.spec, model.cfg
    frames = _kept_frames(model, result)
    replayed = model.replay(frames)
    writer = LogWriter(path, spec)
    try:
        writer.attachment(layout.SPEC_ATTACHMENT, spec.source_text.encode(), "application/yaml")
        writer.attachment(layout.POLICY_ATTACHMENT, policy_file.read_bytes(), "application/xml")
        writer.metadata(layout.RUN_METADATA, {"spec": spec.name, "mode": "replay",
                                              "params": json.dumps(model.params, sort_keys=True),
                                              "command_line": "astaa-deft minimise"})
        topics: dict[str, int] = {}

        def topic(channel: str, original: bool = False) -> int:
            key = spec.channel(channel).key
            name = layout.ORIGINAL_PREFIX + key if original else key
            if name not in topics:
                topics[name] = writer.bus_channel(spec.channel(channel), topic=name)
            return topics[name]

        records: list[tuple[int, int, bytes, Hashable]] = []  # (time, MCAP channel, data, what it is)
        seen: set[Hashable] = set()
        for frame in frames:
            for name, delivered in frame.inputs:
                if delivered.key not in seen:
                    seen.add(delivered.key)
                    records.append((delivered.time_ns, topic(name), delivered.data, delivered.key))
        codec = get_codec(spec.channel(cfg.output).encoding)
        for frame, message, _ in replayed:
            if message is not None:
                records.append((model.output_time(frame), topic(cfg.output), codec.encode(message),
                                ("output", frame.output)))
        chosen = result.chosen
        for mutation, selection in chosen:
            records.append((mutation.original_time_ns, topic(mutation.channel, original=True), mutation.original,
                            ("original-of", mutation.number)))
            key = ("mutation", mutation.number, _normal(selection, mutation))
            data = mutation.payload(selection, spec.channel(mutation.channel).encoding)
            if data is not None and key not in seen and mutation.delivered_time_ns is not None:
                seen.add(key)
                records.append((mutation.delivered_time_ns, topic(mutation.channel), data, key))
        sequences: dict[Hashable, int] = {}
        writer.record(log_records.RunStarted(time_ns=model.start_ns, mode="replay", spec=spec.name))
        for time_ns, channel_id, data, what in sorted(records, key=lambda r: r[0]):
            sequences[what] = writer.message(channel_id, time_ns, data)
        events = writer.tool_channel(layout.MUTATIONS_TOPIC)
        for mutation, selection in chosen:
            fields = mutation.fields if selection is None else tuple(mutation.fields[i] for i in selection)
            body = {**mutation.event, "consumers": list(mutation.consumers),
                    "fields": [change.to_json() for change in fields],
                    "original_sequence": sequences.get(("original-of", mutation.number)),
                    "delivered_sequence": sequences.get(("mutation", mutation.number, _normal(selection, mutation)))}
            writer.message(events, mutation.original_time_ns, json.dumps(body, default=str).encode())
        end = max((r[0] for r in records), default=model.start_ns) + 1
        crashed = [(frame, error) for frame, _, error in replayed if error and not error.startswith("StepHang")]
        if crashed and cfg.per_trigger and cfg.exceptions == "crash":
            # The module's process would have died of this exception: logged as its exit, as a run logs one.
            frame, error = crashed[0]
            end = max(end, model.output_time(frame) + 1)
            writer.record(log_records.ProcessExit(module=cfg.module, pid=0, returncode=1, signal=None,
                                                  time_ns=model.output_time(frame) + 1, during_shutdown=False,
                                                  stderr_tail=error))
        writer.record(log_records.RunStopping(end))
    finally:
        writer.finish()
    return path


def write_module_tests(directory: Path, model: ReplayModel, result: Minimisation) -> Path:
    """DIR/tests: the kept frames as a DeFT suite whose oracle fails on the culprit (module doc)."""
    spec, cfg = model.spec, model.cfg
    codec = get_codec(spec.channel(cfg.output).encoding)
    out_key = spec.channel(cfg.output).key
    extracted: list[ExtractedFrame] = []
    for frame, message, error in model.replay(_kept_frames(model, result)):
        if error is not None and not cfg.per_trigger:
            break
        # A per-trigger module's crash or hang is the failure itself: its frame is kept (no output), and last.
        time_ns = model.output_time(frame)
        output = (LoggedMessage(out_key, time_ns, time_ns, 0, codec.encode(message)) if message is not None
                  else None)
        extracted.append(ExtractedFrame(index=len(extracted), output=output, trigger_time=frame.trigger_time_ns,
            frame_time=frame.frame_time_ns,
            inputs={name: LoggedMessage(spec.channel(name).key, d.time_ns, d.time_ns, 0, d.data)
                    for name, d in frame.inputs},
            comparison=Comparison(distance=0.0, max_error=0.0, points=0, how="replayed"), accepted=True,
            candidates_tried=1, exact=True))
        if error is not None:
            break
    smoke_entry = replace(cfg, threshold=math.inf)
    smoke = replace(spec, planner=replace(spec.planner, threshold=math.inf)) if spec.planner is not None else spec
    oracle = oracle_entry(result.failure.invariant, extracted[-1].index if extracted else 0, model.start_ns)
    return export_suite(extracted, smoke, model.params, directory, oracles=[oracle], entry=smoke_entry)


def _kept_frames(model: ReplayModel, result: Minimisation) -> list[Frame]:
    frames = model.frames(result.kept)
    return [frame for i in result.frames if i < len(frames) and (frame := frames[i]) is not None]


def _normal(selection: FieldSelection, mutation: Mutation) -> FieldSelection:
    if selection is None or len(selection) == len(mutation.fields):
        return None
    return tuple(sorted(selection))


def copy_log(source: Path, out_dir: Path) -> Path:
    target = out_dir / MINIMAL_MCAP
    shutil.copyfile(source, target)
    return target


# ---------------------------------------------------------------- the summary


@dataclass(frozen=True, kw_only=True)
class Confirmation:
    """The live confirmation runs of the minimal test case (``requested`` 0: none were asked for)."""

    runs: int  # the runs that could tell pass from fail
    failures: int
    rate: float | None  # failures / runs; None when no run could tell
    requested: int = 0
    seconds: float = 0.0  # all the runs' wall time
    details: tuple[str, ...] = ()  # up to three details of the runs that did not pass, sorted

    def to_json(self) -> JsonObject:
        """Its form in summary.json (without runs asked for: the counts only)."""
        if not self.requested:
            return {"requested": 0, "runs": self.runs, "failures": self.failures, "rate": self.rate}
        return {"requested": self.requested, "runs": self.runs, "failures": self.failures, "rate": self.rate,
                "seconds": round(self.seconds, 3), "details": list(self.details)}


@dataclass(frozen=True, kw_only=True)
class MinimiseSummary:
    """What a finished minimisation reports: DIR/summary.json (:meth:`to_json`) and the console (:meth:`text`)."""

    result: Minimisation
    log: Path
    why: str  # why this tester (see stages.choose_tester)
    seconds: float  # the whole minimisation's wall time
    confirmation: Confirmation
    verdict: str
    files: Mapping[str, Path]  # what was written, by what it is
    replay_tests: int = 0  # module replays actually run (speculative parallel ones included)
    replay_hits: int = 0  # replay answers found in the replay tester's cache
    live_runs: int = 0  # whole-system runs, the confirmation's included
    live_seconds: float = 0.0
    replayed_module: str | None = None  # the module the replay tester ran (None: whole-system re-runs)

    def to_json(self) -> JsonObject:
        """Everything summary.json holds."""
        result = self.result
        kept_mutations = result.chosen
        out: JsonObject = {
            "log": str(self.log),
            "failure": asdict(result.failure),
            "tester": TesterKind(result.tester).value,
            "why": self.why,
            "verdict": self.verdict,
            "stages": [asdict(s) for s in result.stages],
            "tests_run": sum(s.tests_run for s in result.stages),
            "cache_hits": self.cache_hits,
            "seconds": round(self.seconds, 3),
            "mutations": {"before": len(result.mutations), "after": len(kept_mutations)},
            "fields": {"before": self.fields_before, "after": result.fields_count()},
            "culprit": [m.describe(s) for m, s in kept_mutations],
            "culprit_events": [{"number": m.number, "channel": m.channel, "message_index": m.message_index,
                                "action": m.action, "consumers": list(m.consumers),
                                "fields": [m.fields[i].to_json() for i in (range(len(m.fields)) if s is None else s)]}
                               for m, s in kept_mutations],
            "detail": result.detail,
            "confirmation": self.confirmation.to_json(),
            "live_runs": self.live_runs,
            "live_run_seconds": round(self.live_seconds, 3),
            "notes": list(result.notes),
            "files": {k: str(v) for k, v in self.files.items()},
        }
        if result.tester == TesterKind.REPLAY:
            out["replayed_module"] = self.replayed_module
            out["frames"] = {"before": result.outputs_replayed, "after": len(result.frames)}
            out["replays"] = self.replay_tests
        else:
            out["failure_rate_while_minimising"] = result.failure_rate
        return out

    @property
    def cache_hits(self) -> int:
        return sum(s.cache_hits for s in self.result.stages) + self.replay_hits

    @property
    def fields_before(self) -> int:
        return sum(len(m.fields) for m in self.result.mutations)

    def text(self) -> str:
        """The console's summary: one line per stage, the culprit in words, the verdict."""
        result = self.result
        lines = [f"failure: {result.failure.describe()}", f"tester: {TesterKind(result.tester).value} ({self.why})"]
        for s in result.stages:
            state = "" if s.complete else " (stopped by --max-tests)"
            note = f"; {s.note}" if s.note else ""
            lines.append(f"  {s.name:<12} {s.unit:<9} {s.before:>5} → {s.after:<4} "
                         f"{s.tests_run:>4} tests, {s.cache_hits:>3} cache hits, {s.seconds:6.1f} s{state}{note}")
        parts = [f"mutations {len(result.mutations)} → {len(result.chosen)}"]
        if result.tester == TesterKind.REPLAY:
            parts.append(f"frames {result.outputs_replayed} → {len(result.frames)}")
        parts.append(f"fields {self.fields_before} → {result.fields_count()}")
        lines.append(f"minimised: {', '.join(parts)}; {sum(s.tests_run for s in result.stages)} tests, "
                     f"{self.cache_hits} cache hits, {round(self.seconds, 3):.1f} s")
        culprit = [m.describe(s) for m, s in result.chosen]
        lines.append("culprit:" if len(culprit) == 1 else f"culprits ({len(culprit)}):")
        lines.extend(f"  {text}" for text in culprit)
        for note in result.notes:
            lines.append(f"note: {note}")
        confirm = self.confirmation
        if confirm.runs and confirm.rate is not None:
            lines.append(f"live confirmation of {MINIMAL_XML}: failed in {confirm.failures} of {confirm.runs} "
                         f"run(s) (rate {confirm.rate:.0%})")
        lines.append(f"verdict: {self.verdict}")
        for name, path in self.files.items():
            lines.append(f"  {name}: {path}")
        return "\n".join(lines)


def write_summary(out_dir: Path, body: JsonObject) -> Path:
    """DIR/summary.json, written atomically (OutputError when it cannot be)."""
    path = out_dir / SUMMARY_JSON
    write_atomic(path, json.dumps(body, indent=1, default=str, allow_nan=False) + "\n")
    return path
