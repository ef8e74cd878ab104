"""Run a generated stack on the bus and record it (real processes, Zenoh on loopback, an MCAP log)."""

from __future__ import annotations

from pathlib import Path

from astaa_deft.engine.session import RunOptions, run_session
from astaa_deft.engine.spec.loader import load_spec

from zoo.generate import Stack


def record(stack: Stack, log: Path | None = None, *, mode: str = "passive", run_dir: Path | None = None) -> Path:
    """Run ``stack`` once (until its producer exits: the member's bus time) and return its log.

    ``mode``: "passive" (the recorder observes, as DeFT records; default) or
    "star" (every message through the tool, which knows when it delivered each).
    Raises RuntimeError when the run did not end as planned or recorded nothing of the module's output.
    """
    spec = load_spec(stack.spec_path)
    log = log or stack.directory / "run.mcap"
    result = run_session(spec, RunOptions(mode=mode, record=log, run_dir=run_dir or stack.directory / "run",
                                          time_limit=stack.member.seconds + 30.0,
                                          command_line=["tests/zoo", stack.member.name]))
    if result.crashes or not result.complete:
        raise RuntimeError(f"zoo member {stack.member.name}: the run ended '{result.end_reason}', "
                           f"crashes {[str(c) for c in result.crashes]}, log complete {result.complete}")
    if not result.recorded.get("out"):
        raise RuntimeError(f"zoo member {stack.member.name}: no output recorded ({result.recorded})")
    return log
