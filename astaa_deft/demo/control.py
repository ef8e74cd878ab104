"""Control process: follows the newest trajectory at 50 Hz (one command per localization).

Lateral: pure pursuit on the rear axle. Longitudinal: the trajectory's
acceleration as feed-forward plus PID on the speed error. Publishes
``demo/control/command`` stamped with the localization it reacted to.

Three seeded defects live here (README.md): a subtractive angle loop that
hangs on a huge heading (2), an empty trajectory that crashes the nearest-
point search (3), and a backwards timestamp clamped to dt = 0 that divides
into a non-finite command (4).
"""

from __future__ import annotations

import argparse
import math
import sys

import numpy as np
import zenoh

from astaa_deft.demo import vehicle
from astaa_deft.demo.common import KEYS, Inbox, JsonPublisher, log, run_module
from astaa_deft.demo.common import header as common_header
from astaa_deft.demo.geometry import wrap_angle
from astaa_deft.demo.messages import BadMessage, Localization, TrajectoryPoint, header, localization, trajectory

MODULE = "control"
NOMINAL_DT = 0.02  # s between localizations (50 Hz); used before two stamps are known
KP, KI, KD = 1.2, 0.3, 0.05
DERIVATIVE_TAU = 0.1  # s, low-pass on the derivative term (speed is noisy at 50 Hz)
INTEGRAL_LIMIT = 2.0  # m/s·s, anti wind-up
LOOKAHEAD_GAIN, LOOKAHEAD_MIN, LOOKAHEAD_MAX = 0.8, 5.0, 20.0  # lookahead = gain * v, clamped (m)
SPEED_PREVIEW = 0.1  # s: react to where the plan will be, covering actuation delay
HOLD_BRAKE = -2.0  # m/s² while standing still
FALLBACK_BRAKE = -3.0  # m/s² when the planner has no plan
PLAUSIBLE_HEADING = 1000.0  # rad; even an unwrapped heading never gets near this
# m/s; beyond it a measured speed is a corrupted message (its square or difference may overflow to inf,
# and the PID's filtered derivative then turns NaN for good)
PLAUSIBLE_SPEED = 100.0
# s: a localization stamp this far past the previous one is a corrupted message (defects off), not a gap: no
# demo run is that long, and a real gap (messages lost for a while) must still be followed
MAX_STAMP_STEP = 60.0
# Defects off: localizations in a row it cannot use (corrupted, out of order) before it brakes instead of
# keeping its last command — 0.2 s at 50 Hz; a held bad measurement must not keep it accelerating
MAX_BLIND_CYCLES = 10


def normalize_angle_by_loop(angle: float) -> float:
    # SEEDED DEFECT 2: fine for angles near [-pi, pi]; for |angle| >= ~1e16 subtracting
    # 2*pi no longer changes the float, so the loop never ends.
    while angle > math.pi:
        angle -= 2.0 * math.pi
    while angle < -math.pi:
        angle += 2.0 * math.pi
    return angle


