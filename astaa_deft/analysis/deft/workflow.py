"""DeFT extraction as one library call: a recorded run in, deterministic planner module tests out.

``extract_module_tests(log_path, spec, out_dir, …)`` reads the run,
replays the planner over the frames it reconstructs (:func:`.extract.extract`),
writes the accepted frames as a pytest suite (:func:`.export.export_suite`)
with oracle tests for a collision the run saw, and returns what it found.
``astaa-deft extract`` prints the report; benchmarks and campaigns call this.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

from astaa_deft.model.errors import InputError, Problem
from astaa_deft.io.output_place import Place, ready_dir, writing
from astaa_deft.io.log import records as rec
from astaa_deft.io.log.reader import LogContents, read_log
from astaa_deft.engine.monitor.kinds.collision import CollisionInvariant
from astaa_deft.engine.spec.loader import load_spec
from astaa_deft.engine.spec.replay_section import ReplayModule
from astaa_deft.model.sut import Spec
from astaa_deft.analysis.deft.checkpoint import Checkpoint, LogShape, identity, read_state
from astaa_deft.analysis.deft.diagnosis import Diagnosis, diagnose
from astaa_deft.analysis.deft.export import MANIFEST, export_suite, is_checked
from astaa_deft.analysis.deft.idle_cores import cpu_sample, idle_cores
from astaa_deft.analysis.deft.extract import (
    Decided, ExtractedFrame, Extraction, OnOutput, channel_messages, extract, ground_truth_rate,
)
from astaa_deft.analysis.deft.oracle import oracle_entries
from astaa_deft.analysis.deft.planner_section import replay_module_of
from astaa_deft.analysis.deft.replay import make_planner
from astaa_deft.analysis.deft.run_metadata import RunMetadata
from astaa_deft.analysis.deft.snapshots import add_oracle_snapshots


def run_params(log: LogContents, spec: Spec) -> dict[str, str]:
    """The params the run was recorded with (replay must build the same planner)."""
    meta = RunMetadata.of(log)
    if meta.spec and meta.spec != spec.name:
        raise InputError(Problem(str(log.path), None, None,
                                 f"this log was recorded with spec '{meta.spec}', not '{spec.name}'",
                                 "pass the spec the run used"))
    return meta.params


@dataclass(kw_only=True)
class ExtractReport:
    extraction: Extraction
    spec: Spec  # with the threshold used (the planner's)
    accepted: int  # module tests written
    oracles: int  # oracle tests written (frames that planned into a predicted obstacle before a collision)
    collision: bool  # the run recorded a collision
    manifest: Path | None  # export_suite's manifest; None when nothing was written
    entry: ReplayModule  # the replayed module (the planner's own or a replay: entry), with the threshold used
    ground_truth: tuple[int, int] | None = None  # (frames that used exactly the planner's inputs, checked)
    interrupted: bool = False  # stopped early: ``extraction`` holds the outputs decided so far
    resumed: int = 0  # outputs an interrupted extraction had decided, stepped once each
    # Module tests that failed when the written suite ran once on its own run (an extraction defect); the
    # suite keeps their frames for the state they build, without asserting them.
    suite_failures: list[SuiteFailure] = field(default_factory=list)
    # Why outputs do not reproduce (the fields that differ, how, the ignore: line to add); None: they all do.
    diagnosis: Diagnosis | None = None


@dataclass(frozen=True, kw_only=True)
class ExtractOptions:
    """How an extraction searches and replays (the `extract` command's options past the log, spec and output)."""

    threshold: float | None = None  # accept a frame within this distance, m (None: the spec's)
    process: bool = False  # replay with the planner's own process in lock-step
    ground_truth: str | None = None  # evaluation only: the output field naming the inputs' header.seq
    jobs: int | None = None  # candidate frames tried at once (None: the idle cores)
    module: str | None = None  # a module of the spec's replay: section (None: the planner)
    resume: bool = False  # continue an interrupted extraction into the same output directory


def extract_module_tests(log_path: Path, spec: Spec | Path, out_dir: Path, options: ExtractOptions = ExtractOptions(),
                         *, progress: Callable[[int, int], None] = lambda done, total: None,
                         notice: Callable[[str], None] = lambda line: None) -> ExtractReport:
    """Extract and write the module tests of one run (InputError on bad input).

    ``spec`` is the spec as its command loaded it (read once per command) or the path of its file (read here).
    ``out_dir`` is checked before the log is read (OutputError: a file in the
    way, not writable, no room, no usable temporary directory); a write that
    fails later raises OutputError too.

    ``options.module`` names a module of the spec's ``replay:`` section (default:
    the planner). ``progress(done, total)`` follows the outputs; ``notice``
    gets the log reader's warnings; ``options.jobs`` bounds the worker processes that
    try an output's candidate frames in parallel (default: the idle cores).
    The tests of the outputs decided so far are written as the extraction
    goes (see checkpoint); a KeyboardInterrupt (the command turns SIGTERM
    into one) ends it early with those written and a report marked
    ``interrupted``; ``options.resume`` goes on from such an extraction into the
    same ``out_dir`` (InputError if there is none, or it was another's).
    """
    started = cpu_sample()  # the idle cores are measured while the log is read (idle_cores), if a search forks
    threshold, module, jobs, resume = options.threshold, options.module, options.jobs, options.resume
    place = Place(out_dir, "-o")
    ready_dir(place, temp=True)
    spec_path = (spec.path or Path(spec.name)) if isinstance(spec, Spec) else Path(spec)
    spec = spec if isinstance(spec, Spec) else load_spec(spec)
    module = _module_named(module, spec, spec_path)
    entry = replay_module_of(spec, module)
    _check_ground_truth(options.ground_truth, spec_path, spec=spec, output=entry.output)  # before the work
    if threshold is not None:
        entry = replace(entry, threshold=threshold)
        if module is None and spec.planner is not None:
            spec = replace(spec, planner=replace(spec.planner, threshold=threshold))
    log = read_log(log_path)
    for warning in log.warnings:
        notice(f"warning: {warning}")
    params = run_params(log, spec)
    names = identity(log_path, spec, entry)
    if resume and entry.per_trigger:
        raise InputError(Problem(str(out_dir), None, None, f"--resume continues a planner-style extraction; "
                                 f"{entry.module} is replayed per trigger", "drop --resume"))
    before = read_state(out_dir, names, _shape(log, spec, entry)) if resume else []
    checkpoint = Checkpoint(out_dir, spec, params, entry=entry, extraction=names)
    planner = make_planner(spec, params, prefer_process=options.process, entry=entry)
    try:
        with writing(place):  # the decided outputs' tests are written as the extraction goes
            ex = extract(log, spec, planner, on_output=_following(progress, checkpoint),
                         jobs=jobs or (lambda: idle_cores(started)), entry=entry, resume=before,
                         fresh=lambda: make_planner(spec, params, prefer_process=options.process, entry=entry))
    except KeyboardInterrupt:
        with writing(place):
            checkpoint.write()
        return _interrupted(checkpoint, spec, entry, len(before))
    finally:
        planner.close()
    accepted = [f for f in ex.frames if f.accepted]
    collisions = [v.time_ns for v in log.records(rec.Violation) if v.invariant_kind == CollisionInvariant.kind]
    kept = {f.index for f in accepted}
    oracles = [o for o in oracle_entries(ex, spec, collisions) if o["frame"] in kept] if module is None else []
    with writing(place):
        manifest, accepted, failing, diagnosis = _write_checked_suite(ex, spec, params, out_dir, oracles=oracles,
                                                                      entry=entry)
        checkpoint.finished()
    exact = ground_truth_rate(ex, spec, options.ground_truth, entry) if options.ground_truth else None
    return ExtractReport(extraction=ex, spec=spec, accepted=len(accepted) - len(failing), oracles=len(oracles),
                         collision=bool(collisions), manifest=manifest, entry=entry, ground_truth=exact,
                         resumed=len(before), suite_failures=failing, diagnosis=diagnosis)


def _write_checked_suite(ex: Extraction, spec: Spec, params: dict[str, str], out_dir: Path, *,
                         oracles: list[dict[str, object]], entry: ReplayModule
                         ) -> tuple[Path | None, list[ExtractedFrame], list[SuiteFailure], Diagnosis | None]:
    """Write the suite, have pytest's own run of it the last word, and store why outputs did not reproduce:
    (manifest, accepted frames, frames whose tests no longer assert, diagnosis)."""
    # Every frame kept is stepped by the suite (those not accepted for their state only): the test of
    # an output runs after the frames before it, as the extraction stepped them.
    manifest = export_suite(ex.frames, spec, params, out_dir, oracles=oracles, entry=entry)
    accepted = [f for f in ex.frames if f.accepted]
    # The search's own run of the suite (in order, or beside it) found these; its tests no longer assert
    searched = [SuiteFailure(index, detail) for index, detail in ex.suite_failures or ()]
    if searched:
        uncheck_frames(out_dir, {f.index for f in searched})
    failing: list[SuiteFailure] = []
    if ex.frames:  # the last word: the written suite run as pytest runs it, in a process of its own
        failing, confirmed = check_suite(out_dir, ex)
        if confirmed:  # its own run reproduces frames the search's copies did not: they are tests
            export_suite(ex.frames, spec, params, out_dir, oracles=oracles, entry=entry)
            accepted = [f for f in ex.frames if f.accepted]
    confirmed_now = {f.index for f in ex.frames if f.accepted}
    failing = sorted({f.index: f for f in [*(f for f in searched if f.index not in confirmed_now), *failing]}
                     .values(), key=lambda f: f.index)
    if failing:  # an extraction defect: the suite says so, and those tests no longer assert
        uncheck_frames(out_dir, {f.index for f in failing})
    if oracles:
        add_oracle_snapshots(out_dir)  # the oracle tests then fail first, in one step each (TTRF)
    diagnosis = diagnosis_of(ex, spec, entry)
    if diagnosis is not None and manifest is not None:
        store_diagnosis(out_dir, diagnosis)
    return manifest, accepted, failing, diagnosis


DIAGNOSIS_SAMPLES = 8  # recorded outputs read to tell whether each ignore: entry names a field


def diagnosis_of(extraction: Extraction, spec: Spec, entry: ReplayModule) -> Diagnosis | None:
    """Why the extraction's outputs do not reproduce at the module's θ (diagnosis.py); None when they all do."""
    from astaa_deft.io.codecs import get_codec
    from astaa_deft.io.codecs.base import DecodeError

    if all(f.comparison.within(entry.threshold) for f in extraction.frames):
        return None
    codec = get_codec(spec.channel(entry.output).encoding)
    samples: list[object] = []
    for frame in extraction.frames:
        if frame.output is not None and len(samples) < DIAGNOSIS_SAMPLES:
            try:
                samples.append(codec.decode(frame.output.data))
            except DecodeError:
                continue
    return diagnose([f.comparison for f in extraction.frames], threshold=entry.threshold, ignore=entry.ignore,
                    where=entry.where, brittle=_brittle_in(spec, entry.output), recorded=samples)


def _brittle_in(spec: Spec, channel: str) -> Callable[[str], bool]:
    """Whether the spec declares a field of ``channel``'s messages brittle (``brittle:``, e.g. Header.stamp);
    False for a field its declared type lacks."""
    from astaa_deft.model.errors import AstaaDeftError
    from astaa_deft.model.fields import is_brittle

    type_name = spec.channel(channel).type

    def brittle(path: str) -> bool:
        if not spec.brittle or type_name not in spec.types:
            return False
        try:
            return is_brittle(spec.types, type_name, path, spec.brittle)
        except (AstaaDeftError, KeyError, ValueError):  # a field the declared type does not have
            return False

    return brittle


def store_diagnosis(out_dir: Path, diagnosis: Diagnosis) -> None:
    """Keep the diagnosis in the suite's manifest (``diagnosis``): why its other frames are no tests."""
    import json

    from astaa_deft.io.output_place import write_atomic

    path = out_dir / MANIFEST
    manifest = json.loads(path.read_text())
    manifest["diagnosis"] = diagnosis.as_json()
    write_atomic(path, json.dumps(manifest, indent=1, default=str) + "\n")


def _module_named(module: str | None, spec: Spec, spec_path: Path) -> str | None:
    """The ``replay:`` module to extract, None for the planner (named or not); InputError without either."""
    if module is None and spec.planner is None:
        raise InputError(Problem(str(spec_path), None, None, "the spec has no 'planner' section",
                                 "describe the planning module under 'planner:' (see docs/deft.md), or name a "
                                 "module of its 'replay:' section with --module"))
    if module is not None and spec.planner is not None and module == spec.planner.module:
        return None  # the planner, as its own section describes it
    return module


@dataclass(frozen=True)
class SuiteFailure:
    """A module test that failed when the suite ran once on the run it came from (an extraction defect)."""

    index: int  # the frame's index
    detail: str  # the distance or the error


PLUGIN_MODULE = "astaa_deft.analysis.deft.pytest_plugin"  # the suite's plugin, loaded by name for the check
SUITE_CHECK_TIMEOUT_S = 3600.0  # a suite of a long run of an expensive module: bounded, never forever


def check_suite(out_dir: Path, extraction: Extraction | None = None) -> tuple[list[SuiteFailure], int]:
    """Run the written suite once as the user will, ``pytest DIR`` in a process of its own (a fresh module, every
    frame in order): (the tests that fail — a suite must pass on the run it came from —, frames confirmed).

    In a process of its own, not this one: a module's answers may depend on its process (the
    extraction's forked runner, its own heap and globals — a planner's native search state seeded
    or laid out by what ran there before), so only pytest's own run says what pytest will say.

    With ``extraction``, that run has the last word on its frames: one kept
    but not accepted (the search stepped it on a copy of the state) that the
    fresh module reproduces within θ becomes accepted — a test that passes
    (counted in ``extraction.confirmed_unforked`` and the second number).
    """
    import json
    import os
    import subprocess
    import sys
    import tempfile

    from astaa_deft.analysis.deft.pytest_plugin import RESULTS_ENV
    from astaa_deft.analysis.deft.validator import Comparison
    from astaa_deft.engine.bus import process_launch

    out_dir = out_dir.resolve()  # pytest runs from inside the suite (its own pytest.ini): a relative path breaks
    manifest = json.loads((out_dir / MANIFEST).read_text())
    threshold = float(manifest["threshold"])
    frames = {f.index: f for f in extraction.frames} if extraction is not None else {}
    with tempfile.TemporaryDirectory(prefix="astaa-deft-suite-check-") as scratch:
        results_path = Path(scratch) / "results.json"
        # pytest and the tool's own plugin, no other plugin the environment installs (autoload off): a module's
        # answers do not depend on a timeout or a reporter plugin, and their per-test hooks cost more than a cheap
        # module's steps (each_several: 243 tests in 6-10 s with them, 3 s without, at load 10 on 2 cores).
        env = {**os.environ, RESULTS_ENV: str(results_path), "PYTEST_DISABLE_PLUGIN_AUTOLOAD": "1"}
        argv = [sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider", "-p", PLUGIN_MODULE, str(out_dir)]
        ran: dict[str, Any]
        try:
            done = process_launch.run(argv, timeout=SUITE_CHECK_TIMEOUT_S, cwd=str(out_dir), env=env)
            ran = json.loads(results_path.read_text()).get(str(out_dir), {}) if results_path.is_file() \
                else {"error": (done.stdout + done.stderr).strip()[-300:] or f"pytest exit {done.returncode}"}
        except subprocess.TimeoutExpired:
            ran = {"error": f"pytest did not finish the suite in {SUITE_CHECK_TIMEOUT_S:.0f} s"}
    if "frames" not in ran:  # it did not run at all: none of its tests can be said to pass
        why = f"pytest could not run the suite: {ran.get('error')}"
        return [SuiteFailure(int(e["index"]), why) for e in manifest["frames"] if is_checked(e)], 0
    results: dict[int, dict[str, Any]] = {int(r["index"]): r for r in ran["frames"]}
    out = []
    confirmed = 0
    for entry in manifest["frames"]:
        result = results.get(int(entry["index"]))
        if result is None:
            continue
        if not is_checked(entry):
            frame = frames.get(int(entry["index"]))
            if result["passes"] and frame is not None and frame.output is not None and not result["stopped"]:
                frame.comparison = Comparison(distance=float(result["distance"]), max_error=float(result["max_error"]),
                                              points=int(result["points"]), how=str(result["how"]))
                frame.accepted = True
                frame.exact = frame.comparison.distance == 0.0
                confirmed += 1
            continue
        if not result["passes"]:
            out.append(SuiteFailure(int(entry["index"]), result["error"]
                                    or f"distance {float(result['distance']):.3g} (θ = {threshold:g})"))
    if extraction is not None:
        extraction.confirmed_unforked += confirmed
    return out, confirmed


def uncheck_frames(out_dir: Path, indices: set[int]) -> None:
    """Mark these frames of the suite as stepped for their state only (no test): their tests fail on the
    run they came from, and the suite says only what it can show."""
    import json

    from astaa_deft.io.output_place import write_atomic

    path = out_dir / MANIFEST
    manifest = json.loads(path.read_text())
    for entry in manifest["frames"]:
        if entry["index"] in indices:
            entry["check"] = False
            entry["unchecked_because"] = "failed when the suite was run on the run it came from"
    write_atomic(path, json.dumps(manifest, indent=1) + "\n")


def _check_ground_truth(path: str | None, spec_path: Path, *, spec: Spec, output: str) -> None:
    """InputError when ``--ground-truth`` is not a field path (the output field naming the inputs used), or
    not a field of the ``output`` channel's declared type."""
    from astaa_deft.model.fields import FieldPath, FieldPathError, type_at

    if path is None:
        return
    try:
        type_name = spec.channel(output).type
        parsed = FieldPath.parse(path)
        if type_name in spec.types:
            type_at(spec.types, type_name, parsed)
    except FieldPathError as exc:
        raise InputError(Problem("--ground-truth", None, None, f"'{path}' names no field of '{output}': {exc}",
                                 f"name the field of the module's output (per {spec_path}) that lists the inputs "
                                 f"it used, e.g. debug.inputs")) from None


def _shape(log: LogContents, spec: Spec, entry: ReplayModule) -> LogShape:
    """What a resumed state must fit: the module's recorded outputs and its inputs' messages in the log."""
    messages = channel_messages(log, spec, list(entry.inputs) + [entry.output])
    return LogShape(len(messages.pop(entry.output)), {name: len(msgs) for name, msgs in messages.items()})


def _following(progress: Callable[[int, int], None], checkpoint: Checkpoint) -> OnOutput:
    """The extraction's per-output callback: the caller's progress, then the decided output checkpointed."""
    def on_output(done: int, total: int, outcome: Decided) -> None:
        progress(done, total)
        checkpoint.add(outcome, total)

    return on_output


def _interrupted(checkpoint: Checkpoint, spec: Spec, entry: ReplayModule, resumed: int) -> ExtractReport:
    """The report of an extraction stopped early: the outputs decided before, as written."""
    frames = [d.frame for d in checkpoint.decided if d.frame is not None]
    ex = Extraction(frames=[replace(f, index=i) for i, f in enumerate(frames)],
                    skipped=[(d.output_index, d.skipped or "") for d in checkpoint.decided if d.frame is None],
                    outputs=checkpoint.total)
    accepted = len(checkpoint.accepted())
    manifest = checkpoint.out_dir / MANIFEST if accepted else None
    return ExtractReport(extraction=ex, spec=spec, accepted=accepted, oracles=0, collision=False, manifest=manifest,
                         entry=entry, interrupted=True, resumed=resumed)
