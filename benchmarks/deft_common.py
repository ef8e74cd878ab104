"""Shared helpers for the DeFT benchmarks: record demo runs, read their outcome, match outputs.

Runs are recorded passively (as DeFT records: no star in the path) with the
demo's seeded defects off, and stopped as soon as the simulator's `status`
channel says the scenario is done (goal, collision or its time limit) — the
way `astaa-deft demo run` stops: by the demo spec's run: section.
"""

from __future__ import annotations

import math
import time
from bisect import bisect_left
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any
from collections.abc import Sequence

from astaa_deft.io.codecs import get_codec
from astaa_deft.analysis.deft.replay import trajectory_points
from astaa_deft.analysis.deft.validator import Point, compare
from astaa_deft.demo.bundled import demo_spec_path
from astaa_deft.demo.status import StatusWatch
from astaa_deft.io.log.reader import LogContents
from astaa_deft.engine.session import RunOptions, run_session
from astaa_deft.engine.spec.loader import load_spec
from astaa_deft.model.sut import Spec

PAPER_THRESHOLDS = (0.0, 0.1, 0.23, 1.62, 6.99, 17.15)
RUN_TIME_LIMIT = 60.0  # wall s; every bundled scenario is done in < 25 s of sim time
MATCH_TOLERANCE = 0.05  # s of header.stamp: half the 10 Hz planning cycle


def demo_spec() -> Spec:
    return load_spec(demo_spec_path())


DoneWatch = StatusWatch  # the demo's status as seen: goal, collision, clearance


@dataclass
class RunRecord:
    path: Path
    scenario: str
    wall_seconds: float  # whole run: start (router, recorder, modules) to the log being finished
    driving_seconds: float  # from the modules' launch to the stop condition
    reason: str
    collision: bool
    collision_with: str | None
    sim_time: float
    min_clearance: float
    crashes: int


def record_run(spec: Spec, scenario: str, path: Path, time_limit: float = RUN_TIME_LIMIT) -> RunRecord:
    params = {"scenario": scenario, "defects": "off"}
    options = RunOptions(mode="passive", record=path, params=params, time_limit=time_limit,
                         command_line=["benchmarks/deft_reproduction.py", scenario])
    watch = DoneWatch()
    t0 = time.monotonic()
    outcome = run_session(spec, options, on_start=lambda r: r.subscribe("status", watch.on_sample))
    wall = time.monotonic() - t0
    return RunRecord(path, scenario, wall, outcome.seconds, outcome.end_reason, watch.collision is not None,
                     (watch.collision or {}).get("collision_with"), float(watch.latest.get("sim_time", 0.0)),
                     watch.min_clearance, len(outcome.crashes))


# -- planning outputs of a log ---------------------------------------------------------------

@dataclass
class Output:
    stamp: float  # header.stamp, sim s: the planning cycle
    log_time: int
    points: list[Point]
    message: Any = field(repr=False, default=None)


def planning_outputs(log: LogContents, spec: Spec) -> list[Output]:
    cfg = spec.planner
    ch = spec.channel(cfg.output)
    codec = get_codec(ch.encoding)
    out = []
    for m in sorted(log.on(ch.key), key=lambda m: m.log_time):
        try:
            msg = codec.decode(m.data)
            stamp = float(msg["header"]["stamp"])
        except Exception:  # noqa: BLE001 — an undecodable output is simply not matched
            continue
        out.append(Output(stamp, m.log_time, trajectory_points(msg, cfg.trajectory), msg))
    return out


def match_by_stamp(reference: Sequence[Output], other: Sequence[Output],
                   tolerance: float = MATCH_TOLERANCE) -> list[Output | None]:
    """For each reference output, the other run's output at the nearest planning cycle (header.stamp).

    Several outputs can share a stamp (the simulator holds sim time at 0 until
    the first command): the j-th reference output of a stamp is paired with the
    j-th of the other run's outputs of that stamp (or its last one). None when
    the other run has no output within `tolerance` of the stamp (it ended
    earlier, or skipped that cycle).
    """
    stamps = [o.stamp for o in other]
    by_stamp: dict[float, list[Output]] = {}
    for o in other:
        by_stamp.setdefault(o.stamp, []).append(o)
    seen: dict[float, int] = {}
    result: list[Output | None] = []
    for ref in reference:
        j = seen.get(ref.stamp, 0)
        seen[ref.stamp] = j + 1
        i = bisect_left(stamps, ref.stamp)
        best = None
        for k in (i - 1, i):
            if 0 <= k < len(stamps) and (best is None or abs(stamps[k] - ref.stamp) < abs(stamps[best] - ref.stamp)):
                best = k
        if best is None or abs(stamps[best] - ref.stamp) > tolerance:
            result.append(None)
            continue
        group = by_stamp[stamps[best]]
        result.append(group[min(j, len(group) - 1)] if stamps[best] == ref.stamp else group[0])
    return result


def rerun_distances(reference: Sequence[Output], other: Sequence[Output]) -> list[float]:
    """Per reference output: lock-step distance of the other run's matched output to it (inf if unmatched)."""
    out = []
    for ref, got in zip(reference, match_by_stamp(reference, other)):
        out.append(math.inf if got is None else compare(got.points, ref.points).distance)
    return out


def collision_times_ns(log: LogContents, spec: Spec) -> tuple[list[int], str]:
    """When collisions happened (recorder clock, ns), and where that came from.

    The run's `violation` events of a `collision` invariant first; failing
    those, the first status message that reports a collision.
    """
    times = [int(e["time_ns"]) for e in log.events("violation")
             if e.get("invariant_kind") == "collision" and e.get("time_ns")]
    if times:
        return sorted(times), "violation events (collision invariant)"
    ch = spec.channel("status")
    codec = get_codec(ch.encoding)
    for m in sorted(log.on(ch.key), key=lambda m: m.log_time):
        try:
            if codec.decode(m.data).get("collision"):
                return [m.log_time], "status channel"
        except Exception:  # noqa: BLE001
            continue
    return [], "none"


def quartiles(values: Sequence[float]) -> tuple[float, float, float]:
    finite = sorted(v for v in values if math.isfinite(v))
    if not finite:
        return (math.nan, math.nan, math.nan)

    def q(p: float) -> float:
        x = p * (len(finite) - 1)
        lo = int(math.floor(x))
        hi = min(lo + 1, len(finite) - 1)
        return finite[lo] + (finite[hi] - finite[lo]) * (x - lo)

    return q(0.25), q(0.5), q(0.75)
