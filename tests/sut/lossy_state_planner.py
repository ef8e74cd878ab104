"""A planner whose state does not survive a deep copy bit for bit, like one holding extension objects.

Its state (an odometer integrating every pose it planned from) shifts each
plan a little, so a wrong candidate tried on the real state leaves a trace.
``__getstate__`` hands out the state the way a C++ extension's pickling
often does: through a narrower type (float32 here), so a deep copy plans a
few 1e-9 m off from the original.
"""

from __future__ import annotations

import struct


class LossyStatePlanner:
    def __init__(self):
        self.odometer = 0.1  # not exactly representable: a float32 round trip changes it
        self.seq = 0

    def __getstate__(self):
        return {"odometer": struct.unpack("f", struct.pack("f", self.odometer))[0], "seq": self.seq}

    def __setstate__(self, state):
        self.__dict__.update(state)

    def step(self, frame):
        self.seq += 1
        pose, tick = frame["pose"], frame["tick"]
        self.odometer += abs(pose["x"]) * 0.37
        now = tick["header"]["stamp"]
        drift = self.odometer * 1e-3
        points = [{"t": now + 0.1 * i, "x": pose["x"] + pose["speed"] * 0.1 * i + drift, "y": pose["y"],
                   "heading": 0.0} for i in range(10)]
        return {"header": {"seq": self.seq, "stamp": now}, "points": points}
