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
from collections.abc import Mapping
from dataclasses import asdict, replace
from pathlib import Path
from typing import Any

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
from astaa_deft.analysis.minimise.replay_model import Frame, ReplayModel
from astaa_deft.analysis.minimise.stages import Minimisation

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


def write_testcase_file(out_dir: Path, testcase: TestCase, spec) -> Path:
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

        records: list[tuple[int, int, bytes, Any]] = []  # (time, MCAP channel, data, what it is)
        seen: set[Any] = set()
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
        sequences: dict[Any, int] = {}
        writer.record(log_records.RunStarted(model.start_ns, "replay", spec.name))
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
            writer.record(log_records.ProcessExit(cfg.module, 0, 1, None, model.output_time(frame) + 1,
                                                  False, error))
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
        extracted.append(ExtractedFrame(
            index=len(extracted), output=output,
            trigger_time=frame.trigger_time_ns, frame_time=frame.frame_time_ns,
            inputs={name: LoggedMessage(spec.channel(name).key, d.time_ns, d.time_ns, 0, d.data)
                    for name, d in frame.inputs},
            comparison=Comparison(0.0, 0.0, 0, "replayed"), accepted=True, candidates_tried=1, exact=True))
        if error is not None:
            break
    smoke_entry = replace(cfg, threshold=math.inf)
    smoke = replace(spec, planner=replace(spec.planner, threshold=math.inf)) if spec.planner is not None else spec
    oracle = oracle_entry(result.failure.invariant, extracted[-1].index if extracted else 0, model.start_ns)
    return export_suite(extracted, smoke, model.params, directory, oracles=[oracle], entry=smoke_entry)


def _kept_frames(model: ReplayModel, result: Minimisation) -> list[Frame]:
    frames = model.frames(result.kept)
    return [frame for i in result.frames if i < len(frames) and (frame := frames[i]) is not None]


def _normal(selection, mutation):
    if selection is None or len(selection) == len(mutation.fields):
        return None
    return tuple(sorted(selection))


def copy_log(source: Path, out_dir: Path) -> Path:
    target = out_dir / MINIMAL_MCAP
    shutil.copyfile(source, target)
    return target


# ---------------------------------------------------------------- the summary


def summary(result: Minimisation, *, log: Path, why: str, seconds: float, confirm: Mapping[str, Any],
            verdict: str, files: Mapping[str, Path], replay_tests: int = 0, replay_hits: int = 0,
            live_runs: int = 0, live_seconds: float = 0.0) -> dict:
    """Everything summary.json holds (and the console shows)."""
    stages = [asdict(s) for s in result.stages]
    kept_mutations = result.chosen
    out: dict[str, Any] = {
        "log": str(log),
        "failure": asdict(result.failure),
        "tester": result.tester,
        "why": why,
        "verdict": verdict,
        "stages": stages,
        "tests_run": sum(s.tests_run for s in result.stages),
        "cache_hits": sum(s.cache_hits for s in result.stages) + replay_hits,
        "seconds": round(seconds, 3),
        "mutations": {"before": len(result.mutations), "after": len(kept_mutations)},
        "fields": {"before": sum(len(m.fields) for m in result.mutations), "after": result.fields_count()},
        "culprit": [m.describe(s) for m, s in kept_mutations],
        "culprit_events": [{"number": m.number, "channel": m.channel, "message_index": m.message_index,
                            "action": m.action, "consumers": list(m.consumers),
                            "fields": [m.fields[i].to_json() for i in (range(len(m.fields)) if s is None else s)]}
                           for m, s in kept_mutations],
        "detail": result.detail,
        "confirmation": dict(confirm),
        "live_runs": live_runs,  # whole-system runs, the confirmation's included
        "live_run_seconds": round(live_seconds, 3),
        "notes": list(result.notes),
        "files": {k: str(v) for k, v in files.items()},
    }
    if result.tester == "replay":
        out["frames"] = {"before": result.outputs_replayed, "after": len(result.frames)}
        out["replays"] = replay_tests  # planner replays actually run (speculative parallel ones included)
    else:
        out["failure_rate_while_minimising"] = result.failure_rate
    return out


def write_summary(out_dir: Path, body: Mapping[str, Any]) -> Path:
    path = out_dir / SUMMARY_JSON
    write_atomic(path, json.dumps(body, indent=1, default=str, allow_nan=False) + "\n")
    return path


def format_summary(body: Mapping[str, Any]) -> str:
    """The console's summary: one line per stage, the culprit in words, the verdict."""
    lines = [f"failure: {_failure_text(body['failure'])}", f"tester: {body['tester']} ({body['why']})"]
    for s in body["stages"]:
        state = "" if s["complete"] else " (stopped by --max-tests)"
        note = f"; {s['note']}" if s["note"] else ""
        lines.append(f"  {s['name']:<12} {s['unit']:<9} {s['before']:>5} → {s['after']:<4} "
                     f"{s['tests_run']:>4} tests, {s['cache_hits']:>3} cache hits, {s['seconds']:6.1f} s{state}{note}")
    parts = [f"mutations {body['mutations']['before']} → {body['mutations']['after']}"]
    if "frames" in body:
        parts.append(f"frames {body['frames']['before']} → {body['frames']['after']}")
    parts.append(f"fields {body['fields']['before']} → {body['fields']['after']}")
    lines.append(f"minimised: {', '.join(parts)}; {body['tests_run']} tests, {body['cache_hits']} cache hits, "
                 f"{body['seconds']:.1f} s")
    lines.append("culprit:" if len(body["culprit"]) == 1 else f"culprits ({len(body['culprit'])}):")
    lines.extend(f"  {text}" for text in body["culprit"])
    for note in body["notes"]:
        lines.append(f"note: {note}")
    confirm = body["confirmation"]
    if confirm.get("runs"):
        lines.append(f"live confirmation of {MINIMAL_XML}: failed in {confirm['failures']} of {confirm['runs']} "
                     f"run(s) (rate {confirm['rate']:.0%})")
    lines.append(f"verdict: {body['verdict']}")
    for name, path in body["files"].items():
        lines.append(f"  {name}: {path}")
    return "\n".join(lines)


def _failure_text(failure: Mapping[str, Any]) -> str:
    where = f" on '{failure['channel']}'" if failure.get("channel") else (
        f" (module '{failure['module']}')" if failure.get("module") else "")
    return f"{failure['invariant']} ({failure['kind']}){where} at +{failure['at']:.2f} s: {failure['detail']}"
