"""`astaa-deft minimise RUN.mcap --spec SUT.yaml [--invariant NAME] -o DIR`: the few mutations that cause a failure.

The work is :func:`astaa_deft.analysis.minimise.workflow.minimise_log`; this command
prints its progress and its report and picks the exit code.

Exit codes: 0 minimised and reproduced; 1 a finding without a clean
minimal reproduction (the failure does not reproduce, is flaky, or does not
need the mutations), with the report; 2 bad input (InputError).
"""

from __future__ import annotations

import sys
from pathlib import Path

from astaa_deft.analysis.minimise.workflow import MinimiseOptions, minimise_log
from astaa_deft.cli.commands.console import PlainLines, say as print_line


def run(log_path: Path, spec_path: Path | None, invariant: str | None, out_dir: Path, repeats: int = 1,
        parallel: int = 2, live_only: bool = False, *, confirm: int = 3, max_tests: int | None = None,
        live_fallback: bool = True, verbose: bool = True, jobs: int = 1, trust_log_spec: bool = False) -> int:
    options = MinimiseOptions(spec_path, invariant, repeats, parallel, live_only, confirm, max_tests, live_fallback,
                              jobs, trust_log_spec)
    # Not on a terminal (a CI log, a pipe): the latest step every few seconds on stderr too, a live test included.
    lines = None if sys.stderr.isatty() else PlainLines("minimise")

    def say(line: str) -> None:
        if verbose:
            print_line(line)
        if lines is not None:
            lines.show(line.strip().removeprefix("minimise: "))  # the label says it

    try:
        report = minimise_log(log_path, out_dir, options, progress=say)
    finally:
        if lines is not None:
            lines.close()
    print_line(report.text())
    return 0 if report.reproduced else 1
