"""Run a scenario in one process, without Zenoh or real time: a deterministic closed loop.

The same world, prediction, planner and controller as the real processes,
stepped in lock-step with idealised message timing: every message arrives
at once, a new plan is used from the next control cycle, a command from the
next physics step. Every message makes a JSON round trip, so the recorded
planner frames look exactly like frames rebuilt from a recording.

For tests and tuning only. The real stack differs from this by message
timing — which is what makes ``flaky_cut_in`` flaky there and not here.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from typing import Any
from collections.abc import Callable

from astaa_deft.demo import messages
from astaa_deft.demo.control import Controller
from astaa_deft.demo.planner_core import INPUT_CHANNELS, TRIGGER_CHANNEL, Planner
from astaa_deft.demo.prediction import predict
from astaa_deft.demo.scenario import Scenario, load_scenario
from astaa_deft.demo.simulator import PERIOD_STEPS, PHYSICS_DT
from astaa_deft.demo.world import World


@dataclass
class LoopResult:
    status: dict[str, Any]  # the last status body
    frames: list[dict[str, dict]] = field(default_factory=list)  # every planner frame, in order
    trajectories: list[dict] = field(default_factory=list)  # the planner's output for each frame


class _Wire:
    """Numbers headers per channel and makes each message a JSON round trip."""

    def __init__(self, rewrite: Callable[[str, dict], dict] | None = None) -> None:
        self.seq: dict[str, int] = {}
        self.rewrite = rewrite

    def message(self, channel: str, body: dict, stamp: float) -> dict:
        self.seq[channel] = self.seq.get(channel, 0) + 1
        message = {"header": {"seq": self.seq[channel], "stamp": stamp}, **body}
        if self.rewrite is not None:
            message = self.rewrite(channel, message)
        return json.loads(json.dumps(message))


def run_closed_loop(scenario: str | Scenario, defects: bool = False, max_time: float | None = None,
                    rewrite: Callable[[str, dict], dict] | None = None) -> LoopResult:
    """Run until the scenario is done (or ``max_time`` of sim time); returns what happened.

    ``rewrite(channel, message)``, if given, changes each message as it goes on the wire (the way
    the tool's proxy would in the real stack: Decictor's participants in the benchmarks).
    """
    world = World(scenario if isinstance(scenario, Scenario) else load_scenario(scenario))
    planner, controller, wire = Planner(defects=defects), Controller(defects=defects), _Wire(rewrite)
    result = LoopResult(status={})
    latest: dict[str, dict] = {}
    steering, acceleration = 0.0, 0.0
    step = 0
    limit = max_time if max_time is not None else world.scenario.time_limit
    while not world.done and world.time < limit:
        for channel in ("localization", "traffic_light", "routing"):
            if step % PERIOD_STEPS[channel] == 0:
                latest[channel] = wire.message(channel, getattr(world, f"{channel}_body")(), world.time)
        if step % PERIOD_STEPS["localization"] == 0:
            command = controller.on_localization(messages.localization(latest["localization"]))
            if command is not None:
                steering, acceleration = command["steering"], command["acceleration"]
        if step % PERIOD_STEPS["obstacles"] == 0:
            stamp, obstacles = messages.perception(wire.message("obstacles", world.obstacles_body(), world.time))
            body = {"obstacles": [predict(stamp, o) for o in obstacles]}
            latest[TRIGGER_CHANNEL] = wire.message(TRIGGER_CHANNEL, body, stamp)
            frame = {name: latest[name] for name in INPUT_CHANNELS}
            trajectory = json.loads(json.dumps(planner.step(frame)))
            result.frames.append(frame)
            result.trajectories.append(trajectory)
            controller.on_trajectory(trajectory)  # used from the next control cycle, as on the bus
        world.step(PHYSICS_DT, steering, acceleration)
        step += 1
    result.status = world.status_body("done")
    return result