class Controller:
    """Pure control law plus its state; one ``on_localization`` call per 50 Hz cycle."""

    def __init__(self, defects: bool = True):
        self.defects = defects
        self.plan: dict[str, np.ndarray] | None = None
        self.plan_seq = 0
        self.brake_for_missing_plan = False
        self.prev_stamp: np.float64 | None = None
        self.prev_error = 0.0
        self.integral = 0.0
        self.derivative = 0.0  # low-passed d(error)/dt
        self.last_command: dict | None = None
        self.blind = 0  # localizations in a row it could not use

    def on_trajectory(self, message: dict) -> None:
        points = trajectory(message)
        self.plan_seq = header(message).seq
        if not self.defects and not points:
            # No points = the planner has no plan: brake rather than follow a stale one.
            self.plan, self.brake_for_missing_plan = None, True
            return
        if not all(math.isfinite(v) for p in points for v in p):
            log(MODULE, f"ignored trajectory {self.plan_seq} with non-finite points")
            return
        if not self.defects and any(abs(p.v) > PLAUSIBLE_SPEED for p in points):
            log(MODULE, f"ignored trajectory {self.plan_seq} with a speed no car reaches")
            return
        # Arrays: the nearest-point search and lookahead below are vectorised.
        columns = np.array([tuple(p) for p in points], dtype=np.float64).reshape(-1, len(TrajectoryPoint._fields))
        self.plan = {name: columns[:, i] for i, name in enumerate(TrajectoryPoint._fields)}
        self.brake_for_missing_plan = False

    def on_localization(self, loc: Localization) -> dict | None:
        """The command for this cycle (None before there is a plan)."""
        if not all(math.isfinite(v) for v in (loc.stamp, loc.x, loc.y, loc.heading, loc.speed)):
            return self._blind()  # a measurement we cannot use: keep the last command
        if not self.defects and abs(loc.heading) > PLAUSIBLE_HEADING:
            return self._blind()  # an angle this large has no usable fraction of a turn left
        if not self.defects and abs(loc.speed) > PLAUSIBLE_SPEED:
            return self._blind()  # no car measures this: a corrupted localization
        if self.plan is None:
            # Nothing to follow yet, or the planner has no plan; the cycle clock starts with a plan.
            if self.brake_for_missing_plan:
                return self._command(self.last_steering(), FALLBACK_BRAKE)
            return None
        stamp = np.float64(loc.stamp)
        if self.prev_stamp is None:
            dt = np.float64(NOMINAL_DT)
        elif self.defects:
            if stamp == self.prev_stamp:
                return self.last_command  # the same localization again (e.g. the simulator's hold)
            # SEEDED DEFECT 4: a stamp older than the previous one clamps dt to 0, and the
            # derivative below divides by it (numpy: inf/nan, no exception).
            dt = max(stamp - self.prev_stamp, np.float64(0.0))
        else:
            if stamp == self.prev_stamp:
                return self.last_command  # the same localization again: nothing new to react to
            if stamp < self.prev_stamp or stamp - self.prev_stamp > MAX_STAMP_STEP:
                # out of order, or a time jump (e.g. to 2100): taken, every later stamp would be "old"
                return self._blind()
            dt = stamp - self.prev_stamp
        self.prev_stamp = stamp
        self.blind = 0
        steering = self._steering(loc)
        acceleration = self._acceleration(loc, dt)
        return self._command(steering, acceleration)

    def _blind(self) -> dict | None:
        """The command for a localization it cannot use: the last one; with defects off, a brake once
        MAX_BLIND_CYCLES came in a row."""
        self.blind += 1
        if not self.defects and self.blind > MAX_BLIND_CYCLES and self.last_command is not None:
            return self._command(self.last_steering(), FALLBACK_BRAKE)
        return self.last_command

    def last_steering(self) -> float:
        return self.last_command["steering"] if self.last_command else 0.0

    def _steering(self, loc: Localization) -> float:
        half = 0.5 * vehicle.WHEELBASE
        rear_x = loc.x - half * math.cos(loc.heading)
        rear_y = loc.y - half * math.sin(loc.heading)
        # The plan's points are box centres; pursue the path its rear axle will follow.
        plan = self.plan
        assert plan is not None  # step() brakes instead of steering when there is no plan
        path_x = plan["x"] - half * np.cos(plan["heading"])
        path_y = plan["y"] - half * np.sin(plan["heading"])
        distances = np.hypot(path_x - rear_x, path_y - rear_y)
        nearest = int(np.argmin(distances))  # SEEDED DEFECT 3: raises on a plan with no points
        lookahead = min(LOOKAHEAD_MAX, max(LOOKAHEAD_MIN, LOOKAHEAD_GAIN * loc.speed))
        beyond = np.nonzero(distances[nearest:] >= lookahead)[0]
        target = nearest + int(beyond[0]) if len(beyond) else len(distances) - 1
        reach = float(distances[target])
        if reach < 0.5:
            return 0.0  # standing on the plan's end: nothing to steer towards
        bearing = math.atan2(path_y[target] - rear_y, path_x[target] - rear_x)
        alpha = normalize_angle_by_loop(bearing - loc.heading) if self.defects else wrap_angle(bearing - loc.heading)
        steering = math.atan2(2.0 * vehicle.WHEELBASE * math.sin(alpha), reach)
        return max(-vehicle.MAX_STEERING, min(vehicle.MAX_STEERING, steering))

    def _acceleration(self, loc: Localization, dt: np.float64) -> float:
        t = loc.stamp + SPEED_PREVIEW
        plan = self.plan
        assert plan is not None  # step() brakes instead of following when there is no plan
        v_ref = float(np.interp(t, plan["t"], plan["v"]))
        a_ref = float(np.interp(t, plan["t"], plan["a"]))
        if v_ref < 0.05 and loc.speed < 0.3:
            self.integral, self.prev_error, self.derivative = 0.0, 0.0, 0.0
            return HOLD_BRAKE
        error = v_ref - loc.speed
        self.integral = max(-INTEGRAL_LIMIT, min(INTEGRAL_LIMIT, self.integral + error * dt))
        raw_derivative = (error - self.prev_error) / dt
        self.derivative += dt / (DERIVATIVE_TAU + dt) * (raw_derivative - self.derivative)
        self.prev_error = error
        command = a_ref + KP * error + KI * self.integral + KD * self.derivative
        return float(np.clip(command, -vehicle.MAX_DECELERATION, vehicle.MAX_ACCELERATION))

    def _command(self, steering: float, acceleration: float) -> dict:
        # float(): numpy scalars serialise the same, but the message should hold plain floats.
        self.last_command = {"steering": float(steering), "acceleration": float(acceleration),
                             "trajectory_seq": self.plan_seq}
        return self.last_command


