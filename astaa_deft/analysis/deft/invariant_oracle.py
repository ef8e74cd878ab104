"""The module tests' invariant oracle: a minimised failure kept as a test that fails while the planner still breaks it.

``astaa-deft minimise`` writes an ``invariant`` entry into the extracted
suite's manifest (:func:`oracle_entry`); the pytest plugin calls
:func:`check_invariant_oracle` through :func:`.oracle.check_oracle`.
"""

from __future__ import annotations

from dataclasses import replace
from typing import TYPE_CHECKING

from astaa_deft.engine.monitor import MonitorSet, with_typed_invariants
from astaa_deft.engine.monitor.base import ReplayJudges
from astaa_deft.engine.monitor.kinds import invariant_class
from astaa_deft.engine.monitor.verdict import IMPLICIT
from astaa_deft.engine.spec.replay_section import ReplayModule

if TYPE_CHECKING:
    from astaa_deft.analysis.deft.oracle_entry import OracleEntry
    from astaa_deft.analysis.deft.suite import Suite

ORACLE_KIND = "invariant"


def oracle_entry(invariant: str, frame: int, start_ns: int) -> dict:
    """The manifest entry of a module test that fails while the replayed outputs break ``invariant``."""
    return {"kind": ORACLE_KIND, "invariant": invariant, "frame": frame, "start_ns": start_ns}


def check_invariant_oracle(suite: Suite, entry: OracleEntry) -> str | None:
    """Run by the pytest plugin for an ``invariant`` oracle: why the test fails, or None.

    The invariant is judged, as the replay tester judges it, over the
    suite's replayed outputs in frame order at their recorded times; a
    frame the planner raised on is left to its frame test.
    """
    spec = with_typed_invariants(suite.spec)
    cfg = suite.entry
    crash_counts = cfg.per_trigger and cfg.exceptions == "crash"
    invariant = next((i for i in spec.invariants if i.name == entry.invariant), None)
    if invariant is None and not (crash_counts and entry.invariant == IMPLICIT):
        return f"the suite's spec has no invariant '{entry.invariant}'"
    monitors = MonitorSet(replace(spec, invariants=(invariant,) if invariant is not None else ()),
                          entry.start_ns)
    output = cfg.output
    last = entry.start_ns
    for number, (frame, result) in enumerate(zip(suite.frames, suite.results(), strict=False), start=1):
        if result.error is not None and not cfg.per_trigger:
            continue
        last = int(frame["output_time_ns"])
        monitors.on_tick(last)
        if result.stopped == "crash" and crash_counts:
            # The module's own process would have died of this exception: judged as its abnormal exit.
            found = monitors.on_process_exit(cfg.module, 1, None, last, during_shutdown=False)
            if found or invariant is None:
                return (f"frame {frame['index']}: module '{cfg.module}' crashes: {result.error}"
                        + (f" (invariant '{invariant.name}': {found[0].detail})" if found and invariant else ""))
        if result.stopped == "hang" and invariant is not None and (
                invariant_class(invariant.kind).replay_judges is ReplayJudges.TIMING):
            # The module never answers again: the silence the deadline watches for, whatever the history.
            return (f"frame {frame['index']}: module '{cfg.module}' hangs (invariant '{invariant.name}'): "
                    f"{result.error}")
        if result.error is not None or (result.message is None and cfg.per_trigger):
            continue  # a hung or crashed module, or a frame it answers with nothing: no output here
        found = monitors.on_message(output, last, result.message, number)
        if found:
            return (f"frame {frame['index']}: the {_who(cfg)} output breaks invariant '{entry.invariant}': "
                    f"{found[0].detail}")
    found = monitors.finish(last)
    if found:
        return f"the {_who(cfg)} outputs break invariant '{entry.invariant}': {found[0].detail}"
    return None


def _who(cfg: ReplayModule) -> str:
    return "planner's" if cfg.where == "planner" else f"module '{cfg.module}''s"
