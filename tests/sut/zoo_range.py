"""The semantic zoo's range monitor (semantic_zoo.yaml): it answers each state with the time to reach the
lead (its gap over the ego's speed). With --defects 1 a standing ego (speed exactly 0, the declared minimum)
gets an infinite time, which the spec's ``finite_ttc`` invariant forbids (fixed: -1, "unknown", as for any
value it cannot use: it answers every state). Every other value is checked first. ``Range`` is also its replay factory. Imports nothing from astaa-deft.
"""

import argparse
import math

UNKNOWN = -1.0


def number(value):
    return isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value)


class Range:
    def __init__(self, defects="1"):
        self.defects = str(defects) == "1"

    def step(self, frame):
        state = frame["state"]
        lead = state.get("lead") if isinstance(state.get("lead"), dict) else {}
        speed, gap = state.get("speed"), lead.get("gap")
        if not (number(speed) and number(gap) and 0.0 <= speed <= 30.0 and gap > 0.0):
            return {"ttc": UNKNOWN}
        if speed == 0.0:
            # boundary defect: standing still is "never", not "unknown"
            return {"ttc": math.inf if self.defects else UNKNOWN}
        return {"ttc": gap / speed}


def main():
    from node_loop import serve  # beside this file (the script's folder is first on sys.path)

    ap = argparse.ArgumentParser()
    ap.add_argument("--defects", default="1")
    args = ap.parse_args()
    monitor = Range(args.defects)
    serve(listen="zoo/state", publish="zoo/range", ready="zoo range ready",
          step=lambda message: monitor.step({"state": message}))


if __name__ == "__main__":
    main()
