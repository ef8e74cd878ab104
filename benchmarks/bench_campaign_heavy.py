"""A default campaign on a heavy third-party stack: what a new user gets from `astaa-deft fuzz` there.

    python benchmarks/bench_campaign_heavy.py [--quick] [--budget 20m] [--keep DIR] [--workers K]

Runs the real command as a user would — ``astaa-deft fuzz --spec
examples/ompl_stack/spec.yaml -o DIR --budget 20m --params iterations=900
reuse=0 defects=1`` (the CPU-heavy OMPL planner, ~0.5–0.6 s a cycle, with its
three known defects on: examples/ompl_stack/README.md), every other option
at its default — and reads its journal. Prints:

* the workers the campaign chose, and the cores and load average;
* cases run (baseline, generated, re-runs, errors);
* buckets by kind: confirmed, unconfirmed, flaky, without mutation (the
  campaign's own standing, ``campaign/standing.py``), and *false* — a bucket
  that matches no known defect and never reproduced;
* each known defect: found (its bucket), minimised (to a culprit on the
  defect's field), and whether the bucket's module tests fail on it;
* every bucket: status, severity, verdict, invariant, family, defect,
  culprit, module tests.

``--quick``: a 4-minute budget. Minimisation runs after the hunt and can
take minutes a bucket: the whole command is stopped (SIGINT, as Ctrl-C)
after ``--wall`` seconds (default: 3 × the budget) and what the journal
holds then is reported, stopped campaign or not. Asserts nothing (the
figures depend on the machine and its load).
"""

from __future__ import annotations

import argparse
import os
import re
import shutil
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from astaa_deft.orchestration.journal.journal import Bucket, Journal
from astaa_deft.orchestration.campaign.standing import CONFIRMED, standings
from astaa_deft.cli.commands.fuzz import parse_budget

ROOT = Path(__file__).resolve().parent.parent
SPEC = ROOT / "examples" / "ompl_stack" / "spec.yaml"
PARAMS = ["iterations=900", "reuse=0", "defects=1"]

# Known defect → (what it is, how its bucket shows it, the culprit family a minimisation should reach).
DEFECTS = {
    1: "held corrupt obstacle size → planner aborts",
    2: "non-finite ego heading → planner exception",
    3: "ego stamp jump back → empty plan",
}
OBSTACLE_SIZE = re.compile(r"obstacles:obstacles\[\*?\]\.(length|width)")
HEADING = re.compile(r"ego:heading")
STAMP_BACK = re.compile(r"ego:(\*:(reorder|delay)|header\.stamp)")


def defect_of(bucket: Bucket) -> int | None:
    """Which known defect a bucket is (None: none), from its verdict, invariant, module and mutation family."""
    family = bucket.family
    if bucket.verdict == "Abort" and bucket.module == "planning" and OBSTACLE_SIZE.search(family):
        return 1
    if bucket.invariant == "planner_errors" and HEADING.search(family):
        return 2
    if bucket.invariant == "plan_not_empty" and STAMP_BACK.search(family):
        return 3
    return None


def culprit_reaches(defect: int, culprit: str | None) -> bool:
    """Whether a minimised culprit is on the defect's own field or message fault."""
    if not culprit:
        return False
    folded = re.sub(r"\[\d+\]", "[]", culprit)
    return {1: bool(OBSTACLE_SIZE.search(folded)), 2: "ego:heading" in folded,
            3: bool(re.search(r"ego:(reorder|delay|header\.stamp)", folded))}[defect]


def run_fuzz(out: Path, budget: str, wall: float, workers: int | None) -> tuple[str, float, bool]:
    """The command's output, its wall seconds, and whether it had to be stopped at ``wall``.

    The command runs in a process group of its own, its output to a file (a
    process it leaves behind must not hold a pipe open); what is left of
    that group once it has exited is stopped.
    """
    args = [sys.executable, "-m", "astaa_deft.cli", "fuzz", "--spec", str(SPEC), "-o", str(out), "--budget", budget,
            "--params", *PARAMS]
    if workers:
        args += ["--workers", str(workers)]
    out.parent.mkdir(parents=True, exist_ok=True)
    log = out.parent / f"{out.name}.fuzz.txt"
    started = time.monotonic()
    with open(log, "w") as sink:
        proc = subprocess.Popen(args, stdout=sink, stderr=subprocess.STDOUT, text=True, start_new_session=True)
        stopped = False
        try:
            proc.wait(timeout=wall)
        except subprocess.TimeoutExpired:
            stopped = True
            proc.send_signal(signal.SIGINT)  # as Ctrl-C: the campaign stops cleanly, its journal intact
            try:
                proc.wait(timeout=120)
            except subprocess.TimeoutExpired:
                proc.kill()
                proc.wait()
    try:
        os.killpg(proc.pid, signal.SIGTERM)  # the group is the command's own: anything it left running
        print("note: processes of the command were still running after it exited (stopped)")
    except ProcessLookupError:
        pass
    return log.read_text(), time.monotonic() - started, stopped


