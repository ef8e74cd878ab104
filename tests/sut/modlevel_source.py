"""The module-level stack's source (modlevel.yaml): a state at 20 Hz for --seconds s, then exit. Its
``debug`` fields are for a human reading the log: no module reads them. Imports nothing from astaa-deft."""

import argparse
import json
import math
import signal
import sys
import time

PERIOD = 0.05


def state(i):
    t = i * PERIOD
    return {"header": {"seq": i, "stamp": 1.0e9 + t}, "v": 10.0 + 2.0 * math.sin(0.7 * t),
            "debug": {"note": f"tick {i}", "score": 0.5 * i}}


def main():
    import zenoh

    ap = argparse.ArgumentParser()
    ap.add_argument("--seconds", type=float, default=6.0)
    args = ap.parse_args()
    signal.signal(signal.SIGTERM, lambda *_: sys.exit(0))
    session = zenoh.open(zenoh.Config.from_env())
    pub = session.declare_publisher("ml/state", congestion_control=zenoh.CongestionControl.BLOCK)
    time.sleep(0.3)
    next_t = time.monotonic()
    for i in range(1, int(args.seconds / PERIOD) + 1):
        pub.put(json.dumps(state(i)).encode())
        next_t += PERIOD
        time.sleep(max(0.0, next_t - time.monotonic()))
    print("modlevel source: scenario over", flush=True)
    session.close()


if __name__ == "__main__":
    main()
