"""Decictor's oracle (Section IV-B and the authors' code), as pure functions.

A mutated run is a non-optimal decision when, in order:

1. its task still passed: the goal was reached, no collision in the world,
   and the mutated ego touched none of the injected participants;
2. the seed ego path, replayed at its own times in the mutated scene,
   touches no participant (so the seed's decision was still available);
3. path consistency fails: along each of the ego's lanes a grid of ~2 m
   cells (the cross-lane strip between consecutive stations of the lane's
   centre line, the lane's width wide), a cell occupied when the ego's path
   (its centre) passes through it; per lane the Jaccard similarity of the
   cells the seed and mutated paths occupy; lanes holding under 5 % of all
   the cells either path occupies are dropped (a brush of the boundary);
   the verdict is the worst lane's 1 - Jaccard > 0.4.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from astaa_deft.model.geometry import Box, overlap
from astaa_deft.engine.intercept.actions.participant import Participant
from astaa_deft.analysis.decictor.paths import EgoPath, behaviour_mmd, path_distance, resample

CELL = 2.0  # m along the lane
THRESHOLD = 0.4  # 1 - Jaccard above this on the worst lane: inconsistent (the paper's epsilon = 0.6)
MIN_OCCUPANCY = 0.05
PATH_SAMPLE = 0.25  # m between the path points mapped to cells, so no cell is skipped


@dataclass(frozen=True)
class Lane:
    """A lane: its centre line (a polyline, in driving order) and width."""

    id: str
    centre: tuple[tuple[float, float], ...]
    width: float

    def __post_init__(self) -> None:
        if len(self.centre) < 2 or not self.width > 0:
            raise ValueError(f"lane {self.id}: needs a centre line of two points or more and a positive width")


def straight_lanes(count: int, width: float, length: float) -> tuple[Lane, ...]:
    """Lanes along +x, lane i centred on y = i * width (the demo's road)."""
    return tuple(Lane(str(i), ((0.0, i * width), (length, i * width)), width) for i in range(count))


class LaneGrid:
    """Cells of ~CELL metres along each lane; ``cells(points)`` maps a path to the cells it passes."""

    def __init__(self, lanes: tuple[Lane, ...], cell: float = CELL):
        if not lanes:
            raise ValueError("no lanes: the consistency check needs the ego's lanes")
        self.lanes = lanes
        self.cell = cell
        self._geometry = []
        for lane in lanes:
            pts = np.array(lane.centre, dtype=float)
            seg = np.diff(pts, axis=0)
            lengths = np.hypot(seg[:, 0], seg[:, 1])
            self._geometry.append((pts, seg, lengths, np.concatenate(([0.0], np.cumsum(lengths)))))

    def cell_count(self, lane: int) -> int:
        return max(1, math.ceil(self._geometry[lane][3][-1] / self.cell))

    def locate_all(self, points: np.ndarray) -> list[tuple[np.ndarray, np.ndarray]]:
        """Per lane: (which points lie in its strip, their cell indices), for all points at once."""
        points = np.asarray(points, dtype=float).reshape(-1, 2)
        out = []
        for k, (pts, seg, lengths, stations) in enumerate(self._geometry):
            rel = points[:, None, :] - pts[None, :-1, :]  # (n points, m segments, 2)
            u = np.clip(np.einsum("nmj,mj->nm", rel, seg) / np.maximum(lengths ** 2, 1e-12), 0.0, 1.0)
            foot = pts[None, :-1, :] + seg[None, :, :] * u[:, :, None]
            d = np.hypot(foot[..., 0] - points[:, None, 0], foot[..., 1] - points[:, None, 1])
            j = np.argmin(d, axis=1)
            rows = np.arange(len(points))
            inside = d[rows, j] <= 0.5 * self.lanes[k].width
            station = stations[j] + u[rows, j] * lengths[j]
            cell = np.minimum((station // self.cell).astype(int), self.cell_count(k) - 1)
            out.append((inside, cell))
        return out

    def locate(self, x: float, y: float) -> list[tuple[int, int]]:
        """(lane index, cell index) of every lane strip containing the point."""
        return [(k, int(cell[0])) for k, (inside, cell) in enumerate(self.locate_all(np.array([[x, y]])))
                if inside[0]]

    def cells(self, path: EgoPath) -> dict[int, set[int]]:
        points = resample(path.points, PATH_SAMPLE)
        return {k: set(cell[inside].tolist()) for k, (inside, cell) in enumerate(self.locate_all(points))}


@dataclass(frozen=True, kw_only=True)
class LaneScore:
    lane: str
    jaccard: float
    occupancy: float  # its share of all the cells either path occupies
    seed_cells: int
    mutated_cells: int


@dataclass(frozen=True)
class Consistency:
    lanes: tuple[LaneScore, ...]  # the lanes kept (occupancy >= 5 %)
    worst_lane: str | None
    dissimilarity: float  # 1 - Jaccard on the worst lane

    @property
    def consistent(self) -> bool:
        return self.dissimilarity <= THRESHOLD


def consistency(seed: EgoPath, mutated: EgoPath, grid: LaneGrid) -> Consistency:
    a, b = grid.cells(seed), grid.cells(mutated)
    # A lane's occupancy: its share of all the cells either path occupies (lane lengths do not matter).
    total = max(1, sum(len(a[k] | b[k]) for k in range(len(grid.lanes))))
    scores = []
    for k, lane in enumerate(grid.lanes):
        union, both = a[k] | b[k], a[k] & b[k]
        if not union:
            continue
        occupancy = len(union) / total
        if occupancy < MIN_OCCUPANCY:
            continue
        scores.append(LaneScore(lane=lane.id, jaccard=len(both) / len(union), occupancy=occupancy, seed_cells=len(a[k]),
                                mutated_cells=len(b[k])))
    if not scores:
        return Consistency((), None, 0.0)
    worst = min(scores, key=lambda s: s.jaccard)
    return Consistency(tuple(scores), worst.lane, 1.0 - worst.jaccard)


# ---------------------------------------------------------------- the whole verdict

@dataclass(frozen=True)
class RunObservation:
    """What the oracle needs from one run."""

    ego: EgoPath
    goal_reached: bool
    collision: bool = False  # in the world (the simulator's own objects)


@dataclass(frozen=True, kw_only=True)
class DecisionVerdict:
    non_optimal: bool
    reason: str  # why (or why not)
    consistency: Consistency | None = None
    path_distance: float = 0.0
    behaviour_mmd: float = 0.0
    notes: tuple[str, ...] = field(default_factory=tuple)

    @property
    def fitness(self) -> float:
        return self.path_distance + self.behaviour_mmd


def touches(path: EgoPath, participants: tuple[Participant, ...], margin: float = 0.0) -> str | None:
    """The first contact between the ego path (at its own times) and a participant, described; None if none."""
    for state in path.states:
        ego = path.box(state).grown(margin) if margin else path.box(state)
        for p in participants:
            pose = p.pose_at(state.t)
            if overlap(ego, Box(pose.x, pose.y, pose.heading, p.length, p.width)) > 0.0:
                return f"participant {p.id} at t={state.t:.2f} s ({pose.x:.1f}, {pose.y:.1f})"
    return None


def judge(seed: RunObservation, mutated: RunObservation, participants: tuple[Participant, ...],
          grid: LaneGrid) -> DecisionVerdict:
    """The hierarchical check: task, then the seed path's availability, then path consistency."""
    distance, mmd = path_distance(seed.ego, mutated.ego), behaviour_mmd(seed.ego, mutated.ego)
    if not mutated.goal_reached:
        return DecisionVerdict(non_optimal=False, reason="task failed: the goal was not reached", consistency=None,
                               path_distance=distance, behaviour_mmd=mmd)
    if mutated.collision:
        return DecisionVerdict(non_optimal=False, reason="task failed: a collision in the world", consistency=None,
                               path_distance=distance, behaviour_mmd=mmd)
    hit = touches(mutated.ego, participants)
    if hit is not None:
        return DecisionVerdict(non_optimal=False, reason=f"task failed: the ego touched {hit}", consistency=None,
                               path_distance=distance, behaviour_mmd=mmd)
    blocked = touches(seed.ego, participants)
    if blocked is not None:
        return DecisionVerdict(non_optimal=False, reason=f"invalid mutation: the seed path touches {blocked}",
                               consistency=None, path_distance=distance, behaviour_mmd=mmd)
    result = consistency(seed.ego, mutated.ego, grid)
    if result.consistent:
        return DecisionVerdict(non_optimal=False,
                               reason=f"consistent (1 - Jaccard {result.dissimilarity:.2f} <= {THRESHOLD})",
                               consistency=result, path_distance=distance, behaviour_mmd=mmd)
    return DecisionVerdict(non_optimal=True, reason=f"non-optimal decision: lane {result.worst_lane}: 1 - Jaccard "
                                 f"{result.dissimilarity:.2f} > {THRESHOLD}", consistency=result,
                           path_distance=distance, behaviour_mmd=mmd)
