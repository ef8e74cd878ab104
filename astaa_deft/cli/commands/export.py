"""`astaa-deft export DIR -o regress/`: a campaign's confirmed bugs as a pytest suite for the stack's CI.

The work is :func:`astaa_deft.orchestration.verify.export.export_suite`; this
command prints what it wrote. Exit codes: 0 written, 2 bad input, 4 the
output cannot be written.
"""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import TYPE_CHECKING

from astaa_deft.cli.commands.console import say

if TYPE_CHECKING:
    from astaa_deft.cli.arguments import SubParsers


def add_parser(subparsers: SubParsers) -> None:
    """Declare the `export` command."""
    exp = subparsers.add_parser("export", help="a campaign's confirmed bugs as a pytest regression suite "
                                               "(module tests and live tests) for the stack's own CI")
    exp.add_argument("campaign", type=Path, help="a campaign directory (astaa-deft fuzz -o DIR)")
    exp.add_argument("-o", "--out", type=Path, required=True, help="the suite's folder (e.g. regress/)")
    exp.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """The parsed `export` arguments to :func:`export`."""
    return export(args.campaign, args.out)


def export(campaign: Path, out: Path) -> int:
    """Export and print the suite's tests; exit code 0."""
    from astaa_deft.orchestration.verify.export import export_suite

    report = export_suite(campaign, out)
    for b in report.buckets:
        say(f"  {b.bucket}: test_live.py::test_{b.name}" + (f", module/{b.name}/ (module tests)"
                                                             if b.module_tests else ""))
    for line in report.skipped:
        say(f"  not exported: {line}")
    say(f"regression suite: {report.out} ({len(report.buckets)} bucket(s)): pytest {report.out}"
        f" [-m module | -m live] [--param KEY=VALUE]")
    return 0
