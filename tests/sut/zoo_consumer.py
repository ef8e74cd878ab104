"""The semantic zoo's consumer (semantic_zoo.yaml): it checks each state and, with --defects 1, fails on
one seeded defect per semantic fault family. Imports nothing from astaa-deft.

Every value is checked first (a number, finite, in a plausible range), as a
careful module does, so no exceptional value (NaN, infinities, huge or empty
values) and no other family reaches a defect; each defect is what a
plausible-but-wrong value of one family gets past those checks:

* boundary: the speed indexes a 10-cell table by ``int(v / 30 * 10)``: at the
  declared max exactly (30) the index is 10 (fixed: clamped to 9);
* angle: the heading is wrapped once, not normalised: two turns on, it is
  still outside [-π, π] (fixed: math.remainder);
* units: the lead gap may not jump by a factor over 50 (m read as mm, rad
  as deg) — it raises instead of rejecting the measurement;
* arrays: a path whose first point is past its last (ids and arc lengths)
  raises (fixed: sorted by arc length);
* type: the battery is read as ``msg["battery"] * 1.0``: removed, null, a
  string or a list raise (fixed: checked like the others);
* siblings: y beyond 50 m (x sent as y) is "off the map" and raises;
* stale: the pace divides by the odometer's advance: a stale copy (the same
  value again on a new message) divides by zero (fixed: skipped).

Duplicated messages (the same sequence number again) are ignored, so a
message fault or a repeated sequence number never looks stale. A defect
raises in the main thread: the traceback names it and the process exits 1.
"""

import argparse
import math

SPEED_TABLE = [0.1 * k for k in range(10)]


def number(value):
    return isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value)


class Consumer:
    """The checks, with (``defects``) or without the seeded defects; ``handle`` takes one decoded message."""

    def __init__(self, defects):
        self.defects = defects
        self.last_seq = None
        self.prev_gap = None
        self.prev_odometer = None

    def handle(self, msg):
        header = msg.get("header") if isinstance(msg.get("header"), dict) else {}
        if header.get("seq") == self.last_seq:
            return  # a duplicate
        self.last_seq = header.get("seq")
        pose = msg.get("pose") if isinstance(msg.get("pose"), dict) else {}
        lead = msg.get("lead") if isinstance(msg.get("lead"), dict) else {}
        self.speed(msg.get("speed"))
        self.heading(pose.get("heading"))
        self.gap(lead.get("gap"))
        self.path(msg.get("path"))
        self.battery(msg)
        self.lateral(pose.get("y"))
        self.odometer(msg.get("odometer"))

    def speed(self, v):
        if not (number(v) and 0.0 <= v <= 30.0):
            return
        index = int(v / 30.0 * 10)
        if not self.defects:
            index = min(index, 9)
        return SPEED_TABLE[index]  # boundary defect: IndexError at exactly 30

    def heading(self, h):
        if not (number(h) and abs(h) <= 8 * math.pi):
            return
        if self.defects:
            if h > math.pi:
                h -= 2 * math.pi
            elif h < -math.pi:
                h += 2 * math.pi
            if not -math.pi <= h <= math.pi:
                raise ValueError(f"angle defect: heading {h} not normalised")
        return math.remainder(h, 2 * math.pi)

    def gap(self, g):
        if not (number(g) and 0.5 <= g <= 1e6):
            return
        if self.prev_gap is not None and self.defects:
            ratio = g / self.prev_gap
            if ratio > 50 or ratio < 0.02:
                raise ValueError(f"units defect: lead gap jumped by a factor {ratio:.3g}")
        self.prev_gap = g

    def path(self, points):
        if not (isinstance(points, list) and len(points) >= 2):
            return
        if not all(isinstance(p, dict) and number(p.get("s")) and number(p.get("id")) for p in points):
            return
        if self.defects and points[0]["s"] > points[-1]["s"] and points[0]["id"] > points[-1]["id"]:
            raise ValueError("arrays defect: the path runs backwards")
        return sorted(points, key=lambda p: p["s"])

    def battery(self, msg):
        if self.defects:
            return msg["battery"] * 1.0  # type defect: KeyError / TypeError on a removed or mistyped field
        value = msg.get("battery")
        return float(value) if number(value) else None

    def lateral(self, y):
        if not (number(y) and abs(y) <= 1000.0):
            return
        if self.defects and y > 50.0:
            raise ValueError(f"siblings defect: y = {y} m is off the map")

    def odometer(self, odo):
        if not (number(odo) and 0.0 <= odo <= 1e5):
            return
        previous = self.prev_odometer
        if previous is not None and odo < previous:
            return  # backwards: rejected
        self.prev_odometer = odo
        if previous is None:
            return
        if not self.defects and odo == previous:
            return
        return 0.05 / (odo - previous)  # stale defect: ZeroDivisionError on the same value again


def main():
    from node_loop import serve  # beside this file (the script's folder is first on sys.path)

    ap = argparse.ArgumentParser()
    ap.add_argument("--defects", default="1")
    args = ap.parse_args()
    consumer = Consumer(args.defects == "1")
    serve(listen="zoo/state", ready="zoo consumer ready", step=consumer.handle)


if __name__ == "__main__":
    main()
