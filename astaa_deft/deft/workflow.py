"""DeFT extraction as one library call: a recorded run in, deterministic planner module tests out.

``extract_module_tests(log_path, spec_path, out_dir, …)`` reads the run,
replays the planner over the frames it reconstructs (:func:`.extract.extract`),
writes the accepted frames as a pytest suite (:func:`.export.export_suite`)
with oracle tests for a collision the run saw, and returns what it found.
``astaa-deft extract`` prints the report; benchmarks and campaigns call this.
"""

from __future__ import annotations

import json
import os
from collections.abc import Callable
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

from ..errors import InputError, Problem
from ..output_place import Place, ready_dir, writing
from ..log import layout
from ..log import records as rec
from ..log.reader import LogContents, read_log
from ..spec_loader import load_spec
from ..spec.model import Spec
from .export import export_suite
from .extract import Extraction, extract, ground_truth_rate
from .oracle import oracle_entries
from .planner_section import replay_module_of
from .replay import make_planner
from .snapshots import add_oracle_snapshots


def run_params(log: LogContents, spec: Spec) -> dict[str, str]:
    """The params the run was recorded with (replay must build the same planner)."""
    meta = log.metadata.get(layout.RUN_METADATA, {})
    if meta.get("spec") and meta["spec"] != spec.name:
        raise InputError(Problem(str(log.path), None, None,
                                 f"this log was recorded with spec '{meta['spec']}', not '{spec.name}'",
                                 "pass the spec the run used"))
    try:
        return json.loads(meta.get("params", "{}"))
    except ValueError:
        return {}


@dataclass
class ExtractReport:
    extraction: Extraction
    spec: Spec  # with the threshold used (the planner's)
    accepted: int  # module tests written
    oracles: int  # oracle tests written (frames that planned into a predicted obstacle before a collision)
    collision: bool  # the run recorded a collision
    manifest: Any  # export_suite's manifest; empty when nothing was written
    ground_truth: tuple[int, int] | None = None  # (frames that used exactly the planner's inputs, checked)
    entry: Any = None  # the replayed module's ReplayModule, with the threshold used


def extract_module_tests(log_path: Path, spec_path: Path, out_dir: Path, *, threshold: float | None = None,
                         process: bool = False, ground_truth: str | None = None, jobs: int | None = None,
                         progress: Callable[[int, int], None] = lambda done, total: None,
                         notice: Callable[[str], None] = lambda line: None,
                         module: str | None = None) -> ExtractReport:
    """Extract and write the module tests of one run (InputError on bad input).

    ``out_dir`` is checked before the log is read (OutputError: a file in the
    way, not writable, no room, no usable temporary directory); a write that
    fails later raises OutputError too.

    ``module`` names a module of the spec's ``replay:`` section (default:
    the planner). ``progress(done, total)`` follows the outputs; ``notice``
    gets the log reader's warnings; ``jobs`` bounds the worker processes that
    try an output's candidate frames in parallel (default: one per core).
    """
    place = Place(out_dir, "-o")
    ready_dir(place, temp=True)
    spec = load_spec(spec_path)
    if module is None and spec.planner is None:
        raise InputError(Problem(str(spec_path), None, None, "the spec has no 'planner' section",
                                 "describe the planning module under 'planner:' (see docs/deft.md), or name a "
                                 "module of its 'replay:' section with --module"))
    if module is not None and spec.planner is not None and module == spec.planner.module:
        module = None  # the planner, as its own section describes it
    entry = replay_module_of(spec, module)
    if threshold is not None:
        entry = replace(entry, threshold=threshold)
        if module is None and spec.planner is not None:
            spec = replace(spec, planner=replace(spec.planner, threshold=threshold))
    log = read_log(log_path)
    for warning in log.warnings:
        notice(f"warning: {warning}")
    params = run_params(log, spec)
    planner = make_planner(spec, params, prefer_process=process, entry=entry)
    try:
        ex = extract(log, spec, planner, progress=progress, jobs=jobs or os.cpu_count() or 1, entry=entry)
    finally:
        planner.close()
    accepted = [f for f in ex.frames if f.accepted]
    collisions = [v.time_ns for v in log.records(rec.ViolationRecord) if v.invariant_kind == "collision"]
    kept = {f.index for f in accepted}
    oracles = [o for o in oracle_entries(ex, spec, collisions) if o["frame"] in kept] if module is None else []
    with writing(place):
        manifest = export_suite(accepted, spec, params, out_dir, oracles=oracles, entry=entry)
        if oracles:
            add_oracle_snapshots(out_dir)  # the oracle tests then fail first, in one step each (TTRF)
    exact = ground_truth_rate(ex, spec, ground_truth) if ground_truth else None
    return ExtractReport(ex, spec, len(accepted), len(oracles), bool(collisions), manifest, exact, entry)
