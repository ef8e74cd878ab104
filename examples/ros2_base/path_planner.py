"""A small deterministic planner on ROS 2 messages: nav_msgs/msg/Odometry in, nav_msgs/msg/Path out.

Plans the next second of a unicycle at the odometry's pose, rolling forward at
a smoothed speed and the measured turn rate: ten poses 0.1 s apart, stamped
from the odometry's own stamp (never the wall clock), so the same inputs give
the same path, bit for bit. The speed is smoothed across calls (state), as a
planner's would be.

Two faces of the same arithmetic (`plan`):
- `PathPlanner`, the replay factory DeFT names in the spec
  (`planner.replay.factory: path_planner:PathPlanner`): `step(frame)` takes
  `{"odom": decoded Odometry}` (plain dicts, as astaa-deft decodes CDR) and
  returns the decoded Path;
- `planner.py`, the ROS 2 node, which calls `plan` on what zenoh-ros2-sdk decodes.

Like the base, it trusts its input: a NaN pose plans a NaN path.
"""

from __future__ import annotations

import math

POSES = 10
STEP_NS = 100_000_000  # 0.1 s between planned poses
SMOOTHING = 0.5  # weight of the newest speed


def plan(state: dict, x: float, y: float, qz: float, qw: float, v: float, w: float, sec: int, nanosec: int
         ) -> list[tuple[float, float, float, float, int, int]]:
    """(x, y, qz, qw, sec, nanosec) of each planned pose; ``state`` carries the smoothed speed."""
    speed = state.get("speed", v)
    speed = SMOOTHING * v + (1.0 - SMOOTHING) * speed
    state["speed"] = speed
    yaw = 2.0 * math.atan2(qz, qw)
    dt = STEP_NS * 1e-9
    stamp = sec * 1_000_000_000 + nanosec
    poses = []
    for k in range(1, POSES + 1):
        x += speed * math.cos(yaw) * dt
        y += speed * math.sin(yaw) * dt
        yaw += w * dt
        t = stamp + k * STEP_NS
        poses.append((x, y, math.sin(yaw / 2.0), math.cos(yaw / 2.0), t // 1_000_000_000, t % 1_000_000_000))
    return poses


class PathPlanner:
    """DeFT's replay factory: ``PathPlanner().step({"odom": odometry}) -> path`` (decoded messages)."""

    def __init__(self) -> None:
        self.state: dict = {}

    def step(self, frame: dict) -> dict:
        odom = frame["odom"]
        pose, twist = odom["pose"]["pose"], odom["twist"]["twist"]
        stamp = odom["header"]["stamp"]
        poses = plan(self.state, pose["position"]["x"], pose["position"]["y"], pose["orientation"]["z"],
                     pose["orientation"]["w"], twist["linear"]["x"], twist["angular"]["z"],
                     stamp["sec"], stamp["nanosec"])
        return {
            "header": {"stamp": dict(stamp), "frame_id": "odom"},
            "poses": [{"header": {"stamp": {"sec": sec, "nanosec": nanosec}, "frame_id": "odom"},
                       "pose": {"position": {"x": px, "y": py, "z": 0.0},
                                "orientation": {"x": 0.0, "y": 0.0, "z": qz, "w": qw}}}
                      for px, py, qz, qw, sec, nanosec in poses],
        }
