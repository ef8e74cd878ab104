"""The demo stack's seeded robustness defects, each fired in a real module process.

Each test starts one module as a subprocess with a client config to the
test router, feeds it the trigger over Zenoh from the router session, and
checks the failure class (see astaa_deft/demo/README.md) — and that with
``--defects off`` the same input is handled.
"""

from __future__ import annotations

import json
import math
import os
import signal
import subprocess
import sys
import threading
import time
from contextlib import contextmanager
from pathlib import Path

import pytest

from conftest import json_bytes, wait_for

REPO = Path(__file__).resolve().parents[1]
KEYS = {
    "routing": "demo/sim/routing",
    "localization": "demo/sim/localization",
    "traffic_light": "demo/sim/traffic_light",
    "prediction": "demo/prediction/obstacles",
    "trajectory": "demo/planning/trajectory",
    "command": "demo/control/command",
}
TRUE_LIMIT = 13.0


@contextmanager
def module_process(name: str, config: Path, defects: str, log: Path):
    """One demo module as a child process; stopped (and only it) on the way out."""
    env = dict(os.environ, PYTHONPATH=os.pathsep.join(filter(None, [str(REPO), os.environ.get("PYTHONPATH")])))
    with log.open("w") as err:
        proc = subprocess.Popen(
            [sys.executable, "-m", f"astaa_deft.demo.{name}", "--zenoh-config", str(config), "--defects", defects],
            cwd=REPO, env=env, stdout=subprocess.DEVNULL, stderr=err,
        )
        try:
            yield proc
        finally:
            if proc.poll() is None:
                proc.terminate()
                try:
                    proc.wait(timeout=5)
                except subprocess.TimeoutExpired:
                    proc.kill()
                    proc.wait()


class Received:
    """Messages on one key, decoded, as they arrive at the router session."""

    def __init__(self, session, key: str):
        self._lock = threading.Lock()
        self._messages: list[dict] = []
        self._subscriber = session.declare_subscriber(key, self._on_sample)

    def _on_sample(self, sample) -> None:
        with self._lock:
            self._messages.append(json.loads(sample.payload.to_bytes()))

    def all(self) -> list[dict]:
        with self._lock:
            return list(self._messages)


class Feeder:
    """Publishes test inputs from the router session, numbering headers per key."""

    def __init__(self, session):
        self.session = session
        self.seq: dict[str, int] = {}

    def put(self, channel: str, body: dict, stamp: float) -> int:
        self.seq[channel] = self.seq.get(channel, 0) + 1
        self.session.put(KEYS[channel], json_bytes({"header": {"seq": self.seq[channel], "stamp": stamp}, **body}))
        return self.seq[channel]

    def localization(self, stamp: float, heading: float = 0.0, speed: float = 10.0) -> int:
        return self.put("localization", {"x": 10.0 * stamp, "y": 0.0, "heading": heading, "speed": speed,
                                         "acceleration": 0.0, "yaw_rate": 0.0}, stamp)

    def straight_trajectory(self, start: float) -> int:
        points = [{"t": start + 0.1 * k, "x": 10.0 * (start + 0.1 * k), "y": 0.0, "heading": 0.0, "v": 10.0, "a": 0.0}
                  for k in range(51)]
        return self.trajectory(points, start)

    def trajectory(self, points: list[dict], stamp: float) -> int:
        return self.put("trajectory", {"points": points, "decision": {"lane": 0, "behavior": "cruise"}}, stamp)


def drive_control_until_commands(feeder: Feeder, commands: Received, start: float = 1.0) -> float:
    """Feed a plan and 50 Hz localizations until control answers; returns the next stamp to use."""
    stamp = start
    deadline = time.monotonic() + 15
    while not commands.all():
        assert time.monotonic() < deadline, "control never published a command"
        feeder.straight_trajectory(stamp)
        for _ in range(5):
            feeder.localization(stamp)
            stamp += 0.02
            time.sleep(0.02)
    return stamp


def keep_localizing(feeder: Feeder, stamp: float, seconds: float) -> float:
    for _ in range(int(seconds / 0.02)):
        feeder.localization(stamp)
        stamp += 0.02
        time.sleep(0.02)
    return stamp


@pytest.fixture
def feeder(zenoh_router):
    return Feeder(zenoh_router[0])


# --- 1. planning: a NaN speed limit defeats the limit check -> silent overspeed ---------

