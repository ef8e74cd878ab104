"""`astaa-deft check RUN.mcap [--spec SUT.yaml]`: the spec's invariants over a recorded run.

Exit codes: 0 the run passes (CRASH class Pass), 1 it does not (a violation
or a module exit), 2 bad input (raised as InputError, printed by the CLI).
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

from ..errors import InputError, Problem
from ..log import records as rec
from ..log.reader import read_log
from ..monitor import check_log, format_verdict, format_violation, with_typed_invariants
from ..monitor.offline import CheckResult, spec_from_log
from ..spec.model import Spec


def run(log_path: Path, spec_path: Path | None = None, as_json: bool = False) -> int:
    log = read_log(log_path)
    spec: Spec | None
    if spec_path is not None:
        from ..spec.loader import load_spec

        spec = load_spec(spec_path)
    else:
        spec = spec_from_log(log, f"{log_path}:spec.yaml")
        if spec is None:
            raise InputError(Problem(str(log_path), None, None, "the log holds no spec to check it against",
                                     "give the SUT spec with --spec sut.yaml"))
    spec = with_typed_invariants(spec)
    result = check_log(log, spec)
    if as_json:
        print(json.dumps(_as_json(result), default=str))
    else:
        _print(result, log_path, spec_path, len(spec.invariants))
    for warning in result.warnings:
        print(f"warning: {warning}", file=sys.stderr)
    return 0 if result.passed else 1


def _print(result: CheckResult, log_path: Path, spec_path: Path | None, invariants: int) -> None:
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
    print(format_verdict(result.verdict, result.start_ns))
    if result.online_verdict is not None:
        online = result.online_verdict.klass
        agreement = "agrees" if online == result.verdict.klass else "DIFFERS from this check"
        print(f"online verdict recorded during the run: {online} ({agreement})")


def _as_json(result: CheckResult) -> dict:
    return {
        "verdict": result.verdict.to_json(),
        "violations": [v.to_json() for v in result.violations],
        "stats": result.stats,
        "messages": result.messages,
        "seconds": result.seconds,
        "start_ns": result.start_ns,
        "end_ns": result.end_ns,
        "online_verdict": rec.encode(result.online_verdict) if result.online_verdict is not None else None,
    }
