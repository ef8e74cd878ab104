"""Campaigns on the demo stack: throughput, time to first find per seeded defect, false alarms.

    python benchmarks/bench_campaign.py [--quick] [--keep DIR] [--skip throughput,find,false]
                                        [--pool-workers 3,4,5]

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

A find campaign stops early once every seeded defect has its bucket.
--quick keeps one full run near ~30 minutes on a loaded two-core machine
(12 cases per pool, 5 seeds × 150 s per strategy, 30 clean cases); without
it: 24 cases per pool, 5 seeds × 600 s, 100 clean cases. ``--seeds``,
``--budget``, ``--clean`` override. Prints figures, ratios and the load
average; asserts nothing (times depend on the machine and its load).
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

from astaa_deft.orchestration.campaign.campaign import Campaign, CampaignConfig
from astaa_deft.orchestration.journal.journal import Bucket, Journal
from astaa_deft.demo.bundled import demo_spec_path

HORIZON = 20.0  # seconds a case runs at most (the spec's run: section and --settle end it sooner)

# Seeded defect → (what breaks, the mutated channel:field) as a bucket's signature shows them.
DEFECTS = {
    1: "NaN speed limit → overspeed (planning)",
    2: "huge heading → control hangs",
    3: "empty trajectory → control crashes",
    4: "older localization stamp → non-finite command",
}


STAMP_BACKWARDS = re.compile(r"localization:(\*:(reorder|delay)|header\.stamp:)")
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
    if bucket.invariant in ("finite_command", "finite_steering") and STAMP_BACKWARDS.search(family):
        # defect 4 is an older stamp (a reordered or delayed localization, or a stamp set back); an extreme
        # speed in localization or a plan also makes control's derivative non-finite, but through another path
        return 4
    return None


def _first_xml(journal: Journal, bucket: Bucket) -> str:
    """The test case XML of a bucket's first failing case ("" for a clean run)."""
    case = journal.case(bucket.first_case)
    return (case.testcase_xml or "") if case is not None else ""


@dataclass
class Campaigned:
    seconds: float
    cases: int
    buckets: list[Bucket]
    first_xml: dict[str, str]  # bucket → its first case's test case XML
    started: float  # wall clock (time.time) at the start
    case_seconds: list[float]  # each finished run's seconds from launch to end
    generated_seconds: float  # from the first generated case's start to the campaign's end (after the baseline)
    cpu_seconds: float  # CPU (user + system) of every process the campaign started and waited for, and its own
    own_cpu_seconds: float  # of which the campaign's own process (journal, generation, pool threads)


class UntilAllFound(Campaign):
    """A find campaign that ends once every seeded defect has a bucket (the rest of its budget would not
    change a first-find time)."""

    def _budget_over(self) -> bool:
        if super()._budget_over():
            return True
        found = set()
        for b in self.journal.buckets():
            if not b.without_mutation:
                d = defect_of(b, _first_xml(self.journal, b))
                if d is not None:
                    found.add(d)
        return found >= set(DEFECTS)


def campaign(out: Path, *, cases: int | None, budget: float | None, seed: int, strategy: str = "random",
             cluster: str | None = None, params: dict[str, list[str]] | None = None,
             workers: int | None = None, until_all_found: bool = False, reruns: int = 0) -> Campaigned:
    config = CampaignConfig(spec_path=demo_spec_path(), out=out, cases=cases, budget=budget, seed=seed,
                            strategy=strategy, cluster=cluster, params=params or {}, horizon=HORIZON,
                            baseline_runs=1, reruns=reruns, minimise=False, report=False, workers=workers)
    journal = Journal(out)
    started = time.time()
    cpu_before, own_before = _children_cpu(), _own_cpu()
    kind = UntilAllFound if until_all_found else Campaign
    try:
        result = kind(config, journal, say=lambda text: None).run()
        buckets = journal.buckets()
        first_xml = {b.bucket: _first_xml(journal, b) for b in buckets}
        outcomes = [journal.outcome(r) for r in journal.cases()]
        generated = [r.started_at for r in journal.cases() if r.kind != "baseline" and r.started_at]
        generated_seconds = started + result.seconds - min(generated) if generated else 0.0
        case_seconds = [o.seconds for o in outcomes if o is not None and o.status == "done"]
    finally:
        journal.close()
    return Campaigned(result.seconds, result.cases_done, buckets, first_xml, started, case_seconds, generated_seconds,
                      _children_cpu() - cpu_before, _own_cpu() - own_before)