@pytest.mark.parametrize("defects", ["on", "off"])
def test_nan_speed_limit_makes_the_planner_overspeed(zenoh_router, client_config_file, feeder, tmp_path, defects):
    session, _ = zenoh_router
    trajectories = Received(session, KEYS["trajectory"])
    with module_process("planning", client_config_file(), defects, tmp_path / "planning.log") as proc:

        def plan_with(limit: float, stamp: float) -> dict:
            """Feed a full frame each cycle until a plan made with this routing comes back."""
            routing_seqs: set[int] = set()

            def planned() -> dict | None:
                return next((t for t in trajectories.all()
                             if t["debug"]["inputs"]["routing"] in routing_seqs), None)

            def cycle() -> bool:
                nonlocal stamp
                stamp += 0.1
                # Re-sent every cycle, like the simulator's latched routing, so a late subscriber gets it.
                routing_seqs.add(feeder.put("routing", {"lane_count": 2, "lane_width": 3.5, "road_length": 300.0,
                                                        "goal": {"x": 250.0, "lane": 0}, "speed_limit": limit}, stamp))
                feeder.put("traffic_light", {"lights": []}, stamp)
                feeder.localization(stamp, speed=12.0)
                feeder.put("prediction", {"obstacles": []}, stamp)
                return planned() is not None

            assert wait_for(cycle, timeout=15, step=0.1), "planning never used the routing"
            return planned()

        normal = plan_with(TRUE_LIMIT, stamp=1.0)
        assert max(p["v"] for p in normal["points"]) <= TRUE_LIMIT
        poisoned = plan_with(math.nan, stamp=3.0)
        fastest = max(p["v"] for p in poisoned["points"])
        assert proc.poll() is None
    if defects == "on":
        assert fastest > TRUE_LIMIT + 2.0  # silently planned well over the limit
    else:
        assert fastest <= TRUE_LIMIT  # the last good limit still applies


# --- 2. control: a huge heading hangs the subtractive angle loop -> no more commands -----

@pytest.mark.parametrize("defects", ["on", "off"])
def test_huge_heading_hangs_control(zenoh_router, client_config_file, feeder, tmp_path, defects):
    session, _ = zenoh_router
    commands = Received(session, KEYS["command"])
    with module_process("control", client_config_file(), defects, tmp_path / "control.log") as proc:
        stamp = drive_control_until_commands(feeder, commands)
        bad_stamp = stamp
        feeder.localization(bad_stamp, heading=1e300)
        keep_localizing(feeder, bad_stamp + 0.02, seconds=1.5)
        after = [c for c in commands.all() if c["header"]["stamp"] > bad_stamp]
        alive = proc.poll() is None
        if defects == "on":
            assert alive and not after  # hung: alive, silent
            # Even hung, it stops cleanly on SIGTERM.
            proc.send_signal(signal.SIGTERM)
            assert proc.wait(timeout=5) == 0
        else:
            assert alive and len(after) > 20


# --- 3. control: a trajectory without points crashes it ---------------------------------

@pytest.mark.parametrize("defects", ["on", "off"])
def test_empty_trajectory_crashes_control(zenoh_router, client_config_file, feeder, tmp_path, defects):
    session, _ = zenoh_router
    commands = Received(session, KEYS["command"])
    log = tmp_path / "control.log"
    with module_process("control", client_config_file(), defects, log) as proc:
        stamp = drive_control_until_commands(feeder, commands)
        empty_seq = feeder.trajectory([], stamp)
        time.sleep(0.1)
        keep_localizing(feeder, stamp, seconds=1.0)
        if defects == "on":
            assert proc.wait(timeout=5) != 0
            assert "Traceback" in log.read_text()
        else:
            assert proc.poll() is None
            braking = [c for c in commands.all() if c["trajectory_seq"] == empty_seq]
            assert braking and all(c["acceleration"] < 0 for c in braking)


# --- 4. control: a timestamp going backwards divides by zero -> non-finite command -------

@pytest.mark.parametrize("defects", ["on", "off"])
def test_backwards_timestamp_makes_a_non_finite_command(zenoh_router, client_config_file, feeder, tmp_path, defects):
    session, _ = zenoh_router
    commands = Received(session, KEYS["command"])
    with module_process("control", client_config_file(), defects, tmp_path / "control.log") as proc:
        stamp = drive_control_until_commands(feeder, commands)
        feeder.localization(stamp - 0.5)  # half a second into the past
        keep_localizing(feeder, stamp, seconds=0.5)
        assert proc.poll() is None
    values = [c[field] for c in commands.all() for field in ("steering", "acceleration")]
    non_finite = [v for v in values if not math.isfinite(v)]
    if defects == "on":
        assert non_finite
    else:
        assert not non_finite and len(values) > 40
