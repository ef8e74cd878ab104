"""The module-level stack's controller (modlevel.yaml): it answers each state with a command, and, with
--defects 1, has two seeded defects — a NaN speed goes into the command (``finite_u`` breaks: reachable by a
value fault on ``state.v``), and a state whose stamp is older than the last one raises (reachable only by a
message fault: a reorder or a delay; stamps are brittle, so no value fault writes them). It never reads
``state.debug``: a field nothing reads. ``Ctrl`` is also its replay factory. Imports nothing from astaa-deft.
"""

import argparse
import math
import time


class Ctrl:
    def __init__(self, defects="1", step_ms="0"):
        self.defects = str(defects) == "1"
        self.step_s = float(step_ms) / 1000.0  # a replayed step's cost (modlevel.yaml's step_ms)
        self.last_stamp = None
        self.integral = 0.0

    def step(self, frame):
        if self.step_s:
            time.sleep(self.step_s)
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
    from node_loop import serve  # beside this file (the script's folder is first on sys.path)

    ap = argparse.ArgumentParser()
    ap.add_argument("--defects", default="1")
    args = ap.parse_args()
    ctrl = Ctrl(args.defects)
    serve(listen="ml/state", publish="ml/command", ready="modlevel ctrl ready",
          step=lambda message: ctrl.step({"state": message}))


if __name__ == "__main__":
    main()
