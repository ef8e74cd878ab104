"""A recorded run of the warm-started controller (tests/sut/warm_mpc.py), simulated in time, for DeFT tests.

The controller is triggered by ``state`` (15 Hz): idle, it starts a solve as
a state arrives; busy, it answers the newest state when its solve ends and
drops those that came meanwhile. It reads the newest ``path`` (1 Hz, first
message after its first answers) when a solve starts. Solves take 20–110 ms
(seeded jitter), so some start at a state's arrival and some at the end of
the previous solve.
"""

from __future__ import annotations

import json
import random
from pathlib import Path

from astaa_deft.engine.spec.loader import load_spec
from astaa_deft.io.log.writer import LogWriter

from proxy_helpers import SUT_DIR

MS = 1_000_000


def write_mpc_log(directory: Path, seconds: float = 4.0, *, provenance: bool = False, seed: int = 7,
                  tampered: int | None = None, factory: str = "WarmMpc") -> tuple[Path, Path, int]:
    """(spec path, log path, outputs) of a simulated run; ``provenance``: the spec declares ``used``;
    ``tampered``: that output is logged 1.0 off (no frame reproduces it; the state it built still counts);
    ``factory``: the class of tests/sut/warm_mpc.py the spec replays (the run is recorded with it)."""
    import warm_mpc  # tests/sut, on the path (the callers prepend it)

    text = (SUT_DIR / "warm_mpc.yaml").read_text().replace("warm_mpc:WarmMpc", f"warm_mpc:{factory}")
    if provenance:
        text = text.replace("      frames: per_output\n", "      frames: per_output\n      provenance: used\n")
    spec_path = directory / "warm_mpc.yaml"
    spec_path.write_text(text)
    # The factory beside the spec, as a user's stack has it: its suite then runs under plain pytest (the
    # extraction checks it so, in a process of its own, without this test's sys.path).
    (directory / "warm_mpc.py").write_text((SUT_DIR / "warm_mpc.py").read_text())
    spec = load_spec(spec_path)
    rng = random.Random(seed)
    t0 = 1_000_000_000
    events: list[tuple[int, str, dict]] = []
    for k in range(int(seconds * 15)):
        t = t0 + 50 * MS + k * 66 * MS + rng.randrange(0, 3 * MS)
        events.append((t, "state", {"header": {"seq": k + 1, "stamp": t / 1e9}, "y": 0.1 * k, "v": 1.0 + k % 5}))
    for k in range(int(seconds)):
        t = t0 + 400 * MS + k * 1000 * MS
        events.append((t, "path", {"header": {"seq": k + 1, "stamp": t / 1e9}, "y": 1.0 + k}))
    events.sort(key=lambda e: e[0])
    module = getattr(warm_mpc, factory)()
    outputs: list[tuple[int, dict]] = []
    busy_until, newest, newest_path, used_state = 0, None, None, 0
    i = 0
    while i < len(events) or (newest is not None and newest["header"]["seq"] > used_state):
        if newest is not None and newest["header"]["seq"] > used_state and (i >= len(events)
                                                                              or events[i][0] > busy_until):
            start = busy_until  # idle since: the solve starts at once (at the arrival, or when busy ended)
            frame = {"state": newest} | ({"path": newest_path} if newest_path is not None else {})
            used_state = newest["header"]["seq"]
            busy_until = start + rng.randrange(20 * MS, 110 * MS)
            outputs.append((busy_until, module.step(frame)))
            continue
        t, name, message = events[i]
        i += 1
        if name == "state":
            newest = message
            busy_until = max(busy_until, t)
        else:
            newest_path = message
    writer = LogWriter(spec_path.parent / "mpc.mcap", spec)
    ids = {name: writer.bus_channel(spec.channel(name)) for name in ("state", "path", "command")}
    if tampered is not None:
        outputs[tampered][1]["u"] += 1.0
    logged = [(t, name, m) for t, name, m in events] + [(t, "command", m) for t, m in outputs]
    for t, name, message in sorted(logged, key=lambda e: e[0]):
        writer.message(ids[name], t, json.dumps(message).encode())
    writer.event("run_started", time_ns=t0)
    writer.finish()
    return spec_path, spec_path.parent / "mpc.mcap", len(outputs)
