"""The stack's planning process: OMPL's RRT* (``ompl_planner.OmplPlanner``) on the Zenoh bus.

Third-party style (no astaa-deft import): the session comes from
``ZENOH_CONFIG``; it holds a liveliness token the simulator waits for.
Each obstacles message (10 Hz) triggers a cycle with the newest ego pose
at that moment; while a cycle runs, newer triggers replace older ones (a
planner that takes longer than the period plans on the freshest inputs).
An exception in a cycle is logged and the node carries on — except the
planner's ``CollisionCheckerFault`` (seeded defect 1, ``--defects 1``),
which stands for a native crash in the collision checker: the process
aborts (SIGABRT), as it would on a segfault.

Seeded defect 3 (``--defects 1``) is the node's own: it watches the ego
stream for stale input, taking the gap between an ego stamp and the newest
one before it in wrapping 32-bit milliseconds (as a C ``uint32_t``). A
stamp older than the newest — a reordered or delayed pose — wraps to a gap
of ~49 days, so the node takes its inputs for stale and answers its next
trigger with an empty "stale input" plan.
"""

from __future__ import annotations

import argparse
import json
import os
import signal
import sys
import threading
import traceback

import zenoh

from ompl_planner import CollisionCheckerFault, OmplPlanner

LIVELINESS_KEY = "ompl_stack/alive/planning"
STALE_GAP_MS = 10_000  # defect 3: an ego stream silent this long is stale: plan nothing until it is fresh


def main() -> int:
    ap = argparse.ArgumentParser()
    ap.add_argument("--seed", type=int, default=7)
    ap.add_argument("--iterations", type=int, default=250)
    ap.add_argument("--infeasible-iterations", type=int, default=1250)
    ap.add_argument("--goal-x", type=float, default=50.0)
    ap.add_argument("--reuse", default="1", help="0: plan afresh every cycle instead of reusing a still-free plan")
    ap.add_argument("--defects", default="0", help="1: the seeded defects of README.md are on")
    args = ap.parse_args()
    stop = threading.Event()
    signal.signal(signal.SIGTERM, lambda *_: stop.set())
    signal.signal(signal.SIGINT, lambda *_: stop.set())

    planner = OmplPlanner(seed=args.seed, iterations=args.iterations,
                          infeasible_iterations=args.infeasible_iterations, goal_x=args.goal_x,
                          reuse=args.reuse, defects=args.defects)
    session = zenoh.open(zenoh.Config.from_env())
    pub = session.declare_publisher("ompl/plan", congestion_control=zenoh.CongestionControl.BLOCK)
    wake = threading.Condition()
    latest: dict = {}
    pending: list[dict] = []
    defects = args.defects.strip().lower() not in ("0", "false", "no", "off", "")
    stale = threading.Event()  # defect 3: the next cycle answers with an empty plan
    newest_ms: list[int] = []

    def on_ego(sample: zenoh.Sample) -> None:
        ego = json.loads(sample.payload.to_bytes())
        latest["ego"] = ego
        if defects:
            stamp_ms = int(float(ego["header"]["stamp"]) * 1000)
            if newest_ms and (stamp_ms - newest_ms[0]) & 0xFFFFFFFF > STALE_GAP_MS:  # a jump back wraps
                stale.set()
            newest_ms[:] = [max([stamp_ms, *newest_ms])]

    def on_obstacles(sample: zenoh.Sample) -> None:
        if "ego" not in latest:
            return  # nothing to plan from yet
        frame = {"ego": latest["ego"], "obstacles": json.loads(sample.payload.to_bytes())}
        with wake:
            pending[:] = [frame]
            wake.notify()

    session.declare_subscriber("ompl/ego", on_ego)
    session.declare_subscriber("ompl/obstacles", on_obstacles)
    token = session.liveliness().declare_token(LIVELINESS_KEY)
    print("planning ready", flush=True)
    while not stop.is_set():
        with wake:
            if not pending:
                wake.wait(0.1)
            if not pending:
                continue
            frame = pending.pop()
        if stale.is_set():
            stale.clear()
            pub.put(json.dumps({"header": {"seq": 0, "stamp": frame["ego"]["header"]["stamp"]},
                                "status": "stale input", "iterations": 0, "points": []}))
            continue
        try:
            plan = planner.step(frame)
        except CollisionCheckerFault:
            traceback.print_exc()
            sys.stderr.flush()
            os.abort()  # defect 1: the native checker's crash takes the process down
        except Exception:  # noqa: BLE001 - a node that logs and survives, as many do
            traceback.print_exc()
            continue
        if plan["status"] != "reused" and plan["iterations"] > args.iterations:
            print(f"planning: long search ({plan['iterations']} iterations): {plan['status']}", flush=True)
        pub.put(json.dumps(plan))
    token.undeclare()
    session.close()
    return 0


if __name__ == "__main__":
    code = main()
    sys.stdout.flush()
    sys.stderr.flush()
    os._exit(code)  # skip the interpreter's teardown of OMPL's native objects (nanobind reports them as leaks)
