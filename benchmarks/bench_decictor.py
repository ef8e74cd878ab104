"""Decictor on the demo: non-optimal decisions found per hour, decictor vs random-delta vs random (Table I).

    python benchmarks/bench_decictor.py                          # the full form: 15-minute budgets, 5 seeds
    python benchmarks/bench_decictor.py --first --off-seeds 2    # the quick form: each search stops at its first find
    python benchmarks/bench_decictor.py --live 0 --live-cost 16.6   # reuse a measured live cost (no live runs)

A search's budget is wall-clock time on this machine, as the promise
says ("within a 15-minute budget"): ``--budget-minutes`` divided
by the live cost of one scenario (``--live N`` runs N scenarios through the
proxy with real processes, as ``fuzz`` runs them one at a time; or
``--live-cost S`` gives it) is the number of scenarios a search may run.

The scenarios themselves run in the deterministic closed loop
(``decictor_loop``: the demo's world, prediction, planner and controller in
one process, no bus, no real time; the participants rendered into the
planner's prediction messages by the participant action's own code) — the
same scenes a live campaign would run, minus message timing, at a fraction
of the cost, so five seeds of three strategies fit in one sitting.

Each (strategy, seed) is one search on the ``lane_follow`` seed with the
decision defect on; then decictor again with it off (the clean planner must
give 0). Per strategy: seeds whose search found the defect within the budget,
the scenario of the first find (and its time at the live cost), findings per
search and per hour at the live cost (median and range over seeds; the full
form only: with ``--first`` a search stops at its first find). Cost per
scenario is split into mutation, simulation (the closed loop) and oracle +
feedback, as in the paper's Table V. Prints; asserts nothing.
"""

from __future__ import annotations

import argparse
import statistics
import sys
import tempfile
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

from decictor_loop import observe_closed_loop  # noqa: E402 - this directory, put on the path above

from astaa_deft.orchestration.campaign.strategies.decictor import area_around  # noqa: E402
from astaa_deft.analysis.decictor.config import read_config  # noqa: E402
from astaa_deft.analysis.decictor.feasible import ForbiddenRegion  # noqa: E402
from astaa_deft.analysis.decictor.oracle import LaneGrid, straight_lanes  # noqa: E402
from astaa_deft.analysis.decictor.search import MODES, Search  # noqa: E402
from astaa_deft.engine.intercept.actions.participant import Participant  # noqa: E402
from astaa_deft.engine.spec.loader import load_spec  # noqa: E402

ROOT = Path(__file__).resolve().parent.parent
SPEC = ROOT / "specs" / "demo_av.yaml"
SCENARIO = "lane_follow"
LANES = straight_lanes(2, 3.5, 300.0)  # what lane_follow's routing announces
LIVE_HORIZON = 15.0  # s: lane_follow reaches its goal at ~10.5 s of sim time; the run: section ends it there


def search_once(mode: str, seed: int, scenarios: int, defects: bool, first_only: bool) -> dict:
    config = read_config(load_spec(SPEC))
    started = time.perf_counter()
    seed_run = observe_closed_loop(SCENARIO, (), config.participants, defects)
    seed_seconds = time.perf_counter() - started
    search = Search(mode, seed, seed_run, LaneGrid(LANES), area=area_around(seed_run, LANES),
                    region=ForbiddenRegion(seed_run.ego, config.dt, config.clearance))
    mutation = simulation = oracle = 0.0
    first = None
    run = 0
    for number in range(1, scenarios + 1):
        t0 = time.perf_counter()
        scene = search.propose(number)
        t1 = time.perf_counter()
        observed = observe_closed_loop(SCENARIO, scene.participants, config.participants, defects)
        t2 = time.perf_counter()
        verdict = search.observe(scene, observed)
        t3 = time.perf_counter()
        mutation, simulation, oracle = mutation + t1 - t0, simulation + t2 - t1, oracle + t3 - t2
        run = number
        if verdict.non_optimal and first is None:
            first = number
            if first_only:
                break
    stats = search.stats
    return {"mode": mode, "seed": seed, "defects": defects, "findings": stats.findings, "first": first,
            "task_failed": stats.task_failed, "invalid": stats.invalid, "scenarios": run, "budget": scenarios,
            "mutation": mutation, "simulation": simulation, "oracle": oracle, "seed_seconds": seed_seconds}


def live_cost(count: int) -> list[float]:
    """Seconds per scenario through the proxy (real processes), one scenario at a time, as fuzz runs them."""
    from astaa_deft.orchestration.campaign.runner import CaseLimits, run_case
    from astaa_deft.orchestration.campaign.strategies.decictor import scene_testcase
    from astaa_deft.analysis.decictor.search import Scene
    from astaa_deft.engine.intercept.dictionary import load_dictionary
    from astaa_deft.engine.intercept.testcase import parse_testcase

    spec = load_spec(SPEC)
    cone = Participant(id=901, kind="cone", x=60.0, y=-3.0, heading=0.0, length=0.5, width=0.5)
    proposed = scene_testcase(Scene((cone,), "add"), "tc-000001", 1, "prediction")
    testcase = parse_testcase(proposed.to_xml(), "tc", spec, load_dictionary())
    seconds = []
    with tempfile.TemporaryDirectory() as tmp:
        for k in range(count):
            started = time.perf_counter()
            outcome = run_case(spec, testcase, {}, Path(tmp) / f"c{k}", limits=CaseLimits(horizon=LIVE_HORIZON))
            seconds.append(time.perf_counter() - started)
            print(f"  live scenario {k + 1}: {seconds[-1]:.1f} s ({outcome.status}, {outcome.verdict}, "
                  f"{outcome.summary[:80]})", flush=True)
    return seconds


