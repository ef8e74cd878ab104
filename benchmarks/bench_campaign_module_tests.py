"""Campaigns on zoo members with seeded defects: does every confirmed bucket get module tests that fail on it?

    python benchmarks/bench_campaign_module_tests.py [--cases 12] [--members mpc_crash,...] [--keep DIR]

What it checks: "in a campaign, every confirmed bucket whose
failing module the spec can replay gets module tests that fail on its defect
(zoo members with seeded defects, inputs on slow channels included)". Each
member (tests/zoo) is run as a stack with a default campaign (the random
strategy, 2 workers, its first ``--cases`` cases: the first round mutates
every channel and field, the 1 Hz channel c among them); then for each
confirmed bucket whose module the spec replays: whether the campaign wrote
module tests, whether its own check says they fail on the defect, whether
pytest on the suite in a child process fails, and — buckets of the seeded
defect — whether a copy of the suite with the defect off no longer fails on it.

Prints one row per member; asserts nothing.
"""

from __future__ import annotations

import argparse
import dataclasses
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "tests"))

from astaa_deft.orchestration.campaign.module_tests import judge_pytest  # noqa: E402
from zoo import MPC, Member, write_member  # noqa: E402
from zoo.campaign import run_campaign, run_suite  # noqa: E402

MEMBERS = {
    "mpc_crash": dataclasses.replace(MPC, defect="crash_on_nan", seconds=3.0),
    "mpc_state": dataclasses.replace(MPC, defect="nan_state", seconds=3.0),
    "slow_state": Member("camp_slow_state", trigger="newest_idle", readiness="slow_1hz", state="warm",
                         cost_ms=(2.0, 6.0), seconds=2.5, defect="nan_state"),
    "each_crash": Member("camp_each_crash", readiness="slow_1hz", seconds=3.0, defect="crash_on_nan"),
}


def measure(name: str, member: Member, root: Path, cases: int) -> str:
    stack = write_member(member, root / name / "stack")
    started = time.monotonic()
    found = run_campaign(stack, root / name / "campaign", cases=None, count=cases)
    seconds = time.monotonic() - started
    bugs = [b for b in found.buckets if b.is_bug and b.merged_into is None]
    replayable = found.replayable()
    written = checked = failing = seeded = off_ok = 0
    slow = []
    for bucket in replayable:
        suite = found.suite(bucket)
        if bucket.family.startswith("c:"):
            slow.append(f"{bucket.bucket}{'' if suite is not None else ' (no tests)'}")
        if suite is None:
            continue
        written += 1
        checked += found.module_tests[bucket.bucket].fails_on_defect is True
        on = run_suite(suite)
        failing += judge_pytest(on.returncode, on.output, crash=True).fails_on_defect is True
        if "zoo seeded defect" in on.output:
            seeded += 1
            off = run_suite(suite, defect="none", scratch=root / name)
            off_ok += judge_pytest(off.returncode, off.output, crash=True).fails_on_defect is False
    return (f"{name:<11} {len(bugs):>5} {len(replayable):>6} {written:>7} {checked:>9} {failing:>8} "
            f"{seeded:>7} {off_ok:>8} {len(slow):>5} {seconds:>7.0f}")


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--cases", type=int, default=12)
    ap.add_argument("--members", default=",".join(MEMBERS))
    ap.add_argument("--keep", type=Path, help="where the stacks and campaigns go (default: a temporary folder)")
    args = ap.parse_args()
    root = args.keep or Path(tempfile.mkdtemp(prefix="campaign-module-tests-"))
    print(f"{'member':<11} {'bugs':>5} {'replay':>6} {'written':>7} {'fail(chk)':>9} {'fail(py)':>8} "
          f"{'seeded':>7} {'off ok':>8} {'on c':>5} {'s':>7}", flush=True)
    for name in args.members.split(","):
        print(measure(name, MEMBERS[name], root, args.cases), flush=True)
    print("bugs: confirmed buckets; replay: of them, the module to blame replayable; written: with module tests; "
          "fail(chk): the campaign's check says they fail on the defect; fail(py): pytest in a child fails on it; "
          "seeded: the seeded defect's (not an input too short); off ok: with it off, no longer failing on it; "
          f"on c: buckets mutating the 1 Hz channel c. Folder: {root}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
