"""`astaa-deft minimise RUN.mcap --spec SUT.yaml [--invariant NAME] -o DIR`: the few mutations that cause a failure.

The work is :func:`astaa_deft.analysis.minimise.workflow.minimise_log`; this command
prints its progress and its report and picks the exit code.

Exit codes: 0 minimised and reproduced; 1 a finding without a clean
minimal reproduction (the failure does not reproduce, is flaky, or does not
need the mutations), with the report; 2 bad input (InputError).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import TYPE_CHECKING

from astaa_deft.cli.arguments import CASES, PROCESSES, REPEATS, RERUNS, bounded
from astaa_deft.cli.commands.console import PlainLines, say as print_line

if TYPE_CHECKING:
    from astaa_deft.analysis.minimise.workflow import MinimiseOptions
    from astaa_deft.cli.arguments import SubParsers


def add_parser(subparsers: SubParsers) -> None:
    """Declare the `minimise` command (alias `minimize`)."""
    mini = subparsers.add_parser("minimise", aliases=["minimize"],
                                 help="delta-debug a failing intercepted run down to the mutations, frames and "
                                      "fields that cause it",
                                 epilog="example:\n  astaa-deft minimise astaa-deft-demo/intercepted.mcap "
                                        "--spec specs/demo_av.yaml -o minimised/")
    mini.add_argument("log", type=Path, help="a log recorded by astaa-deft proxy --policy …")
    trust = mini.add_mutually_exclusive_group()
    trust.add_argument("--spec", type=Path, help="the SUT spec (default: none; the one stored in the log "
                                                 "runs only with --trust-log-spec)")
    trust.add_argument("--trust-log-spec", action="store_true",
                       help="run the module commands and replay factories the spec stored in the log names "
                            "(default: off — minimise lists them and stops: a log is data)")
    mini.add_argument("--invariant", help="the failure to keep (default: the run's first violation the mutations "
                                           "cause: one that happens without any of them gives way to the next "
                                           "invariant broken, up to 3 tried)")
    mini.add_argument("-o", "--out", type=Path, required=True, help="directory for the minimised test case and tests")
    bounded(mini, "--repeats", REPEATS, default=1, help="whole-SUT re-runs per test when no replay applies")
    bounded(mini, "--parallel", PROCESSES, default=2, help="tests run at once where the replay allows")
    mini.add_argument("--live-only", action="store_true", help="always re-run the whole SUT (default: a module "
                                                               "replay where the spec allows)")
    bounded(mini, "--confirm", RERUNS, default=3, help="live re-runs of the final result, to report its rate")
    bounded(mini, "--max-tests", CASES, help="stop after this many tests and keep the smallest failure "
                                             "(default: no limit)")
    mini.add_argument("--no-live-fallback", action="store_true",
                      help="when the planner replay does not reproduce the failure, stop (exit 1) "
                           "instead of re-running the SUT (default: fall back to live runs)")
    bounded(mini, "--jobs", PROCESSES, default=1,
            help="whole-system runs at once (live tests, confirmations), each an isolated session")
    mini.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """The parsed `minimise` arguments as MinimiseOptions, to :func:`minimise`."""
    from astaa_deft.analysis.minimise.workflow import MinimiseOptions

    return minimise(args.log, args.out, MinimiseOptions(
        spec_path=args.spec, invariant=args.invariant, repeats=args.repeats, parallel=args.parallel,
        live_only=args.live_only, confirm=args.confirm, max_tests=args.max_tests,
        live_fallback=not args.no_live_fallback, jobs=args.jobs, trust_log_spec=args.trust_log_spec))


def minimise(log_path: Path, out_dir: Path, options: MinimiseOptions, *, verbose: bool = True) -> int:
    """Minimise the failure recorded at ``log_path`` into ``out_dir``, printing progress and the report.

    ``verbose`` False prints only the report (and, off a terminal, the periodic progress lines). Returns
    the exit code the module docstring lists; raises InputError on bad input, OutputError when ``out_dir``
    cannot be written.
    """
    from astaa_deft.analysis.minimise.workflow import minimise_log

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
