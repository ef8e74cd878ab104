"""The semantic zoo's source (semantic_zoo.yaml): a vehicle's state at 20 Hz for --seconds s, then exit.

x grows from 100 m, y stays near -40 m, the heading near 0.1 rad, the speed 8–12 m/s (declared 0–30), the
odometer from 150 m up, the battery down from 90 %, the lead gap 25–35 m, and an 8-point path with
increasing ids and arc lengths. Imports nothing from astaa-deft.
"""

import argparse
import json
import math
import signal
import sys
import time

PERIOD = 0.05


def state(i):
    """The ``i``-th state (from 1)."""
    t = i * PERIOD
    return {
        "header": {"seq": i, "stamp": 1.0e9 + t},
        "pose": {"x": 100.0 + 5.0 * t, "y": -40.0 + 0.5 * math.sin(t), "heading": 0.1 + 0.04 * math.sin(t)},
        "speed": 10.0 + 2.0 * math.sin(0.7 * t),
        "odometer": 150.0 + 10.0 * t,
        "battery": 90.0 - 0.1 * t,
        "lead": {"gap": 30.0 + 5.0 * math.sin(0.5 * t), "id": 7},
        "path": [{"id": k + 1, "s": float(k)} for k in range(8)],
    }


def main():
    import zenoh

    ap = argparse.ArgumentParser()
    ap.add_argument("--seconds", type=float, default=10.0)
    args = ap.parse_args()
    signal.signal(signal.SIGTERM, lambda *_: sys.exit(0))
    session = zenoh.open(zenoh.Config.from_env())
    pub = session.declare_publisher("zoo/state", congestion_control=zenoh.CongestionControl.BLOCK)
    time.sleep(0.3)
    next_t = time.monotonic()
    for i in range(1, int(args.seconds / PERIOD) + 1):
        pub.put(json.dumps(state(i)).encode(), encoding=zenoh.Encoding.APPLICATION_JSON)
        next_t += PERIOD
        time.sleep(max(0.0, next_t - time.monotonic()))
    print("zoo source: scenario over", flush=True)
    session.close()


if __name__ == "__main__":
    main()
