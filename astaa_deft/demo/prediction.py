"""Prediction process: constant-velocity trajectories for every perceived obstacle.

Triggered by each perception message (``demo/sim/obstacles``); publishes
``demo/prediction/obstacles`` stamped with the perception stamp, because the
predicted points are absolute times counted from the moment the obstacles
were seen.
"""

from __future__ import annotations

import argparse
import math
import sys

import zenoh

from astaa_deft.demo.common import KEYS, Inbox, JsonPublisher, log, run_module
from astaa_deft.demo.messages import BadMessage, PerceivedObstacle, perception

MODULE = "prediction"
HORIZON = 5.0  # s
STEP = 0.1  # s between predicted points (the planner's own time step)
POINTS = int(round(HORIZON / STEP)) + 1


def predict(stamp: float, obstacle: PerceivedObstacle) -> dict:
    vx, vy = obstacle.vx, obstacle.vy
    if not (math.isfinite(vx) and math.isfinite(vy)):
        vx = vy = 0.0  # an unknown velocity: predict it standing still rather than nowhere at all
    heading = math.atan2(vy, vx) if (vx or vy) else obstacle.heading
    points = []
    for k in range(POINTS):
        dt = k * STEP
        points.append({"t": round(stamp + dt, 9), "x": obstacle.x + vx * dt, "y": obstacle.y + vy * dt,
                       "heading": heading})
    return {"id": obstacle.id, "kind": obstacle.kind, "length": obstacle.length,
            "width": obstacle.width, "trajectory": points}


def main(session: zenoh.Session, args: argparse.Namespace) -> None:
    inbox = Inbox(session, MODULE)
    inbox.subscribe(KEYS["obstacles"], "obstacles")
    publisher = JsonPublisher(session, KEYS["prediction"])
    while True:
        received = inbox.get(timeout=0.5)
        if received is None:
            continue
        try:
            stamp, obstacles = perception(received[1])
        except BadMessage as exc:
            log(MODULE, f"ignored malformed perception message: {exc}")
            continue
        publisher.publish({"obstacles": [predict(stamp, o) for o in obstacles]}, stamp=stamp)


if __name__ == "__main__":
    sys.exit(run_module(MODULE, "Demo AV prediction: constant-velocity obstacle trajectories.", main))
