"""The semantic zoo's headway monitor (semantic_zoo.yaml): it answers each state with how far the lead is
along the ego's path (the gap plus the path's last arc length). With --defects 1 it reads the last point of
the path without checking there is one: an empty path raises IndexError (fixed: -1, "unknown", as for a
path that is not a list of points: it answers every state). Reversed, shuffled, cut or duplicated paths keep
a last point.
``Headway`` is also its replay factory. Imports nothing from astaa-deft.
"""

import argparse
import math

UNKNOWN = -1.0


def number(value):
    return isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value)


class Headway:
    def __init__(self, defects="1"):
        self.defects = str(defects) == "1"

    def step(self, frame):
        state = frame["state"]
        lead = state.get("lead") if isinstance(state.get("lead"), dict) else {}
        path, gap = state.get("path"), lead.get("gap")
        if not (isinstance(path, list) and number(gap)):
            return {"ahead": UNKNOWN}
        if not all(isinstance(p, dict) and number(p.get("s")) for p in path):
            return {"ahead": UNKNOWN}
        if self.defects:
            end = path[-1]["s"]  # arrays defect: IndexError on an empty path
        elif not path:
            return {"ahead": UNKNOWN}
        else:
            end = max(p["s"] for p in path)
        return {"ahead": gap + end}


def main():
    from node_loop import serve  # beside this file (the script's folder is first on sys.path)

    ap = argparse.ArgumentParser()
    ap.add_argument("--defects", default="1")
    args = ap.parse_args()
    monitor = Headway(args.defects)
    serve(listen="zoo/state", publish="zoo/headway", ready="zoo headway ready",
          step=lambda message: monitor.step({"state": message}))


if __name__ == "__main__":
    main()
