"""Plane geometry shared by the simulator and the planner: angles and oriented boxes.

Pure functions on Python floats (no numpy) so that the planner stays
bit-for-bit reproducible and the simulator's collision check is the same
code the planner reasons with.
"""

from __future__ import annotations

import math
from typing import NamedTuple

TWO_PI = 2.0 * math.pi


def wrap_angle(angle: float) -> float:
    """The angle in [-pi, pi]; O(1) for any finite input (unlike a subtractive loop)."""
    return math.remainder(angle, TWO_PI)


def smoothstep5(u: float) -> tuple[float, float]:
    """Quintic 0→1 blend on u in [0, 1] with zero slope and curvature at both ends.

    Returns (value, derivative with respect to u). Used for lane-change shapes.
    """
    if u <= 0.0:
        return 0.0, 0.0
    if u >= 1.0:
        return 1.0, 0.0
    return u**3 * (10.0 - 15.0 * u + 6.0 * u * u), 30.0 * u * u * (1.0 - u) ** 2


class Box(NamedTuple):
    """An oriented rectangle: centre, heading, full length (along heading) and width."""

    x: float
    y: float
    heading: float
    length: float
    width: float

    def inflated(self, d_length: float, d_width: float) -> Box:
        return self._replace(length=self.length + d_length, width=self.width + d_width)

    def bounding_radius(self) -> float:
        return 0.5 * math.hypot(self.length, self.width)


def separation(a: Box, b: Box) -> float:
    """Signed gap between two oriented rectangles along the best separating axis.

    Positive: they are apart by at least this much (exactly, for parallel
    boxes). Zero or negative: they overlap, by this much along the axis of
    least penetration. The separating axis test checks the boxes' own axes.
    """
    dx, dy = b.x - a.x, b.y - a.y
    ca, sa = math.cos(a.heading), math.sin(a.heading)
    cb, sb = math.cos(b.heading), math.sin(b.heading)
    best = -math.inf
    for ux, uy in ((ca, sa), (-sa, ca), (cb, sb), (-sb, cb)):
        ra = 0.5 * (a.length * abs(ca * ux + sa * uy) + a.width * abs(-sa * ux + ca * uy))
        rb = 0.5 * (b.length * abs(cb * ux + sb * uy) + b.width * abs(-sb * ux + cb * uy))
        best = max(best, abs(dx * ux + dy * uy) - ra - rb)
    return best


def boxes_overlap(a: Box, b: Box) -> bool:
    """True if the two oriented rectangles intersect (touching counts)."""
    dx, dy = b.x - a.x, b.y - a.y
    reach = a.bounding_radius() + b.bounding_radius()
    if dx * dx + dy * dy > reach * reach:  # cheap reject: most pairs are far apart
        return False
    return separation(a, b) <= 0.0
