"""The ego's driving path as Decictor sees it, and the paper's two feedback distances.

Pure functions on typed records: an ``EgoPath`` is the ego's sampled states
(time, position, heading, speed, acceleration) from one run; the search is
steered by ``path_distance`` (the paper's Eq. 7: the mean over the mutated
path of each point's distance to the nearest seed-path point, both paths
resampled every 2 m) plus ``behaviour_mmd`` (Eq. 8: the maximum mean
discrepancy between the two runs' (heading, speed, acceleration) samples,
scaled and weighted as in the authors' code).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from astaa_deft.model.geometry import Box

RESAMPLE_STEP = 2.0  # m, as in the paper and the authors' code
# Behaviour features: ranges they are scaled by (heading in [-pi, pi], speed in [0, 12] m/s,
# acceleration in [0, 10] m/s² as magnitude), weights, and the overall factor — the authors' code.
FEATURE_RANGES = (math.pi, 12.0, 10.0)
FEATURE_WEIGHTS = (1.0, 0.5, 0.5)
MMD_FACTOR = 10.0


@dataclass(frozen=True, kw_only=True)
class EgoState:
    t: float
    x: float
    y: float
    heading: float
    speed: float = 0.0
    acceleration: float = 0.0


@dataclass(frozen=True)
class EgoPath:
    """The ego's states in time order (times non-decreasing), and its footprint size."""

    states: tuple[EgoState, ...]
    length: float = 4.6
    width: float = 1.9

    def __post_init__(self) -> None:
        if any(b.t < a.t for a, b in zip(self.states, self.states[1:], strict=False)):
            raise ValueError("ego states must be in time order")

    @property
    def points(self) -> np.ndarray:
        return np.array([(s.x, s.y) for s in self.states], dtype=float).reshape(-1, 2)

    @property
    def start(self) -> float:
        return self.states[0].t if self.states else 0.0

    @property
    def end(self) -> float:
        return self.states[-1].t if self.states else 0.0

    def box(self, state: EgoState) -> Box:
        return Box(state.x, state.y, state.heading, self.length, self.width)

    def state_at(self, t: float) -> EgoState | None:
        """Interpolated state at ``t``; None outside the recorded span."""
        states = self.states
        if not states or t < states[0].t or t > states[-1].t:
            return None
        times = [s.t for s in states]
        k = int(np.searchsorted(times, t, side="right"))
        if k >= len(states):
            return states[-1]
        a, b = states[k - 1], states[k]
        u = 0.0 if b.t == a.t else (t - a.t) / (b.t - a.t)
        dh = math.atan2(math.sin(b.heading - a.heading), math.cos(b.heading - a.heading))
        return EgoState(t=t, x=a.x + u * (b.x - a.x), y=a.y + u * (b.y - a.y), heading=a.heading + u * dh,
                        speed=a.speed + u * (b.speed - a.speed),
                        acceleration=a.acceleration + u * (b.acceleration - a.acceleration))

    def thinned(self, spacing: float) -> tuple[EgoState, ...]:
        """States at least ``spacing`` metres apart (first and last kept): enough for footprints."""
        if not self.states:
            return ()
        kept = [self.states[0]]
        for state in self.states[1:]:
            if math.hypot(state.x - kept[-1].x, state.y - kept[-1].y) >= spacing:
                kept.append(state)
        if kept[-1] is not self.states[-1]:
            kept.append(self.states[-1])
        return tuple(kept)


def resample(points: np.ndarray, step: float = RESAMPLE_STEP) -> np.ndarray:
    """Points every ``step`` metres of arc length along a polyline (first and last included)."""
    points = np.asarray(points, dtype=float).reshape(-1, 2)
    if len(points) < 2:
        return points
    seg = np.hypot(*np.diff(points, axis=0).T)
    arc = np.concatenate(([0.0], np.cumsum(seg)))
    if arc[-1] == 0.0:
        return points[:1]
    stations = np.arange(0.0, arc[-1], step)
    stations = np.append(stations, arc[-1]) if stations[-1] < arc[-1] else stations
    return np.column_stack([np.interp(stations, arc, points[:, 0]), np.interp(stations, arc, points[:, 1])])


def path_distance(seed: EgoPath, mutated: EgoPath, step: float = RESAMPLE_STEP) -> float:
    """Eq. 7: mean over the mutated path's points of the distance to the nearest seed-path point."""
    a, b = resample(seed.points, step), resample(mutated.points, step)
    if len(a) == 0 or len(b) == 0:
        return 0.0
    d = np.hypot(b[:, None, 0] - a[None, :, 0], b[:, None, 1] - a[None, :, 1])
    return float(d.min(axis=1).mean())


def behaviour_features(path: EgoPath) -> np.ndarray:
    """(heading, speed, acceleration) per state, each scaled by its range, clipped and weighted."""
    if not path.states:
        return np.zeros((0, 3))
    raw = np.array([(math.atan2(math.sin(s.heading), math.cos(s.heading)), s.speed, abs(s.acceleration))
                    for s in path.states], dtype=float)
    ranges, weights = np.array(FEATURE_RANGES), np.array(FEATURE_WEIGHTS)
    low = np.array([-math.pi, 0.0, 0.0])
    scaled = np.clip(raw, low, ranges) / ranges
    return scaled * weights


def behaviour_mmd(seed: EgoPath, mutated: EgoPath) -> float:
    """Eq. 8 with a linear kernel: the distance between the mean feature vectors, times the paper's factor."""
    a, b = behaviour_features(seed), behaviour_features(mutated)
    if len(a) == 0 or len(b) == 0:
        return 0.0
    diff = a.mean(axis=0) - b.mean(axis=0)
    return MMD_FACTOR * float(np.sqrt(diff @ diff))


def fitness(seed: EgoPath, mutated: EgoPath) -> float:
    """Eq. 9: path feedback + behaviour feedback (larger: further from the seed's decision)."""
    return path_distance(seed, mutated) + behaviour_mmd(seed, mutated)
