"""A local planner on OMPL (the Open Motion Planning Library, C++ with Python bindings, from PyPI).

This is the planning module of a small third-party stack; it knows nothing
of astaa-deft. Each cycle it plans from the ego's pose to a point ahead on
its lane with RRT* in a Reeds-Shepp state space (a car's turning radius),
states checked against the obstacles it perceives (moving ones swept along
their velocity), and turns the path into a timed trajectory.

What makes it a realistic replay target:

* its state holds native OMPL objects (state space, space information, the
  RRT* planner and the previous plan as a ``PathGeometric``): they cannot
  be deep-copied, so candidate frames must start from a forked process;
* it is deterministic without being stateless: one fixed seed is set
  before any planner exists (every RNG OMPL creates draws its seed from
  that sequence), every search stops after a number of iterations (never a
  wall-clock budget), and a cycle reuses the previous plan while it stays
  collision-free — so an output depends on every frame before it;
* cycles cost tens to hundreds of milliseconds, and a cycle with no way
  through (both lanes blocked) searches five times longer before it brakes.

``OmplPlanner(**args).step(frame) -> plan`` is also the spec's replay
factory: ``frame`` is ``{"ego": pose, "obstacles": obstacles}``.

``defects=True`` switches on two of the stack's seeded defects (README.md,
"Known defects"; the third is the planning node's); each is reached only by
inputs a clean run never has:

1. an obstacle whose length or width is not a positive number (NaN, 0,
   negative) keeps its last good size, but held for ``CORRUPT_GRACE``
   cycles in a row it raises :class:`CollisionCheckerFault` — the planning
   node lets that kill the process, as a native collision checker's
   segfault would;
2. a non-finite ego heading makes the route's direction ``int(nan)``: a
   ``ValueError`` (the node logs it and carries on, the cycle publishes
   nothing).
"""

from __future__ import annotations

import atexit
import gc
import math
import weakref
from typing import Any

from ompl import base as ob
from ompl import geometric as og
from ompl import util as ou

EGO_LENGTH, EGO_WIDTH = 4.4, 1.8
ROAD_HALF_WIDTH = 3.5
LANE_Y = -1.75  # the ego's own lane (the other, y = +1.75, is the oncoming one)
TURNING_RADIUS = 5.0
CRUISE = 5.0  # m/s
ACCEL, BRAKE = 2.0, 4.0  # m/s²
LOOKAHEAD = 25.0  # m: the local goal ahead of the ego
GOAL_TOLERANCE = 1.0
SWEEP_S, SWEEP_STEP_S = 2.0, 0.5  # moving obstacles occupy where they will be over the next 2 s
MARGIN = 0.3  # m of clearance the planner keeps
REUSE_MIN_LENGTH = 12.0  # m of the previous plan left: below this, plan again
POINT_SPACING = 0.5  # m between trajectory points
CORRUPT_GRACE = 3  # defect 1: cycles in a row a corrupt obstacle size is bridged before the checker fails


class CollisionCheckerFault(RuntimeError):
    """Defect 1: a corrupt obstacle footprint reached the collision checker (the node dies of it)."""


_LIVE: weakref.WeakSet = weakref.WeakSet()


@atexit.register
def _release_all() -> None:
    """Drop the native objects before the interpreter tears OMPL's bindings down (else nanobind reports leaks)."""
    for planner in list(_LIVE):
        planner.release()
    gc.collect()


