"""Campaigns on the demo stack: throughput, time to first find per seeded defect, false alarms.

    python benchmarks/bench_campaign.py [--quick] [--keep DIR] [--skip throughput,find,false]

1. **Throughput**: the same short campaign (no minimisation) on the local
   process pool and on a Dask ``LocalCluster`` of worker processes; cases per
   core-hour = cases / (wall hours × cores of this machine). Target ≥ 600.
2. **Time to first find** of each of the four seeded demo defects
   (astaa_deft/demo/README.md), random vs guided, over several seeds: the
   seconds (and cases) from the campaign's start to the first bucket whose
   signature is that defect's (invariant and mutated channel:field); median
   per strategy, and guided/random ratios. Also: buckets per defect (a
   defect split over several buckets) and buckets that match no defect.
3. **False alarms**: a campaign with the defects off (``--params
   defects=off``): every bucket it opens is a false alarm (flaky clean
   outcomes are counted as such, not as findings).

--quick keeps one full run under ~15 minutes on a loaded two-core machine
(12 cases per pool, 3 seeds × 90 s per strategy, 8 clean cases); without
it: 20 cases per pool, 5 seeds × 300 s, 100 clean cases. Prints figures and
ratios; asserts nothing (times depend on the machine and its load).
"""

from __future__ import annotations

import argparse
import os
import re
import statistics
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path

from astaa_deft.campaign.campaign import Campaign, CampaignConfig
from astaa_deft.campaign.journal import Bucket, Journal
from astaa_deft.demo.bundled import demo_spec_path

HORIZON = 8.0  # seconds a case runs at most (the spec's run: section usually ends it sooner)

# Seeded defect → (what breaks, the mutated channel:field) as a bucket's signature shows them.
DEFECTS = {
    1: "NaN speed limit → overspeed (planning)",
    2: "huge heading → control hangs",
    3: "empty trajectory → control crashes",
    4: "older localization stamp → non-finite command",
}


NON_FINITE = re.compile(r'path="speed_limit" value="[^"]*(nan|inf)', re.IGNORECASE)


def defect_of(bucket: Bucket, first_xml: str) -> int | None:
    """Which seeded defect a bucket is (None: none of them), from its signature and its first case's values."""
    family = bucket.family
    if bucket.invariant in ("speed_limit", "planned_speed", "finite_plan") and "routing:speed_limit" in family:
        # defect 1 is a non-finite limit; a finite limit above 15 m/s breaks planned_speed without any defect
        return 1 if NON_FINITE.search(first_xml or "") else None
    if bucket.verdict == "Restart" and "localization:heading" in family:
        return 2
    if bucket.module == "control" and bucket.verdict == "Abort" and "trajectory:points" in family:
        return 3
    if bucket.invariant in ("finite_command", "finite_steering") and "localization:" in family \
            and "localization:heading" not in family:
        return 4
    return None


@dataclass
class Campaigned:
    seconds: float
    cases: int
    buckets: list[Bucket]
    first_xml: dict[str, str]  # bucket → its first case's test case XML
    started: float  # wall clock (time.time) at the start


def campaign(out: Path, *, cases: int | None, budget: float | None, seed: int, strategy: str = "random",
             cluster: str | None = None, params: dict[str, list[str]] | None = None,
             workers: int | None = None) -> Campaigned:
    config = CampaignConfig(demo_spec_path(), out, cases=cases, budget=budget, seed=seed, strategy=strategy,
                            cluster=cluster, params=params or {}, horizon=HORIZON, baseline_runs=1, reruns=0,
                            minimise=False, report=False, workers=workers)
    journal = Journal(out)
    started = time.time()
    try:
        result = Campaign(config, journal, say=lambda text: None).run()
        buckets = journal.buckets()
        first_xml = {b.bucket: (journal.case(b.first_case)["testcase_xml"] or "") for b in buckets}
    finally:
        journal.close()
    return Campaigned(result.seconds, result.cases_done, buckets, first_xml, started)


def throughput(tmp: Path, cases: int) -> None:
    cores = os.cpu_count() or 1
    print(f"== throughput: {cases} generated cases (+1 baseline), horizon {HORIZON:.0f} s, {cores} cores ==")
    rates = {}
    workers = _workers_used()
    print(f"  {workers} cases at once (the default for the demo on {cores} cores)")
    for name, cluster in (("local pool", None), ("LocalCluster", f"local:{workers}")):
        done = campaign(tmp / f"throughput-{name.replace(' ', '-')}", cases=cases, budget=None, seed=1,
                        cluster=cluster, workers=workers)
        rate = done.cases / (done.seconds / 3600 * cores)
        rates[name] = rate
        print(f"  {name:13} {done.cases:3d} cases in {done.seconds:6.1f} s wall: {rate:6.0f} cases per core-hour"
              f" ({done.seconds / max(1, done.cases):.1f} s wall per case)")
    print(f"  LocalCluster / local pool: {rates['LocalCluster'] / rates['local pool']:.2f}×; "
          f"target ≥ 600 cases per core-hour (Decictor's published cost ≈ 46)")


