"""`astaa-deft check RUN.mcap [--spec SUT.yaml]`: the spec's invariants over a recorded run.

Exit codes: 0 the run passes (CRASH class Pass), 1 it does not (a violation
or a module exit), 2 bad input (raised as InputError, printed by the CLI) —
including a log that is damaged, stops early or holds nothing readable: a
record that was not fully read cannot support a Pass, and findings next to
damage may come from the damage rather than the SUT, so no verdict is given.
A log that merely stops early (a killed writer) still reports its findings
with exit 1: what was read is intact. A log whose recorder outlived its tool
(the tool killed mid-run: a ``run_end`` event says "tool lost") reports its
findings with exit 1 but withholds a Pass: exit 3, the run was not fully observed. So does a run
some message of which no monitor reading it could read (a payload that does not decode, on a channel
a collision, temporal or process monitor reads) or whose monitor failed and was switched off. The work is
:func:`astaa_deft.engine.session.check.check_recorded_run`; this prints its result.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from typing import TYPE_CHECKING

from astaa_deft.model.errors import InputError, Problem
from astaa_deft.io.log import layout
from astaa_deft.io.log import records as rec

if TYPE_CHECKING:
    from astaa_deft.cli.arguments import SubParsers
    from astaa_deft.engine.monitor.offline import CheckResult
    from astaa_deft.io.log.reader import LogContents

EXIT_NOT_OBSERVED = 3  # as `proxy`: the run was not observed to its end, no Pass can be given


def add_parser(subparsers: SubParsers) -> None:
    """Declare the `check` command."""
    chk = subparsers.add_parser("check", help="evaluate the spec's invariants over a recorded log (exit 1 on a "
                                              "finding)",
                                epilog="examples:\n  astaa-deft check run.mcap\n"
                                       "  astaa-deft check run.mcap --spec specs/demo_av.yaml --json")
    chk.add_argument("log", type=Path, help="the MCAP test log")
    chk.add_argument("--spec", type=Path, help="the SUT spec (default: the one stored in the log)")
    chk.add_argument("--json", action="store_true", help="print the result as one JSON object (default: text)")
    chk.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """The parsed `check` arguments to :func:`check_log`."""
    return check_log(args.log, args.spec, as_json=args.json)


def check_log(log_path: Path, spec_path: Path | None = None, *, as_json: bool = False) -> int:
    """Judge the recorded run at ``log_path`` against the spec (None: the one in the log), print the result
    (as one JSON object with ``as_json``) and return the exit code the module docstring lists."""
    from astaa_deft.engine.session.check import check_recorded_run

    checked = check_recorded_run(log_path, spec_path)
    result, log = checked.result, checked.log
    tool_lost = any(e.reason == layout.TOOL_LOST for e in log.records(rec.RunEnd))
    if as_json:
        print(json.dumps(_as_json(result, log, tool_lost), default=str))
    else:
        _print(result, log_path, spec_path, len(checked.spec.invariants),
               show_pass=log.intact and not tool_lost and not result.unjudged)
    for warning in result.warnings:
        print(f"warning: {warning}", file=sys.stderr)
    if log.intact and tool_lost and result.passed:
        if not as_json:
            print("verdict withheld: the tool was lost mid-run (killed), so the run was not observed to its end "
                  "and cannot Pass")
        return EXIT_NOT_OBSERVED
    if log.intact and result.unjudged and result.passed:  # a Pass over messages no monitor could read
        if not as_json:
            print(f"verdict withheld: not every message was judged ({result.unjudged}), so the run cannot Pass")
        return EXIT_NOT_OBSERVED
    if log.intact:
        return 0 if result.passed else 1
    if log.truncated and len(log.damage) == 1 and not result.passed:
        return 1  # every finding comes from complete chunks before the cut
    if not as_json:
        print(_withheld(log, result))
    raise InputError(Problem(str(log_path), None, None,
                             "no verdict: the log is " + ("incomplete" if log.truncated else "damaged")
                             + f" ({log.describe_reading()})",
                             "re-record the run, or read what survives with: astaa-deft log info"))


def _withheld(log: LogContents, result: CheckResult) -> str:
    what = "stops early" if log.truncated and len(log.damage) == 1 else "is damaged"
    if result.passed:
        return f"verdict withheld: the log {what}, so the run was not fully observed and cannot Pass"
    return (f"verdict withheld: the log {what}; the findings above were made on what could be read and may come "
            f"from the damage rather than the system under test")


def _print(result: CheckResult, log_path: Path, spec_path: Path | None, invariants: int, *, show_pass: bool) -> None:
    from astaa_deft.engine.monitor import format_verdict, format_violation

    against = str(spec_path) if spec_path else "the spec stored in the log"
    rate = result.messages / result.seconds if result.seconds > 0 else 0.0
    print(f"check: {log_path} against {against}: {invariants} invariant{'s' if invariants != 1 else ''}, "
          f"{result.messages} messages judged in {result.seconds:.2f} s ({rate:,.0f}/s)")
    if not invariants:
        print("   (no invariants declared: only module exits are judged)")
    for violation in result.violations:
        print(format_violation(violation, result.start_ns))
    if result.stats:
        print()
        width = max(len(name) for name in result.stats)
        print(f"{'invariant':{width}}  {'judged':>8}  {'broken':>8}")
        for name, counts in result.stats.items():
            print(f"{name:{width}}  {counts['evaluations']:8d}  {counts['violating']:8d}")
    print()
    if show_pass or not result.passed:
        print(format_verdict(result.verdict, result.start_ns))
    if result.online_verdict is not None:
        online = result.online_verdict.klass
        agreement = "agrees" if online == result.verdict.klass else "DIFFERS from this check"
        print(f"online verdict recorded during the run: {online} ({agreement})")


def _as_json(result: CheckResult, log: LogContents, tool_lost: bool = False) -> dict[str, object]:
    return {
        "verdict": result.verdict.to_json() if (log.intact and not tool_lost and not result.unjudged)
        or not result.passed else None,
        "unjudged": result.unjudged,
        "violations": [v.to_json() for v in result.violations],
        "stats": result.stats,
        "messages": result.messages,
        "seconds": result.seconds,
        "start_ns": result.start_ns,
        "end_ns": result.end_ns,
        "online_verdict": rec.encode(result.online_verdict) if result.online_verdict is not None else None,
        "log": {"intact": log.intact, "truncated": log.truncated, "damage": log.damage,
                "read": log.describe_reading()},
    }
