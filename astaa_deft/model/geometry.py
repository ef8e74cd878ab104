"""Oriented rectangles on the ground plane and how far apart two of them are.

Shared by the collision monitor and the DeFT collision oracle.

The separating axis theorem: two convex polygons are disjoint exactly when
their projections onto one of their edge normals are disjoint. For two
rectangles that is four axes; the largest gap over those axes is positive
when they are apart (a lower bound of their distance) and, when they
overlap, minus the smallest push that would separate them.
"""

from __future__ import annotations

import math
from dataclasses import dataclass


@dataclass(frozen=True)
class Box:
    """A footprint: centre (x, y), heading in radians from the x axis, length along it, width across."""

    x: float
    y: float
    heading: float
    length: float
    width: float

    def grown(self, margin: float) -> Box:
        """The box with ``margin`` added on every side."""
        return Box(self.x, self.y, self.heading, self.length + 2 * margin, self.width + 2 * margin)

    @property
    def radius(self) -> float:
        return 0.5 * math.hypot(self.length, self.width)


def overlap(a: Box, b: Box) -> float:
    """How deep ``a`` and ``b`` overlap (metres, > 0), or 0.0 when they do not (touching included)."""
    if math.hypot(b.x - a.x, b.y - a.y) >= a.radius + b.radius:  # bounding circles apart: skip the axes
        return 0.0
    return max(0.0, -separation(a, b))


def separation(a: Box, b: Box) -> float:
    """The largest gap between the boxes' projections on their four axes (metres).

    > 0: apart by at least that much; <= 0: touching, or overlapping by that much.
    """
    dx, dy = b.x - a.x, b.y - a.y
    best = -math.inf
    a_axes = _axes(a.heading)
    b_axes = _axes(b.heading)
    for ux, uy in a_axes + b_axes:
        gap = abs(dx * ux + dy * uy) - _half_extent(a, a_axes, ux, uy) - _half_extent(b, b_axes, ux, uy)
        best = max(best, gap)
    return best


def _axes(heading: float) -> tuple[tuple[float, float], tuple[float, float]]:
    c, s = math.cos(heading), math.sin(heading)
    return (c, s), (-s, c)


def _half_extent(box: Box, axes: tuple[tuple[float, float], tuple[float, float]], ux: float, uy: float) -> float:
    (lx, ly), (wx, wy) = axes
    return 0.5 * box.length * abs(lx * ux + ly * uy) + 0.5 * box.width * abs(wx * ux + wy * uy)


def interpolate_pose(poses: list[tuple[float, float, float, float]], t: float) -> tuple[float, float, float] | None:
    """(x, y, heading) at time t from time-sorted (t, x, y, heading) poses; None outside their span."""
    if not poses or t < poses[0][0] or t > poses[-1][0]:
        return None
    for (t0, x0, y0, h0), (t1, x1, y1, h1) in zip(poses, poses[1:], strict=False):
        if t0 <= t <= t1:
            u = 0.0 if t1 == t0 else (t - t0) / (t1 - t0)
            dh = math.atan2(math.sin(h1 - h0), math.cos(h1 - h0))
            return x0 + u * (x1 - x0), y0 + u * (y1 - y0), h0 + u * dh
    t0, x0, y0, h0 = poses[-1]
    return x0, y0, h0


def box_between(a: Box, b: Box, u: float) -> Box:
    """The box a fraction u of the way from a to b (centre linearly, heading the short way round)."""
    dh = math.atan2(math.sin(b.heading - a.heading), math.cos(b.heading - a.heading))
    return Box(a.x + u * (b.x - a.x), a.y + u * (b.y - a.y), a.heading + u * dh,
               a.length + u * (b.length - a.length), a.width + u * (b.width - a.width))


def box_moved(box: Box, vx: float, vy: float, dt: float) -> Box:
    """The box carried dt seconds along a constant velocity (vx, vy)."""
    return Box(box.x + vx * dt, box.y + vy * dt, box.heading, box.length, box.width)