def _own_cpu() -> float:
    import resource

    own = resource.getrusage(resource.RUSAGE_SELF)
    return own.ru_utime + own.ru_stime


def _children_cpu() -> float:
    """CPU seconds of this process's finished descendants (each waited for by its parent: case processes,
    their recorders and SUT modules) plus this process's own — less load-sensitive than wall time."""
    import resource

    own = resource.getrusage(resource.RUSAGE_SELF)
    kids = resource.getrusage(resource.RUSAGE_CHILDREN)
    return own.ru_utime + own.ru_stime + kids.ru_utime + kids.ru_stime


def throughput(tmp: Path, cases: int, pool_workers: list[int] | None = None) -> None:
    cores = os.cpu_count() or 1
    print(f"== throughput: {cases} generated cases (+1 baseline) per campaign, {cores} cores,"
          f" load average {_load()} ==")
    default = _workers_used()
    rates = {}
    runs = [("local pool", None, default), ("LocalCluster", f"local:{default}", default),
            ("local pool", None, 2 * default)]
    if pool_workers:  # only local pools, these many cases at once (the first is the reference)
        runs = [("local pool", None, k) for k in pool_workers]
    for name, cluster, workers in runs:
        done = campaign(tmp / f"throughput-{name.replace(' ', '-')}-{workers}", cases=cases, budget=None, seed=1,
                        cluster=cluster, workers=workers)
        rate = done.cases / (done.seconds / 3600 * cores)
        rates[(name, workers)] = rate
        run_seconds = statistics.mean(done.case_seconds) if done.case_seconds else 0.0
        cluster_note = "" if cluster is None else "; the cluster's workers counted only as far as reaped"
        print(f"  {name:13} {workers} at once: {done.cases:3d} cases in {done.seconds:6.1f} s wall:"
              f" {rate:6.0f} cases per core-hour ({done.seconds / max(1, done.cases):.1f} s wall per case,"
              f" a run {run_seconds:.1f} s from launch to end; {done.cpu_seconds / max(1, done.cases):.2f} CPU s"
              f" per case, {done.own_cpu_seconds / max(1, done.cases):.2f} of them in the campaign's process"
              f"{cluster_note})")
        if done.generated_seconds > 0:
            steady = (done.cases - 1) / (done.generated_seconds / 3600 * cores)
            print(f"  {'':13} after the baseline: {done.cases - 1} generated cases in {done.generated_seconds:5.1f} s:"
                  f" {steady:6.0f} cases per core-hour (a long campaign's rate: its one baseline run amortised)")
    if pool_workers:
        first = rates[("local pool", pool_workers[0])]
        print("  " + "; ".join(f"{k} / {pool_workers[0]} at once: {rates[('local pool', k)] / first:.2f}×"
                               for k in pool_workers[1:]) + f"; load average now {_load()}")
        return
    pool = rates[("local pool", default)]
    print(f"  LocalCluster / local pool: {rates[('LocalCluster', default)] / pool:.2f}×;"
          f" {2 * default} / {default} at once: {rates[('local pool', 2 * default)] / pool:.2f}×;"
          f" target ≥ 600 cases per core-hour (Decictor's published cost ≈ 46); load average now {_load()}")


def _load() -> str:
    return " ".join(f"{x:.1f}" for x in os.getloadavg())


