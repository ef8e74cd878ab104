"""A toy planner for DeFT's own tests: drives straight along +x at a constant speed.

``step(frame)`` plans 10 points, 0.1 s apart, from the pose in the frame;
with ``stop=True`` it plans to stand still instead (the "fixed" planner).
``shift`` moves every planned point (a planner whose output "changed").
"""

from __future__ import annotations


class ToyPlanner:
    def __init__(self, stop: bool = False, shift: str = "0"):
        self.stop = stop
        self.shift = float(shift)
        self.seq = 0

    def step(self, frame):
        self.seq += 1
        pose, trigger = frame["pose"], frame["tick"]
        now = trigger["header"]["stamp"]
        v = 0.0 if self.stop else pose["speed"]
        points = [{"t": now + 0.1 * i, "x": pose["x"] + v * 0.1 * i + self.shift, "y": pose["y"], "heading": 0.0}
                  for i in range(10)]
        return {"header": {"seq": self.seq, "stamp": now}, "points": points}
