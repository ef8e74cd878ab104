"""Simulator process: runs a scenario's world in real time and publishes what it sees.

Publishes (plain keys; see ``common.KEYS``): localization 50 Hz, obstacles
10 Hz, traffic_light 5 Hz, status 5 Hz, routing once a second (a latched
topic re-sent for late joiners). Subscribes to the control command.

Start-up: until the first control command arrives (or ``HOLD_TIMEOUT``
passes) the world is frozen at t = 0 and everything is published with stamp
0, so the stack can start in any order. After that, sim time advances with
wall time in fixed physics steps; each step applies the newest command
received, so real message latency between the processes shapes the run.
"""

from __future__ import annotations

import argparse
import math
import sys
import time

import zenoh

from astaa_deft.demo.common import KEYS, ConfigError, Inbox, JsonPublisher, log, run_module
from astaa_deft.demo.messages import BadMessage, command as read_command
from astaa_deft.demo.scenario import ScenarioError, load_scenario
from astaa_deft.demo.world import World

MODULE = "simulator"
PHYSICS_DT = 0.01  # s, 100 Hz
# Publish period of each channel, in physics steps.
PERIOD_STEPS = {"localization": 2, "obstacles": 10, "traffic_light": 20, "status": 20, "routing": 100}
HOLD_TIMEOUT = 20.0  # s of wall time to wait for the stack before running anyway
COMMAND_TIMEOUT = 0.5  # s of sim time without a command before the vehicle brakes on its own
WATCHDOG_DECELERATION = -4.0  # m/s²


class Simulator:
    def __init__(self, session: zenoh.Session, world: World):
        self.world = world
        self.inbox = Inbox(session, MODULE)
        self.inbox.subscribe(KEYS["command"], "command")
        self.publishers = {name: JsonPublisher(session, KEYS[name]) for name in PERIOD_STEPS}
        self.steering = 0.0
        self.acceleration = 0.0
        self.last_command_time: float | None = None  # sim time of the newest usable command
        self._warned_non_finite = False

    def run(self) -> None:
        self.hold()
        self.run_real_time()

    def hold(self) -> None:
        """Publish the frozen t = 0 world until the first control command arrives."""
        deadline = time.monotonic() + HOLD_TIMEOUT
        tick = 0
        while self.last_command_time is None:
            if time.monotonic() > deadline:
                log(MODULE, f"no control command within {HOLD_TIMEOUT:.0f} s; starting anyway")
                return
            self.publish_due(tick, state="waiting")
            tick += 1
            time.sleep(PHYSICS_DT)
            self.take_commands()
        log(MODULE, "first control command received; scenario time starts")

    def run_real_time(self) -> None:
        start = time.monotonic()
        step = 0
        while True:
            self.take_commands()
            self.world.step(PHYSICS_DT, *self.actuation())
            step += 1
            self.publish_due(step, state="done" if self.world.done else "running")
            # Sleep to the next step's wall time; if we fell behind, catch up without sleeping.
            delay = start + step * PHYSICS_DT - time.monotonic()
            if delay > 0:
                time.sleep(delay)

    def take_commands(self) -> None:
        for _, message in self.inbox.drain():
            try:
                cmd = read_command(message)
            except BadMessage as exc:
                log(MODULE, f"ignored malformed command: {exc}")
                continue
            if not (math.isfinite(cmd.steering) and math.isfinite(cmd.acceleration)):
                # Actuators reject non-finite set points; the previous command stays in force.
                if not self._warned_non_finite:
                    log(MODULE, f"ignored non-finite command {cmd} (further ones silently)")
                    self._warned_non_finite = True
                continue
            self.steering, self.acceleration = cmd.steering, cmd.acceleration
            self.last_command_time = self.world.time

    def actuation(self) -> tuple[float, float]:
        """The command in force; brakes if the controller went quiet (a lost control link)."""
        if self.last_command_time is None or self.world.time - self.last_command_time > COMMAND_TIMEOUT:
            return self.steering, WATCHDOG_DECELERATION
        return self.steering, self.acceleration

    def publish_due(self, step: int, state: str) -> None:
        w = self.world
        bodies = {
            "localization": w.localization_body,
            "obstacles": w.obstacles_body,
            "traffic_light": w.traffic_light_body,
            "routing": w.routing_body,
            "status": lambda: w.status_body(state),
        }
        for name, period in PERIOD_STEPS.items():
            if step % period == 0:
                self.publishers[name].publish(bodies[name](), stamp=w.time)


def main(session: zenoh.Session, args: argparse.Namespace) -> None:
    # --defects has no effect here: the seeded defects live in the stack, not in the world.
    try:
        scenario = load_scenario(args.scenario)
    except ScenarioError as exc:
        raise ConfigError(str(exc)) from exc
    Simulator(session, World(scenario)).run()


if __name__ == "__main__":
    sys.exit(run_module(MODULE, "Demo AV simulator: the world, in real time, on Zenoh.", main))
