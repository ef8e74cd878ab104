"""`astaa-deft extract run.mcap --spec sut.yaml -o DIR`: DeFT module tests from a recorded run.

The work is :func:`astaa_deft.analysis.deft.workflow.extract_module_tests`; this prints its report.
"""

from __future__ import annotations

from pathlib import Path

from astaa_deft.engine.spec.planner import PAPER_THRESHOLDS
from astaa_deft.analysis.deft.extract import Extraction, near_miss_note, search_note
from astaa_deft.analysis.deft.workflow import extract_module_tests
from astaa_deft.cli.commands.console import CountProgress, say, stop_as_interrupt

def summary_table(ex: Extraction, thresholds=PAPER_THRESHOLDS) -> str:
    lines = [f"planning outputs found: {ex.outputs}; frames reconstructed: {len(ex.frames)}; "
             f"skipped: {len(ex.skipped)}"]
    if ex.recorded_outputs is not None:  # a per-trigger module: one frame per trigger message
        lines = [f"trigger messages: {ex.outputs} (recorded outputs: {ex.recorded_outputs}); frames replayed: "
                 f"{len(ex.frames)}; skipped: {len(ex.skipped)}"]
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
        ground_truth: str | None, jobs: int | None = None, module: str | None = None, resume: bool = False) -> int:
    progress = CountProgress("extract", "outputs")
    try:
        with stop_as_interrupt():
            report = extract_module_tests(log_path, spec_path, out_dir, threshold=threshold, process=process,
                                          ground_truth=ground_truth, jobs=jobs, progress=progress, notice=say,
                                          module=module, resume=resume)
    finally:
        progress.close()
    if report.resumed:
        say(f"resumed: {report.resumed} output(s) decided before, stepped once each")
    if report.interrupted:
        ex = report.extraction
        decided = len(ex.frames) + len(ex.skipped)
        say(f"interrupted after {decided}/{ex.outputs} outputs: {report.accepted} module test(s) of the outputs "
            f"decided so far written to {out_dir}; continue with: astaa-deft extract {log_path} --spec {spec_path} "
            f"-o {out_dir}{' --module ' + module if module else ''}"
            f"{f' --threshold {threshold:g}' if threshold is not None else ''} --resume")
        return 130
    say(summary_table(report.extraction))
    searched = search_note(report.extraction)
    if searched:
        say(searched)
    note = near_miss_note(report.extraction)
    if note:
        say(note)
    if report.collision:
        say(f"collision observed in the run: {report.oracles} frame(s) planned into a predicted obstacle "
            f"beforehand → oracle tests that fail while the planner still does so")
    if report.ground_truth is not None:
        exact, checked = report.ground_truth
        say(f"ground truth ({ground_truth}): {exact}/{checked} frames used exactly the planner's inputs"
            + (f" ({exact / checked:.1%})" if checked else ""))
    entry = report.entry
    unit = " m" if entry.trajectory is not None else ""
    say(f"{report.accepted} module tests (θ = {entry.threshold:g}{unit}) written to {out_dir}; "
        f"run them with: pytest {out_dir}")
    return 0 if report.manifest else 1
