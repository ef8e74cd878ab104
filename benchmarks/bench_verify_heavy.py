"""verify on the heavy OMPL stack: a campaign's confirmed bugs checked against the stack with its defects off.

    python benchmarks/bench_verify_heavy.py [--quick] [--campaign DIR] [--runs N]

Without ``--campaign``: first runs ``benchmarks/bench_campaign_heavy.py``'s
campaign (``astaa-deft fuzz --spec examples/ompl_stack/spec.yaml --params
iterations=900 reuse=0 defects=1``, its budget; ``--quick``: 4 minutes) into
a temporary folder. Then ``astaa-deft verify DIR --param defects=0 --runs N``
(the stack with its known defects off, at the campaign's runs at once) and,
for contrast, ``--param defects=1``. Prints each bucket's status and the
counts — the figure that matters: how many confirmed bugs say "still
failing" with the defects off (load, not the stack) — and the wall time of
each verify. Asserts nothing (the figures depend on the machine's load).
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_campaign_heavy import run_fuzz  # noqa: E402

from astaa_deft.orchestration.journal.journal import open_existing  # noqa: E402
from astaa_deft.orchestration.journal.verifications import verifications  # noqa: E402


def verify(campaign: Path, defects: str, runs: int) -> tuple[float, int, str]:
    started = time.monotonic()
    done = subprocess.run([sys.executable, "-m", "astaa_deft.cli", "verify", str(campaign), "--param",
                           f"defects={defects}", "--runs", str(runs), "--label", f"defects={defects}",
                           "--trust-journal-spec"],  # the campaign this script ran itself
                          capture_output=True, text=True)
    return time.monotonic() - started, done.returncode, done.stdout + done.stderr


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--quick", action="store_true", help="a 4-minute campaign")
    ap.add_argument("--campaign", type=Path, help="verify this campaign instead of running one")
    ap.add_argument("--runs", type=int, default=2, help="runs of each test case and as many twins (default 2)")
    a = ap.parse_args()
    campaign = a.campaign
    if campaign is None:
        campaign = Path(tempfile.mkdtemp(prefix="bench-verify-")) / "campaign"
        budget = "4m" if a.quick else "20m"
        print(f"campaign: {campaign} (budget {budget})", flush=True)
        _, seconds, stopped = run_fuzz(campaign, budget, 3 * 60 * (4 if a.quick else 20), None)
        print(f"  {seconds:.0f} s{' (stopped)' if stopped else ''}", flush=True)
    journal = open_existing(campaign)
    try:
        bugs = [b.bucket for b in journal.buckets(include_merged=False) if b.is_bug]
    finally:
        journal.close()
    print(f"{len(bugs)} confirmed bug(s): {', '.join(bugs) or '-'}; cores {os.cpu_count()},"
          f" load {os.getloadavg()[0]:.1f}", flush=True)
    for defects in ("0", "1"):
        seconds, code, output = verify(campaign, defects, a.runs)
        journal = open_existing(campaign)
        try:
            rows = [r for r in verifications(journal) if r.revision == f"defects={defects}"]
        finally:
            journal.close()
        counts: dict[str, int] = {}
        for r in rows:
            counts[str(r.status)] = counts.get(str(r.status), 0) + 1
        print(f"verify --param defects={defects}: exit {code}, {seconds:.0f} s, "
              + ", ".join(f"{n} {s}" for s, n in sorted(counts.items())), flush=True)
        for r in rows:
            print(f"  {r.bucket} {r.status} {r.stability} (twins {r.twin_failures}/{r.twins})"
                  f"{' [a confirmed bug]' if r.bucket in bugs else ''}")
        if code not in (0, 1, 3):
            print(output[-2000:])
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
