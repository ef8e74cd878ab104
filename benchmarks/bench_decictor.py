"""Decictor on the demo: non-optimal decisions found per hour, decictor vs random-delta vs random (Table I).

    python benchmarks/bench_decictor.py [--scenarios 18] [--seeds 5] [--jobs 2] [--live 2]

Each (strategy, seed) is one search of ``--scenarios`` scenarios on the
``lane_follow`` seed, in the deterministic closed loop (the demo's world,
prediction, planner and controller in one process: no bus, no real time; the
participants rendered into the planner's prediction messages by the
participant action's own code), with the decision defect on; then decictor
again with it off (the clean planner must give 0). Per strategy: findings
(median and range over seeds), seeds with a finding, scenario of the first
finding, and findings per hour at the measured cost per scenario — in the
closed loop, and projected at the live cost (``--live N``: N scenarios run
through the proxy with real processes, as ``fuzz`` runs them, one at a time).
Cost per scenario is split into mutation, simulation (the closed loop) and
oracle + feedback, as in the paper's Table V. Prints; asserts nothing.
"""

from __future__ import annotations

import argparse
import statistics
import tempfile
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

from astaa_deft.campaign.strategies.decictor import area_around
from astaa_deft.decictor.closed_loop import observe_closed_loop
from astaa_deft.decictor.feasible import ForbiddenRegion
from astaa_deft.decictor.oracle import LaneGrid, straight_lanes
from astaa_deft.decictor.search import MODES, Search
from astaa_deft.intercept.actions.participant import Participant, read_mappings
from astaa_deft.spec_loader import load_spec

ROOT = Path(__file__).resolve().parent.parent
SPEC = ROOT / "specs" / "demo_av.yaml"
SCENARIO = "lane_follow"
LANES = straight_lanes(2, 3.5, 300.0)  # what lane_follow's routing announces


def search_once(mode: str, seed: int, scenarios: int, defects: bool) -> dict:
    spec = load_spec(SPEC)
    mapping = read_mappings(spec)["prediction"]
    clearance = float(spec.decictor["clearance"])
    started = time.perf_counter()
    seed_run = observe_closed_loop(SCENARIO, (), mapping, defects)
    seed_seconds = time.perf_counter() - started
    search = Search(mode, seed, seed_run, LaneGrid(LANES), area_around(seed_run, LANES),
                    ForbiddenRegion(seed_run.ego, clearance=clearance))
    mutation = simulation = oracle = 0.0
    first = None
    for number in range(1, scenarios + 1):
        t0 = time.perf_counter()
        scene = search.propose(number)
        t1 = time.perf_counter()
        run = observe_closed_loop(SCENARIO, scene.participants, mapping, defects)
        t2 = time.perf_counter()
        verdict = search.observe(scene, run)
        t3 = time.perf_counter()
        mutation, simulation, oracle = mutation + t1 - t0, simulation + t2 - t1, oracle + t3 - t2
        if verdict.non_optimal and first is None:
            first = number
    stats = search.stats
    return {"mode": mode, "seed": seed, "defects": defects, "findings": stats.findings, "first": first,
            "task_failed": stats.task_failed, "invalid": stats.invalid, "scenarios": scenarios,
            "mutation": mutation, "simulation": simulation, "oracle": oracle, "seed_seconds": seed_seconds}


def live_cost(count: int) -> list[float]:
    """Seconds per scenario through the proxy (real processes), one scenario at a time."""
    from astaa_deft.campaign.runner import run_case
    from astaa_deft.campaign.strategies.decictor import scene_xml
    from astaa_deft.decictor.search import Scene
    from astaa_deft.intercept.dictionary import load_dictionary
    from astaa_deft.intercept.testcase import parse_testcase

    spec = load_spec(SPEC)
    cone = Participant(901, "cone", 60.0, -3.0, 0.0, 0.5, 0.5)
    xml = scene_xml(Scene((cone,), "add"), "tc-000001", 1, "prediction")
    testcase = parse_testcase(xml.encode(), "tc", spec, load_dictionary())
    seconds = []
    with tempfile.TemporaryDirectory() as tmp:
        for k in range(count):
            started = time.perf_counter()
            outcome = run_case(spec, testcase, {}, Path(tmp) / f"c{k}", 15.0)
            seconds.append(time.perf_counter() - started)
            print(f"  live scenario {k + 1}: {seconds[-1]:.1f} s ({outcome.status}, {outcome.verdict})", flush=True)
    return seconds


