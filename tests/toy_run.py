"""A recorded run of the toy planner (tests/sut/toy_planner.py) of any length, for extraction and output tests.

The spec is test_deft_oracle's (a simulator publishing pose and tick, the
toy planner answering with a plan); ``cycles`` planning cycles at 10 Hz, in
chunks of ``chunk_size`` bytes (small chunks: damage costs a few messages,
not the whole log). The spec's replay factory needs tests/sut importable.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

SUT = Path(__file__).resolve().parent / "sut"


def toy_log(directory: Path, cycles: int, *, chunk_size: int | None = None) -> tuple[Path, Path]:
    """Write ``directory/toy.yaml`` and ``directory/toy.mcap``; returns (spec, log)."""
    from astaa_deft.io.log.writer import LogWriter
    from astaa_deft.engine.spec.loader import load_spec

    sys.path[:0] = [str(SUT), str(SUT.parent)]
    try:
        from test_deft_oracle import SPEC
        from toy_planner import ToyPlanner

        spec_path = directory / "toy.yaml"
        spec_path.write_text(SPEC)
        spec = load_spec(spec_path)
    finally:
        del sys.path[:2]
    log_path = directory / "toy.mcap"
    w = LogWriter(log_path, spec, **({"chunk_size": chunk_size} if chunk_size else {}))
    ids = {name: w.bus_channel(spec.channel(name)) for name in ("pose", "tick", "plan")}
    planner = ToyPlanner()
    for k in range(cycles):
        now = 0.1 * k
        pose = {"header": {"seq": k + 1, "stamp": now}, "x": 10.0 * now, "y": 0.0, "speed": 10.0}
        tick = {"header": {"seq": k + 1, "stamp": now}, "obstacles": []}
        base = 1_000_000_000 + k * 100_000_000
        w.message(ids["pose"], base, json.dumps(pose).encode())
        w.message(ids["tick"], base + 1_000_000, json.dumps(tick).encode())
        w.message(ids["plan"], base + 5_000_000, json.dumps(planner.step({"pose": pose, "tick": tick})).encode())
    w.metadata("astaa-deft.run", {"spec": "toy", "params": json.dumps({"stop": "off", "shift": "0"})})
    w.finish()
    return spec_path, log_path
