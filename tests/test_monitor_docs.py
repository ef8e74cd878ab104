"""The complete example in docs/monitors.md is a valid invariants section."""

from __future__ import annotations

import re
from pathlib import Path

from astaa_deft.monitor import with_typed_invariants
from astaa_deft.spec_loader import load_spec_text

DOCS = Path(__file__).parent.parent / "docs" / "monitors.md"

SPEC = """\
name: doc
modules:
  - {name: sim, command: "true"}
  - {name: planning, command: "true"}
  - {name: control, command: "true"}
channels:
  - {name: localization, key: d/loc, producer: sim, type: Pose}
  - {name: obstacles, key: d/obs, producer: sim, type: Obstacles}
  - {name: traffic_lights, key: d/lights, producer: sim, type: Lights}
  - {name: lead_vehicle, key: d/lead, producer: sim, type: Relative}
  - {name: trajectory, key: d/traj, producer: planning, type: Trajectory}
  - {name: command, key: d/cmd, producer: control, type: Command}
  - {name: status, key: d/status, producer: control, type: Status}
types:
  Header: {seq: uint64, stamp: time}
  Pose: {header: Header, x: float64, y: float64, heading: float64, speed: float64}
  Obstacle: {id: int32, x: float64, y: float64, heading: float64, length: float64, width: float64}
  Obstacles: {header: Header, obstacles: "Obstacle[]"}
  Light: {id: int32, state: {enum: [red, yellow, green]}, stop_line_x: float64}
  Lights: {header: Header, lights: "Light[]"}
  Relative: {dx: float64, dy: float64}
  Point: {t: float64, x: float64, v: float64}
  Trajectory: {header: Header, points: "Point[]", gear: {enum: [drive, reverse, park]}}
  Command: {header: Header, acceleration: float64, steering: float64}
  Status: {ego_speed: float64, speed_limit: float64, mode: string, planner_points: uint32}
"""


def test_the_documented_example_loads():
    text = DOCS.read_text()
    example = re.search(r"## A complete example\n\n```yaml\n(invariants:\n.*?)```", text, re.DOTALL).group(1)
    spec = with_typed_invariants(load_spec_text(SPEC + example, name="docs/monitors.md"))
    assert [i.kind for i in spec.invariants].count("temporal") == 2
    assert len(spec.invariants) == 15
