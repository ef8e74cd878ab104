"""The four demo modules as real processes on a real Zenoh router: a short whole run.

The tool gives every module a generated config (client mode, loopback, maybe
a namespace); the modules must work with any of them, started in any order,
and leave with exit code 0 on SIGTERM and SIGINT.
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import threading
from pathlib import Path

from conftest import wait_for

REPO = Path(__file__).resolve().parents[1]
MODULES = ("simulator", "prediction", "planning", "control")


def start(module: str, config: Path, log: Path, args: list[str], via_env: bool) -> subprocess.Popen:
    env = dict(os.environ, PYTHONPATH=os.pathsep.join(filter(None, [str(REPO), os.environ.get("PYTHONPATH")])))
    command = [sys.executable, "-m", f"astaa_deft.demo.{module}", *args]
    if via_env:
        env["ZENOH_CONFIG"] = str(config)
    else:
        command += ["--zenoh-config", str(config)]
    return subprocess.Popen(command, cwd=REPO, env=env, stdout=subprocess.DEVNULL, stderr=log.open("w"))


def stop(proc: subprocess.Popen, sig: signal.Signals = signal.SIGTERM) -> int:
    if proc.poll() is None:
        proc.send_signal(sig)
    try:
        return proc.wait(timeout=10)
    except subprocess.TimeoutExpired:
        proc.kill()
        proc.wait()
        return -9


def test_lane_follow_reaches_the_goal_in_a_namespace_whatever_the_start_order(
        zenoh_router, client_config_file, tmp_path):
    session, _ = zenoh_router
    namespace = "run1/demo"
    statuses: list[dict] = []
    lock = threading.Lock()

    def on_status(sample) -> None:
        with lock:
            statuses.append(json.loads(sample.payload.to_bytes()))

    # Namespaced keys: the modules publish plain demo/… keys, the router sees the prefix.
    subscriber = session.declare_subscriber(f"{namespace}/demo/sim/status", on_status)
    procs: dict[str, subprocess.Popen] = {}
    try:
        # Control first, simulator last: the simulator holds t = 0 until commands flow.
        for module in reversed(MODULES):
            procs[module] = start(module, client_config_file(namespace=namespace), tmp_path / f"{module}.log",
                                  ["--scenario", "lane_follow", "--defects", "off"], via_env=module != "simulator")

        def done() -> bool:
            with lock:
                return bool(statuses) and statuses[-1]["done"]

        assert wait_for(done, timeout=40, step=0.1), [p.poll() for p in procs.values()]
        final = statuses[-1]
        assert final["goal_reached"] and not final["collision"]
        assert 9.0 < final["goal_time"] < 12.0
        assert final["ego_speed"] <= final["speed_limit"]
        assert statuses[0]["state"] == "waiting" or statuses[0]["sim_time"] < 1.0
    finally:
        codes = {m: stop(p, signal.SIGINT if m in ("planning", "control") else signal.SIGTERM)
                 for m, p in procs.items()}
        subscriber.undeclare()
    logs = {m: (tmp_path / f"{m}.log").read_text() for m in procs}
    assert codes == {m: 0 for m in procs}, logs
    assert not any("Traceback" in text for text in logs.values()), logs


def test_a_module_without_a_zenoh_config_says_so(tmp_path):
    env = {k: v for k, v in os.environ.items() if k != "ZENOH_CONFIG"}
    env["PYTHONPATH"] = str(REPO)
    result = subprocess.run([sys.executable, "-m", "astaa_deft.demo.control"], cwd=REPO, env=env,
                            capture_output=True, text=True, timeout=30)
    assert result.returncode == 2
    assert "--zenoh-config" in result.stderr and "ZENOH_CONFIG" in result.stderr


def test_an_unknown_scenario_is_named_in_the_error(client_config_file, tmp_path):
    env = dict(os.environ, PYTHONPATH=str(REPO))
    result = subprocess.run(
        [sys.executable, "-m", "astaa_deft.demo.simulator", "--zenoh-config", str(client_config_file()),
         "--scenario", "no_such_scenario"],
        cwd=REPO, env=env, capture_output=True, text=True, timeout=30)
    assert result.returncode == 2
    assert "no_such_scenario" in result.stderr and "lane_follow" in result.stderr