def report(out: Path, output: str, seconds: float, stopped: bool) -> None:
    journal = Journal(out)
    notes = [n.text for n in journal.notes("concurrency")]
    print(f"runs at once: {journal.meta().workers or '?'} (the campaign's own choice) on {os.cpu_count()} cores;"
          f" load average at the end {os.getloadavg()[0]:.1f}; wall {seconds:.0f} s"
          f"{' (stopped at the wall limit: minimisation unfinished)' if stopped else ''}")
    for text in notes:
        print(f"  {text}")
    try:
        counts = journal.counts()
        kinds = {kind: sum(n for k, n in counts.items() if k.startswith(kind + ":")) for kind in
                 ("baseline", "mutated", "rerun")}
        errors = sum(n for k, n in counts.items() if k.endswith(":error"))
        print(f"cases: {kinds['baseline']} baseline, {kinds['mutated']} generated, {kinds['rerun']} re-runs"
              f" ({errors} could not run)")
        ranked = standings(journal)
        minimised = journal.minimisations()
        tests = journal.module_tests()
        by_status: dict[str, int] = {}
        for s in ranked:
            by_status[s.status] = by_status.get(s.status, 0) + 1
        false = [s for s in ranked if defect_of(s.bucket) is None and s.failures == 0]
        merged = len(journal.buckets()) - len(ranked)
        print("buckets: " + ", ".join(f"{n} {status}" for status, n in by_status.items())
              + f"; {len(false)} false (no known defect, never reproduced); {merged} merged")
        for defect, what in DEFECTS.items():
            mine = [s for s in ranked if defect_of(s.bucket) == defect]
            found = ", ".join(f"{s.bucket.bucket} ({s.status})" for s in mine) or "not found"
            reached = [s.bucket.bucket for s in mine
                       if (m := minimised.get(s.bucket.bucket)) is not None and m.exit_code == 0
                       and culprit_reaches(defect, m.culprit)]
            failing = [s.bucket.bucket for s in mine if (t := tests.get(s.bucket.bucket)) is not None
                       and t.fails_on_defect is True]
            print(f"known defect {defect} ({what}): {found}; minimised to it: {', '.join(reached) or 'no'};"
                  f" module tests fail on it: {', '.join(failing) or 'no'}")
        print(f"{'bucket':7} {'status':16} {'severity':8} {'verdict':9} {'invariant':22} {'defect':6} family"
              " | culprit | module tests")
        for s in ranked:
            b = s.bucket
            m = minimised.get(b.bucket)
            t = tests.get(b.bucket)
            culprit = (m.culprit or m.status) if m is not None else "not minimised"
            verdict = ("-" if t is None else "fail on the defect" if t.fails_on_defect is True
                       else "do NOT fail on the defect" if t.fails_on_defect is False else "could not run")
            defect = defect_of(b)
            print(f"{b.bucket:7} {s.status:16} {s.severity:8} {b.verdict:9} {b.invariant:22}"
                  f" {str(defect) if defect else '—':6} {b.family} | {culprit} | {verdict}"
                  f"{'' if s.status == CONFIRMED else f' [{s.why}]'}")
    finally:
        journal.close()


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--quick", action="store_true", help="a 4-minute budget")
    ap.add_argument("--budget", help="the campaign's --budget (default 20m; --quick: 4m)")
    ap.add_argument("--wall", type=float, help="stop the whole command after this many seconds (default 3 × budget)")
    ap.add_argument("--workers", type=int, help="--workers for the campaign (default: the campaign's own choice)")
    ap.add_argument("--keep", type=Path, help="keep the campaign here (default: a temp dir, removed)")
    a = ap.parse_args()
    budget = a.budget or ("4m" if a.quick else "20m")
    wall = a.wall or 3 * parse_budget(budget)
    out = a.keep or Path(tempfile.mkdtemp(prefix="bench_heavy_")) / "campaign"
    print(f"astaa-deft fuzz --spec {SPEC.relative_to(ROOT)} -o {out} --budget {budget} --params {' '.join(PARAMS)}"
          f"{f' --workers {a.workers}' if a.workers else ''}  (wall limit {wall:.0f} s)")
    output, seconds, stopped = run_fuzz(out, budget, wall, a.workers)
    tail = [line for line in output.splitlines() if line.startswith(("campaign ", "most severe", "report:"))]
    print("\n".join(tail) or output[-2000:])
    report(out, output, seconds, stopped)
    if a.keep is None:
        shutil.rmtree(out.parent, ignore_errors=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