def spread(values: list[float]) -> str:
    return f"{statistics.median(values):g} [{min(values):g}–{max(values):g}]"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--scenarios", type=int, default=18, help="scenarios per search (the budget)")
    parser.add_argument("--seeds", type=int, default=5)
    parser.add_argument("--off-seeds", type=int, default=3, help="decictor searches with the defect off")
    parser.add_argument("--jobs", type=int, default=2, help="searches at once (processes)")
    parser.add_argument("--live", type=int, default=2, help="live scenarios through the proxy, for the live cost")
    args = parser.parse_args()
    jobs = [(mode, seed, args.scenarios, True) for mode in MODES for seed in range(1, args.seeds + 1)]
    jobs += [("decictor", seed, args.scenarios, False) for seed in range(1, args.off_seeds + 1)]
    started = time.perf_counter()
    results = []
    with ProcessPoolExecutor(max_workers=args.jobs) as pool:
        for r in pool.map(search_once, *zip(*jobs, strict=True)):
            results.append(r)
            print(f"  {r['mode']:13} seed {r['seed']} defect {'on ' if r['defects'] else 'off'}: {r['findings']} "
                  f"finding(s), first at {r['first']}, {r['simulation'] / r['scenarios']:.1f} s/scenario simulated",
                  flush=True)
    wall = time.perf_counter() - started
    live = live_cost(args.live) if args.live else []
    live_per = statistics.median(live) if live else None

    print(f"\nDecictor benchmark: {SCENARIO}, {args.scenarios} scenarios per search, {len(jobs)} searches, "
          f"{args.jobs} at once, {wall:.0f} s wall")
    print(f"{'strategy':14} {'defect':6} {'seeds':>5} {'findings med [range]':>21} {'seeds w/ 1+':>11} "
          f"{'1st at (med)':>12} {'s/scenario':>10} {'found/h loop':>12} {'found/h live':>12}")
    for defects in (True, False):
        for mode in MODES:
            rows = [r for r in results if r["mode"] == mode and r["defects"] == defects]
            if not rows:
                continue
            findings = [r["findings"] for r in rows]
            per_scenario = statistics.median((r["mutation"] + r["simulation"] + r["oracle"]) / r["scenarios"]
                                             for r in rows)
            per_hour = [3600.0 * r["findings"] / (r["mutation"] + r["simulation"] + r["oracle"]) for r in rows]
            firsts = [r["first"] for r in rows if r["first"] is not None]
            live_hour = [3600.0 * r["findings"] / (r["scenarios"] * live_per) for r in rows] if live_per else []
            print(f"{mode:14} {'on' if defects else 'off':6} {len(rows):>5} {spread(findings):>21} "
                  f"{sum(1 for f in findings if f):>5}/{len(rows):<5} "
                  f"{(statistics.median(firsts) if firsts else '-'):>12} {per_scenario:>10.2f} "
                  f"{statistics.median(per_hour):>12.0f} "
                  f"{(f'{statistics.median(live_hour):.0f}' if live_hour else '-'):>12}")
    print("\ncost per scenario (median over searches, s): mutation / simulation (closed loop) / oracle + feedback")
    for mode in MODES:
        rows = [r for r in results if r["mode"] == mode and r["defects"]]
        parts = [statistics.median(r[k] / r["scenarios"] for r in rows) for k in ("mutation", "simulation", "oracle")]
        total = sum(parts)
        print(f"  {mode:14} {parts[0]:.3f} / {parts[1]:.3f} / {parts[2]:.3f} = {total:.2f} "
              f"(simulation {100 * parts[1] / total:.0f} %)")
    print("  task failed / invalid mutations: "
          + ", ".join(f"{m}: {sum(r['task_failed'] for r in results if r['mode'] == m and r['defects'])}/"
                      f"{sum(r['invalid'] for r in results if r['mode'] == m and r['defects'])}" for m in MODES))
    if live:
        print(f"live scenario through the proxy (15 s horizon): {spread([round(s, 1) for s in live])} s "
              f"(paper's anchor: 77.6 s, 86 % simulation)")


if __name__ == "__main__":
    main()