def _workers_used() -> int:
    from astaa_deft.campaign.campaign import default_workers
    from astaa_deft.spec_loader import load_spec

    return default_workers(len(load_spec(demo_spec_path()).modules))


def first_finds(tmp: Path, seeds: list[int], budget: float, max_cases: int) -> None:
    print(f"== time to first find: seeds {seeds}, {budget:.0f} s (at most {max_cases} cases) per campaign ==")
    finds: dict[str, dict[int, list[tuple[float, int] | None]]] = {}
    extra: dict[str, list[str]] = {}
    split: dict[str, list[str]] = {}
    for strategy in ("random", "guided"):
        finds[strategy] = {d: [] for d in DEFECTS}
        extra[strategy], split[strategy] = [], []
        for seed in seeds:
            done = campaign(tmp / f"find-{strategy}-{seed}", cases=max_cases, budget=budget, seed=seed,
                            strategy=strategy)
            per_defect: dict[int, list[Bucket]] = {}
            for b in done.buckets:
                if b.without_mutation:
                    continue
                d = defect_of(b, done.first_xml[b.bucket])
                if d is None:
                    extra[strategy].append(f"seed {seed}: {b.verdict} {b.invariant} {b.family}")
                else:
                    per_defect.setdefault(d, []).append(b)
            for d in DEFECTS:
                found = sorted(per_defect.get(d, []), key=lambda b: b.created_at)
                finds[strategy][d].append((found[0].created_at - done.started, found[0].created_after_cases)
                                          if found else None)
                if len(found) > 1:
                    split[strategy].append(f"seed {seed}: defect {d} in {len(found)} buckets "
                                           f"({', '.join(b.family for b in found)})")
            shown = ", ".join(f"d{d} {_fmt(finds[strategy][d][-1])}" for d in DEFECTS)
            print(f"  {strategy:6} seed {seed:3d}: {done.cases:3d} cases in {done.seconds:5.0f} s — {shown}")
    print("  defect                                          random (found, median s / cases)"
          "   guided                 guided/random")
    for d, text in DEFECTS.items():
        cells = []
        medians = []
        for strategy in ("random", "guided"):
            hits = [f for f in finds[strategy][d] if f is not None]
            if hits:
                med_s = statistics.median(h[0] for h in hits)
                med_n = statistics.median(h[1] for h in hits)
                cells.append(f"{len(hits)}/{len(seeds)}, {med_s:5.0f} s / {med_n:4.0f}")
                medians.append(med_s)
            else:
                cells.append(f"0/{len(seeds)},     -         ")
                medians.append(None)
        ratio = (f"{medians[1] / medians[0]:.2f}×" if None not in medians and medians[0] else "-")
        print(f"  {d} {text:45} {cells[0]:24} {cells[1]:24} {ratio}")
    for strategy in ("random", "guided"):
        print(f"  {strategy}: {len(extra[strategy])} bucket(s) matching no seeded defect;"
              f" {len(split[strategy])} defect(s) split over several buckets")
        for line in extra[strategy][:6] + split[strategy][:6]:
            print(f"    {line}")


def _fmt(find: tuple[float, int] | None) -> str:
    return "-" if find is None else f"{find[0]:.0f}s/{find[1]}c"


def false_alarms(tmp: Path, cases: int) -> None:
    print(f"== false alarms: {cases} generated cases with the defects off ==")
    done = campaign(tmp / "false-alarms", cases=cases, budget=None, seed=7, params={"defects": ["off"]})
    real = [b for b in done.buckets if not b.without_mutation]
    flaky = [b for b in done.buckets if b.without_mutation]
    print(f"  {done.cases} cases in {done.seconds:.0f} s: {len(real)} bucket(s) blamed on a mutation"
          f" (target 0), {len(flaky)} without mutation (flaky clean runs)")
    for b in real + flaky:
        print(f"    {b.bucket} {b.verdict} {b.invariant} {b.family}{' (without mutation)' if b.without_mutation else ''}")


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--quick", action="store_true", help="a run under ~15 minutes")
    ap.add_argument("--keep", type=Path, help="keep the campaigns here (default: a temp dir, removed)")
    ap.add_argument("--skip", default="", help="comma-separated parts to skip: throughput, find, false")
    args = ap.parse_args()
    skip = {s.strip() for s in args.skip.split(",") if s.strip()}
    pool_cases, seeds, budget, max_cases, clean = (12, [1, 2, 3], 90.0, 40, 8) if args.quick else \
        (20, [1, 2, 3, 4, 5], 300.0, 150, 100)
    started = time.monotonic()
    with tempfile.TemporaryDirectory(prefix="bench-campaign-") as tmp_name:
        tmp = args.keep or Path(tmp_name)
        tmp.mkdir(parents=True, exist_ok=True)
        if "throughput" not in skip:
            throughput(tmp, pool_cases)
        if "find" not in skip:
            first_finds(tmp, seeds, budget, max_cases)
        if "false" not in skip:
            false_alarms(tmp, clean)
    print(f"(benchmark wall time {time.monotonic() - started:.0f} s)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
