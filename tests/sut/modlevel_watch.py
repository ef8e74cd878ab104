"""The module-level stack's watchdog (modlevel.yaml): it answers each command with a health message, and,
with --defects 1, dies on a command past 1e6 (a value fault on ``command.u``); the controller never sends one.
``Watch`` is also its replay factory. Imports nothing from astaa-deft.
"""

import argparse
import json
import math
import os
import queue
import signal
import sys
import traceback


class Watch:
    def __init__(self, defects="1"):
        self.defects = str(defects) == "1"
        self.count = 0

    def step(self, frame):
        u = frame["command"]["u"]
        if not (isinstance(u, (int, float)) and math.isfinite(u)):
            return {"count": self.count, "level": -1}
        if abs(u) > 1e6:
            if self.defects:
                raise OverflowError(f"command {u} past the actuator's range")
            return {"count": self.count, "level": -1}
        self.count += 1
        return {"count": self.count, "level": min(3, int(abs(u)))}


def main():
    import zenoh

    ap = argparse.ArgumentParser()
    ap.add_argument("--defects", default="1")
    args = ap.parse_args()
    inbox = queue.Queue()
    signal.signal(signal.SIGTERM, lambda *_: inbox.put(None))
    session = zenoh.open(zenoh.Config.from_env())
    pub = session.declare_publisher("ml/health")
    session.declare_subscriber("ml/command", lambda sample: inbox.put(sample.payload.to_bytes()))
    print("modlevel watch ready", flush=True)
    watch = Watch(args.defects)
    while True:
        payload = inbox.get()
        if payload is None:
            break
        try:
            out = watch.step({"command": json.loads(payload)})
        except Exception:  # a seeded defect: its traceback, then exit at once
            traceback.print_exc()
            sys.stderr.flush()
            os._exit(1)
        pub.put(json.dumps(out).encode())
    session.close()


if __name__ == "__main__":
    main()