class OmplPlanner:
    def __init__(self, seed: int = 7, iterations: int = 250, infeasible_iterations: int = 1250,
                 goal_x: float = 50.0, reuse: bool | str = True, defects: bool | str = False):
        ou.setLogLevel(ou.LOG_WARN)
        # Before any planner exists: OMPL seeds each RNG it creates from this sequence. A second
        # planner in one process (a test suite's fresh replay) re-seeds it on purpose; OMPL calls that an
        # error ("not deterministic"), which it is not when the new planner is the only one drawing.
        level = ou.getLogLevel()
        ou.setLogLevel(ou.LOG_NONE)
        ou.RNG.setSeed(int(seed))
        ou.setLogLevel(level)
        # Numbers may come as text (a spec's replay args are strings).
        self.iterations, self.infeasible_iterations = int(iterations), int(infeasible_iterations)
        self.goal_x = float(goal_x)
        # reuse=False plans afresh every cycle (a CPU-heavy planner: every cycle a full search).
        self.reuse = _flag(reuse)
        self.defects = _flag(defects)  # the seeded defects of the module doc
        self.sizes: dict[object, tuple[float, float]] = {}  # defect 1: each obstacle's last good (length, width)
        self.corrupt_cycles = 0  # defect 1: cycles in a row with a corrupt obstacle size
        self.space = ob.ReedsSheppStateSpace(TURNING_RADIUS)
        self._set_bounds(0.0)
        self.si = ob.SpaceInformation(self.space)
        self.si.setStateValidityChecker(self._valid)
        self.si.setStateValidityCheckingResolution(0.01)
        self.si.setup()
        self.planner = og.RRTstar(self.si)
        self.planner.setRange(4.0)
        self.planner.setGoalBias(0.2)
        self.previous: Any = None  # og.PathGeometric of the last plan (native), reused while it stays valid
        self.boxes: list[tuple[float, float, float, float, float]] = []  # (x, y, heading, half l, half w)
        self.seq = 0
        _LIVE.add(self)

    def release(self) -> None:
        """Let go of the OMPL objects (the validity checker holds this planner: a cycle through C++)."""
        self.previous = self.planner = self.si = self.space = None

    # -- geometry ------------------------------------------------------------
    def _set_bounds(self, ego_x: float) -> None:
        bounds = ob.RealVectorBounds(2)
        bounds.setLow(0, ego_x - 3.0)
        bounds.setHigh(0, ego_x + LOOKAHEAD + 5.0)
        bounds.setLow(1, -ROAD_HALF_WIDTH + EGO_WIDTH / 2)
        bounds.setHigh(1, ROAD_HALF_WIDTH - EGO_WIDTH / 2)
        self.space.setBounds(bounds)

    def _valid(self, state: Any) -> bool:
        return self._free(state.getX(), state.getY(), state.getYaw())

    def _free(self, x: float, y: float, yaw: float) -> bool:
        if abs(y) > ROAD_HALF_WIDTH - EGO_WIDTH / 2 + 1e-9:
            return False
        c, s = math.cos(yaw), math.sin(yaw)
        ego_hl, ego_hw = EGO_LENGTH / 2 + MARGIN, EGO_WIDTH / 2 + MARGIN
        for ox, oy, oh, hl, hw in self.boxes:
            if _overlap(x, y, c, s, ego_hl, ego_hw, ox, oy, math.cos(oh), math.sin(oh), hl, hw):
                return False
        return True

    def _perceive(self, obstacles: list[dict]) -> None:
        boxes = []
        corrupt = False
        for o in obstacles:
            x, y, heading = float(o["x"]), float(o["y"]), float(o.get("heading", 0.0))
            vx, vy = float(o.get("vx", 0.0)), float(o.get("vy", 0.0))
            hl, hw = float(o["length"]) / 2, float(o["width"]) / 2
            if self.defects:
                if hl > 0 and hw > 0:  # NaN fails both comparisons
                    self.sizes[o.get("id")] = (hl, hw)
                else:  # bridged with the last good size … for a few cycles only (defect 1)
                    corrupt = True
                    hl, hw = self.sizes.get(o.get("id"), (2.25, 0.95))
            steps = int(SWEEP_S / SWEEP_STEP_S) if (vx or vy) else 0
            for k in range(steps + 1):
                t = k * SWEEP_STEP_S
                boxes.append((x + vx * t, y + vy * t, heading, hl, hw))
        self.boxes = boxes
        if self.defects:
            self.corrupt_cycles = self.corrupt_cycles + 1 if corrupt else 0
            if self.corrupt_cycles >= CORRUPT_GRACE:
                raise CollisionCheckerFault(f"obstacle footprint corrupt for {self.corrupt_cycles} cycles")

    # -- one cycle -------------------------------------------------------------
    def step(self, frame: dict) -> dict:
        ego, obstacles = frame["ego"], frame["obstacles"]
        stamp = float(ego["header"]["stamp"])
        x, y, yaw, v0 = float(ego["x"]), float(ego["y"]), float(ego["heading"]), float(ego["v"])
        if self.defects:
            _route_direction(yaw)  # defect 2: int(nan) raises before the cycle changes any state
        self._perceive(obstacles.get("obstacles", []))
        self._set_bounds(x)
        self.seq += 1
        status, iterations = "reused", 0
        path = self._reusable(x, y) if self.reuse else None
        if path is None:
            path, iterations = self._search(x, y, yaw)
            status = "planned" if path is not None else "stop"
            if iterations > self.iterations:
                status += " after a long search"
        if path is None:
            self.previous = None
            points = _braking(x, y, yaw, v0, stamp)
        else:
            self.previous = path
            points = _timed([(path.getState(i).getX(), path.getState(i).getY(), path.getState(i).getYaw())
                             for i in range(path.getStateCount())], v0, stamp)
        return {"header": {"seq": self.seq, "stamp": stamp}, "status": status, "iterations": iterations,
                "points": points}

    def _reusable(self, x: float, y: float) -> Any:
        """The rest of the previous plan from the ego on, if it is still free and long enough."""
        if self.previous is None:
            return None
        states = [self.previous.getState(i) for i in range(self.previous.getStateCount())]
        nearest = min(range(len(states)), key=lambda i: math.hypot(states[i].getX() - x, states[i].getY() - y))
        if math.hypot(states[nearest].getX() - x, states[nearest].getY() - y) > 1.0:
            return None
        rest = og.PathGeometric(self.si)
        for state in states[nearest:]:
            rest.append(state)
        if rest.length() < REUSE_MIN_LENGTH or not rest.check():
            return None
        return rest

    def _search(self, x: float, y: float, yaw: float) -> tuple[Any, int]:
        start = self.space.allocState()
        start.setX(x)
        start.setY(y)
        start.setYaw(yaw)
        goal = self.space.allocState()
        goal.setX(min(x + LOOKAHEAD, self.goal_x + 10.0))
        goal.setY(LANE_Y)
        goal.setYaw(0.0)
        if not self._valid(start):
            return None, 0  # already touching something: nothing to plan from
        pdef = ob.ProblemDefinition(self.si)
        pdef.setStartAndGoalStates(start, goal, GOAL_TOLERANCE)
        pdef.setOptimizationObjective(ob.PathLengthOptimizationObjective(self.si))
        self.planner.clear()
        self.planner.setProblemDefinition(pdef)
        self.planner.setup()
        count = [0]
        budget = [self.iterations]

        def done() -> bool:  # called once per RRT* iteration: a budget of iterations, never of time
            if count[0] >= budget[0]:
                return True
            count[0] += 1
            return False

        self.planner.solve(ob.PlannerTerminationCondition(done))
        if not pdef.hasExactSolution():
            # No way through yet: search five times longer before giving up (the tree grows on).
            budget[0] = self.infeasible_iterations
            count[0] = 0
            self.planner.solve(ob.PlannerTerminationCondition(done))
            iterations = self.iterations + count[0]
        else:
            iterations = count[0]
        if not pdef.hasExactSolution():
            return None, iterations
        path = og.PathGeometric(pdef.getSolutionPath())
        path.interpolate(max(2, int(path.length() / POINT_SPACING) + 1))
        return path, iterations


