"""ddmin cost, measured on synthetic testers: tests per minimisation, and parallel speed-up.

    python benchmarks/bench_ddmin.py [--quick]

Part 1: the number of tests (cache misses, including the two start-up checks)
to find k culprits that fail only together, among n items, over random
culprit placements. Part 2: wall time with a tester that sleeps like a slow
re-run, sequential against ``parallel=N`` threads. Prints; asserts nothing.
"""

from __future__ import annotations

import argparse
import random
import statistics
import time
from typing import Sequence

from astaa_deft.analysis.minimise import DDOptions, Outcome, TestResult, ddmin


def conjunction(culprits: set[int], delay: float = 0.0):
    def tester(subset: Sequence[int]) -> TestResult:
        if delay:
            time.sleep(delay)
        return TestResult(Outcome.FAIL if culprits <= set(subset) else Outcome.PASS)

    return tester


def tests_per_culprits(quick: bool) -> None:
    rng = random.Random(0)
    trials = 20 if quick else 100
    print(f"tests per minimisation ({trials} random placements each)")
    print(f"{'n':>6} {'k':>3} {'min':>5} {'mean':>7} {'max':>5} {'cache hits':>11}")
    for n in (100, 1000) if quick else (100, 1000, 10000):
        for k in (1, 2, 4, 8):
            runs, hits = [], []
            for _ in range(trials):
                culprits = set(rng.sample(range(n), k))
                result = ddmin(list(range(n)), conjunction(culprits))
                assert set(result.minimal) == culprits
                runs.append(result.tests_run)
                hits.append(result.cache_hits)
            print(
                f"{n:>6} {k:>3} {min(runs):>5} {statistics.mean(runs):>7.1f} {max(runs):>5} {statistics.mean(hits):>11.1f}"
            )


def parallel_speedup(quick: bool) -> None:
    delay = 0.005 if quick else 0.02
    n, culprits = 200, {17, 130, 151}
    print(f"\nwall time, {n} items, culprits {sorted(culprits)}, each test sleeps {delay * 1000:.0f} ms")
    base = None
    for parallel in (1, 2, 4, 8):
        started = time.monotonic()
        result = ddmin(list(range(n)), conjunction(culprits, delay), DDOptions(parallel=parallel))
        seconds = time.monotonic() - started
        base = base or seconds
        print(
            f"  parallel={parallel}: {seconds:6.2f} s, {result.tests_run:3} tests, "
            f"speed-up {base / seconds:4.1f}x, minimal {result.minimal}"
        )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--quick", action="store_true", help="fewer trials, shorter sleeps")
    args = parser.parse_args()
    tests_per_culprits(args.quick)
    parallel_speedup(args.quick)


if __name__ == "__main__":
    main()
