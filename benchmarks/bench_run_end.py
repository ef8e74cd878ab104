"""Run ends dated from what each module really does: clean runs of a simulator whose exit comes 0.5-3 s after its
last message, beside CPU-bound load, and the deadline findings at their end.

    python benchmarks/bench_run_end.py [--teardowns 0.5,1.5,3] [--baseline 2] [--runs 15] [--load 2]

tests/sut/ticks.yaml (real processes on loopback, a real log): the simulator
ticks, the controller answers each tick within 0.2 s (control_gap: deadline),
the simulator's exit ends the run ``teardown`` seconds after its last tick.
For each teardown, as a campaign does: ``--baseline`` clean runs date their
end with the baseline's own delay and teach the simulator's shutdown delay
(the longest they saw × 2 + 0.5 s), then ``--runs`` runs date theirs by it.
``--load`` CPU-bound loops run beside it the whole time (started and stopped
by their pids, nothing else). A deadline finding after the controller's last
answer is a finding "at the end" — false: the controller answered every tick
there was; one followed by another answer is a true mid-run stall (the load
held the controller back) and is counted apart.

For each run the log also says how the two fixed-grace rules would have dated
the same end: "exit - 1 s" (what the session did before shutdown delays) and
"doc 1 s" (the last message when the exit came within 1 s, else the exit),
so the printout compares, on the same runs, the findings at the end under
each rule. Asserts nothing; prints counts, the measured shutdowns and the load.
"""

from __future__ import annotations

import argparse
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from astaa_deft.engine.session import RunOptions, run_session
from astaa_deft.engine.spec.loader import load_spec
from astaa_deft.io.log import records as rec
from astaa_deft.io.log.reader import read_log
from astaa_deft.orchestration.campaign.baseline import learned_shutdown_delays, learning_shutdown_delays
from astaa_deft.orchestration.journal.model import CaseOutcome

TICKS = Path(__file__).resolve().parent.parent / "tests" / "sut" / "ticks.yaml"
MAX_GAP_NS = 200_000_000  # the spec's control_gap
FIXED_GRACE_NS = 1_000_000_000
LOOP = "while True: pass"


def one_run(spec, directory: Path, name: str, teardown: float, ticks: int, delays: dict[str, float]) -> dict:
    """One clean run; what it found at its end, and when each rule would have dated that end."""
    log = directory / f"{name}.mcap"
    result = run_session(spec, RunOptions(record=log, run_dir=directory / name, time_limit=60.0,
                                          params={"ticks": str(ticks), "teardown": str(teardown)},
                                          shutdown_delays=delays))
    contents = read_log(log)
    answers = contents.on("sim/command")
    [end] = contents.records(rec.RunEnd)
    [exit_] = [e for e in contents.records(rec.ProcessExit) if e.module == "sim"]
    last_tick = max(m.publish_time for m in contents.messages if m.topic in ("sim/ego", "sim/vehicles"))
    last_answer = max((m.publish_time for m in answers), default=last_tick)
    deadline = [v for v in result.violations if v.invariant_kind == "deadline"]
    at_end = [v for v in deadline if v.seq is None or v.seq >= len(answers)]
    minus_grace = min(exit_.time_ns, max(last_tick, exit_.time_ns - FIXED_GRACE_NS))
    doc_fixed = last_tick if exit_.time_ns - last_tick <= FIXED_GRACE_NS else exit_.time_ns
    return {"end_reason": result.end_reason, "shutdowns": result.shutdowns, "at_end": len(at_end),
            "stalls": len(deadline) - len(at_end), "dated_at_last": end.time_ns == last_tick,
            "minus_grace": minus_grace - last_answer > MAX_GAP_NS, "doc_fixed": doc_fixed - last_answer > MAX_GAP_NS}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--teardowns", default="0.5,1.5,3", help="seconds from the last tick to the exit, one module each")
    ap.add_argument("--baseline", type=int, default=2, help="clean runs that teach the delay (per teardown)")
    ap.add_argument("--runs", type=int, default=15, help="runs dated by the learned delay (per teardown)")
    ap.add_argument("--ticks", type=int, default=12)
    ap.add_argument("--load", type=int, default=2, help="CPU-bound loops beside the runs")
    args = ap.parse_args()
    spec = load_spec(TICKS)
    loops = [subprocess.Popen([sys.executable, "-c", LOOP]) for _ in range(args.load)]
    print(f"load average at the start: {os.getloadavg()[0]:.2f} ({args.load} loops of ours beside the other work)")
    rows = []
    t0 = time.monotonic()
    try:
        with tempfile.TemporaryDirectory(prefix="bench_run_end_") as tmp:
            for teardown in (float(t) for t in args.teardowns.split(",")):
                taught: list[CaseOutcome] = []
                for n in range(args.baseline + args.runs):
                    baseline = n < args.baseline
                    delays = learning_shutdown_delays(spec) if baseline else learned_shutdown_delays(taught)
                    run = one_run(spec, Path(tmp), f"t{teardown}-{n}", teardown, args.ticks, delays)
                    if baseline:
                        taught.append(CaseOutcome(status="done", verdict="Pass", summary="Pass",
                                                  shutdowns=run["shutdowns"]))
                    rows.append({**run, "teardown": teardown, "baseline": baseline,
                                 "delay": delays.get("sim"), "load": os.getloadavg()[0]})
    finally:
        for loop in loops:
            loop.kill()
            loop.wait()
    print(f"{'teardown':>8} {'runs':>5} {'learned':>8} {'shutdown s (min/med/max)':>25} {'at end':>7}"
          f" {'exit-1s':>8} {'doc 1s':>7} {'stalls':>7} {'load':>10}")
    for teardown in sorted({r["teardown"] for r in rows}):
        mine = [r for r in rows if r["teardown"] == teardown]
        later = [r for r in mine if not r["baseline"]]
        took = [r["shutdowns"].get("sim", float("nan")) for r in mine]
        loads = [r["load"] for r in mine]
        print(f"{teardown:>8g} {len(mine):>5} {later[0]['delay'] if later else '-':>8}"
              f" {min(took):>8.2f}/{statistics.median(took):.2f}/{max(took):.2f}"
              f" {sum(r['at_end'] for r in mine):>10} {sum(r['minus_grace'] for r in mine):>8}"
              f" {sum(r['doc_fixed'] for r in mine):>7} {sum(r['stalls'] for r in mine):>7}"
              f" {min(loads):>4.1f}-{max(loads):.1f}")
    other = [r for r in rows if r["end_reason"] != "scenario over"]
    print(f"{len(rows)} runs in {time.monotonic() - t0:.0f} s: {sum(r['at_end'] for r in rows)} deadline findings at"
          f" the end with learned delays; the fixed 1 s grace on the same runs: {sum(r['minus_grace'] for r in rows)}"
          f" (exit - 1 s), {sum(r['doc_fixed'] for r in rows)} (last message within 1 s, else the exit);"
          f" {sum(r['stalls'] for r in rows)} true mid-run stalls; {len(other)} runs ended otherwise")


if __name__ == "__main__":
    main()
