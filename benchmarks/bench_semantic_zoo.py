"""A default campaign on the semantic zoo (tests/sut/semantic_zoo.yaml): how many seeded defects it finds.

    python benchmarks/bench_semantic_zoo.py [--budget 20m] [--seed 1] [--defects 1|0] [--keep DIR]

What it measures: the zoo holds one seeded defect per semantic fault
family (boundary, angle, units, arrays, type, siblings, stale), each
reachable only by its family (tests/test_semantic_faults.py checks that
offline, tests/test_semantic_zoo.py live). This runs ``astaa-deft fuzz``
with its defaults and the given budget, then reads the journal: each
confirmed bucket's cases' consumer tracebacks name the defect it found
(zoo_consumer.py raises a different error per family). It prints the
defects found out of 7, the buckets per defect (one each is the target), the
buckets that are no defect (false bugs; target 0) and whether each was
minimised. ``--defects 0``: the zoo without its defects (target: 0 buckets).

Prints figures; asserts nothing.
"""

from __future__ import annotations

import argparse
import os
import re
import sqlite3
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
ZOO = ROOT / "tests" / "sut" / "semantic_zoo.yaml"
FAMILIES = ("boundary", "angle", "units", "arrays", "type", "siblings", "stale")


def defect_in(text: str) -> str | None:
    """The family whose seeded defect a consumer log's traceback shows (zoo_consumer.py), or None."""
    if "Traceback" not in text:
        return None
    last = [line for line in text.splitlines() if re.match(r"^\w+Error", line)]
    if not last:
        return None
    line = last[-1]
    if line.startswith("IndexError"):
        return "boundary"
    if line.startswith("ZeroDivisionError"):
        return "stale"
    if line.startswith(("KeyError", "TypeError")):
        return "type"
    match = re.match(r"ValueError: (\w+) defect", line)
    return match.group(1) if match else None


def case_defects(journal: sqlite3.Connection, out: Path, bucket: str) -> set[str | None]:
    """The defects the bucket's cases (and their re-runs) show in their consumer logs."""
    found: set[str | None] = set()
    for (case_id, log_path) in journal.execute("SELECT case_id, log_path FROM cases WHERE bucket = ?", (bucket,)):
        run_dir = Path(log_path).parent if log_path else out / "cases" / case_id
        log = next((p for p in (run_dir / "modules" / "consumer.log", run_dir / "consumer.log") if p.exists()),
                   run_dir / "consumer.log")
        found.add(defect_in(log.read_text(errors="replace")) if log.exists() else None)
    return found


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--budget", default="20m")
    ap.add_argument("--seed", default="1")
    ap.add_argument("--defects", default="1", choices=["0", "1"])
    ap.add_argument("--keep", type=Path, help="the campaign directory (default: a temporary one)")
    args = ap.parse_args()
    out = args.keep or Path(tempfile.mkdtemp(prefix="zoo-campaign-")) / "campaign"
    command = [sys.executable, "-m", "astaa_deft.cli", "fuzz", "--spec", str(ZOO), "-o", str(out),
               "--budget", args.budget, "--seed", args.seed, "--params", f"defects={args.defects}"]
    print("$", " ".join(command[2:]), flush=True)
    started = time.monotonic()
    res = subprocess.run(command, capture_output=True, text=True, env=os.environ.copy())
    elapsed = time.monotonic() - started
    print("\n".join(res.stdout.splitlines()[-4:]))
    journal = sqlite3.connect(out / "journal.sqlite")
    cases = journal.execute("SELECT COUNT(*) FROM cases WHERE kind != 'baseline'").fetchone()[0]
    rows = journal.execute("SELECT bucket, kind, merged_into, module FROM buckets ORDER BY bucket").fetchall()
    minimised = {row[0] for row in journal.execute("SELECT bucket FROM minimisations WHERE status = 'minimised'")}
    per_defect: dict[str, list[str]] = {}
    false_bugs = []
    for bucket, kind, merged_into, module in rows:
        if merged_into or kind != "bug":
            continue
        defects = case_defects(journal, out, bucket) - {None}
        if not defects:
            false_bugs.append(bucket)
        for defect in defects:
            per_defect.setdefault(defect, []).append(bucket)
        print(f"  {bucket} ({module}): {', '.join(sorted(defects)) or 'no seeded defect'}"
              + (" — minimised" if bucket in minimised else ""))
    print(f"semantic zoo, defects={args.defects}, budget {args.budget}, seed {args.seed}: {cases} cases in "
          f"{elapsed / 60:.1f} min (exit {res.returncode})")
    if args.defects == "1":
        print(f"defects found: {len(per_defect)} / {len(FAMILIES)} "
              f"({', '.join(f'{f}: {len(per_defect.get(f, []))} bucket(s)' for f in FAMILIES)})")
    print(f"confirmed buckets: {sum(1 for r in rows if r[1] == 'bug' and not r[2])}; "
          f"false bugs (no seeded defect in their cases): {len(false_bugs)} {false_bugs or ''}")
    print(f"campaign directory: {out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