def _workers_used() -> int:
    from astaa_deft.orchestration.campaign.campaign import default_workers
    from astaa_deft.engine.spec.loader import load_spec

    return default_workers(len(load_spec(demo_spec_path()).modules))


def first_finds(tmp: Path, seeds: list[int], budget: float, max_cases: int) -> None:
    print(f"== time to first find: seeds {seeds}, {budget:.0f} s (at most {max_cases} cases) per campaign,"
          f" each ended once all four are found; load average {_load()} ==")
    finds: dict[str, dict[int, list[tuple[float, int] | None]]] = {}
    extra: dict[str, list[str]] = {}
    split: dict[str, list[str]] = {}
    for strategy in ("random", "guided"):
        finds[strategy] = {d: [] for d in DEFECTS}
        extra[strategy], split[strategy] = [], []
        for seed in seeds:
            done = campaign(tmp / f"find-{strategy}-{seed}", cases=max_cases, budget=budget, seed=seed,
                            strategy=strategy, until_all_found=True)
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


def false_alarms(tmp: Path, cases: int, seed: int = 7) -> None:
    """As `astaa-deft fuzz` runs it: each bucket's first failure re-run twice for its rate."""
    print(f"== false alarms: {cases} generated cases with the defects off, seed {seed}; load average {_load()} ==")
    done = campaign(tmp / "false-alarms", cases=cases, budget=None, seed=seed, params={"defects": ["off"]},
                    reruns=2)
    real = [b for b in done.buckets if not b.without_mutation]
    flaky = [b for b in done.buckets if b.without_mutation]
    unconfirmed = [b for b in real if b.reruns and not b.rerun_failures]
    print(f"  {done.cases} cases in {done.seconds:.0f} s: {len(real)} bucket(s) blamed on a mutation"
          f" (target 0; {len(unconfirmed)} of them failed none of their re-runs), {len(flaky)} without mutation"
          f" (flaky clean runs)")
    for b in real + flaky:
        note = " (without mutation)" if b.without_mutation else ""
        print(f"    {b.bucket} {b.verdict} {b.invariant} {b.family}{note}"
              f" — re-runs failed {b.rerun_failures}/{b.reruns}")


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--quick", action="store_true", help="a run under ~15 minutes")
    ap.add_argument("--keep", type=Path, help="keep the campaigns here (default: a temp dir, removed)")
    ap.add_argument("--skip", default="", help="comma-separated parts to skip: throughput, find, false")
    ap.add_argument("--seeds", type=int, help="find campaigns per strategy (seeds 1..N)")
    ap.add_argument("--budget", type=float, help="seconds per find campaign")
    ap.add_argument("--clean", type=int, help="generated cases of the false-alarm campaign")
    ap.add_argument("--pool-workers", help="throughput of local pools only, with these many cases at once (e.g. 3,4,5)")
    args = ap.parse_args()
    skip = {s.strip() for s in args.skip.split(",") if s.strip()}
    pool_cases, seeds, budget, max_cases, clean = (12, [1, 2, 3, 4, 5], 150.0, 200, 30) if args.quick else \
        (24, [1, 2, 3, 4, 5], 600.0, 400, 100)
    seeds = list(range(1, args.seeds + 1)) if args.seeds else seeds
    budget = args.budget or budget
    clean = args.clean or clean
    print(f"bench_campaign: load average {_load()} at the start")
    started = time.monotonic()
    with tempfile.TemporaryDirectory(prefix="bench-campaign-") as tmp_name:
        tmp = args.keep or Path(tmp_name)
        tmp.mkdir(parents=True, exist_ok=True)
        if "throughput" not in skip:
            throughput(tmp, pool_cases,
                       [int(k) for k in args.pool_workers.split(",")] if args.pool_workers else None)
        if "find" not in skip:
            first_finds(tmp, seeds, budget, max_cases)
        if "false" not in skip:
            false_alarms(tmp, clean)
    print(f"(benchmark wall time {time.monotonic() - started:.0f} s)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
