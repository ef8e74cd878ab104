"""`astaa-deft extract run.mcap --spec sut.yaml -o DIR`: DeFT module tests from a recorded run."""

from __future__ import annotations

import json
import os
import sys
from pathlib import Path

from ..deft.config import PAPER_THRESHOLDS
from ..deft.export import export_suite
from ..deft.extract import Extraction, extract, ground_truth_rate, near_miss_note
from ..deft.oracle import oracle_entries
from ..deft.replay import make_planner
from ..errors import InputError, Problem
from ..log import layout
from ..log.reader import read_log
from ..spec.loader import load_spec
from ..spec.model import Spec
from .console import say


def run_params(log, spec: Spec) -> dict[str, str]:
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


def progress_bar(done: int, total: int) -> None:
    if not sys.stderr.isatty() or total == 0:
        return
    width = 30
    filled = int(width * done / total)
    sys.stderr.write(f"\r  [{'#' * filled}{'.' * (width - filled)}] {done}/{total} outputs")
    if done == total:
        sys.stderr.write("\r\033[K")
    sys.stderr.flush()


def summary_table(ex: Extraction, thresholds=PAPER_THRESHOLDS) -> str:
    lines = [f"planning outputs found: {ex.outputs}; frames reconstructed: {len(ex.frames)}; "
             f"skipped: {len(ex.skipped)}"]
    lines.append(f"{'θ (m)':>8} {'reproduced':>11} {'rate':>8}")
    for th in thresholds:
        n = ex.accepted_at(th)
        lines.append(f"{th:8.2f} {n:11d} {n / ex.outputs if ex.outputs else 0:8.1%}")
    n = max(len(ex.frames), 1)
    lines.append(f"per frame: reconstruction {ex.reconstruction_seconds / n * 1e3:.3f} ms (candidate search and "
                 f"input decoding), validation {ex.validation_seconds / n * 1e3:.3f} ms, "
                 f"planner replay {ex.planner_seconds / n * 1e3:.2f} ms")
    return "\n".join(lines)


def run(log_path: Path, spec_path: Path, out_dir: Path, threshold: float | None, process: bool,
        ground_truth: str | None, jobs: int | None = None) -> int:
    spec = load_spec(spec_path)
    if spec.planner is None:
        raise InputError(Problem(str(spec_path), None, None, "the spec has no 'planner' section",
                                 "describe the planning module under 'planner:' (see docs/deft.md)"))
    if threshold is not None:
        from dataclasses import replace

        spec = replace(spec, planner=replace(spec.planner, threshold=threshold))
    log = read_log(log_path)
    for w in log.warnings:
        say(f"warning: {w}")
    params = run_params(log, spec)
    planner = make_planner(spec, params, prefer_process=process)
    try:
        ex = extract(log, spec, planner, progress=progress_bar, jobs=jobs or os.cpu_count() or 1)
    finally:
        planner.close()
    accepted = [f for f in ex.frames if f.accepted]
    collisions = [e["time_ns"] for e in log.events("violation") if e.get("invariant_kind") == "collision"]
    kept = {f.index for f in accepted}
    oracles = [o for o in oracle_entries(ex, spec, collisions) if o["frame"] in kept]
    manifest = export_suite(accepted, spec, params, out_dir, oracles=oracles)
    say(summary_table(ex))
    note = near_miss_note(ex)
    if note:
        say(note)
    if collisions:
        say(f"collision observed in the run: {len(oracles)} frame(s) planned into a predicted obstacle "
            f"beforehand → oracle tests that fail while the planner still does so")
    if ground_truth:
        exact, checked = ground_truth_rate(ex, spec, ground_truth)
        say(f"ground truth ({ground_truth}): {exact}/{checked} frames used exactly the planner's inputs"
            + (f" ({exact / checked:.1%})" if checked else ""))
    say(f"{len(accepted)} module tests (θ = {spec.planner.threshold:g} m) written to {out_dir}; "
        f"run them with: pytest {out_dir}")
    return 0 if manifest else 1
