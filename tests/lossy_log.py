"""A real log of the lossy-state planner (tests/sut/lossy.yaml, lossy_state_planner.py) for fork-replay tests."""

from __future__ import annotations

import json

from astaa_deft.io.log.writer import LogWriter
from astaa_deft.engine.spec.loader import load_spec

from proxy_helpers import SUT_DIR

SPEC = (SUT_DIR / "lossy.yaml").read_text()
MS = 1_000_000


def write_lossy_log(tmp_path, late: list[bool], name: str = "late_pose.mcap"):
    """A real log of a planner that, on cycle k, got the pose logged with its tick too late if ``late[k]``."""
    from lossy_state_planner import LossyStatePlanner  # tests/sut, on the path (the callers prepend it)

    spec_path = tmp_path / "lossy.yaml"
    spec_path.write_text(SPEC)
    spec = load_spec(spec_path)
    log_path = tmp_path / name
    w = LogWriter(log_path, spec)
    ids = {name: w.bus_channel(spec.channel(name)) for name in ("pose", "tick", "plan")}
    planner = LossyStatePlanner()
    t0, seq = 1_000_000_000, 0
    for k, too_late in enumerate(late):
        base = t0 + k * 100 * MS
        poses = []
        for j, dt in enumerate((0, MS // 2)):
            seq += 1
            pose = {"header": {"seq": seq, "stamp": 0.1 * k}, "x": 1.0 * k + 0.3 * j, "y": 0.0, "speed": 10.0}
            w.message(ids["pose"], base + dt, json.dumps(pose).encode())
            poses.append(pose)
        tick = {"header": {"seq": k + 1, "stamp": 0.1 * k}}
        w.message(ids["tick"], base + MS, json.dumps(tick).encode())
        plan = planner.step({"pose": poses[0] if too_late else poses[1], "tick": tick})
        w.message(ids["plan"], base + 5 * MS, json.dumps(plan).encode())
    w.event("run_started", time_ns=t0)
    w.finish()
    return spec, log_path
