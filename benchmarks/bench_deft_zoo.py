"""DeFT on the zoo of module behaviours: every member against its plain-replay floor.

    python benchmarks/bench_deft_zoo.py [--members mpc,each_warm] [--quick] [--pairs 3] [--jobs N]
                                        [--seconds S] [--mode passive|star] [--keep DIR] [--json FILE]

For each member of the zoo (tests/zoo: a module as a real process on Zenoh,
its inputs from a producer process, a spec with a ``replay:`` entry and its
factory), one recorded run, then:

- floor: the plain replay — the logged inputs in log order into one fresh
  instance of the factory, the best of three plain ways (tests/zoo/floor.py)
  — outputs reproduced bit for bit;
- θ = 0: the outputs ``extract --module module --threshold 0`` reproduces
  exactly; ``lost``: those the floor reproduced and extraction did not;
- right: the frames chosen that are the ones the module used (its own
  evaluation record, never read by extraction);
- suite: the extracted module tests under pytest on the very run they came
  from (passed / written);
- ÷ plain: the extraction's wall time over the plain replay's (reading the log
  included in both), the median of ``--pairs`` interleaved pairs.

Acceptance: θ = 0 ≥ floor, suite 100 %, ÷ plain ≤ 2× for members
of ≥ 50 ms a cycle. ``--quick``: the short zoo (three members, 2 s of bus
time each) and one pair. Prints figures; asserts nothing.
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import statistics
import sys
import tempfile
import time
from dataclasses import replace
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "tests"))

from zoo import MEMBERS, SHORT, by_name, record, write_member  # noqa: E402
from zoo.judge import extract, lost, plain_replay, run_suite  # noqa: E402

EXPENSIVE_MS = 50.0  # members at or above this cost a cycle are held to ÷ plain ≤ 2×


def say(text: str = "") -> None:
    print(text, flush=True)


def measure(member, out: Path, pairs: int, jobs: int | None, mode: str) -> dict:
    stack = write_member(member, out / member.name)
    t0 = time.perf_counter()
    log = record(stack, mode=mode)
    recorded_s = time.perf_counter() - t0
    ratios, floor, extracted = [], None, None
    for pair in range(pairs):  # interleaved: extraction, plain replay, extraction, …
        extracted = extract(stack, log, stack.directory / f"suite{pair}", jobs=jobs)
        # The first plain replay tries every plain way (the floor is the best); the later ones only that one.
        plain = plain_replay(stack, log, ways=(floor.way,) if floor is not None else None)
        floor = floor or plain
        ratios.append((extracted.seconds / max(plain.seconds, 1e-9), extracted.seconds, plain.seconds))
    assert floor is not None and extracted is not None
    suite = run_suite(stack.directory / f"suite{pairs - 1}")
    ratio, extraction_s, plain_s = sorted(ratios)[len(ratios) // 2]
    return {"member": member.name, "axes": member.axes(), "cost_ms": list(member.cost_ms),
            "frames": member.frames_mode, "outputs": floor.outputs, "floor": floor.count, "floor_way": floor.way,
            "floor_ways": floor.ways, "theta0": extracted.exact, "within_1e-9": extracted.near,
            "lost": lost(floor, extracted, stack, log),
            "right": extracted.right, "answered": extracted.frames, "tests": suite.tests, "passed": suite.passed,
            "failed": suite.failed, "suite_all_pass": suite.all_pass, "suite_tail": suite.output,
            "ratio": ratio, "ratios": [r[0] for r in ratios], "extraction_s": extraction_s, "plain_s": plain_s,
            "recorded_s": recorded_s}


def row(r: dict) -> str:
    if "error" in r:
        return f"{r['member']:22} error: {r['error']}"
    suite = "—" if r["tests"] == 0 else f"{r['passed']}/{r['tests']}" + ("" if r["suite_all_pass"] else " ✗")
    ok = r["theta0"] >= r["floor"]
    return (f"{r['member']:22} {r['outputs']:5d} {r['floor']:5d} {r['floor_way'][:10]:10} "
            f"{r['theta0']:5d}{'' if ok else ' <':2} {r['lost']:4d} {r['right']:4d}/{r['answered']:<4d} "
            f"{suite:>11} {r['ratio']:7.2f}× {r['extraction_s']:7.1f} {r['plain_s']:6.2f}  "
            f"{r['cost_ms'][0]:g}-{r['cost_ms'][1]:g} ms, {r['frames']}")


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--members", help="comma-separated member names (default: the whole zoo)")
    ap.add_argument("--quick", action="store_true", help="the short zoo, one pair")
    ap.add_argument("--pairs", type=int, help="interleaved extraction / plain replay pairs (default 3; quick 1)")
    ap.add_argument("--jobs", type=int, help="extract's --jobs (default: extract's, the idle cores)")
    ap.add_argument("--seconds", type=float, help="bus time of every member's run (default: each member's own)")
    ap.add_argument("--mode", default="passive", choices=("passive", "star"), help="how the runs are recorded")
    ap.add_argument("--keep", type=Path, help="keep the stacks, logs and suites here")
    ap.add_argument("--json", type=Path, help="write the per-member figures here")
    args = ap.parse_args()
    members = list(SHORT if args.quick else MEMBERS)
    if args.members:
        members = [by_name(name.strip()) for name in args.members.split(",") if name.strip()]
    if args.seconds:
        members = [replace(m, seconds=args.seconds) for m in members]
    members.sort(key=lambda m: sum(m.cost_ms))  # the cheap members' figures first
    pairs = args.pairs or (1 if args.quick else 3)
    out = args.keep or Path(tempfile.mkdtemp(prefix="bench-deft-zoo-"))
    out.mkdir(parents=True, exist_ok=True)
    say(f"DeFT zoo: {len(members)} members, {pairs} interleaved pair(s) each, runs recorded {args.mode}, "
        f"jobs {args.jobs or 'idle cores'}; load average {os.getloadavg()[0]:.1f} on {os.cpu_count()} CPUs")
    say(f"{'member':22} {'outs':>5} {'floor':>5} {'floor way':10} {'θ=0':>5}{'':2} {'lost':>4} {'right':>9} "
        f"{'suite':>11} {'÷plain':>8} {'extr s':>7} {'plain s':>6}")
    results = []
    for member in members:
        try:
            r = measure(member, out, pairs, args.jobs, args.mode)
        except Exception as exc:  # noqa: BLE001 — one member's failure is a row, the others still run
            r = {"member": member.name, "error": f"{type(exc).__name__}: {str(exc).splitlines()[0][:150]}"}
        results.append(r)
        say(row(r))
    done = [r for r in results if "error" not in r]
    expensive = [r for r in done if sum(r["cost_ms"]) / 2 >= EXPENSIVE_MS]  # the mean cost a cycle
    say(f"members: {len(done)} measured, {len(results) - len(done)} failed to run; "
        f"θ = 0 ≥ floor: {sum(r['theta0'] >= r['floor'] for r in done)}/{len(done)}; "
        f"outputs lost against the floor: {sum(r['lost'] for r in done)}; "
        f"suite 100 % on its own run: {sum(r['suite_all_pass'] for r in done)}/{len(done)} "
        f"({sum(r['tests'] == 0 for r in done)} wrote no tests); "
        f"÷ plain ≤ 2× (≥ {EXPENSIVE_MS:g} ms a cycle): {sum(r['ratio'] <= 2.0 for r in expensive)}/{len(expensive)}"
        + (f", median {statistics.median(r['ratio'] for r in expensive):.2f}×" if expensive else ""))
    say(f"outputs: {sum(r['outputs'] for r in done)}, floor {sum(r['floor'] for r in done)}, "
        f"θ = 0 {sum(r['theta0'] for r in done)} (within 1e-9: {sum(r['within_1e-9'] for r in done)}), "
        f"right frames {sum(r['right'] for r in done)}/"
        f"{sum(r['answered'] for r in done)}; load average now {os.getloadavg()[0]:.1f}")
    if args.json:
        args.json.write_text(json.dumps(results, indent=1) + "\n")
    if args.keep is None:
        shutil.rmtree(out, ignore_errors=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
