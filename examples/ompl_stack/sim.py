"""The stack's simulator: a kinematic ego on a two-lane road, a parked car and an oncoming one.

A third-party-style program (no astaa-deft import): it finds its Zenoh
session through ``ZENOH_CONFIG``, waits for the planner's liveliness token
before its clock starts, then steps at 20 Hz of wall time:

* the ego follows the newest plan exactly (its pose is the plan's point at
  the current time; without a plan it stands still) and is published every
  step on ``ompl/ego``;
* obstacles are published every second step (10 Hz) on ``ompl/obstacles``
  with their velocity and a predicted trajectory; the status at 10 Hz on
  ``ompl/status``;
* it measures its own ground truth at every step — the ego's box against
  each obstacle's box at their exact poses — and ends the scenario:
  exit 0 when the ego reaches the goal, 1 at the first contact (after a few
  more steps, so the last poses reach the bus), 2 when time runs out.

``--stopped-car D`` adds a car that stands D m ahead of the ego, in its way (D < 0: overlapping it),
from ``--stopped-at`` seconds on (a car that was hidden, or pulled in).
``--truth FILE`` writes what it measured (JSON) for anyone comparing.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import signal
import sys
import threading
import time

import zenoh

DT = 0.05
EGO_LENGTH, EGO_WIDTH = 4.4, 1.8
LANE_Y, ONCOMING_Y = -1.75, 1.75
START_X = 0.0
LIVELINESS_KEY = "ompl_stack/alive/planning"
AFTER_CONTACT_STEPS = 6  # steps published after the first contact before exiting


def main() -> int:
    ap = argparse.ArgumentParser()
    ap.add_argument("--goal-x", type=float, default=50.0)
    ap.add_argument("--time-limit", type=float, default=30.0, help="sim seconds before 'goal not reached'")
    ap.add_argument("--parked-x", type=float, default=20.0)
    ap.add_argument("--oncoming-x", type=float, default=120.0)
    ap.add_argument("--oncoming-speed", type=float, default=6.0)
    ap.add_argument("--stopped-car", type=float, default=0.0,
                    help="metres ahead of the ego (0: none; negative: it appears overlapping the ego's front)")
    ap.add_argument("--stopped-at", type=float, default=5.0)
    ap.add_argument("--wait-planner", type=float, default=20.0, help="seconds to wait for its liveliness")
    ap.add_argument("--truth", default="")
    args = ap.parse_args()

    stop = threading.Event()
    signal.signal(signal.SIGTERM, lambda *_: stop.set())
    signal.signal(signal.SIGINT, lambda *_: stop.set())

    session = zenoh.open(zenoh.Config.from_env())
    pubs = {name: session.declare_publisher(f"ompl/{name}", congestion_control=zenoh.CongestionControl.BLOCK)
            for name in ("ego", "obstacles", "status")}
    plans: list[dict] = []
    lock = threading.Lock()

    def on_plan(sample: zenoh.Sample) -> None:
        try:
            plan = json.loads(sample.payload.to_bytes())
        except ValueError:
            return
        with lock:
            plans.append(plan)
            del plans[:-1]

    session.declare_subscriber("ompl/plan", on_plan)
    planner_alive = threading.Event()
    session.liveliness().declare_subscriber(
        LIVELINESS_KEY, lambda s: planner_alive.set() if s.kind == zenoh.SampleKind.PUT else None, history=True)
    print("simulator: waiting for the planner", flush=True)
    if not planner_alive.wait(args.wait_planner):
        print("simulator: planner not alive, starting anyway", flush=True)

    world = World(args)
    t0 = time.monotonic()
    print("simulator: clock started", flush=True)
    code, step, contact_step = 2, 0, None
    while not stop.is_set():
        t = step * DT
        with lock:
            plan = plans[-1] if plans else None
        world.advance(t, plan)
        touching = world.contacts(t)
        if touching and contact_step is None:
            contact_step = step
            world.contact = touching[0]
            print(f"simulator: contact with obstacle {touching[0][0]} at t={t:.2f} s "
                  f"(depth {touching[0][1]:.3f} m)", flush=True)
        ego = world.ego_message(step, t)
        pubs["ego"].put(json.dumps(ego))
        if step % 2 == 0:
            pubs["obstacles"].put(json.dumps(world.obstacles_message(step // 2, t)))
            pubs["status"].put(json.dumps(world.status(step // 2, t, args.goal_x)))
        if contact_step is not None and step - contact_step >= AFTER_CONTACT_STEPS:
            code = 1
            break
        if contact_step is None and world.x >= args.goal_x:
            code = 0
            break
        if t >= args.time_limit:
            code = 2
            break
        step += 1
        delay = t0 + step * DT - time.monotonic()
        if delay > 0:
            stop.wait(delay)
    if args.truth:
        with open(args.truth, "w") as fh:
            json.dump({"code": code, "contact": world.contact, "contacts": world.truth, "steps": step}, fh)
    print(f"simulator: done, exit code {code}", flush=True)
    time.sleep(0.2)  # the last messages leave before the session closes
    session.close()
    return code


class World:
    def __init__(self, args: argparse.Namespace):
        self.args = args
        self.x, self.y, self.heading, self.v = START_X, LANE_Y, 0.0, 0.0
        self.contact: tuple[int, float, float] | None = None  # (obstacle id, depth m, time s) of the first
        self.truth: list[tuple[int, float, float]] = []  # every contact step: (id, depth, t)
        self.stopped: tuple[float, float, float] | None = None  # where the seeded stopped car stands

    def advance(self, t: float, plan: dict | None) -> None:
        if self.contact is not None:  # a crash stops the car where it is
            self.v = 0.0
            return
        points = plan["points"] if plan else []
        if not points:  # no plan yet: stand still
            return
        if t <= points[0]["t"]:
            p = points[0]
            self.x, self.y, self.heading, self.v = p["x"], p["y"], p["heading"], p["v"]
            return
        for a, b in zip(points, points[1:], strict=False):
            if a["t"] <= t <= b["t"]:
                f = (t - a["t"]) / (b["t"] - a["t"]) if b["t"] > a["t"] else 1.0
                self.x = a["x"] + f * (b["x"] - a["x"])
                self.y = a["y"] + f * (b["y"] - a["y"])
                self.heading = _angle(a["heading"] + f * _angle(b["heading"] - a["heading"]))
                self.v = a["v"] + f * (b["v"] - a["v"])
                return
        p = points[-1]  # past the plan's end: stand at its last point
        self.x, self.y, self.heading, self.v = p["x"], p["y"], p["heading"], 0.0

    def obstacles_at(self, t: float) -> list[dict]:
        a = self.args
        out = [{"id": 1, "kind": "parked_car", "x": a.parked_x, "y": LANE_Y, "heading": 0.0, "vx": 0.0, "vy": 0.0,
                "length": 4.5, "width": 1.9},
               {"id": 2, "kind": "car", "x": a.oncoming_x - a.oncoming_speed * t, "y": ONCOMING_Y,
                "heading": math.pi, "vx": -a.oncoming_speed, "vy": 0.0, "length": 4.6, "width": 1.9}]
        if a.stopped_car != 0 and t >= a.stopped_at:
            if self.stopped is None:
                ahead = a.stopped_car + EGO_LENGTH / 2 + 2.25  # centre to centre: D m between the bumpers
                self.stopped = (self.x + ahead * math.cos(self.heading), self.y + ahead * math.sin(self.heading),
                                self.heading)
            out.append({"id": 50, "kind": "stopped_car", "x": self.stopped[0], "y": self.stopped[1],
                        "heading": self.stopped[2], "vx": 0.0, "vy": 0.0, "length": 4.5, "width": 1.9})
        return out

    def contacts(self, t: float) -> list[tuple[int, float, float]]:
        found = []
        for o in self.obstacles_at(t):
            depth = _depth((self.x, self.y, self.heading, EGO_LENGTH, EGO_WIDTH),
                           (o["x"], o["y"], o["heading"], o["length"], o["width"]))
            if depth > 0:
                found.append((o["id"], depth, t))
        self.truth.extend(found)
        return found

    def ego_message(self, seq: int, t: float) -> dict:
        return {"header": {"seq": seq, "stamp": t}, "x": self.x, "y": self.y, "heading": self.heading, "v": self.v}

    def obstacles_message(self, seq: int, t: float) -> dict:
        items = []
        for o in self.obstacles_at(t):
            o["trajectory"] = [{"t": t + k * 0.5, "x": o["x"] + o["vx"] * k * 0.5, "y": o["y"] + o["vy"] * k * 0.5,
                                "heading": o["heading"]} for k in range(7)]
            items.append(o)
        return {"header": {"seq": seq, "stamp": t}, "obstacles": items}

    def status(self, seq: int, t: float, goal_x: float) -> dict:
        return {"header": {"seq": seq, "stamp": t}, "sim_time": t, "goal_reached": self.x >= goal_x,
                "collision": self.contact is not None,
                "collision_with": self.contact[0] if self.contact is not None else -1}


def _angle(a: float) -> float:
    return math.atan2(math.sin(a), math.cos(a))


def _depth(a: tuple, b: tuple) -> float:
    """How deep two oriented boxes (x, y, heading, length, width) overlap: the smallest push apart, 0 if clear."""
    axes = []
    for _, _, h, _, _ in (a, b):
        axes += [(math.cos(h), math.sin(h)), (-math.sin(h), math.cos(h))]
    dx, dy = b[0] - a[0], b[1] - a[1]
    depth = math.inf
    for ux, uy in axes:
        radius = 0.0
        for _, _, h, length, width in (a, b):
            c, s = math.cos(h), math.sin(h)
            radius += length / 2 * abs(c * ux + s * uy) + width / 2 * abs(-s * ux + c * uy)
        gap = radius - abs(dx * ux + dy * uy)
        if gap <= 0:
            return 0.0
        depth = min(depth, gap)
    return depth


if __name__ == "__main__":
    code = main()
    sys.stdout.flush()
    os._exit(code)
