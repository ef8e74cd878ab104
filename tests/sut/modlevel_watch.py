"""The module-level stack's watchdog (modlevel.yaml): it answers each command with a health message, and,
with --defects 1, dies on a command past 1e6 (a value fault on ``command.u``); the controller never sends one.
``Watch`` is also its replay factory. Imports nothing from astaa-deft.
"""

import argparse
import math
import time


class Watch:
    def __init__(self, defects="1", step_ms="0"):
        self.defects = str(defects) == "1"
        self.step_s = float(step_ms) / 1000.0  # a replayed step's cost (modlevel.yaml's step_ms)
        self.count = 0

    def step(self, frame):
        if self.step_s:
            time.sleep(self.step_s)
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
    from node_loop import serve  # beside this file (the script's folder is first on sys.path)

    ap = argparse.ArgumentParser()
    ap.add_argument("--defects", default="1")
    args = ap.parse_args()
    watch = Watch(args.defects)
    serve(listen="ml/command", publish="ml/health", ready="modlevel watch ready",
          step=lambda message: watch.step({"command": message}))


if __name__ == "__main__":
    main()
