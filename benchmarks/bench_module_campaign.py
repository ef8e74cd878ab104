"""Module-level cases per core-hour against live cases, on the same stack in the same campaign.

    python benchmarks/bench_module_campaign.py [--spec specs/demo_av.yaml] [--budget 300] [--module-seconds S]
                                               [--params k=v ...] [--keep DIR]

Runs ``astaa-deft fuzz`` as a user would (defaults; the module-level search on,
its share of the budget decided by measurement unless ``--module-seconds``), then reads
the campaign's journal and its module-level state and prints, per level
(module / live): cases run, CPU seconds, cases per core-hour, findings,
confirmations, time to first find — and the ratio of the two rates. Every
module-level finding is listed with where it stands (confirmed live, module-level
only, not yet run) and the fields left out of live generation.

Prints; asserts nothing.
"""

from __future__ import annotations

import argparse
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent


def main() -> int:
    ap = argparse.ArgumentParser()
    ap.add_argument("--spec", type=Path, default=ROOT / "specs" / "demo_av.yaml")
    ap.add_argument("--budget", type=float, default=300.0, help="seconds of the whole campaign")
    ap.add_argument("--module-seconds", type=float, default=None)
    ap.add_argument("--params", nargs="*", default=[])
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--keep", type=Path, default=None, help="the campaign directory (default: a temporary one)")
    args = ap.parse_args()
    from astaa_deft.orchestration.journal.journal import open_existing
    from astaa_deft.orchestration.campaign.module_level import finding_standing, level_figures, read_state

    with tempfile.TemporaryDirectory(prefix="bench-module-") as tmp:
        out = args.keep or Path(tmp) / "campaign"
        argv = [sys.executable, "-m", "astaa_deft.cli", "fuzz", "--spec", str(args.spec), "-o", str(out),
                "--budget", f"{args.budget:g}s", "--seed", str(args.seed), "--no-minimise"]
        if args.module_seconds is not None:
            argv += ["--module-level-seconds", f"{args.module_seconds:g}"]
        if args.params:
            argv += ["--params", *args.params]
        started = time.monotonic()
        done = subprocess.run(argv, capture_output=True, text=True)
        wall = time.monotonic() - started
        print(f"fuzz {args.spec.name} --budget {args.budget:g}s: exit {done.returncode} in {wall:.0f} s")
        if done.returncode not in (0, 1) or not (out / "journal.sqlite").is_file():
            print(done.stderr[-2000:])
            return 1
        journal = open_existing(out)
        state = read_state(out)
        if state is None:
            print("no module-level search ran (no module of the spec can be replayed in process)")
            return 0
        module, live = level_figures(state, journal)
        for level in (module, live):
            rate = f"{level.per_core_hour:,.0f}" if level.per_core_hour else "—"
            first = f"{level.first_find:.1f} s" if level.first_find is not None else "—"
            print(f"{level.level:13} cases {level.cases:6}  CPU {level.core_seconds:8.1f} s  per core-hour {rate:>10}"
                  f"  findings {level.findings:3}  confirmed {level.confirmed:3}  first find {first}")
        if module.per_core_hour and live.per_core_hour:
            print(f"module level / live, cases per core-hour: {module.per_core_hour / live.per_core_hour:,.1f}×")
        print(f"modules replayed: {', '.join(state.modules) or '—'}; not: {'; '.join(state.skipped) or '—'}")
        print(f"fields left out of live generation: {len(state.unread)}"
              + (f" ({', '.join(f'{c}:{p}' for c, p in state.unread)})" if state.unread else ""))
        for finding in state.findings:
            v = finding.verdict
            print(f"  {finding.name} {v.module}: {v.signature} — {v.fault.describe()} after {finding.found_after:.2f} s"
                  f" of replay: {finding_standing(finding, journal)}; module test fails on it: {finding.tests_fail}")
        journal.close()
    return 0


if __name__ == "__main__":
    sys.exit(main())
