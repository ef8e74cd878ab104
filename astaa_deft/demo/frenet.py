"""Building blocks of the sampling planner, in the road (Frenet) frame.

The demo road is straight along +x, so the station ``s`` is x and the
lateral offset ``l`` is y; keeping the Frenet vocabulary keeps the planner
honest about which quantity is which. Everything here is a pure function of
its arguments on Python floats, evaluated in a fixed order: the planner must
be bit-for-bit reproducible.
"""

from __future__ import annotations

import math
from typing import NamedTuple
from collections.abc import Sequence

from astaa_deft.demo.geometry import Box
from astaa_deft.demo.messages import PredictedObstacle

DT = 0.1  # s between trajectory points (prediction uses the same step)
STEPS = 50  # points after the first: a 5 s horizon


class SpeedProfile(NamedTuple):
    """Station, speed and acceleration at t = now + k*DT for k = 0..STEPS."""

    s: tuple[float, ...]
    v: tuple[float, ...]
    a: tuple[float, ...]
    label: str  # how it was made, for debugging ("to 13.9 at 2.0", "stop at 80.0")


def speed_profile(s0: float, v0: float, target: float, rate: float, label: str) -> SpeedProfile:
    """Approach ``target`` speed with acceleration magnitude ``rate``, then hold it."""
    s, v, a = [s0], [v0], []
    for _ in range(STEPS):
        change = max(-rate * DT, min(rate * DT, target - v[-1]))
        v_next = max(0.0, v[-1] + change)
        a.append((v_next - v[-1]) / DT)
        s.append(s[-1] + 0.5 * (v[-1] + v_next) * DT)
        v.append(v_next)
    a.append(a[-1])
    return SpeedProfile(tuple(s), tuple(v), tuple(a), label)


def stop_profile(s0: float, v0: float, distance: float, max_decel: float) -> SpeedProfile:
    """Brake evenly to stand still ``distance`` metres ahead (harder than max_decel: as hard as that)."""
    if distance <= 0.05:
        return speed_profile(s0, v0, 0.0, max_decel if v0 > 0.0 else 0.0, f"stop now from {s0:.1f}")
    rate = v0 * v0 / (2.0 * distance)
    return speed_profile(s0, v0, 0.0, min(rate, max_decel), f"stop at {s0 + distance:.1f}")


class LateralPath:
    """Quintic move from offset l0 (slope d0) at station s0 to l1 ``length`` metres later, then straight.

    Zero curvature at both ends, so the controller sees no steering jump when
    a lane change starts or ends.
    """

    def __init__(self, s0: float, l0: float, d0: float, l1: float, length: float):
        self.s0, self.l0, self.d0, self.l1, self.length = s0, l0, d0, l1, length
        span = l1 - l0 - d0 * length  # what the cubic-and-up terms must still cover
        slope_gap = -d0 * length  # the end slope they must cancel
        self.c3 = 10.0 * span - 4.0 * slope_gap
        self.c4 = -15.0 * span + 7.0 * slope_gap
        self.c5 = 6.0 * span - 3.0 * slope_gap

    def at(self, s: float) -> tuple[float, float]:
        """(offset, slope dl/ds) at station ``s``."""
        ds = s - self.s0
        if ds >= self.length:
            return self.l1, 0.0
        u = max(0.0, ds / self.length)
        offset = self.l0 + self.d0 * self.length * u + self.c3 * u**3 + self.c4 * u**4 + self.c5 * u**5
        slope = (self.d0 * self.length + 3.0 * self.c3 * u**2 + 4.0 * self.c4 * u**3
                 + 5.0 * self.c5 * u**4) / self.length
        return offset, slope


def forecast_boxes(obstacle: PredictedObstacle, now: float) -> list[Box] | None:
    """The obstacle's footprint at now + k*DT, k = 0..STEPS; None if unusable.

    Predicted points are interpolated linearly in time and held flat past
    either end. An obstacle with no usable points carries no information and
    is left out rather than guessed.
    """
    points = sorted((p for p in obstacle.trajectory
                     if math.isfinite(p.t) and math.isfinite(p.x) and math.isfinite(p.y)),
                    key=lambda p: p.t)
    if not points or not (math.isfinite(obstacle.length) and math.isfinite(obstacle.width)):
        return None
    length = min(max(obstacle.length, 0.1), 50.0)
    width = min(max(obstacle.width, 0.1), 10.0)
    boxes, i = [], 0
    for k in range(STEPS + 1):
        t = now + k * DT
        while i + 1 < len(points) and points[i + 1].t <= t:
            i += 1
        p = points[i]
        x, y, heading = p.x, p.y, p.heading
        if i + 1 < len(points) and t > p.t:
            q = points[i + 1]
            w = (t - p.t) / (q.t - p.t)
            x, y = p.x + w * (q.x - p.x), p.y + w * (q.y - p.y)
        boxes.append(Box(x, y, heading if math.isfinite(heading) else 0.0, length, width))
    return boxes


def interpolate(times: Sequence[float], values: Sequence[float], t: float) -> float:
    """Linear interpolation, held flat outside [times[0], times[-1]] (times ascending)."""
    if t <= times[0]:
        return values[0]
    if t >= times[-1]:
        return values[-1]
    hi = next(i for i, ti in enumerate(times) if ti >= t)
    lo = hi - 1
    w = (t - times[lo]) / (times[hi] - times[lo])
    return values[lo] + w * (values[hi] - values[lo])
