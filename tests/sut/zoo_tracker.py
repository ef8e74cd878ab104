"""The semantic zoo's tracker (semantic_zoo.yaml): it answers each state with the speed it estimates from the
odometer's advance over the stamps' advance. With --defects 1 it divides by that advance unchecked: the same
message delivered twice (a duplicate: the same stamp again) divides by zero. Nothing else reaches it — a stale
odometer advances by nothing over a new stamp (0 m/s), a late or reordered state goes back in time and is
ignored, and no value fault writes the stamp (it is brittle). It answers every state (the last estimate when
it cannot make a new one: a module that goes silent is a finding of its own). ``Tracker`` is also its replay
factory. Imports nothing from astaa-deft.
"""

import argparse
import math


def number(value):
    return isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value)


class Tracker:
    def __init__(self, defects="1"):
        self.defects = str(defects) == "1"
        self.last = None  # (stamp, odometer) of the last state used
        self.speed = 0.0  # the last estimate

    def step(self, frame):
        state = frame["state"]
        header = state.get("header") if isinstance(state.get("header"), dict) else {}
        stamp, odometer = header.get("stamp"), state.get("odometer")
        if number(stamp) and number(odometer):
            self.estimate(stamp, odometer)
        return {"header": dict(header), "speed": self.speed}

    def estimate(self, stamp, odometer):
        last = self.last
        if last is not None and stamp < last[0]:
            return  # an old state: ignored
        self.last = (stamp, odometer)
        if last is None or (stamp == last[0] and not self.defects):
            return  # the first state, or the same state again
        self.speed = (odometer - last[1]) / (stamp - last[0])  # duplicate defect: ZeroDivisionError on the same stamp


def main():
    from node_loop import serve  # beside this file (the script's folder is first on sys.path)

    ap = argparse.ArgumentParser()
    ap.add_argument("--defects", default="1")
    args = ap.parse_args()
    tracker = Tracker(args.defects)
    serve(listen="zoo/state", publish="zoo/track", ready="zoo tracker ready",
          step=lambda message: tracker.step({"state": message}))


if __name__ == "__main__":
    main()
