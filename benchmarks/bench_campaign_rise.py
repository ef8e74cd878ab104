"""Runs at once follow the machine: a campaign started beside other CPU load raises its concurrency once the load
ends.

    python benchmarks/bench_campaign_rise.py [--quick] [--budget S] [--burners N] [--keep DIR]

Starts N CPU-load processes (``python -c "while True: pass"``, stopped by their pids), then the real command a
user runs — ``astaa-deft fuzz --spec specs/demo_av.yaml -o DIR --budget S --no-minimise``, runs at once
calibrated (the default) — and stops the load processes halfway through the budget. Prints, from the journal,
every decision about runs at once (topic ``concurrency``) with its time relative to the end of the load, the
runs at once the finished cases saw, and how long after the load ended the runs at once first rose.
Asserts nothing: the figures depend on the machine and whatever else runs on it (the one-minute load average
counts every process, not only ours).
"""

from __future__ import annotations

import argparse
import os
import re
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from astaa_deft.orchestration.journal.journal import Journal  # noqa: E402


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="a 5-minute budget, one load process")
    ap.add_argument("--budget", type=float, default=600.0, help="seconds (default 600)")
    ap.add_argument("--burners", type=int, default=None, help="CPU-load processes (default: the cores)")
    ap.add_argument("--keep", type=Path, default=None, help="campaign directory to keep (default: a temporary one)")
    args = ap.parse_args()
    budget = 300.0 if args.quick else args.budget
    burners = args.burners or (1 if args.quick else (os.cpu_count() or 1))
    out = args.keep or Path(tempfile.mkdtemp(prefix="bench-rise-")) / "campaign"
    print(f"cores {os.cpu_count()}, load {os.getloadavg()[0]:.1f} before; {burners} load process(es) for the first"
          f" {budget / 2:.0f} s of a {budget:.0f} s campaign in {out}")
    load = [subprocess.Popen([sys.executable, "-c", "while True: pass"]) for _ in range(burners)]
    started = time.monotonic()
    stopped_at: float | None = None
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    fuzz = subprocess.Popen([sys.executable, "-m", "astaa_deft.cli", "fuzz", "--spec", str(ROOT / "specs" /
                             "demo_av.yaml"), "-o", str(out), "--budget", f"{budget:.0f}s", "--no-minimise"],
                            stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, env=env)
    try:
        while fuzz.poll() is None:
            if stopped_at is None and time.monotonic() - started >= budget / 2:
                for p in load:  # stop what we started, by pid
                    p.terminate()
                for p in load:
                    p.wait(timeout=10)
                stopped_at = time.time()
                print(f"load processes {', '.join(str(p.pid) for p in load)} stopped at"
                      f" {time.monotonic() - started:.0f} s (load {os.getloadavg()[0]:.1f})")
            time.sleep(1.0)
    finally:
        for p in load:
            if p.poll() is None:
                p.kill()
                p.wait()
        if fuzz.poll() is None:
            fuzz.terminate()
            fuzz.wait(timeout=60)
    journal = Journal(out)
    try:
        notes = journal.notes("concurrency")
        ended = stopped_at or time.time()
        print("decisions (s relative to the end of the load):")
        for note in notes:
            print(f"  {note.time - ended:+7.0f} s  {note.text}")
        changes = [(n, _count(n.text)) for n in notes if n.text.startswith("runs at once:")]
        before = [k for n, k in changes if n.time <= ended]
        level = before[-1] if before else None
        rises = [n for n, k in changes if n.time > ended and level is not None and k > level]
        cases = [r for r in journal.cases() if r.finished and r.at_once is not None and r.finished_at is not None]
        for label, rows in (("before", [r for r in cases if r.finished_at <= ended]),
                            ("after", [r for r in cases if r.finished_at > ended])):
            seen = sorted({r.at_once for r in rows if r.at_once is not None})
            print(f"cases finished {label} the load ended: {len(rows)}, runs at once {seen}")
        if rises:
            print(f"runs at once rose {rises[0].time - ended:.0f} s after the load ended: {rises[0].text}")
        else:
            print("runs at once did not rise after the load ended")
    finally:
        journal.close()
    return 0


def _count(text: str) -> int:
    """The runs at once a decision set: ``runs at once: 2 (was 1): …`` → 2."""
    return int(re.match(r"runs at once: (\d+)", text).group(1))  # type: ignore[union-attr]


if __name__ == "__main__":
    raise SystemExit(main())
