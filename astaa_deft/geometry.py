"""Oriented rectangles in the plane and whether they overlap (separating axis test).

Shared by the collision monitor and the DeFT collision oracle: vehicles and
obstacles are boxes given by centre, heading, length and width.
"""

from __future__ import annotations

import math
from typing import NamedTuple


class Box(NamedTuple):
    x: float
    y: float
    heading: float  # rad
    length: float
    width: float

    def corners(self) -> list[tuple[float, float]]:
        c, s = math.cos(self.heading), math.sin(self.heading)
        hl, hw = self.length / 2.0, self.width / 2.0
        return [(self.x + dx * c - dy * s, self.y + dx * s + dy * c)
                for dx, dy in ((hl, hw), (hl, -hw), (-hl, -hw), (-hl, hw))]

    def grown(self, margin: float) -> "Box":
        return self._replace(length=self.length + 2 * margin, width=self.width + 2 * margin)


def overlap(a: Box, b: Box) -> bool:
    """True if the two boxes intersect (touching counts)."""
    if math.hypot(a.x - b.x, a.y - b.y) > (math.hypot(a.length, a.width) + math.hypot(b.length, b.width)) / 2:
        return False  # cheap reject: bounding circles apart
    ca, cb = a.corners(), b.corners()
    for box in (a, b):
        for angle in (box.heading, box.heading + math.pi / 2):
            ax, ay = math.cos(angle), math.sin(angle)
            pa = [x * ax + y * ay for x, y in ca]
            pb = [x * ax + y * ay for x, y in cb]
            if max(pa) < min(pb) or max(pb) < min(pa):
                return False
    return True


def interpolate_pose(poses: list[tuple[float, float, float, float]], t: float) -> tuple[float, float, float] | None:
    """(x, y, heading) at time t from time-sorted (t, x, y, heading) poses; None outside their span."""
    if not poses or t < poses[0][0] or t > poses[-1][0]:
        return None
    for (t0, x0, y0, h0), (t1, x1, y1, h1) in zip(poses, poses[1:]):
        if t0 <= t <= t1:
            u = 0.0 if t1 == t0 else (t - t0) / (t1 - t0)
            dh = math.atan2(math.sin(h1 - h0), math.cos(h1 - h0))
            return x0 + u * (x1 - x0), y0 + u * (y1 - y0), h0 + u * dh
    t0, x0, y0, h0 = poses[-1]
    return x0, y0, h0
