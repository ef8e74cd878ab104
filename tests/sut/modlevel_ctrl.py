"""The module-level stack's controller (modlevel.yaml): it answers each state with a command, and, with
--defects 1, has two seeded defects — a NaN speed goes into the command (``finite_u`` breaks: reachable by a
value fault on ``state.v``), and a state whose stamp is older than the last one raises (reachable only by a
message fault: a reorder or a delay; stamps are brittle, so no value fault writes them). It never reads
``state.debug``: a field nothing reads. ``Ctrl`` is also its replay factory. Imports nothing from astaa-deft.
"""

import argparse
import json
import math
import os
import queue
import signal
import sys
import traceback


class Ctrl:
    def __init__(self, defects="1"):
        self.defects = str(defects) == "1"
        self.last_stamp = None
        self.integral = 0.0

    def step(self, frame):
        state = frame["state"]
        stamp = state["header"]["stamp"]
        if self.last_stamp is not None and stamp < self.last_stamp:
            if self.defects:
                raise ValueError(f"stamp went back: {stamp} < {self.last_stamp}")
            return None  # an old state: ignored
        self.last_stamp = stamp
        v = state["v"]
        if not self.defects and not (isinstance(v, (int, float)) and math.isfinite(v)):
            return None
        self.integral = 0.9 * self.integral + 0.1 * (10.0 - v)
        return {"header": dict(state["header"]), "u": 0.5 * (10.0 - v) + self.integral}


def main():
    import zenoh

    ap = argparse.ArgumentParser()
    ap.add_argument("--defects", default="1")
    args = ap.parse_args()
    inbox = queue.Queue()
    signal.signal(signal.SIGTERM, lambda *_: inbox.put(None))
    session = zenoh.open(zenoh.Config.from_env())
    pub = session.declare_publisher("ml/command")
    session.declare_subscriber("ml/state", lambda sample: inbox.put(sample.payload.to_bytes()))
    print("modlevel ctrl ready", flush=True)
    ctrl = Ctrl(args.defects)
    while True:
        payload = inbox.get()
        if payload is None:
            break
        try:
            message = json.loads(payload)
            out = ctrl.step({"state": message})
        except Exception:  # a seeded defect: its traceback, then exit at once
            traceback.print_exc()
            sys.stderr.flush()
            os._exit(1)
        if out is not None:
            pub.put(json.dumps(out).encode())
    session.close()


if __name__ == "__main__":
    main()
