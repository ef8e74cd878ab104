"""`astaa-deft verify DIR`: a campaign's buckets against the stack as it is now (or bisected over its history).

The work is :func:`astaa_deft.orchestration.verify.workflow.verify_campaign`
(and :func:`astaa_deft.orchestration.verify.bisect.bisect_bucket`); this
command prints their lines and picks the exit code.

Exit codes: 0 every bucket verified is fixed; 1 one still fails (the same
way, another way, or flaky); 2 bad input; 3 no bucket fails but a run was
not observed to its end; 4 the campaign folder cannot take the runs.
"""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import TYPE_CHECKING

from astaa_deft.cli.arguments import PROCESSES, REPEATS, bounded
from astaa_deft.cli.commands.console import parse_params, say

if TYPE_CHECKING:
    from astaa_deft.cli.arguments import SubParsers
    from astaa_deft.orchestration.journal.checks import BucketCheck
    from astaa_deft.orchestration.verify.workflow import VerifyOptions


def add_parser(subparsers: SubParsers) -> None:
    """Declare the `verify` command."""
    ver = subparsers.add_parser("verify", help="re-check a campaign's buckets against the stack as it is now: "
                                               "fixed, still failing, changed or flaky",
                                 epilog="examples:\n  astaa-deft verify campaign/ --spec sut.yaml\n"
                                        "  astaa-deft verify campaign/ --spec sut.yaml --bucket B003 --label fixed\n"
                                        "  astaa-deft verify campaign/ --spec sut.yaml --bucket B003 "
                                        "--bisect v1.0..HEAD --build 'pip install -q .'")
    ver.add_argument("campaign", type=Path, help="a campaign directory (astaa-deft fuzz -o DIR)")
    add_spec_options(ver)
    ver.add_argument("--param", action="append", default=[], metavar="KEY=VALUE",
                     help="override a spec param of every run (as in proxy; default: the campaign's)")
    bounded(ver, "--runs", REPEATS, default=3, help="runs of each test case, and as many unmutated twins (default 3)")
    ver.add_argument("--label", help="the stack's revision (default: git describe of the spec's source: folder)")
    ver.add_argument("--bucket", action="append", default=[], metavar="B003",
                     help="check only this bucket (repeatable; default: every bucket)")
    ver.add_argument("--dictionary", type=Path, action="append", default=[],
                     help="the campaign's extra dictionaries (its test cases may name their values; "
                          "default: the bundled one only)")
    bounded(ver, "--workers", PROCESSES, help="runs at once (default: the campaign's)")
    ver.add_argument("--bisect", metavar="GOOD..BAD",
                     help="the first revision between these where the bucket starts or stops failing "
                          "(git revisions of the spec's source: checkout; needs --bucket; default: no bisection)")
    ver.add_argument("--build", metavar="CMD", help="with --bisect: a shell command run in the checkout after "
                                                   "each checkout (e.g. 'pip install -q .'; default: none)")
    ver.set_defaults(func=run)


def add_spec_options(parser: argparse.ArgumentParser) -> None:
    """``--spec`` / ``--trust-journal-spec``: what a command that re-runs a campaign's findings runs."""
    trust = parser.add_mutually_exclusive_group()
    trust.add_argument("--spec", type=Path, metavar="FILE",
                       help="the stack's SUT spec (your own copy): what the live runs and module tests run "
                            "(default: none — the spec the campaign's journal names is used only with "
                            "--trust-journal-spec)")
    trust.add_argument("--trust-journal-spec", action="store_true",
                       help="run the spec the journal names (default: without --spec, refuse and list what that "
                            "spec would run; a campaign folder is data)")


def run(args: argparse.Namespace) -> int:
    """The parsed `verify` arguments as VerifyOptions, to :func:`verify` or :func:`bisect`."""
    from astaa_deft.model.errors import InputError, Problem
    from astaa_deft.orchestration.verify.workflow import VerifyOptions

    options = VerifyOptions(campaign=args.campaign, spec=args.spec, trust_journal_spec=args.trust_journal_spec,
                            params=parse_params(args.param), runs=args.runs, label=args.label,
                            buckets=tuple(args.bucket), dictionaries=tuple(args.dictionary), workers=args.workers)
    if args.bisect is None:
        if args.build is not None:
            raise InputError(Problem("--build", None, None, "--build runs only between the steps of --bisect",
                                     "add --bisect GOOD..BAD, or drop --build"))
        return verify(options)
    good, sep, bad = args.bisect.partition("..")
    if not sep or not good or not bad:
        raise InputError(Problem("--bisect", None, None, f"'{args.bisect}' is not GOOD..BAD",
                                 "write e.g. --bisect v1.0..main"))
    if len(args.bucket) != 1:
        raise InputError(Problem("--bisect", None, None, "bisect follows one bucket",
                                 "give the bucket with --bucket B003"))
    return bisect(options, good, bad, args.build)


def verify(options: VerifyOptions) -> int:
    """Verify and print each bucket's check; the exit code (module doc)."""
    from astaa_deft.orchestration.verify.workflow import verify_campaign

    report = verify_campaign(options, say=say)
    for line in report.skipped:
        say(f"  not verified: {line}")
    fixed = sum(1 for c in report.checks if c.status == "fixed")
    say(f"verify {report.revision}: {fixed}/{len(report.checks)} bucket(s) fixed"
        + "".join(f", {n} {status}" for status, n in _counts(report.checks).items() if status != "fixed")
        + f" (runs in {report.out_dir})")
    return report.exit_code


def _counts(checks: list[BucketCheck]) -> dict[str, int]:
    out: dict[str, int] = {}
    for check in checks:
        out[str(check.status)] = out.get(str(check.status), 0) + 1
    return out


def bisect(options: VerifyOptions, good: str, bad: str, build: str | None) -> int:
    """Bisect one bucket over GOOD..BAD and print the revision found; 0 found, 1 no change found."""
    from astaa_deft.orchestration.verify.bisect import bisect_bucket

    result = bisect_bucket(options, good, bad, build, say=say)
    say(result.describe())
    return 0 if result.first is not None else 1
