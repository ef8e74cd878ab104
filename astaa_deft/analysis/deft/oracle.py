"""Collision oracle: turn a recorded collision into a module test that fails.

A planned trajectory is faulty if one of its poses, reached at its planned
time, overlaps an obstacle at that obstacle's predicted pose for the same
time, in the very frame the planner planned from. Such a frame becomes an
oracle test: it fails while the planner still plans into the obstacle and
passes once it does not.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import TYPE_CHECKING

from astaa_deft.io.codecs import get_codec
from astaa_deft.io.codecs.base import DecodeError
from astaa_deft.model.fields import get
from astaa_deft.model.geometry import Box, interpolate_pose, overlap
from astaa_deft.model.sut import Spec
from astaa_deft.engine.spec.replay_module import CollisionOracle, TrajectoryLayout
from astaa_deft.analysis.deft.extract import Extraction

if TYPE_CHECKING:
    from astaa_deft.analysis.deft.oracle_entry import OracleEntry
    from astaa_deft.analysis.deft.suite import Suite
from astaa_deft.analysis.deft.oracle_entry import COLLISION, INVARIANT
from astaa_deft.analysis.deft.planner_section import planner_of
from astaa_deft.analysis.deft.replay import trajectory_points

Pose = tuple[float, float, float, float]  # t, x, y, heading


def planned_poses(message: object, layout: TrajectoryLayout) -> list[Pose]:
    """(t, x, y, heading) of each planned point (heading 0 where the layout's field is missing)."""
    return [(t, x, y, heading) for x, y, t, heading in trajectory_points(message, layout, with_heading=True)]


def first_collision(plan: Sequence[Pose], obstacles_msg: object, oracle: CollisionOracle) -> dict | None:
    """The first planned pose that overlaps a predicted obstacle: {t, obstacle, x, y}, or None."""
    if not isinstance(obstacles_msg, Mapping):
        return None
    found = get(obstacles_msg, oracle.array)
    obstacles = found[0][1] if found and isinstance(found[0][1], list) else []
    tracks = []
    for ob in obstacles:
        try:
            poses = sorted((float(p["t"]), float(p["x"]), float(p["y"]), float(p.get("heading", 0.0)))
                           for p in get(ob, oracle.trajectory)[0][1])
            size = (float(get(ob, oracle.length)[0][1]), float(get(ob, oracle.width)[0][1]))
            ident = get(ob, oracle.id)[0][1] if get(ob, oracle.id) else None
        except (IndexError, KeyError, TypeError, ValueError):
            continue
        tracks.append((ident, poses, size))
    for t, x, y, heading in plan:
        ego = Box(x, y, heading, oracle.ego_length, oracle.ego_width).grown(oracle.margin)
        for ident, poses, (length, width) in tracks:
            pose = interpolate_pose(poses, t)
            if pose is not None and overlap(ego, Box(pose[0], pose[1], pose[2], length, width)) > 0:
                return {"t": t, "obstacle": ident, "x": x, "y": y}
    return None


def oracle_entries(extraction: Extraction, spec: Spec, collision_times_ns: Sequence[int],
                   window_s: float = 5.0) -> list[dict]:
    """Oracle tests for frames whose recorded plan ran into a predicted obstacle shortly before a collision."""
    cfg = planner_of(spec)
    oracle: CollisionOracle | None = cfg.collision
    layout = cfg.trajectory  # the planner section always has one (outputs are trajectories)
    if oracle is None or layout is None or not collision_times_ns:
        return []
    out_codec = get_codec(spec.channel(cfg.output).encoding)
    ob_codec = get_codec(spec.channel(oracle.channel).encoding)
    entries = []
    for f in extraction.frames:
        if f.output is None:
            continue
        if not any(0 <= t - f.output.log_time <= window_s * 1e9 for t in collision_times_ns):
            continue
        try:
            plan = planned_poses(out_codec.decode(f.output.data), layout)
            obstacles = ob_codec.decode(f.inputs[oracle.channel].data)
        except (DecodeError, KeyError):
            continue
        hit = first_collision(plan, obstacles, oracle)
        if hit is not None:
            entries.append({"kind": COLLISION, "frame": f.index, "recorded": hit})
    return entries


def check_oracle(suite: Suite, entry: OracleEntry) -> str | None:
    """Run by the pytest plugin: the reason the test fails, or None."""
    if entry.kind == INVARIANT:  # written by `astaa-deft minimise`
        from astaa_deft.analysis.deft.invariant_oracle import check_invariant_oracle

        return check_invariant_oracle(suite, entry)
    from astaa_deft.analysis.deft.snapshots import usable_snapshot

    cfg = suite.spec.planner
    # Collision oracles are exported only for a planner with a collision oracle and a trajectory layout.
    assert cfg is not None and cfg.collision is not None and cfg.trajectory is not None, "not a collision suite"
    assert entry.frame is not None, "a collision oracle names its frame"
    snapshot = usable_snapshot(suite, entry) if not suite.replayed else None
    if snapshot is not None:  # fail fast: one step from the state just before the frame
        result = suite.result_from_snapshot(entry.frame, snapshot)
    else:
        result = next(r for r in suite.results() if r.index == entry.frame)
    frame_entry = next(e for e in suite.frames if e["index"] == entry.frame)
    obstacles = suite.decoded(cfg.collision.channel, frame_entry["inputs"][cfg.collision.channel])
    hit = first_collision(planned_poses(result.message, cfg.trajectory), obstacles, cfg.collision)
    if hit is None:
        return None
    return (f"frame {entry.frame}: the planned trajectory reaches obstacle {hit['obstacle']} "
            f"at t = {hit['t']:.2f} s (x {hit['x']:.2f}, y {hit['y']:.2f}) as predicted in its own inputs")