def _flag(value: bool | str) -> bool:
    """A switch given as a bool or as text (a spec's replay args and the command line are strings)."""
    return value if isinstance(value, bool) else str(value).strip().lower() not in ("0", "false", "no", "off", "")


def _route_direction(yaw: float) -> int:
    """Which way along the road the ego faces, in quarter turns (0: along +x). Defect 2: int(nan) raises."""
    return int(round(yaw / (math.pi / 2))) % 4


def _timed(poses: list[tuple[float, float, float]], v0: float, stamp: float) -> list[dict]:
    """Points along the path with speeds (accelerating to cruise) and absolute times."""
    points, t, s_prev = [], stamp, 0.0
    v = max(v0, 0.0)
    for i, (x, y, yaw) in enumerate(poses):
        if i:
            px, py, _ = poses[i - 1]
            ds = math.hypot(x - px, y - py)
            v_next = min(CRUISE, math.sqrt(v * v + 2 * ACCEL * ds))
            t += ds / max((v + v_next) / 2, 0.5)
            v, s_prev = v_next, s_prev + ds
        points.append({"x": x, "y": y, "heading": yaw, "v": v, "t": t})
    return points


def _braking(x: float, y: float, yaw: float, v0: float, stamp: float) -> list[dict]:
    """Straight on, braking to a stop: what the planner sends when it finds no way through."""
    points, v, t, dt = [], max(v0, 0.0), stamp, 0.1
    while True:
        points.append({"x": x, "y": y, "heading": yaw, "v": v, "t": t})
        if v <= 0.0:
            return points
        v_next = max(0.0, v - BRAKE * dt)
        ds = (v + v_next) / 2 * dt
        x, y, t, v = x + ds * math.cos(yaw), y + ds * math.sin(yaw), t + dt, v_next


def _overlap(ax, ay, ac, as_, ahl, ahw, bx, by, bc, bs, bhl, bhw) -> bool:
    """Separating-axis test of two oriented boxes (centre, cos/sin heading, half length/width)."""
    dx, dy = bx - ax, by - ay
    for ux, uy in ((ac, as_), (-as_, ac), (bc, bs), (-bs, bc)):
        ra = ahl * abs(ac * ux + as_ * uy) + ahw * abs(-as_ * ux + ac * uy)
        rb = bhl * abs(bc * ux + bs * uy) + bhw * abs(-bs * ux + bc * uy)
        if abs(dx * ux + dy * uy) > ra + rb:
            return False
    return True
