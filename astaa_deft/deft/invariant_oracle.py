"""The module tests' invariant oracle: a minimised failure kept as a test that fails while the planner still breaks it.

``astaa-deft minimise`` writes an ``invariant`` entry into the extracted
suite's manifest (:func:`oracle_entry`); the pytest plugin calls
:func:`check_invariant_oracle` through :func:`.oracle.check_oracle`.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import replace
from typing import Any

from ..monitor import MonitorSet, with_typed_invariants
from .planner_section import planner_of

ORACLE_KIND = "invariant"


def oracle_entry(invariant: str, frame: int, start_ns: int) -> dict:
    """The manifest entry of a module test that fails while the replayed outputs break ``invariant``."""
    return {"kind": ORACLE_KIND, "invariant": invariant, "frame": frame, "start_ns": start_ns}


def check_invariant_oracle(suite, entry: Mapping[str, Any]) -> str | None:
    """Run by the pytest plugin for an ``invariant`` oracle: why the test fails, or None.

    The invariant is judged, as the replay tester judges it, over the
    suite's replayed outputs in frame order at their recorded times; a
    frame the planner raised on is left to its frame test.
    """
    spec = with_typed_invariants(suite.spec)
    invariant = next((i for i in spec.invariants if i.name == entry["invariant"]), None)
    if invariant is None:
        return f"the suite's spec has no invariant '{entry['invariant']}'"
    monitors = MonitorSet(replace(spec, invariants=(invariant,)), int(entry.get("start_ns", 0)))
    output = planner_of(spec).output
    last = int(entry.get("start_ns", 0))
    for number, (frame, result) in enumerate(zip(suite.frames, suite.results(), strict=False), start=1):
        if result.error is not None:
            continue
        last = int(frame["output_time_ns"])
        monitors.on_tick(last)
        found = monitors.on_message(output, last, result.message, number)
        if found:
            return (f"frame {frame['index']}: the planner's output breaks invariant '{invariant.name}': "
                    f"{found[0].detail}")
    found = monitors.finish(last)
    if found:
        return f"the planner's outputs break invariant '{invariant.name}': {found[0].detail}"
    return None