class ReplayControl:
    """The control process's handling of one localization, without the bus (the spec's ``replay:`` entry).

    ``step(frame)`` gets ``{"localization": the message that triggers this cycle, "trajectory": the newest
    trajectory received before it (absent until one arrives)}`` and returns the command the process
    publishes for it, header included, or None when it publishes nothing. It does what :func:`main`
    does per message: a malformed message is dropped; any other exception is one the process dies of.
    Deterministic: no clock, no randomness; its state pickles.
    """

    def __init__(self, defects: bool = True):
        self.controller = Controller(defects=defects)
        self.trajectory: dict | None = None  # the last trajectory handed to the controller
        self.seq = 0  # header.seq of the commands published (JsonPublisher numbers from 1)

    def step(self, frame: dict) -> dict | None:
        message = frame.get("trajectory")
        if message is not None and message is not self.trajectory and message != self.trajectory:
            self.trajectory = message  # a newer trajectory arrived since the last cycle
            try:
                self.controller.on_trajectory(message)
            except BadMessage as exc:
                log(MODULE, f"ignored malformed trajectory message: {exc}")
        try:
            loc = localization(frame["localization"])
        except BadMessage as exc:
            log(MODULE, f"ignored malformed localization message: {exc}")
            return None
        command = self.controller.on_localization(loc)
        if command is None:
            return None
        self.seq += 1
        return {"header": common_header(self.seq, loc.stamp), **command}


def main(session: zenoh.Session, args: argparse.Namespace) -> None:
    controller = Controller(defects=args.defects)
    inbox = Inbox(session, MODULE)
    inbox.subscribe(KEYS["trajectory"], "trajectory")
    inbox.subscribe(KEYS["localization"], "localization")
    publisher = JsonPublisher(session, KEYS["command"])
    while True:
        received = inbox.get(timeout=0.5)
        if received is None:
            continue
        channel, message = received
        try:
            if channel == "trajectory":
                controller.on_trajectory(message)
                continue
            loc = localization(message)
        except BadMessage as exc:
            log(MODULE, f"ignored malformed {channel} message: {exc}")
            continue
        command = controller.on_localization(loc)
        if command is not None:
            publisher.publish(command, stamp=loc.stamp)


if __name__ == "__main__":
    sys.exit(run_module(MODULE, "Demo AV control: pure pursuit and PID speed control.", main))
