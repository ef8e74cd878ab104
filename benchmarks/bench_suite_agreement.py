"""The extraction's own check of its suite against pytest, on the OMPL stack, under load: how often they disagree.

    python benchmarks/bench_suite_agreement.py [--runs 200] [--loops 2] [--log FILE] [--keep DIR]

Records one clean run of examples/ompl_stack through the star (or takes
``--log``), then ``--runs`` times, with ``--loops`` CPU-bound processes
spinning beside it: extracts the planner's module tests from that log (the
extraction checks the suite it writes and says how many tests it asserts),
then runs the written suite with plain pytest in a fresh process, as a user
would. A disagreement is a run where pytest's result is not the tool's: a
test failing or erroring, or a count of passed tests other than the tests
the extraction said it wrote. Prints one line per run (tests written, pytest's
last line, seconds, load) and the count of disagreements; exit code 1 when
there was one. Asserts nothing of the times.
"""

from __future__ import annotations

import argparse
import os
import signal
import re
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from astaa_deft.analysis.deft.workflow import ExtractOptions, extract_module_tests
from bench_third_party import SPEC, drive  # this folder is on sys.path when a benchmark runs

# A loop ignores Ctrl-C (the terminal sends it to the whole group): this script stops it by its pid on the way out.
LOOP = "import signal\nsignal.signal(signal.SIGINT, signal.SIG_IGN)\nwhile True: pass"


def record(tmp: Path, goal_x: str) -> Path:
    """One clean run of the OMPL stack through the star, recorded (bench_third_party's run, no parked car)."""
    log, truth, _ = drive(tmp, "clean", 0, goal_x)
    if truth.get("code") != 0:
        sys.exit(f"the clean run did not pass as the simulator says: {truth}")
    return log


def pytest_counts(suite: Path) -> tuple[int, int, str]:
    """(passed, failed or errored, pytest's last line) of plain pytest on the written suite, a fresh process."""
    env = {k: v for k, v in os.environ.items() if k != "PYTHONPATH"}
    res = subprocess.run([sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider",
                          str(suite)], capture_output=True, text=True, timeout=600, cwd=suite.parent, env=env)
    last = next((line for line in reversed(res.stdout.splitlines()) if line.strip()), res.stderr[-200:])
    passed = sum(int(n) for n in re.findall(r"(\d+) passed", last))
    bad = sum(int(n) for n in re.findall(r"(\d+) (?:failed|error)", last))
    if res.returncode != 0 and bad == 0:
        bad = 1  # pytest could not run the suite at all
    return passed, bad, last


def main() -> None:
    # SIGTERM ends the run as Ctrl-C does: the loops this script started are stopped on the way out.
    signal.signal(signal.SIGTERM, lambda *_: sys.exit(143))
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--runs", type=int, default=200, help="extractions, each checked by pytest (default 200)")
    ap.add_argument("--loops", type=int, default=2, help="CPU-bound loops beside the runs (default 2)")
    ap.add_argument("--log", type=Path, help="a recorded clean run of the OMPL stack (default: record one)")
    ap.add_argument("--goal-x", default="35", help="the recorded run's goal, m (default 35)")
    ap.add_argument("--keep", type=Path, help="keep the work folder here")
    args = ap.parse_args()
    tmp = Path(tempfile.mkdtemp(prefix="suite_agreement_"))
    spinners: list[subprocess.Popen] = []
    disagreements = 0
    try:
        log = args.log or record(tmp, args.goal_x)
        spinners = [subprocess.Popen([sys.executable, "-c", LOOP]) for _ in range(args.loops)]
        for run in range(1, args.runs + 1):
            out = tmp / f"suite_{run}"
            started, load = time.monotonic(), os.getloadavg()[0]
            report = extract_module_tests(log, SPEC, out, ExtractOptions(jobs=2))
            passed, bad, last = pytest_counts(out)
            agree = bad == 0 and passed == report.accepted + report.oracles
            disagreements += not agree
            print(f"run {run}: wrote {report.accepted} (+{report.oracles} oracle), unchecked "
                  f"{len(report.suite_failures)}; pytest: {last} — {time.monotonic() - started:.1f} s, "
                  f"load {load:.1f}{'' if agree else '  DISAGREE'}", flush=True)
            if agree:
                shutil.rmtree(out, ignore_errors=True)  # keep only the suites that disagreed
    finally:
        for spinner in spinners:  # ours only, by their pids
            spinner.kill()
            spinner.wait()
        if args.keep:
            shutil.copytree(tmp, args.keep, dirs_exist_ok=True)
        shutil.rmtree(tmp, ignore_errors=True)
    print(f"{args.runs} extraction(s) with {args.loops} CPU-bound loop(s) beside: {disagreements} disagreement(s) "
          f"between the extraction's check and pytest")
    sys.exit(1 if disagreements else 0)


if __name__ == "__main__":
    try:
        main()
    except KeyboardInterrupt:  # Ctrl-C: the loops are stopped on the way out; no traceback
        sys.exit(130)
