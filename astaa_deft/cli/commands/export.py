"""`astaa-deft export DIR -o regress/`: a campaign's confirmed bugs as a pytest suite for the stack's CI.

The work is :func:`astaa_deft.orchestration.verify.export.export_suite`; this
command prints what it wrote. Exit codes: 0 written (and, checked, every
test fails on the campaign's stack), 1 a checked test passes there, 2 bad
input, 4 the output cannot be written.
"""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import TYPE_CHECKING

from astaa_deft.cli.commands.console import say
from astaa_deft.cli.commands.verify import add_spec_options

if TYPE_CHECKING:
    from astaa_deft.cli.arguments import SubParsers


def add_parser(subparsers: SubParsers) -> None:
    """Declare the `export` command."""
    exp = subparsers.add_parser("export", help="a campaign's confirmed bugs as a pytest regression suite "
                                               "(module tests and live tests) for the stack's own CI",
                                 epilog="examples:\n  astaa-deft export campaign/ --spec sut.yaml -o regress/\n"
                                        "  pytest regress/ -m module")
    exp.add_argument("campaign", type=Path, help="a campaign directory (astaa-deft fuzz -o DIR)")
    exp.add_argument("-o", "--out", type=Path, required=True, help="the suite's folder (e.g. regress/)")
    add_spec_options(exp)
    exp.add_argument("--check", choices=("module", "all", "none"), default="module",
                     help="run the suite once on the campaign's stack (its params) and say whether each test fails"
                          " there as it should: the fast module set (default), all (live runs too), or none")
    exp.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """The parsed `export` arguments to :func:`export`."""
    return export(args.campaign, args.out, args.check, spec=args.spec, trust_journal_spec=args.trust_journal_spec)


def export(campaign: Path, out: Path, check: str = "module", *, spec: Path | None = None,
           trust_journal_spec: bool = False) -> int:
    """Export and print the suite's tests, then check them (``check``: module, all, none); exit code 0, or 1
    when a checked test passes on the stack the campaign ran (it would not catch its bug) or errors there."""
    from astaa_deft.orchestration.verify.export import check_suite, export_suite

    report = export_suite(campaign, out, spec=spec, trust_journal_spec=trust_journal_spec)
    for b in report.buckets:
        say(f"  {b.bucket}: test_live.py::test_{b.name}" + (f", module/{b.name}/ (module tests)"
                                                             if b.module_tests else ""))
    for line in report.skipped:
        say(f"  not exported: {line}")
    say(f"regression suite: {report.out} ({len(report.buckets)} bucket(s)): pytest {report.out}"
        f" [-m module | -m live] [--param KEY=VALUE]")
    if check == "none" or not report.buckets:
        return 0
    if check == "module" and not any(b.module_tests for b in report.buckets):
        say("no module tests to check (no bucket has any): --check all runs the live tests on the campaign's stack")
        return 0
    checked = check_suite(report.out, "module" if check == "module" else "")
    what = "its module tests" if check == "module" else "every test"
    if checked.holds:
        say(f"checked {what} on the campaign's stack: {len(checked.failed)} fail there, as they should"
            f" ({checked.detail})")
        return 0
    for test in checked.passed:
        say(f"  PASSES on the campaign's stack (would not catch its bug): {test}")
    for test in checked.errors:
        say(f"  ERRORS on the campaign's stack (it did not run to a verdict): {test}")
    say(f"checked {what} on the campaign's stack: {len(checked.failed)} fail, {len(checked.passed)} pass, "
        f"{len(checked.errors)} error(s) there ({checked.detail})")
    return 1
