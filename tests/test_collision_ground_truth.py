"""The collision monitor agrees with a simulator's own ground truth on multi-rate channels.

The simulator (below) steps at 20 Hz: the ego drives along x at 10 m/s and
publishes its pose every step; obstacles cross the road at 5 m/s and are
published every second step (10 Hz). At each step it measures, from the
exact poses, which obstacles the ego overlaps — its ground truth, by its
own arithmetic (every box is axis-aligned here: two overlap when their
centres are closer than half their summed lengths along x and half their
summed widths along y), nothing of the tool's geometry. Some
obstacles graze the ego by a few centimetres, others pass a few centimetres
clear: pairing a pose with the newest obstacle message (0.05 s old, 0.25 m
off at 5 m/s) gets several of them wrong; comparing at one instant gets
none wrong.
"""

from __future__ import annotations

from astaa_deft.engine.monitor.offline import check_log
from monitor_helpers import HandMadeLog, load, obstacle, obstacles, pose

EGO_SPEED, CROSSING_SPEED, STEP = 10.0, 5.0, 0.05
EGO_LENGTH, EGO_WIDTH = 4.0, 2.0
INVARIANT = """
- name: no_collision
  kind: collision
  ego: {channel: localization, length: 4.0, width: 2.0}
  obstacles: {channel: obstacles, array: obstacles, id: id}
"""
# (id, x where it crosses, time its centre crosses y = 0, side it comes from); the ego's centre passes
# x at x / 10 s. A 2 m x 2 m obstacle crossing at 5 m/s meets the 4 m x 2 m ego for a short while only.
CROSSERS = [
    (1, 20.0, 2.00, 1),           # through the middle: a collision either way
    (2, 30.0, 3.00 + 0.62, 1),    # grazes the ego's rear: a collision the newest-message pairing misses
    (3, 40.0, 4.00 - 0.67, -1),   # clears the ego's front: no collision, the newest-message pairing sees one
    (4, 50.0, 5.00 + 0.63, -1),   # grazes the rear, from the other side
    (5, 60.0, 6.00 - 0.68, 1),    # clears the front, from the other side
    (6, 70.0, 7.00 + 0.75, 1),    # well clear behind
]


def crosser_y(t: float, t_cross: float, side: int) -> float:
    return side * CROSSING_SPEED * (t_cross - t)


def boxes_overlap(ego_x: float, x: float, y: float, size: float = 2.0) -> bool:
    """The ego (centre ego_x, 0; heading 0) and a size x size obstacle at (x, y) share some area."""
    return abs(x - ego_x) < (EGO_LENGTH + size) / 2 and abs(y) < (EGO_WIDTH + size) / 2


def simulate(steps: int = 220):
    """(ego messages, obstacle messages, ground truth): messages as (time s, value); truth as set of ids."""
    ego_msgs, obstacle_msgs, truth = [], [], set()
    for k in range(steps):
        t = k * STEP
        ego_x = EGO_SPEED * t
        ego_msgs.append((t, pose(k, x=ego_x)))
        items = []
        for ident, x, t_cross, side in CROSSERS:
            y = crosser_y(t, t_cross, side)
            if abs(y) < 30:
                items.append(obstacle(ident, x, y=y, length=2.0, width=2.0))
                if boxes_overlap(ego_x, x, y):
                    truth.add(ident)
        if k % 2 == 0:
            obstacle_msgs.append((t, obstacles(k // 2, *items)))
    return ego_msgs, obstacle_msgs, truth


def test_no_false_and_no_missed_collisions_against_the_simulator(tmp_path):
    ego_msgs, obstacle_msgs, truth = simulate()
    assert truth == {1, 2, 4}  # the scenario's hits and grazes (CROSSERS); 3, 5 and 6 pass clear
    spec = load(INVARIANT)
    log = HandMadeLog(tmp_path / "run.mcap", spec)
    for (t, value) in sorted([(t, ("obstacles", v)) for t, v in obstacle_msgs] +
                             [(t + 1e-6, ("localization", v)) for t, v in ego_msgs], key=lambda m: m[0]):
        log.message(value[0], t, value[1])
    violations = check_log(log.close(), spec).violations
    reported = {v.message["obstacle_id"] for v in violations}
    assert reported - truth == set(), "false collisions"
    assert truth - reported == set(), "missed collisions"
    assert all(v.message["skew_s"] < 0.001 for v in violations)