def spread(values: list[float], fmt: str = "g") -> str:
    if not values:
        return "-"
    return f"{statistics.median(values):{fmt}} [{min(values):{fmt}}–{max(values):{fmt}}]"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--budget-minutes", type=float, default=15.0, help="wall-clock budget of one search, live")
    parser.add_argument("--seeds", type=int, default=5)
    parser.add_argument("--off-seeds", type=int, default=3, help="decictor searches with the defect off")
    parser.add_argument("--jobs", type=int, default=2, help="searches at once (processes)")
    parser.add_argument("--live", type=int, default=2, help="live scenarios through the proxy, for the live cost")
    parser.add_argument("--live-cost", type=float, default=None, help="seconds per live scenario (skips --live)")
    parser.add_argument("--first", action="store_true", help="stop each search at its first find (the quick form)")
    parser.add_argument("--modes", nargs="+", default=list(MODES), choices=MODES)
    args = parser.parse_args()

    if args.live_cost is not None:
        live, per_live = [], args.live_cost
    else:
        live = live_cost(max(1, args.live))
        per_live = statistics.median(live)
    scenarios = max(1, int(args.budget_minutes * 60.0 // per_live))
    print(f"budget {args.budget_minutes:g} min at {per_live:.1f} s per live scenario = {scenarios} scenarios "
          f"per search{' (each stops at its first find)' if args.first else ''}", flush=True)

    jobs = [(mode, seed, scenarios, True, args.first) for mode in args.modes for seed in range(1, args.seeds + 1)]
    jobs += [("decictor", seed, scenarios, False, False) for seed in range(1, args.off_seeds + 1)]
    started = time.perf_counter()
    results = []
    with ProcessPoolExecutor(max_workers=args.jobs) as pool:
        for r in pool.map(search_once, *zip(*jobs, strict=True)):
            results.append(r)
            print(f"  {r['mode']:13} seed {r['seed']} defect {'on ' if r['defects'] else 'off'}: {r['findings']} "
                  f"finding(s) in {r['scenarios']} scenarios, first at {r['first']}, "
                  f"{r['simulation'] / r['scenarios']:.2f} s/scenario in the loop", flush=True)
    wall = time.perf_counter() - started

    print(f"\nDecictor benchmark (Table I analogue): {SCENARIO}, budget {args.budget_minutes:g} min = {scenarios} "
          f"scenarios at {per_live:.1f} s live, {len(jobs)} searches in the closed loop, {args.jobs} at once, "
          f"{wall:.0f} s wall{'; quick form: searches stop at their first find' if args.first else ''}")
    print(f"{'strategy':14} {'defect':6} {'found in budget':>15} {'1st find at (scenario)':>24} "
          f"{'1st find at (live min)':>24} {'findings/search':>16} {'found/h live':>16}")
    for defects in (True, False):
        for mode in MODES:
            rows = [r for r in results if r["mode"] == mode and r["defects"] == defects]
            if not rows:
                continue
            found = sum(1 for r in rows if r["first"] is not None)
            firsts = [r["first"] for r in rows if r["first"] is not None]
            findings = [r["findings"] for r in rows]
            per_hour = [3600.0 * r["findings"] / (r["scenarios"] * per_live) for r in rows]
            full = not args.first or not defects
            print(f"{mode:14} {'on' if defects else 'off':6} {found:>9}/{len(rows):<5} {spread(firsts):>24} "
                  f"{spread([round(f * per_live / 60.0, 1) for f in firsts]):>24} "
                  f"{(spread(findings) if full else '-'):>16} {(spread(per_hour, '.0f') if full else '-'):>16}")
    print("\ncost per scenario (median over searches, s): mutation / simulation (closed loop) / oracle + feedback")
    for mode in args.modes:
        rows = [r for r in results if r["mode"] == mode and r["defects"]]
        parts = [statistics.median(r[k] / r["scenarios"] for r in rows) for k in ("mutation", "simulation", "oracle")]
        total = sum(parts)
        print(f"  {mode:14} {parts[0]:.3f} / {parts[1]:.3f} / {parts[2]:.3f} = {total:.2f} "
              f"(simulation {100 * parts[1] / total:.0f} %)")
    print("  task failed / invalid mutations: "
          + ", ".join(f"{m}: {sum(r['task_failed'] for r in results if r['mode'] == m and r['defects'])}/"
                      f"{sum(r['invalid'] for r in results if r['mode'] == m and r['defects'])}" for m in args.modes))
    if live:
        print(f"live scenario through the proxy ({LIVE_HORIZON:g} s horizon, ended by the run: section at the goal): "
              f"{spread([round(s, 1) for s in live])} s (paper's anchor: 77.6 s, 86 % simulation)")
    else:
        print(f"live scenario cost given: {per_live:.1f} s (paper's anchor: 77.6 s, 86 % simulation)")


if __name__ == "__main__":
    main()
