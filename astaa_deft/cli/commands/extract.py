"""`astaa-deft extract run.mcap --spec sut.yaml -o DIR`: DeFT module tests from a recorded run.

The work is :func:`astaa_deft.analysis.deft.workflow.extract_module_tests`; this prints its report.
"""

from __future__ import annotations

import argparse
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING

from astaa_deft.cli.arguments import PROCESSES, THRESHOLD_M, bounded
from astaa_deft.cli.commands.console import CountProgress, say, stop_as_interrupt

if TYPE_CHECKING:
    from astaa_deft.analysis.deft.extract import Extraction
    from astaa_deft.analysis.deft.workflow import ExtractOptions
    from astaa_deft.cli.arguments import SubParsers
    from astaa_deft.model.sut import Spec


def add_parser(subparsers: SubParsers) -> None:
    """Declare the `extract` command."""
    ext = subparsers.add_parser("extract", help="DeFT: turn a recorded run into deterministic planner module tests",
                                 epilog="examples:\n  astaa-deft extract run.mcap --spec specs/demo_av.yaml -o "
                                        "planner-tests/\n"
                                        "  pytest planner-tests/")
    ext.add_argument("log", type=Path, help="a log recorded by astaa-deft proxy")
    ext.add_argument("--spec", type=Path, required=True, help="the SUT spec (YAML) the log was recorded with")
    ext.add_argument("-o", "--out", type=Path, required=True, help="directory for the module tests")
    bounded(ext, "--threshold", THRESHOLD_M, help="accept a frame within this distance, m (default: the spec's)")
    ext.add_argument("--process", action="store_true",
                     help="replay with the planner's own process in lock-step (needs planner.replay.command; "
                          "default: the replay factory in this process)")
    ext.add_argument("--ground-truth", metavar="FIELD",
                     help="evaluation only: the output field naming the inputs' header.seq (e.g. debug.inputs; "
                          "default: none)")
    bounded(ext, "--jobs", PROCESSES, metavar="N",
            help="candidate frames tried at once, in forked processes (default: the idle cores)")
    ext.add_argument("--module", help="a module of the spec's replay: section (default: the planner)")
    ext.add_argument("--resume", action="store_true",
                     help="continue an interrupted extraction into the same -o directory (default: start afresh)")
    ext.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """The parsed `extract` arguments as ExtractOptions, to :func:`extract`."""
    from astaa_deft.analysis.deft.workflow import ExtractOptions

    return extract(args.log, args.spec, args.out, ExtractOptions(
        threshold=args.threshold, process=args.process, ground_truth=args.ground_truth, jobs=args.jobs,
        module=args.module, resume=args.resume))


def summary_table(ex: Extraction, thresholds: Sequence[float] | None = None, module: str | None = None) -> str:
    """The extraction's counts and its reproduction rate at each threshold (default: the paper's) as text;
    ``module``: a module of the spec's replay: section (None: the planner)."""
    from astaa_deft.engine.spec.planner import PAPER_THRESHOLDS

    thresholds = PAPER_THRESHOLDS if thresholds is None else thresholds
    found = "planning outputs found" if module is None else f"outputs of module '{module}' found"
    lines = [f"{found}: {ex.outputs}; frames reconstructed: {len(ex.frames)}; skipped: {len(ex.skipped)}"]
    if ex.recorded_outputs is not None:  # a per-trigger module: one frame per trigger message
        lines = [f"trigger messages: {ex.outputs} (recorded outputs: {ex.recorded_outputs}); frames replayed: "
                 f"{len(ex.frames)}; skipped: {len(ex.skipped)}"]
    lines.append(f"{'θ (m)' if module is None else 'θ':>8} {'reproduced':>11} {'rate':>8}")
    for th in thresholds:
        n = ex.accepted_at(th)
        lines.append(f"{th:8.2f} {n:11d} {n / ex.outputs if ex.outputs else 0:8.1%}")
    n = max(len(ex.frames), 1)
    lines.append(f"per frame: reconstruction {ex.reconstruction_seconds / n * 1e3:.3f} ms (candidate search and "
                 f"input decoding), validation {ex.validation_seconds / n * 1e3:.3f} ms, "
                 f"{'planner' if module is None else 'module'} replay {ex.planner_seconds / n * 1e3:.2f} ms")
    return "\n".join(lines)


def extract(log_path: Path, spec: Spec | Path, out_dir: Path, options: ExtractOptions) -> int:
    """DeFT module tests of the run at ``log_path`` written to ``out_dir``, with progress and a summary;
    ``spec`` as the command loaded it, or its file (read once, by the extraction).

    Returns 0 when tests were written, 1 when none could be, 130 when interrupted (Ctrl-C, SIGTERM; what was
    decided is kept for ``resume``). Raises InputError on bad input, OutputError when ``out_dir`` cannot
    be written.
    """
    from astaa_deft.analysis.deft.extract import near_miss_note, search_note
    from astaa_deft.analysis.deft.workflow import extract_module_tests

    from astaa_deft.model.sut import Spec

    threshold, module, ground_truth = options.threshold, options.module, options.ground_truth
    spec_path = (spec.path or spec.name) if isinstance(spec, Spec) else spec
    progress = CountProgress("extract", "outputs")
    try:
        with stop_as_interrupt():
            report = extract_module_tests(log_path, spec, out_dir, options, progress=progress, notice=say)
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
    entry = report.entry
    unit = " m" if entry.trajectory is not None else ""
    say(summary_table(report.extraction, module=None if entry.where == "planner" else entry.module))
    searched = search_note(report.extraction)
    if searched:
        say(searched)
    note = near_miss_note(report.extraction, unit)
    if note:
        say(note)
    if report.diagnosis is not None:
        for line in report.diagnosis.lines(str(spec_path)):
            say(line)
    if report.suite_failures:
        shown = ", ".join(f"frame {f.index} ({f.detail})" for f in report.suite_failures[:5])
        more = f" and {len(report.suite_failures) - 5} more" if len(report.suite_failures) > 5 else ""
        say(f"extraction defect: {len(report.suite_failures)} module test(s) failed when the suite ran once on the "
            f"run it came from: {shown}{more}; those frames stay in the suite for the state they build, not as "
            f"tests")
    if report.collision:
        say(f"collision observed in the run: {report.oracles} frame(s) planned into a predicted obstacle "
            f"beforehand → oracle tests that fail while the planner still does so")
    if report.ground_truth is not None:
        exact, checked = report.ground_truth
        who = "the planner's" if entry.where == "planner" else f"module '{entry.module}''s"
        say(f"ground truth ({ground_truth}): {exact}/{checked} frames used exactly {who} inputs"
            + (f" ({exact / checked:.1%})" if checked else ""))
    say(f"{report.accepted} module tests (θ = {entry.threshold:g}{unit}) written to {out_dir}; "
        f"run them with: pytest {out_dir}")
    return 0 if report.manifest else 1
